// SPDX-License-Identifier: Apache-2.0
// plumb-backend: receives fragments (live over LCM, from an LCM log, or from a fragment store),
// persists them into the fragment store, then runs the reconstruction pipeline
// (backend/app/backend_cli.hpp).

#include <string>
#include <vector>

#include "backend/app/backend_cli.hpp"

int main(int argc, char** argv) {
    return plumb::backend::runBackendCommand(std::vector<std::string>(argv + 1, argv + argc),
                                             "plumb-backend");
}
