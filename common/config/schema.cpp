// SPDX-License-Identifier: Apache-2.0
#include "common/config/schema.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <sstream>
#include <utility>

namespace plumb::config {

namespace detail {

struct Node {
    const toml::node& node;
};

}  // namespace detail

namespace {

using detail::Node;

// ---------------------------------------------------------------- number and string formatting

std::string shortestDouble(double v) {
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof(buf), v);
    return std::string(buf, r.ptr);
}

// TOML floats need a fraction or an exponent; nan and inf are spelled as in TOML.
std::string tomlFloat(std::string text) {
    if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
    return text;
}

std::string formatDoubleValue(double v) {
    if (std::isnan(v)) return "nan";
    if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
    return tomlFloat(shortestDouble(v));
}

std::string formatFloatValue(float v) {
    if (std::isnan(v)) return "nan";
    if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
    // The shortest float text is the nicest, but it is read back as a double and then rounded to
    // float; use it only when that double rounding gives back the same float.
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof(buf), v);
    std::string text(buf, r.ptr);
    if (static_cast<float>(std::strtod(text.c_str(), nullptr)) == v) return tomlFloat(text);
    return formatDoubleValue(static_cast<double>(v));
}

std::string quote(std::string_view s) {
    std::string out = "\"";
    for (const char ch : s) {
        const auto c = static_cast<unsigned char>(ch);
        switch (c) {
            case '"':
                out += "\\\"";
                break;
            case '\\':
                out += "\\\\";
                break;
            case '\n':
                out += "\\n";
                break;
            case '\t':
                out += "\\t";
                break;
            case '\r':
                out += "\\r";
                break;
            case '\b':
                out += "\\b";
                break;
            case '\f':
                out += "\\f";
                break;
            default:
                if (c < 0x20 || c == 0x7f) {
                    char esc[8];
                    std::snprintf(esc, sizeof(esc), "\\u%04x", c);
                    out += esc;
                } else {
                    out += ch;
                }
        }
    }
    return out + "\"";
}

template <typename T, typename F>
std::string formatArray(const T& values, F&& format_one) {
    std::string out = "[";
    bool first = true;
    for (const auto& v : values) {
        if (!first) out += ", ";
        out += format_one(v);
        first = false;
    }
    return out + "]";
}

// ---------------------------------------------------------------- reading typed values

const char* describeNode(const toml::node& n) {
    switch (n.type()) {
        case toml::node_type::table:
            return "a table";
        case toml::node_type::array:
            return "an array";
        case toml::node_type::string:
            return "a string";
        case toml::node_type::integer:
            return "an integer";
        case toml::node_type::floating_point:
            return "a float";
        case toml::node_type::boolean:
            return "a boolean";
        case toml::node_type::date:
            return "a date";
        case toml::node_type::time:
            return "a time";
        case toml::node_type::date_time:
            return "a date-time";
        case toml::node_type::none:
            break;
    }
    return "nothing";
}

bool mismatch(const toml::node& n, const char* expected, std::string* error) {
    *error = std::string("expected ") + expected + ", got " + describeNode(n);
    return false;
}

bool readInt64(const toml::node& n, int64_t* out, std::string* error) {
    if (const auto* v = n.as_integer()) {
        *out = v->get();
        return true;
    }
    return mismatch(n, "an integer", error);
}

bool readDouble(const toml::node& n, double* out, std::string* error) {
    if (const auto* v = n.as_floating_point()) {
        *out = v->get();
        return true;
    }
    if (const auto* v = n.as_integer()) {
        *out = static_cast<double>(v->get());
        return true;
    }
    return mismatch(n, "a float", error);
}

bool readFloat(const toml::node& n, float* out, std::string* error) {
    double d = 0.0;
    if (!readDouble(n, &d, error)) return false;
    // Doubles from FLT_MAX + half an ulp upwards would round to infinity.
    const double overflow = std::ldexp(1.0, 128) - std::ldexp(1.0, 103);
    if (std::isfinite(d) && std::abs(d) >= overflow) {
        *error = "value " + shortestDouble(d) + " does not fit in a 32-bit float";
        return false;
    }
    *out = static_cast<float>(d);
    return true;
}

bool readString(const toml::node& n, std::string* out, std::string* error) {
    if (const auto* v = n.as_string()) {
        *out = v->get();
        return true;
    }
    return mismatch(n, "a string", error);
}

template <typename T, typename F>
bool readArray(const toml::node& n, const char* expected, F&& read_one, std::vector<T>* out,
               std::string* error) {
    const toml::array* a = n.as_array();
    if (a == nullptr) return mismatch(n, expected, error);
    std::vector<T> values(a->size());
    for (size_t i = 0; i < a->size(); ++i) {
        std::string why;
        if (!read_one(*a->get(i), &values[i], &why)) {
            *error = "element " + std::to_string(i) + " of the array: " + why;
            return false;
        }
    }
    *out = std::move(values);
    return true;
}

template <typename Vec>
bool readVector3(const toml::node& n, Vec* out, std::string* error) {
    std::vector<double> values;
    if (!readArray<double>(n, "an array of 3 floats", readDouble, &values, error)) return false;
    if (values.size() != 3) {
        *error =
            "expected an array of 3 floats, got " + std::to_string(values.size()) + " elements";
        return false;
    }
    for (int i = 0; i < 3; ++i) (*out)[i] = static_cast<typename Vec::Scalar>(values[i]);
    return true;
}

// ---------------------------------------------------------------- errors with a place

struct Problem {
    int64_t line = 0;
    int64_t column = 0;
    std::string text;
};

std::string joinProblems(std::vector<Problem> problems, std::string_view source_name) {
    std::stable_sort(problems.begin(), problems.end(), [](const Problem& a, const Problem& b) {
        return std::tie(a.line, a.column) < std::tie(b.line, b.column);
    });
    std::string out;
    for (const Problem& p : problems) {
        if (!out.empty()) out += "\n";
        out += std::string(source_name) + ":" + std::to_string(p.line) + ":" +
               std::to_string(p.column) + ": " + p.text;
    }
    return out;
}

std::string joinPath(std::string_view prefix, std::string_view key) {
    return prefix.empty() ? std::string(key) : std::string(prefix) + "." + std::string(key);
}

const Schema::Entry* findEntry(const Schema& s, std::string_view key) {
    for (const Schema::Entry& e : s.entries()) {
        if (e.key == key) return &e;
    }
    return nullptr;
}

// All dotted paths of fields and sections below `s`.
void collectPaths(const Schema& s, const std::string& prefix, std::vector<std::string>* out) {
    for (const Schema::Entry& e : s.entries()) {
        const std::string path = joinPath(prefix, e.key);
        out->push_back(path);
        if (e.isSection()) collectPaths(*e.section, path, out);
    }
}

// " (did you mean 'x'?)" for the closest key of the same section, else for a key of the same name
// in another section of `root`; "" when nothing is close.
std::string suggestion(const Schema& root, const Schema& section, const std::string& prefix,
                       std::string_view key) {
    const size_t threshold = std::max<size_t>(2, key.size() / 3);
    size_t best = std::numeric_limits<size_t>::max();
    std::string best_key;
    for (const Schema::Entry& e : section.entries()) {
        const size_t d = editDistance(key, e.key);
        if (d < best) {
            best = d;
            best_key = e.key;
        }
    }
    if (best <= threshold) return " (did you mean '" + joinPath(prefix, best_key) + "'?)";
    std::vector<std::string> paths;
    collectPaths(root, "", &paths);
    for (const std::string& path : paths) {
        const size_t dot = path.rfind('.');
        const std::string_view last = dot == std::string::npos
                                          ? std::string_view(path)
                                          : std::string_view(path).substr(dot + 1);
        if (editDistance(last, key) == 0 && path != joinPath(prefix, key)) {
            return " (did you mean '" + path + "'?)";
        }
    }
    return "";
}

std::string outOfRange(const std::string& path, const Schema::Entry& e) {
    return "'" + path + "' = " + e.format() + " is out of range " + e.bounds.toString() +
           (e.unit.empty() ? "" : " " + e.unit);
}

// Checks the bounds of a field that was just assigned; "" when fine.
std::string checkBounds(const std::string& path, const Schema::Entry& e) {
    const std::optional<std::vector<double>> nums = e.numbers();
    if (!nums) return "'" + path + "' = " + e.format() + " is invalid (expected " + e.type + ")";
    for (const double v : *nums) {
        if (!e.bounds.contains(v)) return outOfRange(path, e);
    }
    return "";
}

void applyTable(const Schema& root, const Schema& schema, const toml::table& table,
                const std::string& prefix, std::vector<Problem>* problems) {
    for (auto&& [key, node] : table) {
        const std::string path = joinPath(prefix, key.str());
        const toml::source_region& where =
            key.source().begin.line != 0 ? key.source() : node.source();
        auto report = [&](std::string text) {
            problems->push_back({static_cast<int64_t>(where.begin.line),
                                 static_cast<int64_t>(where.begin.column), std::move(text)});
        };
        const Schema::Entry* e = findEntry(schema, key.str());
        if (e == nullptr) {
            report("unknown key '" + path + "'" + suggestion(root, schema, prefix, key.str()));
            continue;
        }
        if (e->isSection()) {
            if (const toml::table* sub = node.as_table()) {
                applyTable(root, *e->section, *sub, path, problems);
            } else {
                report("'" + path + "' is a section: expected a table, got " + describeNode(node));
            }
            continue;
        }
        std::string why;
        if (!e->read(Node{node}, &why)) {
            report("'" + path + "': " + why + (e->unit.empty() ? "" : " (unit: " + e->unit + ")"));
            continue;
        }
        if (std::string bad = checkBounds(path, *e); !bad.empty()) report(bad);
    }
}

void validateInto(const Schema& s, const std::string& prefix, std::vector<std::string>* out) {
    for (const Schema::Entry& e : s.entries()) {
        const std::string path = joinPath(prefix, e.key);
        if (e.isSection()) {
            validateInto(*e.section, path, out);
        } else if (std::string bad = checkBounds(path, e); !bad.empty()) {
            out->push_back(std::move(bad));
        }
    }
}

std::string commentLines(std::string_view text) {
    std::string out;
    std::istringstream in{std::string(text)};
    std::string line;
    while (std::getline(in, line)) out += line.empty() ? "#\n" : "# " + line + "\n";
    return out;
}

std::string fieldComment(const Schema::Entry& e) {
    std::string text = e.doc;
    if (!text.empty() && text.back() != '.') text += ".";
    std::string details = "Type: " + e.type + ".";
    if (!e.unit.empty()) details += " Unit: " + e.unit + ".";
    if (const std::string range = e.bounds.toString(); !range.empty()) {
        details += " Range: " + range + ".";
    }
    if (!e.default_text.empty()) details += " Default: " + e.default_text + ".";
    return commentLines(text + "\n" + details);
}

void writeToml(const Schema& s, const std::string& prefix, std::string_view section_doc,
               std::string* out) {
    if (!prefix.empty()) {
        *out += "\n";
        if (!section_doc.empty()) *out += commentLines(section_doc);
        *out += "[" + prefix + "]\n";
    }
    for (const Schema::Entry& e : s.entries()) {
        if (e.isSection()) continue;
        *out += '\n';
        *out += fieldComment(e);
        *out += e.key;
        *out += " = ";
        *out += e.format();
        *out += '\n';
    }
    for (const Schema::Entry& e : s.entries()) {
        if (e.isSection()) writeToml(*e.section, joinPath(prefix, e.key), e.doc, out);
    }
}

std::string markdownCell(std::string_view text) {
    std::string out;
    for (const char c : text) {
        if (c == '|') {
            out += "\\|";
        } else if (c == '\n') {
            out += ' ';
        } else {
            out += c;
        }
    }
    return out;
}

void writeMarkdownRows(const Schema& s, const std::string& prefix, std::string* out) {
    for (const Schema::Entry& e : s.entries()) {
        if (e.isSection()) continue;
        std::string meaning = e.doc;
        if (const std::string range = e.bounds.toString(); !range.empty()) {
            meaning += " (range " + range + ")";
        }
        *out += "| `" + joinPath(prefix, e.key) + "` | " + markdownCell(e.type) + " | `" +
                markdownCell(e.default_text.empty() ? e.format() : e.default_text) + "` | " +
                markdownCell(e.unit) + " | " + markdownCell(meaning) + " |\n";
    }
    for (const Schema::Entry& e : s.entries()) {
        if (e.isSection()) writeMarkdownRows(*e.section, joinPath(prefix, e.key), out);
    }
}

void collectFieldKeys(const Schema& s, const std::string& prefix, std::vector<std::string>* out) {
    for (const Schema::Entry& e : s.entries()) {
        if (e.isSection()) {
            collectFieldKeys(*e.section, joinPath(prefix, e.key), out);
        } else {
            out->push_back(joinPath(prefix, e.key));
        }
    }
}

bool isBareKey(std::string_view key) {
    if (key.empty()) return false;
    return std::all_of(key.begin(), key.end(), [](char c) {
        return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
               c == '_' || c == '-';
    });
}

std::string_view trim(std::string_view s) {
    const auto space = [](char c) { return c == ' ' || c == '\t'; };
    while (!s.empty() && space(s.front())) s.remove_prefix(1);
    while (!s.empty() && space(s.back())) s.remove_suffix(1);
    return s;
}

}  // namespace

// ---------------------------------------------------------------- detail: typed read/format

namespace detail {

bool read(const Node& n, bool* out, std::string* error) {
    if (const auto* v = n.node.as_boolean()) {
        *out = v->get();
        return true;
    }
    return mismatch(n.node, "a boolean (true or false)", error);
}

bool read(const Node& n, int* out, std::string* error) {
    int64_t v = 0;
    if (!readInt64(n.node, &v, error)) return false;
    if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max()) {
        *error = "value " + std::to_string(v) + " does not fit in a 32-bit integer";
        return false;
    }
    *out = static_cast<int>(v);
    return true;
}

bool read(const Node& n, int64_t* out, std::string* error) { return readInt64(n.node, out, error); }

bool read(const Node& n, uint64_t* out, std::string* error) {
    int64_t v = 0;
    if (!readInt64(n.node, &v, error)) return false;
    if (v < 0) {
        *error = "expected a non-negative integer, got " + std::to_string(v);
        return false;
    }
    *out = static_cast<uint64_t>(v);
    return true;
}

bool read(const Node& n, float* out, std::string* error) { return readFloat(n.node, out, error); }
bool read(const Node& n, double* out, std::string* error) { return readDouble(n.node, out, error); }
bool read(const Node& n, std::string* out, std::string* error) {
    return readString(n.node, out, error);
}
bool read(const Node& n, Eigen::Vector3d* out, std::string* error) {
    return readVector3(n.node, out, error);
}
bool read(const Node& n, Eigen::Vector3f* out, std::string* error) {
    return readVector3(n.node, out, error);
}
bool read(const Node& n, std::vector<double>* out, std::string* error) {
    return readArray<double>(n.node, "an array of floats", readDouble, out, error);
}
bool read(const Node& n, std::vector<int64_t>* out, std::string* error) {
    return readArray<int64_t>(n.node, "an array of integers", readInt64, out, error);
}
bool read(const Node& n, std::vector<std::string>* out, std::string* error) {
    return readArray<std::string>(n.node, "an array of strings", readString, out, error);
}

std::string format(bool v) { return v ? "true" : "false"; }
std::string format(int v) { return std::to_string(v); }
std::string format(int64_t v) { return std::to_string(v); }
std::string format(uint64_t v) { return std::to_string(v); }
std::string format(float v) { return formatFloatValue(v); }
std::string format(double v) { return formatDoubleValue(v); }
std::string format(const std::string& v) { return quote(v); }
std::string format(const Eigen::Vector3d& v) {
    return formatArray(v, [](double x) { return formatDoubleValue(x); });
}
std::string format(const Eigen::Vector3f& v) {
    return formatArray(v, [](float x) { return formatFloatValue(x); });
}
std::string format(const std::vector<double>& v) {
    return formatArray(v, [](double x) { return formatDoubleValue(x); });
}
std::string format(const std::vector<int64_t>& v) {
    return formatArray(v, [](int64_t x) { return std::to_string(x); });
}
std::string format(const std::vector<std::string>& v) {
    return formatArray(v, [](const std::string& x) { return quote(x); });
}

const char* typeName(const bool*) { return "boolean"; }
const char* typeName(const int*) { return "integer"; }
const char* typeName(const int64_t*) { return "integer"; }
const char* typeName(const uint64_t*) { return "integer"; }
const char* typeName(const float*) { return "float"; }
const char* typeName(const double*) { return "float"; }
const char* typeName(const std::string*) { return "string"; }
const char* typeName(const Eigen::Vector3d*) { return "array of 3 floats"; }
const char* typeName(const Eigen::Vector3f*) { return "array of 3 floats"; }
const char* typeName(const std::vector<double>*) { return "array of floats"; }
const char* typeName(const std::vector<int64_t>*) { return "array of integers"; }
const char* typeName(const std::vector<std::string>*) { return "array of strings"; }

}  // namespace detail

// ---------------------------------------------------------------- Bounds

bool Bounds::contains(double v) const {
    if (lo && !(lo_exclusive ? v > *lo : v >= *lo)) return false;
    if (hi && !(hi_exclusive ? v < *hi : v <= *hi)) return false;
    return true;
}

std::string Bounds::toString() const {
    if (lo && hi) {
        return std::string(lo_exclusive ? "(" : "[") + shortestDouble(*lo) + ", " +
               shortestDouble(*hi) + (hi_exclusive ? ")" : "]");
    }
    if (lo) return std::string(lo_exclusive ? "> " : ">= ") + shortestDouble(*lo);
    if (hi) return std::string(hi_exclusive ? "< " : "<= ") + shortestDouble(*hi);
    return "";
}

// ---------------------------------------------------------------- Schema

Bounds& Schema::FieldOptions::bounds() { return schema_->entries_[index_].bounds; }

Schema::FieldOptions& Schema::FieldOptions::min(double lo) {
    bounds().lo = lo;
    bounds().lo_exclusive = false;
    return *this;
}
Schema::FieldOptions& Schema::FieldOptions::max(double hi) {
    bounds().hi = hi;
    bounds().hi_exclusive = false;
    return *this;
}
Schema::FieldOptions& Schema::FieldOptions::range(double lo, double hi) {
    PLUMB_CHECK(lo <= hi) << "range [" << lo << ", " << hi << "] of '"
                          << schema_->entries_[index_].key << "' is empty";
    return min(lo).max(hi);
}
Schema::FieldOptions& Schema::FieldOptions::greaterThan(double lo) {
    bounds().lo = lo;
    bounds().lo_exclusive = true;
    return *this;
}
Schema::FieldOptions& Schema::FieldOptions::lessThan(double hi) {
    bounds().hi = hi;
    bounds().hi_exclusive = true;
    return *this;
}

Schema::Entry& Schema::addEntry(std::string_view key, std::string_view doc) {
    PLUMB_CHECK(isBareKey(key)) << "configuration key '" << key
                                << "' must be a TOML bare key [A-Za-z0-9_-]+";
    PLUMB_CHECK(findEntry(*this, key) == nullptr)
        << "configuration key '" << key << "' is declared twice";
    Entry& e = entries_.emplace_back();
    e.key = std::string(key);
    e.doc = std::string(doc);
    return e;
}

Status Schema::applyToml(std::string_view text, std::string_view source_name) {
    toml::table table;
    try {
        table = toml::parse(text, std::string_view(source_name));
    } catch (const toml::parse_error& err) {
        const toml::source_position& at = err.source().begin;
        return invalidArgument(std::string(source_name) + ":" + std::to_string(at.line) + ":" +
                               std::to_string(at.column) +
                               ": TOML syntax error: " + std::string(err.description()));
    } catch (const std::exception& err) {
        return invalidArgument(std::string(source_name) + ": cannot parse TOML: " + err.what());
    }
    std::vector<Problem> problems;
    applyTable(*this, *this, table, "", &problems);
    if (problems.empty()) return Status::ok();
    return invalidArgument(joinProblems(std::move(problems), source_name));
}

Status Schema::applyAssignment(std::string_view assignment) {
    const std::string flag = "--set " + std::string(assignment);
    const size_t eq = assignment.find('=');
    if (eq == std::string_view::npos) {
        return invalidArgument(flag + ": expected section.key=value");
    }
    const std::string_view path = trim(assignment.substr(0, eq));
    const std::string_view value = trim(assignment.substr(eq + 1));
    if (path.empty()) return invalidArgument(flag + ": the key is empty");

    // Walk the dotted path down to the field.
    const Schema* schema = this;
    std::string prefix;
    std::string_view rest = path;
    const Entry* e = nullptr;
    while (true) {
        const size_t dot = rest.find('.');
        const std::string_view part = rest.substr(0, dot);
        e = findEntry(*schema, part);
        if (e == nullptr) {
            return invalidArgument(flag + ": unknown key '" + std::string(path) + "'" +
                                   suggestion(*this, *schema, prefix, part));
        }
        prefix = joinPath(prefix, part);
        if (dot == std::string_view::npos) break;
        if (!e->isSection()) {
            return invalidArgument(flag + ": '" + prefix + "' is a key, not a section");
        }
        schema = e->section.get();
        rest = rest.substr(dot + 1);
    }
    if (e->isSection()) {
        return invalidArgument(flag + ": '" + prefix + "' is a section; set one of its keys (" +
                               prefix + ".<key>=value)");
    }

    // The value is TOML; strings and enum names may be given without quotes.
    toml::table parsed;
    bool parsed_ok = false;
    try {
        const std::string doc = "v = " + std::string(value);
        parsed = toml::parse(std::string_view(doc), std::string_view("--set"));
        parsed_ok = parsed.contains("v");
    } catch (const std::exception&) {  // toml::parse_error or allocation failure
        parsed_ok = false;
    }
    std::string why;
    if (e->takes_text && !(parsed_ok && parsed.get("v")->is_string())) {
        const toml::value<std::string> text{std::string(value)};
        if (!e->read(detail::Node{text}, &why)) {
            return invalidArgument(flag + ": '" + prefix + "': " + why);
        }
    } else if (!parsed_ok) {
        return invalidArgument(flag + ": '" + std::string(value) + "' is not a valid " + e->type +
                               " value");
    } else if (!e->read(detail::Node{*parsed.get("v")}, &why)) {
        return invalidArgument(flag + ": '" + prefix + "': " + why);
    }
    if (std::string bad = checkBounds(prefix, *e); !bad.empty()) {
        return invalidArgument(flag + ": " + bad);
    }
    return Status::ok();
}

Status Schema::validate() const {
    std::vector<std::string> problems;
    validateInto(*this, "", &problems);
    if (problems.empty()) return Status::ok();
    std::string text;
    for (const std::string& p : problems) text += (text.empty() ? "" : "\n") + p;
    return invalidArgument(text);
}

void Schema::attachDefaults(const Schema& defaults) {
    PLUMB_CHECK(defaults.entries_.size() == entries_.size())
        << "describe() listed " << entries_.size() << " and " << defaults.entries_.size()
        << " keys for two instances of the same struct";
    for (size_t i = 0; i < entries_.size(); ++i) {
        Entry& e = entries_[i];
        const Entry& d = defaults.entries_[i];
        PLUMB_CHECK(e.key == d.key && e.isSection() == d.isSection())
            << "describe() must list the same keys for every instance ('" << e.key << "' vs '"
            << d.key << "')";
        if (e.isSection()) {
            e.section->attachDefaults(*d.section);
        } else {
            e.default_text = d.format();
        }
    }
}

std::string Schema::toToml(std::string_view title) const {
    std::string out;
    if (!title.empty()) out += commentLines(title);
    out += commentLines(
        "Every key is optional: a missing key keeps its default. Unknown keys are errors.");
    writeToml(*this, "", "", &out);
    return out;
}

std::string Schema::toMarkdown() const {
    std::string out =
        "| key | type | default | unit | meaning |\n"
        "|---|---|---|---|---|\n";
    writeMarkdownRows(*this, "", &out);
    return out;
}

std::vector<std::string> Schema::keys() const {
    std::vector<std::string> out;
    collectFieldKeys(*this, "", &out);
    return out;
}

size_t editDistance(std::string_view a, std::string_view b) {
    const auto lower = [](char c) { return (c >= 'A' && c <= 'Z') ? char(c - 'A' + 'a') : c; };
    const size_t n = a.size(), m = b.size();
    // d[i][j]: distance between the first i characters of a and the first j of b.
    std::vector<std::vector<size_t>> d(n + 1, std::vector<size_t>(m + 1, 0));
    for (size_t i = 0; i <= n; ++i) d[i][0] = i;
    for (size_t j = 0; j <= m; ++j) d[0][j] = j;
    for (size_t i = 1; i <= n; ++i) {
        for (size_t j = 1; j <= m; ++j) {
            const size_t cost = lower(a[i - 1]) == lower(b[j - 1]) ? 0 : 1;
            d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
            if (i > 1 && j > 1 && lower(a[i - 1]) == lower(b[j - 2]) &&
                lower(a[i - 2]) == lower(b[j - 1])) {
                d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
            }
        }
    }
    return d[n][m];
}

}  // namespace plumb::config
