# SPDX-License-Identifier: Apache-2.0
# `make demo` and `make test` work on a fresh Debian 12 machine: each installs what is missing,
# configures, builds, then runs the demo or the test suite.
BUILD_DIR ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
ifeq ($(CI),true)
  CMAKE_FLAGS += -DPLUMB_WERROR=ON
endif

.PHONY: all setup configure build test demo format clean

all: build

setup:
	bash tools/setup.sh

configure: setup
	cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) --timeout 1200

demo: build
	$(BUILD_DIR)/tools/plumb demo --out out/demo

format:
	bash tools/format.sh

clean:
	rm -rf $(BUILD_DIR)
