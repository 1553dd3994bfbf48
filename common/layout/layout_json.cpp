// SPDX-License-Identifier: Apache-2.0
#include "common/layout/layout_json.hpp"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/geometry/lie.hpp"
#include "common/io/text_file.hpp"

namespace plumb::io {
namespace {

using nlohmann::json;

constexpr double kUnitNormalTolerance = 1e-6;
constexpr double kRigidTolerance = 1e-6;

json vectorJson(const Eigen::Vector2d& v) { return json::array({v.x(), v.y()}); }
json vectorJson(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

/// Reads fields of one JSON object, naming `where` (e.g. "layout.json: planes[2]") in errors.
class FieldReader {
  public:
    FieldReader(const json& object, std::string where)
        : object_(object), where_(std::move(where)) {}

    Status isObject() const {
        if (!object_.is_object()) return corrupt(fmt::format("{}: expected a JSON object", where_));
        return Status::ok();
    }

    std::string path(const std::string& field) const { return where_ + "." + field; }

    Result<const json*> field(const std::string& name) const {
        const auto it = object_.find(name);
        if (it == object_.end()) {
            return corrupt(fmt::format("{}: missing field \"{}\"", where_, name));
        }
        return &*it;
    }

    Result<double> number(const std::string& name) const {
        auto f = field(name);
        if (!f.isOk()) return f.status();
        return toNumber(**f, path(name));
    }

    Result<int> integer(const std::string& name) const {
        auto f = field(name);
        if (!f.isOk()) return f.status();
        const json& v = **f;
        if (!v.is_number_integer()) {
            return corrupt(fmt::format("{}: expected an integer", path(name)));
        }
        const auto i = v.get<int64_t>();
        if (i < INT32_MIN || i > INT32_MAX) {
            return corrupt(fmt::format("{}: {} does not fit an int", path(name), i));
        }
        return static_cast<int>(i);
    }

    Result<bool> boolean(const std::string& name) const {
        auto f = field(name);
        if (!f.isOk()) return f.status();
        if (!(*f)->is_boolean())
            return corrupt(fmt::format("{}: expected true or false", path(name)));
        return (*f)->get<bool>();
    }

    Result<std::string> string(const std::string& name) const {
        auto f = field(name);
        if (!f.isOk()) return f.status();
        if (!(*f)->is_string()) return corrupt(fmt::format("{}: expected a string", path(name)));
        return (*f)->get<std::string>();
    }

    template <int N>
    Result<Eigen::Matrix<double, N, 1>> vector(const std::string& name) const {
        auto f = field(name);
        if (!f.isOk()) return f.status();
        return toVector<N>(**f, path(name));
    }

    static Result<double> toNumber(const json& v, const std::string& where) {
        if (!v.is_number()) return corrupt(fmt::format("{}: expected a number", where));
        const double x = v.get<double>();
        if (!std::isfinite(x)) return corrupt(fmt::format("{}: not a finite number", where));
        return x;
    }

    template <int N>
    static Result<Eigen::Matrix<double, N, 1>> toVector(const json& v, const std::string& where) {
        if (!v.is_array() || v.size() != static_cast<size_t>(N)) {
            return corrupt(fmt::format("{}: expected an array of {} numbers", where, N));
        }
        Eigen::Matrix<double, N, 1> out;
        for (int i = 0; i < N; ++i) {
            auto x = toNumber(v[static_cast<size_t>(i)], fmt::format("{}[{}]", where, i));
            if (!x.isOk()) return x.status();
            out[i] = *x;
        }
        return out;
    }

  private:
    const json& object_;
    std::string where_;
};

#define PLUMB_ASSIGN_OR_RETURN_STATUS(lhs, expr)                  \
    do {                                                          \
        auto plumb_result_ = (expr);                              \
        if (!plumb_result_.isOk()) return plumb_result_.status(); \
        lhs = std::move(*plumb_result_);                          \
    } while (false)

Result<Eigen::Isometry3d> readTransform(const json& v, const std::string& where) {
    if (!v.is_array() || v.size() != 4) {
        return corrupt(fmt::format("{}: expected 4 rows of 4 numbers", where));
    }
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
        Eigen::Vector4d row;
        PLUMB_ASSIGN_OR_RETURN_STATUS(
            row,
            FieldReader::toVector<4>(v[static_cast<size_t>(r)], fmt::format("{}[{}]", where, r)));
        M.row(r) = row.transpose();
    }
    if (M.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
        return corrupt(fmt::format("{}: last row must be [0, 0, 0, 1]", where));
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.matrix() = M;
    if (!lie::isValidPose(T, kRigidTolerance)) {
        return corrupt(
            fmt::format("{}: rotation part is not orthonormal with determinant +1", where));
    }
    return T;
}

Result<LayoutPlane> readPlane(const json& v, const std::string& where) {
    const FieldReader r(v, where);
    PLUMB_RETURN_IF_ERROR(r.isObject());
    LayoutPlane p;
    PLUMB_ASSIGN_OR_RETURN_STATUS(p.id, r.integer("id"));
    std::string kind;
    PLUMB_ASSIGN_OR_RETURN_STATUS(kind, r.string("kind"));
    auto parsed_kind = parseLayoutPlaneKind(kind);
    if (!parsed_kind.isOk()) {
        return corrupt(fmt::format("{}: {}", r.path("kind"), parsed_kind.status().message()));
    }
    p.kind = *parsed_kind;
    PLUMB_ASSIGN_OR_RETURN_STATUS(p.normal_L, r.vector<3>("normal_L"));
    if (std::abs(p.normal_L.norm() - 1.0) > kUnitNormalTolerance) {
        return corrupt(fmt::format("{}: normal has length {}, expected 1", r.path("normal_L"),
                                   p.normal_L.norm()));
    }
    PLUMB_ASSIGN_OR_RETURN_STATUS(p.d_L, r.number("d_L"));
    PLUMB_ASSIGN_OR_RETURN_STATUS(p.start_L, r.vector<2>("start_L"));
    PLUMB_ASSIGN_OR_RETURN_STATUS(p.end_L, r.vector<2>("end_L"));
    PLUMB_ASSIGN_OR_RETURN_STATUS(p.manhattan_snapped, r.boolean("manhattan_snapped"));
    return p;
}

}  // namespace

nlohmann::json layoutToJson(const Layout& layout) {
    json out = json::object();
    out["format"] = kLayoutFormat;
    json T = json::array();
    const Eigen::Matrix4d M = layout.T_W_L.matrix();
    for (int r = 0; r < 4; ++r) T.push_back(json::array({M(r, 0), M(r, 1), M(r, 2), M(r, 3)}));
    out["T_W_L"] = T;
    // An unseen ceiling has no height: null, not 0.
    out["ceiling_height_m"] =
        layout.ceiling_height_m > 0.0 ? json(layout.ceiling_height_m) : json(nullptr);
    json polygon = json::array();
    for (const Eigen::Vector2d& v : layout.room_polygon_L) polygon.push_back(vectorJson(v));
    out["room_polygon_L"] = polygon;
    json planes = json::array();
    for (const LayoutPlane& p : layout.planes) {
        json jp = json::object();
        jp["id"] = p.id;
        jp["kind"] = toString(p.kind);
        jp["normal_L"] = vectorJson(p.normal_L);
        jp["d_L"] = p.d_L;
        jp["start_L"] = vectorJson(p.start_L);
        jp["end_L"] = vectorJson(p.end_L);
        jp["manhattan_snapped"] = p.manhattan_snapped;
        planes.push_back(jp);
    }
    out["planes"] = planes;
    return out;
}

Result<Layout> layoutFromJson(const nlohmann::json& json_doc, const std::string& source) {
    const FieldReader r(json_doc, source);
    PLUMB_RETURN_IF_ERROR(r.isObject());
    std::string format;
    PLUMB_ASSIGN_OR_RETURN_STATUS(format, r.string("format"));
    if (format != kLayoutFormat) {
        return unsupported(fmt::format("{}: format \"{}\" is not supported (expected \"{}\")",
                                       source, format, kLayoutFormat));
    }
    Layout layout;
    const json* T = nullptr;
    PLUMB_ASSIGN_OR_RETURN_STATUS(T, r.field("T_W_L"));
    PLUMB_ASSIGN_OR_RETURN_STATUS(layout.T_W_L, readTransform(*T, r.path("T_W_L")));
    const json* ceiling = nullptr;
    PLUMB_ASSIGN_OR_RETURN_STATUS(ceiling, r.field("ceiling_height_m"));
    if (ceiling->is_null()) {
        layout.ceiling_height_m = 0.0;
    } else {
        PLUMB_ASSIGN_OR_RETURN_STATUS(layout.ceiling_height_m, r.number("ceiling_height_m"));
    }
    if (layout.ceiling_height_m < 0.0) {
        return corrupt(fmt::format("{}: must not be negative", r.path("ceiling_height_m")));
    }
    const json* polygon = nullptr;
    PLUMB_ASSIGN_OR_RETURN_STATUS(polygon, r.field("room_polygon_L"));
    if (!polygon->is_array()) {
        return corrupt(fmt::format("{}: expected an array of [x, y]", r.path("room_polygon_L")));
    }
    for (size_t i = 0; i < polygon->size(); ++i) {
        Eigen::Vector2d v;
        PLUMB_ASSIGN_OR_RETURN_STATUS(
            v, FieldReader::toVector<2>((*polygon)[i],
                                        fmt::format("{}[{}]", r.path("room_polygon_L"), i)));
        layout.room_polygon_L.push_back(v);
    }
    const json* planes = nullptr;
    PLUMB_ASSIGN_OR_RETURN_STATUS(planes, r.field("planes"));
    if (!planes->is_array()) {
        return corrupt(fmt::format("{}: expected an array of planes", r.path("planes")));
    }
    for (size_t i = 0; i < planes->size(); ++i) {
        LayoutPlane p;
        PLUMB_ASSIGN_OR_RETURN_STATUS(
            p, readPlane((*planes)[i], fmt::format("{}[{}]", r.path("planes"), i)));
        layout.planes.push_back(p);
    }
    return layout;
}

Status writeLayoutJson(const std::filesystem::path& path, const Layout& layout) {
    return io::writeText(path, layoutToJson(layout).dump(2) + '\n');
}

Result<Layout> readLayoutJson(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
        return notFound(fmt::format("{}: no such layout file", path.string()));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(fmt::format("{}: cannot open for reading", path.string()));
    std::stringstream buffer;
    buffer << in.rdbuf();
    json doc;
    try {
        doc = json::parse(buffer.str());
    } catch (const json::exception& e) {
        return corrupt(fmt::format("{}: invalid JSON: {}", path.string(), e.what()));
    }
    return layoutFromJson(doc, path.string());
}

}  // namespace plumb::io

#undef PLUMB_ASSIGN_OR_RETURN_STATUS
