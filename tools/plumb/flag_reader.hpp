// SPDX-License-Identifier: Apache-2.0
#pragma once

// The command-line walk shared by the `plumb eval` commands: flags as `--flag VALUE` or
// `--flag=VALUE`, everything else positional; errors come back as the message for usageError().

#include <optional>
#include <string>
#include <vector>

namespace plumb::tools {

/// Walks `args` one argument at a time. Not thread-safe (one parser, one thread); `args` must
/// outlive the reader.
class FlagReader {
  public:
    explicit FlagReader(const std::vector<std::string>& args) : args_(args) {}

    /// Moves to the next argument (after any value() consumed); false when there is none.
    bool next();
    /// The current argument's flag: "--frame" of "--frame=gt" or of "--frame gt"; a positional
    /// argument as it is.
    const std::string& flag() const { return flag_; }
    /// The current argument as typed.
    const std::string& arg() const { return args_[index_]; }
    /// True when the current argument carries its value ("--flag=VALUE").
    bool hasInlineValue() const { return inline_value_.has_value(); }
    /// True when the current argument is an option ('-' and at least one more character).
    bool isOption() const { return flag_.size() > 1 && flag_[0] == '-'; }

    /// The current flag's value: the inline one, else the next argument (consumed); nullopt
    /// when there is none.
    std::optional<std::string> value();
    /// Parses the value (parseNumber) into *out. nullopt on success, else the message:
    /// "F needs a value (WHAT)" or "F takes WHAT, got 'V'".
    std::optional<std::string> number(double* out, const char* what);
    /// As number() for a value > 0 ("F takes WHAT > 0, got 'V'"); *out is left alone on error.
    std::optional<std::string> positive(double* out, const char* what);

  private:
    const std::vector<std::string>& args_;
    size_t index_ = 0;
    bool started_ = false;
    std::string flag_;
    std::optional<std::string> inline_value_;
};

}  // namespace plumb::tools
