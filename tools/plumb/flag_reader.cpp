// SPDX-License-Identifier: Apache-2.0
#include "tools/plumb/flag_reader.hpp"

#include "tools/plumb/command.hpp"

namespace plumb::tools {

bool FlagReader::next() {
    if (started_) ++index_;
    started_ = true;
    if (index_ >= args_.size()) return false;
    flag_ = args_[index_];
    inline_value_.reset();
    if (flag_.rfind("--", 0) == 0 && flag_.find('=') != std::string::npos) {
        inline_value_ = flag_.substr(flag_.find('=') + 1);
        flag_ = flag_.substr(0, flag_.find('='));
    }
    return true;
}

std::optional<std::string> FlagReader::value() {
    if (inline_value_) return inline_value_;
    if (index_ + 1 >= args_.size()) return std::nullopt;
    return args_[++index_];
}

std::optional<std::string> FlagReader::number(double* out, const char* what) {
    const std::optional<std::string> text = value();
    if (!text) return flag_ + " needs a value (" + what + ")";
    if (!parseNumber(*text, out)) return flag_ + " takes " + what + ", got '" + *text + "'";
    return std::nullopt;
}

std::optional<std::string> FlagReader::positive(double* out, const char* what) {
    const std::optional<std::string> text = value();
    if (!text) return flag_ + " needs a value (" + what + ")";
    double v = 0.0;
    if (!parseNumber(*text, &v) || !(v > 0.0)) {
        return flag_ + " takes " + what + " > 0, got '" + *text + "'";
    }
    *out = v;
    return std::nullopt;
}

}  // namespace plumb::tools
