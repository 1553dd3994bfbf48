// SPDX-License-Identifier: Apache-2.0
#include "common/config/config.hpp"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <system_error>

namespace plumb::config {

Status readTextFile(const std::filesystem::path& path, std::string* text) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
        return notFound(path.string() + ": configuration file does not exist");
    }
    if (std::filesystem::is_directory(path, ec)) {
        return invalidArgument(path.string() + ": is a directory, not a configuration file");
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(path.string() + ": cannot open: " + std::strerror(errno));
    std::ostringstream buffer;
    buffer << in.rdbuf();
    if (in.bad()) return ioError(path.string() + ": read failed");
    *text = buffer.str();
    return Status::ok();
}

Result<ConfigArgs> extractConfigArgs(std::vector<std::string>& args) {
    ConfigArgs out;
    std::vector<std::string> rest;
    bool have_file = false;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        std::string value;
        bool is_config = false;
        bool is_set = false;
        if (a == "--config" || a == "--set") {
            if (i + 1 >= args.size()) return invalidArgument(a + " needs a value");
            is_config = a == "--config";
            is_set = !is_config;
            value = args[++i];
        } else if (a.rfind("--config=", 0) == 0) {
            is_config = true;
            value = a.substr(9);
        } else if (a.rfind("--set=", 0) == 0) {
            is_set = true;
            value = a.substr(6);
        } else {
            rest.push_back(a);
            continue;
        }
        if (is_config) {
            if (have_file) return invalidArgument("--config given twice");
            if (value.empty()) return invalidArgument("--config needs a file name");
            out.file = value;
            have_file = true;
        } else if (is_set) {
            if (value.find('=') == std::string::npos) {
                return invalidArgument("--set " + value + ": expected section.key=value");
            }
            out.overrides.push_back(value);
        }
    }
    args = std::move(rest);
    return out;
}

}  // namespace plumb::config
