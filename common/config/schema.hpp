// SPDX-License-Identifier: Apache-2.0
#pragma once

// The description of a configuration struct, written once per module and used for everything
// else: loading TOML files, `--set key=value` overrides, writing the effective configuration and
// documenting every key.
//
// A module keeps its Config as a plain struct with in-class defaults and declares one free function
// next to it (found by argument-dependent lookup):
//
//   struct TsdfConfig {
//       /// Voxel edge length in metres.
//       double voxel_size_m = 0.01;
//       /// Truncation distance in voxels.
//       int truncation_voxels = 4;
//   };
//   void describe(plumb::config::Schema& s, TsdfConfig& c) {
//       s.field("voxel_size_m", c.voxel_size_m, "TSDF voxel edge length", "m").positive().max(1.0);
//       s.field("truncation_voxels", c.truncation_voxels, "truncation distance", "voxels").min(1);
//   }
//   void describe(plumb::config::Schema& s, FusionConfig& c) {
//       s.section("tsdf", c.tsdf, "the fused volume");
//   }
//
// Contract for describe(): it lists the same keys in the same order whatever the values in `c`
// are, and every field reference points into `c`. Keys are TOML bare keys ([A-Za-z0-9_-]+) and
// unique within their section. The operations themselves live in common/config/config.hpp.
//
// Supported field types: bool, int, int64_t, uint64_t, float, double, std::string,
// Eigen::Vector3d, Eigen::Vector3f, std::vector<double>, std::vector<int64_t>,
// std::vector<std::string>, and any enum with a name table (EnumName).
//
// Thread-safety: a Schema is bound to one struct instance; use it from one thread at a time.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "common/core/check.hpp"
#include "common/core/status.hpp"

namespace plumb::config {

/// One entry of an enum's name table: `{Mode::kFast, "fast"}`.
template <typename E>
struct EnumName {
    E value;
    const char* name;
};

/// Inclusive or exclusive numeric limits of a field (applied to every element of an array).
struct Bounds {
    std::optional<double> lo;   ///< lower limit, none when unbounded below
    std::optional<double> hi;   ///< upper limit, none when unbounded above
    bool lo_exclusive = false;  ///< true: value > lo; false: value >= lo
    bool hi_exclusive = false;  ///< true: value < hi; false: value <= hi
    /// True when `v` satisfies both limits (NaN satisfies none unless unbounded).
    bool contains(double v) const;
    /// "[0, 1]", "(0, 1]", ">= 1", "> 0", "<= 10", or "" when unbounded.
    std::string toString() const;
};

namespace detail {

/// A parsed TOML value (wraps toml::node; defined in schema.cpp so toml++ stays out of headers).
struct Node;

// Reading one TOML value into a supported C++ type: true and `*out` assigned on success, false
// and `*error` = what was expected and what was found (e.g. "expected a float, got a string").
bool read(const Node& node, bool* out, std::string* error);
bool read(const Node& node, int* out, std::string* error);
bool read(const Node& node, int64_t* out, std::string* error);
bool read(const Node& node, uint64_t* out, std::string* error);
bool read(const Node& node, float* out, std::string* error);
bool read(const Node& node, double* out, std::string* error);
bool read(const Node& node, std::string* out, std::string* error);
bool read(const Node& node, Eigen::Vector3d* out, std::string* error);
bool read(const Node& node, Eigen::Vector3f* out, std::string* error);
bool read(const Node& node, std::vector<double>* out, std::string* error);
bool read(const Node& node, std::vector<int64_t>* out, std::string* error);
bool read(const Node& node, std::vector<std::string>* out, std::string* error);

// Writing a value as TOML text that reads back to the identical value.
std::string format(bool v);
std::string format(int v);
std::string format(int64_t v);
std::string format(uint64_t v);
std::string format(float v);
std::string format(double v);
std::string format(const std::string& v);
std::string format(const Eigen::Vector3d& v);
std::string format(const Eigen::Vector3f& v);
std::string format(const std::vector<double>& v);
std::string format(const std::vector<int64_t>& v);
std::string format(const std::vector<std::string>& v);

// The type as documentation shows it ("float", "integer", "array of 3 floats", ...).
const char* typeName(const bool*);
const char* typeName(const int*);
const char* typeName(const int64_t*);
const char* typeName(const uint64_t*);
const char* typeName(const float*);
const char* typeName(const double*);
const char* typeName(const std::string*);
const char* typeName(const Eigen::Vector3d*);
const char* typeName(const Eigen::Vector3f*);
const char* typeName(const std::vector<double>*);
const char* typeName(const std::vector<int64_t>*);
const char* typeName(const std::vector<std::string>*);

// The numbers a range applies to (empty for booleans and strings).
template <typename T>
std::vector<double> numbers(const T& v) {
    if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
        return {static_cast<double>(v)};
    } else if constexpr (std::is_same_v<T, Eigen::Vector3d> || std::is_same_v<T, Eigen::Vector3f>) {
        return {static_cast<double>(v.x()), static_cast<double>(v.y()), static_cast<double>(v.z())};
    } else if constexpr (std::is_same_v<T, std::vector<double>> ||
                         std::is_same_v<T, std::vector<int64_t>>) {
        return std::vector<double>(v.begin(), v.end());
    } else {
        return {};
    }
}

}  // namespace detail

/// The description of one struct: its fields (bound to the struct's members) and nested sections.
class Schema {
  public:
    /// One key of a section: a field (value accessors set) or a nested section (`section` set).
    struct Entry {
        std::string key;           ///< TOML bare key within its section
        std::string doc;           ///< one-line meaning
        std::string unit;          ///< unit of the value ("m", "rad", "frames"), may be empty
        std::string type;          ///< type as documented ("float", "one of: a, b")
        Bounds bounds;             ///< numeric limits, unbounded by default
        std::string default_text;  ///< TOML text of the default, when attached (see withDefaults)
        bool takes_text = false;   ///< true for strings and enums (`--set k=v` needs no quotes)
        /// Reads a TOML value into the bound member; false with a reason on a type mismatch.
        std::function<bool(const detail::Node&, std::string*)> read;
        /// The bound member as TOML text.
        std::function<std::string()> format;
        /// The numbers `bounds` applies to; an empty optional marks an invalid value (an enum
        /// value without a name).
        std::function<std::optional<std::vector<double>>()> numbers;
        std::unique_ptr<Schema> section;  ///< set for a nested section, null for a field

        bool isSection() const { return section != nullptr; }
    };

    /// Chained limits on the field just declared: `s.field(...).min(0).max(1)`.
    class FieldOptions {
      public:
        FieldOptions(Schema* schema, size_t index) : schema_(schema), index_(index) {}
        /// value >= lo
        FieldOptions& min(double lo);
        /// value <= hi
        FieldOptions& max(double hi);
        /// lo <= value <= hi
        FieldOptions& range(double lo, double hi);
        /// value > lo
        FieldOptions& greaterThan(double lo);
        /// value < hi
        FieldOptions& lessThan(double hi);
        /// value > 0
        FieldOptions& positive() { return greaterThan(0.0); }

      private:
        Bounds& bounds();
        Schema* schema_;
        size_t index_;
    };

    Schema() = default;
    Schema(Schema&&) = default;
    Schema& operator=(Schema&&) = default;
    Schema(const Schema&) = delete;
    Schema& operator=(const Schema&) = delete;

    /// Declares a field bound to `value`. `unit` may be empty for unitless values.
    template <typename T>
    FieldOptions field(std::string_view key, T& value, std::string_view doc,
                       std::string_view unit = {}) {
        static_assert(!std::is_enum_v<T>, "enum fields need a name table (EnumName)");
        Entry& e = addEntry(key, doc);
        e.unit = std::string(unit);
        e.type = detail::typeName(static_cast<const T*>(nullptr));
        e.takes_text = std::is_same_v<T, std::string>;
        T* p = &value;
        e.read = [p](const detail::Node& node, std::string* error) {
            return detail::read(node, p, error);
        };
        e.format = [p] { return detail::format(*p); };
        e.numbers = [p] { return std::optional<std::vector<double>>(detail::numbers(*p)); };
        return FieldOptions(this, entries_.size() - 1);
    }

    /// Declares an enum field written as one of the names in `names`.
    template <typename E, size_t N>
    FieldOptions field(std::string_view key, E& value, std::string_view doc,
                       const std::array<EnumName<E>, N>& names) {
        static_assert(std::is_enum_v<E>, "a name table is for enum fields");
        static_assert(N > 0, "an enum name table needs at least one name");
        Entry& e = addEntry(key, doc);
        std::vector<std::pair<E, std::string>> table;
        std::string choices;
        for (const EnumName<E>& n : names) {
            table.emplace_back(n.value, n.name);
            choices += (choices.empty() ? "" : ", ") + std::string(n.name);
        }
        e.type = "one of: " + choices;
        e.takes_text = true;
        E* p = &value;
        e.read = [p, table, choices](const detail::Node& node, std::string* error) {
            std::string text;
            if (!detail::read(node, &text, error)) return false;
            for (const auto& [v, name] : table) {
                if (name == text) {
                    *p = v;
                    return true;
                }
            }
            *error = "expected one of " + choices + ", got '" + text + "'";
            return false;
        };
        e.format = [p, table] {
            for (const auto& [v, name] : table) {
                if (v == *p) return detail::format(name);
            }
            return detail::format("<unnamed value " + std::to_string(static_cast<int64_t>(*p)) +
                                  ">");
        };
        e.numbers = [p, table]() -> std::optional<std::vector<double>> {
            for (const auto& entry : table) {
                if (entry.first == *p) return std::vector<double>{};
            }
            return std::nullopt;
        };
        return FieldOptions(this, entries_.size() - 1);
    }

    /// Declares a nested section `[key]` described by `describe(Schema&, C&)`.
    template <typename C>
    void section(std::string_view key, C& child, std::string_view doc = {}) {
        Entry& e = addEntry(key, doc);
        e.type = "section";
        e.section = std::make_unique<Schema>();
        describe(*e.section, child);
    }

    const std::vector<Entry>& entries() const { return entries_; }

    // ---- operations on the bound struct (schema.cpp); see config.hpp for the typed wrappers ----

    /// Applies a TOML document to the bound struct. `source_name` (usually the file path) appears
    /// in errors. Keys absent from the document keep their values. On error the struct may be
    /// partly assigned (the typed wrappers work on a copy). Every problem is reported, one per
    /// line, sorted by line: "<source>:<line>:<column>: <what>".
    Status applyToml(std::string_view text, std::string_view source_name);

    /// Applies one `section.key=value` assignment (the text after `--set`). The value is TOML
    /// (`0.01`, `true`, `[1, 2, 3]`, `"text"`); strings and enum names need no quotes.
    Status applyAssignment(std::string_view assignment);

    /// Ok when every value lies within its bounds and every enum value has a name.
    Status validate() const;

    /// Copies the formatted values of `defaults` (the same struct type, default-constructed) into
    /// every entry's default_text.
    void attachDefaults(const Schema& defaults);

    /// The bound values as a TOML document with each key's meaning, unit, range and default as
    /// comments. `title` becomes the first comment line when not empty.
    std::string toToml(std::string_view title = {}) const;

    /// A markdown table: key, type, default, unit, meaning (with the range).
    std::string toMarkdown() const;

    /// Every field's dotted key ("tsdf.voxel_size_m"), in declaration order.
    std::vector<std::string> keys() const;

  private:
    Entry& addEntry(std::string_view key, std::string_view doc);

    std::vector<Entry> entries_;
};

/// Edit distance between two keys (optimal string alignment: insertions, deletions,
/// substitutions and adjacent transpositions each cost 1; ASCII case is ignored).
size_t editDistance(std::string_view a, std::string_view b);

}  // namespace plumb::config
