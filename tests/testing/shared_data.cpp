// SPDX-License-Identifier: Apache-2.0
#include "tests/testing/shared_data.hpp"

#include <cstdlib>

namespace plumb::testing {

std::filesystem::path sharedDataDir() {
    if (const char* env = std::getenv("PLUMB_SHARED_DATA_DIR"); env != nullptr && *env != '\0') {
        return env;
    }
    return PLUMB_SHARED_DATA_DIR;
}

bool runningInCi() {
    const char* ci = std::getenv("CI");
    if (ci == nullptr) return false;
    const std::string v = ci;
    return v == "true" || v == "1" || v == "TRUE" || v == "yes";
}

std::filesystem::path freshTempDir(const std::string& name) {
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("plumb-test-" + name);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir;
}

}  // namespace plumb::testing
