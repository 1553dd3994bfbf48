// SPDX-License-Identifier: Apache-2.0
#pragma once

// Locating ../shared/data from tests. Without the data a test skips, except under CI=true, where
// missing data is a failure (CI always has it).

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace plumb::testing {

/// The shared data directory (compiled-in path, or $PLUMB_SHARED_DATA_DIR when set).
std::filesystem::path sharedDataDir();

/// True under CI=true (or CI=1).
bool runningInCi();

/// A fresh, empty temporary directory unique to the calling test; removed by the next call
/// with the same name.
std::filesystem::path freshTempDir(const std::string& name);

}  // namespace plumb::testing

/// Declares `path` = sharedDataDir()/relative; skips the test (fails under CI) if it is missing.
#define PLUMB_REQUIRE_SHARED_DATA(path, relative)                                      \
    const std::filesystem::path path = ::plumb::testing::sharedDataDir() / (relative); \
    do {                                                                               \
        if (!std::filesystem::exists(path)) {                                          \
            if (::plumb::testing::runningInCi()) {                                     \
                FAIL() << "shared data missing under CI: " << path;                    \
            } else {                                                                   \
                GTEST_SKIP() << "shared data not found: " << path;                     \
            }                                                                          \
        }                                                                              \
    } while (false)
