// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/scene.hpp"

#include <toml++/toml.h>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include <fmt/format.h>

#include "common/geometry/polygon.hpp"

namespace plumb::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Proper or touching intersection of closed segments [a, b] and [c, d].
bool segmentsIntersect(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c,
                       const Eigen::Vector2d& d) {
    const double d1 = cross2(b - a, c - a);
    const double d2 = cross2(b - a, d - a);
    const double d3 = cross2(d - c, a - c);
    const double d4 = cross2(d - c, b - c);
    if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) {
        return true;
    }
    auto on = [](const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r,
                 double cr) {
        return std::abs(cr) < 1e-12 && r.x() >= std::min(p.x(), q.x()) - 1e-12 &&
               r.x() <= std::max(p.x(), q.x()) + 1e-12 && r.y() >= std::min(p.y(), q.y()) - 1e-12 &&
               r.y() <= std::max(p.y(), q.y()) + 1e-12;
    };
    return on(a, b, c, d1) || on(a, b, d, d2) || on(c, d, a, d3) || on(c, d, b, d4);
}

bool finite(const Eigen::Vector3d& v) { return v.allFinite(); }

// True when p is inside the box grown by `margin` on every side.
bool insideBox(const Box& box, const Eigen::Vector3d& p, double margin) {
    const Eigen::Vector3d q = p - box.center_W;
    const double c = std::cos(box.yaw_rad);
    const double s = std::sin(box.yaw_rad);
    const Eigen::Vector3d local(c * q.x() + s * q.y(), -s * q.x() + c * q.y(), q.z());
    return std::abs(local.x()) < 0.5 * box.size_m.x() + margin &&
           std::abs(local.y()) < 0.5 * box.size_m.y() + margin &&
           std::abs(local.z()) < 0.5 * box.size_m.z() + margin;
}

bool insideCylinder(const Cylinder& cyl, const Eigen::Vector3d& p, double margin) {
    return (p.head<2>() - cyl.center_xy).norm() < cyl.radius_m + margin &&
           p.z() > cyl.z_min_m - margin && p.z() < cyl.z_max_m + margin;
}

// ---- built-in scenes ---------------------------------------------------------------------------

Box makeBox(double x, double y, double z_min, double sx, double sy, double sz, double yaw_deg,
            float albedo, const Colour& colour, FurniturePattern pattern) {
    Box b;
    b.colour = colour;
    b.pattern = pattern;
    b.center_W = {x, y, z_min + 0.5 * sz};
    b.size_m = {sx, sy, sz};
    b.yaw_rad = yaw_deg * kPi / 180.0;
    b.albedo = albedo;
    return b;
}

Cylinder makeCylinder(double x, double y, double r, double z_min, double z_max, float albedo,
                      const Colour& colour, FurniturePattern pattern) {
    Cylinder c;
    c.colour = colour;
    c.pattern = pattern;
    c.center_xy = {x, y};
    c.radius_m = r;
    c.z_min_m = z_min;
    c.z_max_m = z_max;
    c.albedo = albedo;
    return c;
}

Opening makeOpening(int wall, double offset, double width, double z_min, double z_max) {
    Opening o;
    o.wall = wall;
    o.offset_m = offset;
    o.width_m = width;
    o.z_min_m = z_min;
    o.z_max_m = z_max;
    return o;
}

Scene livingRoom() {
    Scene s;
    s.name = "living_room";
    s.polygon = {{0.0, 0.0}, {6.0, 0.0}, {6.0, 4.6}, {0.0, 4.6}};
    s.height_m = 2.6;
    s.path_inset_m = 1.5;
    s.boxes = {
        // sofa against the south wall
        makeBox(2.6, 0.4, 0.0, 2.0, 0.8, 0.85, 0.0, 0.45F, {0.20F, 0.32F, 0.55F},
                FurniturePattern::kNoise),
        // coffee table, yawed
        makeBox(3.0, 2.3, 0.0, 1.1, 0.6, 0.45, 12.0, 0.7F, {0.62F, 0.45F, 0.28F},
                FurniturePattern::kStripes),
        // shelf against the east wall
        makeBox(5.8, 3.2, 0.0, 0.4, 1.4, 1.9, 0.0, 0.55F, {0.85F, 0.84F, 0.80F},
                FurniturePattern::kChecker),
        // sideboard against the west wall
        makeBox(0.3, 3.4, 0.0, 0.6, 1.2, 0.9, 0.0, 0.65F, {0.45F, 0.25F, 0.15F},
                FurniturePattern::kStripes),
        // armchair, yawed, near north wall
        makeBox(1.3, 4.05, 0.0, 1.0, 0.6, 0.75, -20.0, 0.5F, {0.65F, 0.18F, 0.16F},
                FurniturePattern::kNoise),
    };
    s.cylinders = {
        makeCylinder(5.4, 0.5, 0.15, 0.0, 1.6, 0.4F, {0.30F, 0.30F, 0.32F},
                     FurniturePattern::kSolid),  // floor lamp
        makeCylinder(0.6, 0.7, 0.25, 0.0, 0.6, 0.35F, {0.70F, 0.40F, 0.25F},
                     FurniturePattern::kChecker),  // plant pot
    };
    s.openings = {
        makeOpening(3, 2.2, 0.9, 0.0, 2.05),  // door in the west wall
        makeOpening(1, 0.7, 1.3, 0.9, 2.1),   // window in the east wall
    };
    return s;
}

Scene weakManhattan() {
    Scene s;
    s.name = "weak_manhattan";
    s.wall_colour = {0.72F, 0.78F, 0.74F};  // pale green
    s.floor_pattern = FloorPattern::kTiles;
    s.floor_colour = {0.70F, 0.66F, 0.58F};
    s.texture_seed = 2;
    // The east wall leans 12 degrees off the y axis; the others are axis-aligned.
    s.polygon = {{0.0, 0.0}, {5.6, 0.0}, {6.5, 4.4}, {0.0, 4.4}};
    s.height_m = 2.7;
    s.path_inset_m = 1.5;
    s.boxes = {
        // bench against the south wall
        makeBox(2.5, 0.35, 0.0, 1.6, 0.7, 0.8, 0.0, 0.5F, {0.35F, 0.50F, 0.30F},
                FurniturePattern::kStripes),
        // desk, yawed
        makeBox(3.0, 2.2, 0.0, 1.4, 0.8, 0.74, 25.0, 0.7F, {0.75F, 0.70F, 0.60F},
                FurniturePattern::kNoise),
        // wardrobe against the west wall
        makeBox(0.25, 2.4, 0.0, 0.5, 1.6, 2.0, 0.0, 0.55F, {0.50F, 0.33F, 0.20F},
                FurniturePattern::kChecker),
    };
    s.cylinders = {makeCylinder(4.9, 3.8, 0.2, 0.0, 1.1, 0.4F, {0.20F, 0.45F, 0.60F},
                                FurniturePattern::kStripes)};
    s.openings = {makeOpening(2, 2.0, 1.0, 0.0, 2.1)};
    return s;
}

Scene lShape() {
    Scene s;
    s.name = "l_shape";
    s.wall_colour = {0.82F, 0.74F, 0.62F};  // warm beige
    s.floor_pattern = FloorPattern::kTiles;
    s.floor_colour = {0.55F, 0.57F, 0.60F};
    s.texture_seed = 3;
    s.polygon = {{0.0, 0.0}, {7.0, 0.0}, {7.0, 3.2}, {3.2, 3.2}, {3.2, 7.0}, {0.0, 7.0}};
    s.height_m = 2.6;
    s.path_inset_m = 1.3;
    s.boxes = {
        // counter against the south wall
        makeBox(4.5, 0.3, 0.0, 2.0, 0.6, 0.9, 0.0, 0.55F, {0.80F, 0.80F, 0.78F},
                FurniturePattern::kChecker),
        // shelf against the west wall
        makeBox(0.3, 5.0, 0.0, 0.6, 1.6, 1.8, 0.0, 0.6F, {0.55F, 0.38F, 0.22F},
                FurniturePattern::kStripes),
        // crate in the east arm
        makeBox(6.6, 2.2, 0.0, 0.8, 0.8, 1.0, 10.0, 0.5F, {0.60F, 0.50F, 0.30F},
                FurniturePattern::kNoise),
    };
    s.cylinders = {makeCylinder(2.4, 2.4, 0.25, 0.0, 2.6, 0.45F, {0.75F, 0.74F, 0.70F},
                                FurniturePattern::kNoise)};  // pillar at the inner corner
    s.openings = {makeOpening(4, 1.0, 1.0, 0.0, 2.1)};
    return s;
}

Scene corridor() {
    Scene s;
    s.name = "corridor";
    s.wall_colour = {0.76F, 0.76F, 0.80F};  // cool grey
    s.floor_colour = {0.45F, 0.30F, 0.20F};
    s.texture_seed = 4;
    s.polygon = {{0.0, 0.0}, {10.0, 0.0}, {10.0, 2.4}, {0.0, 2.4}};
    s.height_m = 2.5;
    s.path_inset_m = 0.8;
    s.boxes = {
        // bench against the south wall
        makeBox(4.0, 0.2, 0.0, 1.5, 0.4, 0.45, 0.0, 0.5F, {0.55F, 0.40F, 0.25F},
                FurniturePattern::kStripes),
        // cabinet against the north wall
        makeBox(7.5, 2.2, 0.0, 0.8, 0.4, 1.2, 0.0, 0.6F, {0.40F, 0.45F, 0.50F},
                FurniturePattern::kChecker),
    };
    s.cylinders = {makeCylinder(9.6, 0.35, 0.2, 0.0, 0.7, 0.4F, {0.25F, 0.55F, 0.30F},
                                FurniturePattern::kSolid)};  // bin
    s.openings = {
        makeOpening(0, 6.0, 0.9, 0.0, 2.05),  // side door
        makeOpening(2, 2.5, 0.9, 0.0, 2.05),  // door opposite
    };
    return s;
}

// ---- TOML --------------------------------------------------------------------------------------

std::string where(const std::string& source, const toml::node& node) {
    return fmt::format("{}:{}", source, node.source().begin.line);
}

Status checkKeys(const toml::table& table, const std::vector<std::string>& allowed,
                 const std::string& source) {
    for (const auto& [key, node] : table) {
        if (std::find(allowed.begin(), allowed.end(), std::string(key.str())) == allowed.end()) {
            return invalidArgument(
                fmt::format("{}: unknown key '{}'", where(source, node), std::string(key.str())));
        }
    }
    return Status::ok();
}

Result<double> getNumber(const toml::table& table, const std::string& key, double fallback,
                         bool required, const std::string& source, const std::string& context) {
    const toml::node* node = table.get(key);
    if (node == nullptr) {
        if (required) {
            return invalidArgument(fmt::format("{}: {}: missing '{}'", source, context, key));
        }
        return fallback;
    }
    if (auto v = node->value<double>()) return *v;
    return invalidArgument(
        fmt::format("{}: {}: '{}' must be a number", where(source, *node), context, key));
}

Result<std::vector<double>> getVector(const toml::table& table, const std::string& key, size_t size,
                                      bool required, const std::string& source,
                                      const std::string& context) {
    const toml::node* node = table.get(key);
    if (node == nullptr) {
        if (required) {
            return invalidArgument(fmt::format("{}: {}: missing '{}'", source, context, key));
        }
        return std::vector<double>{};
    }
    const toml::array* arr = node->as_array();
    if (arr == nullptr || arr->size() != size) {
        return invalidArgument(fmt::format("{}: {}: '{}' must be an array of {} numbers",
                                           where(source, *node), context, key, size));
    }
    std::vector<double> out;
    for (const toml::node& e : *arr) {
        auto v = e.value<double>();
        if (!v) {
            return invalidArgument(
                fmt::format("{}: {}: '{}' must hold numbers", where(source, *node), context, key));
        }
        out.push_back(*v);
    }
    return out;
}

Result<std::vector<Eigen::Vector2d>> getPoints(const toml::table& table, const std::string& key,
                                               bool required, const std::string& source) {
    const toml::node* node = table.get(key);
    std::vector<Eigen::Vector2d> out;
    if (node == nullptr) {
        if (required) return invalidArgument(fmt::format("{}: missing '{}'", source, key));
        return out;
    }
    const toml::array* arr = node->as_array();
    if (arr == nullptr) {
        return invalidArgument(
            fmt::format("{}: '{}' must be an array of [x, y] pairs", where(source, *node), key));
    }
    for (const toml::node& e : *arr) {
        const toml::array* pair = e.as_array();
        std::optional<double> x, y;
        if (pair != nullptr && pair->size() == 2) {
            x = (*pair)[0].value<double>();
            y = (*pair)[1].value<double>();
        }
        if (!x || !y) {
            return invalidArgument(
                fmt::format("{}: '{}' must be an array of [x, y] pairs", where(source, e), key));
        }
        out.emplace_back(*x, *y);
    }
    return out;
}

template <typename Fn>
Status forEachTable(const toml::table& root, const std::string& key, const std::string& source,
                    Fn&& fn) {
    const toml::node* node = root.get(key);
    if (node == nullptr) return Status::ok();
    const toml::array* arr = node->as_array();
    if (arr == nullptr) {
        return invalidArgument(fmt::format("{}: '{}' must be an array of tables ([[{}]])",
                                           where(source, *node), key, key));
    }
    int index = 0;
    for (const toml::node& e : *arr) {
        const toml::table* t = e.as_table();
        if (t == nullptr) {
            return invalidArgument(
                fmt::format("{}: {}[{}] must be a table", where(source, e), key, index));
        }
        PLUMB_RETURN_IF_ERROR(fn(*t, fmt::format("{}[{}]", key, index)));
        ++index;
    }
    return Status::ok();
}

template <typename T, typename U>
Status assignTo(Result<T> result, U* out) {
    if (!result.isOk()) return result.status();
    *out = std::move(result).value();
    return Status::ok();
}

// An RGB reflectance [r, g, b] with every channel in [0, 1]; `fallback` when the key is absent.
Result<Colour> getColour(const toml::table& table, const std::string& key, const Colour& fallback,
                         const std::string& source, const std::string& context) {
    if (table.get(key) == nullptr) return fallback;
    std::vector<double> rgb;
    PLUMB_RETURN_IF_ERROR(assignTo(getVector(table, key, 3, false, source, context), &rgb));
    for (const double c : rgb) {
        if (!(c >= 0.0 && c <= 1.0)) {
            return invalidArgument(
                fmt::format("{}: {}: '{}' must hold 3 numbers in [0, 1] (r, g, b)",
                            where(source, *table.get(key)), context, key));
        }
    }
    return Colour(static_cast<float>(rgb[0]), static_cast<float>(rgb[1]),
                  static_cast<float>(rgb[2]));
}

// A name from a fixed list (`parse` maps it, `names` lists the valid ones for the message).
template <typename T, typename Parse>
Result<T> getName(const toml::table& table, const std::string& key, T fallback, Parse&& parse,
                  const char* names, const std::string& source, const std::string& context) {
    const toml::node* node = table.get(key);
    if (node == nullptr) return fallback;
    const std::optional<std::string> text = node->value<std::string>();
    const std::optional<T> value = text ? parse(*text) : std::nullopt;
    if (!value) {
        return invalidArgument(
            fmt::format("{}: {}: '{}' must be {}, got {}", where(source, *node), context, key,
                        names, text ? "\"" + *text + "\"" : std::string("a non-string")));
    }
    return *value;
}

// A non-negative integer no larger than `max_value`.
Result<int64_t> getCount(const toml::table& table, const std::string& key, int64_t fallback,
                         int64_t max_value, const std::string& source, const std::string& context) {
    const toml::node* node = table.get(key);
    if (node == nullptr) return fallback;
    const std::optional<int64_t> v = node->is_integer() ? node->value<int64_t>() : std::nullopt;
    if (!v || *v < 0 || *v > max_value) {
        return invalidArgument(fmt::format("{}: {}: '{}' must be an integer in [0, {}]",
                                           where(source, *node), context, key, max_value));
    }
    return *v;
}

constexpr const char* kFurniturePatternNames = "\"solid\", \"noise\", \"stripes\" or \"checker\"";

Result<Scene> parseTable(const toml::table& root, const std::string& source) {
    PLUMB_RETURN_IF_ERROR(
        checkKeys(root,
                  {"name", "height_m", "polygon", "path", "path_inset_m", "wall_albedo", "texture",
                   "texture_seed", "wall_colour", "floor_colour", "ceiling_colour", "floor_pattern",
                   "pictures_per_wall", "box", "cylinder", "opening"},
                  source));
    Scene s;
    s.name = root["name"].value_or(std::string("custom"));
    PLUMB_RETURN_IF_ERROR(
        assignTo(getNumber(root, "height_m", 2.6, true, source, "scene"), &s.height_m));
    PLUMB_RETURN_IF_ERROR(assignTo(getPoints(root, "polygon", true, source), &s.polygon));
    PLUMB_RETURN_IF_ERROR(assignTo(getPoints(root, "path", false, source), &s.path_waypoints));
    PLUMB_RETURN_IF_ERROR(
        assignTo(getNumber(root, "path_inset_m", 1.0, false, source, "scene"), &s.path_inset_m));
    double wall_albedo = 0.8;
    PLUMB_RETURN_IF_ERROR(
        assignTo(getNumber(root, "wall_albedo", 0.8, false, source, "scene"), &wall_albedo));
    s.wall_albedo = static_cast<float>(wall_albedo);
    PLUMB_RETURN_IF_ERROR(assignTo(getName(root, "texture", s.texture, parseTextureMode,
                                           "\"textured\" or \"plain\"", source, "scene"),
                                   &s.texture));
    int64_t texture_seed = 0, pictures = 0;
    PLUMB_RETURN_IF_ERROR(assignTo(
        getCount(root, "texture_seed", 1, std::numeric_limits<int64_t>::max(), source, "scene"),
        &texture_seed));
    s.texture_seed = static_cast<uint64_t>(texture_seed);
    PLUMB_RETURN_IF_ERROR(assignTo(getCount(root, "pictures_per_wall", s.pictures_per_wall,
                                            kMaxPicturesPerWall, source, "scene"),
                                   &pictures));
    s.pictures_per_wall = static_cast<int>(pictures);
    PLUMB_RETURN_IF_ERROR(
        assignTo(getColour(root, "wall_colour", s.wall_colour, source, "scene"), &s.wall_colour));
    PLUMB_RETURN_IF_ERROR(assignTo(getColour(root, "floor_colour", s.floor_colour, source, "scene"),
                                   &s.floor_colour));
    PLUMB_RETURN_IF_ERROR(assignTo(
        getColour(root, "ceiling_colour", s.ceiling_colour, source, "scene"), &s.ceiling_colour));
    PLUMB_RETURN_IF_ERROR(
        assignTo(getName(root, "floor_pattern", s.floor_pattern, parseFloorPattern,
                         "\"wood\" or \"tiles\"", source, "scene"),
                 &s.floor_pattern));

    PLUMB_RETURN_IF_ERROR(forEachTable(
        root, "box", source, [&](const toml::table& t, const std::string& ctx) -> Status {
            PLUMB_RETURN_IF_ERROR(
                checkKeys(t, {"center", "size", "yaw_deg", "albedo", "colour", "pattern"}, source));
            Box b;
            std::vector<double> c, sz;
            double yaw = 0.0, albedo = 0.6;
            PLUMB_RETURN_IF_ERROR(assignTo(getVector(t, "center", 3, true, source, ctx), &c));
            PLUMB_RETURN_IF_ERROR(assignTo(getVector(t, "size", 3, true, source, ctx), &sz));
            PLUMB_RETURN_IF_ERROR(assignTo(getNumber(t, "yaw_deg", 0.0, false, source, ctx), &yaw));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "albedo", 0.6, false, source, ctx), &albedo));
            b.center_W = {c[0], c[1], c[2]};
            b.size_m = {sz[0], sz[1], sz[2]};
            b.yaw_rad = yaw * kPi / 180.0;
            b.albedo = static_cast<float>(albedo);
            PLUMB_RETURN_IF_ERROR(assignTo(
                getColour(t, "colour", Colour::Constant(b.albedo), source, ctx), &b.colour));
            PLUMB_RETURN_IF_ERROR(assignTo(getName(t, "pattern", b.pattern, parseFurniturePattern,
                                                   kFurniturePatternNames, source, ctx),
                                           &b.pattern));
            s.boxes.push_back(b);
            return Status::ok();
        }));
    PLUMB_RETURN_IF_ERROR(forEachTable(
        root, "cylinder", source, [&](const toml::table& t, const std::string& ctx) -> Status {
            PLUMB_RETURN_IF_ERROR(checkKeys(
                t, {"center", "radius_m", "z_min_m", "z_max_m", "albedo", "colour", "pattern"},
                source));
            Cylinder cyl;
            std::vector<double> c;
            double albedo = 0.5;
            PLUMB_RETURN_IF_ERROR(assignTo(getVector(t, "center", 2, true, source, ctx), &c));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "radius_m", 0.2, true, source, ctx), &cyl.radius_m));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "z_min_m", 0.0, false, source, ctx), &cyl.z_min_m));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "z_max_m", 1.0, true, source, ctx), &cyl.z_max_m));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "albedo", 0.5, false, source, ctx), &albedo));
            cyl.center_xy = {c[0], c[1]};
            cyl.albedo = static_cast<float>(albedo);
            PLUMB_RETURN_IF_ERROR(assignTo(
                getColour(t, "colour", Colour::Constant(cyl.albedo), source, ctx), &cyl.colour));
            PLUMB_RETURN_IF_ERROR(assignTo(getName(t, "pattern", cyl.pattern, parseFurniturePattern,
                                                   kFurniturePatternNames, source, ctx),
                                           &cyl.pattern));
            s.cylinders.push_back(cyl);
            return Status::ok();
        }));
    PLUMB_RETURN_IF_ERROR(forEachTable(
        root, "opening", source, [&](const toml::table& t, const std::string& ctx) -> Status {
            PLUMB_RETURN_IF_ERROR(
                checkKeys(t, {"wall", "offset_m", "width_m", "z_min_m", "z_max_m"}, source));
            Opening o;
            double wall = 0.0;
            PLUMB_RETURN_IF_ERROR(assignTo(getNumber(t, "wall", 0.0, true, source, ctx), &wall));
            if (wall != std::floor(wall) || wall < 0) {
                return invalidArgument(
                    fmt::format("{}: {}: 'wall' must be a non-negative integer", source, ctx));
            }
            o.wall = static_cast<int>(wall);
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "offset_m", 0.0, true, source, ctx), &o.offset_m));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "width_m", 0.9, true, source, ctx), &o.width_m));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "z_min_m", 0.0, false, source, ctx), &o.z_min_m));
            PLUMB_RETURN_IF_ERROR(
                assignTo(getNumber(t, "z_max_m", 2.0, true, source, ctx), &o.z_max_m));
            s.openings.push_back(o);
            return Status::ok();
        }));
    const Status valid = validateScene(s);
    if (!valid.isOk()) {
        return invalidArgument(fmt::format("{}: {}", source, valid.message()));
    }
    return s;
}

}  // namespace

const char* textureModeName(TextureMode mode) {
    return mode == TextureMode::kPlain ? "plain" : "textured";
}

std::optional<TextureMode> parseTextureMode(const std::string& name) {
    if (name == "textured") return TextureMode::kTextured;
    if (name == "plain") return TextureMode::kPlain;
    return std::nullopt;
}

const char* floorPatternName(FloorPattern pattern) {
    return pattern == FloorPattern::kTiles ? "tiles" : "wood";
}

std::optional<FloorPattern> parseFloorPattern(const std::string& name) {
    if (name == "wood") return FloorPattern::kWood;
    if (name == "tiles") return FloorPattern::kTiles;
    return std::nullopt;
}

const char* furniturePatternName(FurniturePattern pattern) {
    switch (pattern) {
        case FurniturePattern::kSolid:
            return "solid";
        case FurniturePattern::kNoise:
            return "noise";
        case FurniturePattern::kStripes:
            return "stripes";
        case FurniturePattern::kChecker:
            return "checker";
    }
    return "?";
}

std::optional<FurniturePattern> parseFurniturePattern(const std::string& name) {
    if (name == "solid") return FurniturePattern::kSolid;
    if (name == "noise") return FurniturePattern::kNoise;
    if (name == "stripes") return FurniturePattern::kStripes;
    if (name == "checker") return FurniturePattern::kChecker;
    return std::nullopt;
}

Status validateScene(const Scene& s) {
    const size_t n = s.polygon.size();
    if (n < 3) return invalidArgument(fmt::format("polygon has {} vertices, need >= 3", n));
    for (size_t i = 0; i < n; ++i) {
        if (!s.polygon[i].allFinite()) {
            return invalidArgument(fmt::format("polygon vertex {} is not finite", i));
        }
        if ((s.polygon[(i + 1) % n] - s.polygon[i]).norm() < 0.01) {
            return invalidArgument(fmt::format("polygon edge {} is shorter than 1 cm", i));
        }
    }
    for (size_t i = 0; i < n; ++i) {
        for (size_t j = i + 1; j < n; ++j) {
            if (j == i + 1 || (i == 0 && j == n - 1)) continue;
            if (segmentsIntersect(s.polygon[i], s.polygon[(i + 1) % n], s.polygon[j],
                                  s.polygon[(j + 1) % n])) {
                return invalidArgument(
                    fmt::format("polygon is not simple: edges {} and {} intersect", i, j));
            }
        }
    }
    if (signedArea(s.polygon) <= 0.0) {
        return invalidArgument("polygon is clockwise; list the vertices counter-clockwise");
    }
    if (!(s.height_m > 0.0) || !std::isfinite(s.height_m)) {
        return invalidArgument(fmt::format("height_m must be positive, got {}", s.height_m));
    }
    for (size_t i = 0; i < s.boxes.size(); ++i) {
        const Box& b = s.boxes[i];
        if (!finite(b.center_W) || !finite(b.size_m) || !std::isfinite(b.yaw_rad) ||
            (b.size_m.array() <= 0.0).any()) {
            return invalidArgument(fmt::format("box[{}]: non-finite or non-positive size", i));
        }
        if (!insidePolygon(s.polygon, b.center_W.head<2>()) ||
            b.center_W.z() - 0.5 * b.size_m.z() < -1e-9 ||
            b.center_W.z() + 0.5 * b.size_m.z() > s.height_m + 1e-9) {
            return invalidArgument(fmt::format("box[{}]: not inside the room", i));
        }
    }
    for (size_t i = 0; i < s.cylinders.size(); ++i) {
        const Cylinder& c = s.cylinders[i];
        if (!c.center_xy.allFinite() || !(c.radius_m > 0.0) || !(c.z_max_m > c.z_min_m)) {
            return invalidArgument(
                fmt::format("cylinder[{}]: needs finite centre, radius > 0, z_max_m > z_min_m", i));
        }
        if (!insidePolygon(s.polygon, c.center_xy) || c.z_min_m < -1e-9 ||
            c.z_max_m > s.height_m + 1e-9) {
            return invalidArgument(fmt::format("cylinder[{}]: not inside the room", i));
        }
    }
    for (size_t i = 0; i < s.openings.size(); ++i) {
        const Opening& o = s.openings[i];
        if (o.wall < 0 || o.wall >= s.numWalls()) {
            return invalidArgument(
                fmt::format("opening[{}]: wall {} does not exist (room has {} walls)", i, o.wall,
                            s.numWalls()));
        }
        const double len = (s.polygon[(o.wall + 1) % n] - s.polygon[o.wall]).norm();
        if (!(o.offset_m >= 0.0) || !(o.width_m > 0.0) || o.offset_m + o.width_m > len + 1e-9 ||
            !(o.z_min_m >= 0.0) || !(o.z_max_m > o.z_min_m) || o.z_max_m > s.height_m + 1e-9) {
            return invalidArgument(
                fmt::format("opening[{}]: must lie inside wall {} ({:.3f} m long, {:.3f} m high)",
                            i, o.wall, len, s.height_m));
        }
    }
    auto colour_ok = [](const Colour& c) {
        return (c.array() >= 0.0F).all() && (c.array() <= 1.0F).all();
    };
    if (!colour_ok(s.wall_colour) || !colour_ok(s.floor_colour) || !colour_ok(s.ceiling_colour)) {
        return invalidArgument("wall, floor and ceiling colours need channels in [0, 1]");
    }
    for (size_t i = 0; i < s.boxes.size(); ++i) {
        if (!colour_ok(s.boxes[i].colour)) {
            return invalidArgument(fmt::format("box[{}]: colour channels must be in [0, 1]", i));
        }
    }
    for (size_t i = 0; i < s.cylinders.size(); ++i) {
        if (!colour_ok(s.cylinders[i].colour)) {
            return invalidArgument(
                fmt::format("cylinder[{}]: colour channels must be in [0, 1]", i));
        }
    }
    if (s.pictures_per_wall < 0 || s.pictures_per_wall > kMaxPicturesPerWall) {
        return invalidArgument(fmt::format("pictures_per_wall must be in [0, {}], got {}",
                                           kMaxPicturesPerWall, s.pictures_per_wall));
    }
    for (size_t i = 0; i < s.path_waypoints.size(); ++i) {
        if (!insidePolygon(s.polygon, s.path_waypoints[i])) {
            return invalidArgument(fmt::format("path waypoint {} is outside the room", i));
        }
    }
    if (s.path_waypoints.empty() && !(s.path_inset_m > 0.0)) {
        return invalidArgument("path_inset_m must be positive");
    }
    return Status::ok();
}

std::vector<std::string> builtinSceneNames() {
    return {"living_room", "weak_manhattan", "l_shape", "corridor"};
}

Result<Scene> builtinScene(const std::string& name) {
    Scene s;
    if (name == "living_room") {
        s = livingRoom();
    } else if (name == "weak_manhattan") {
        s = weakManhattan();
    } else if (name == "l_shape") {
        s = lShape();
    } else if (name == "corridor") {
        s = corridor();
    } else {
        std::string names;
        for (const auto& n : builtinSceneNames()) names += (names.empty() ? "" : ", ") + n;
        return notFound(
            fmt::format("no built-in scene '{}' (built-in: {}; or a .toml file)", name, names));
    }
    PLUMB_CHECK(validateScene(s).isOk()) << "built-in scene " << name << " is invalid";
    return s;
}

Result<Scene> parseSceneToml(const std::string& text, const std::string& source) {
    try {
        const toml::table root = toml::parse(text, source);
        return parseTable(root, source);
    } catch (const toml::parse_error& e) {
        return invalidArgument(
            fmt::format("{}:{}: {}", source, e.source().begin.line, std::string(e.description())));
    } catch (const std::exception& e) {
        return invalidArgument(fmt::format("{}: {}", source, e.what()));
    }
}

Result<Scene> loadSceneFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return notFound(fmt::format("{}: cannot open scene file", path.string()));
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) return ioError(fmt::format("{}: read error", path.string()));
    return parseSceneToml(text.str(), path.string());
}

namespace {

/// resolveScene's rule: a `.toml` extension or a directory separator names a file.
bool namesSceneFile(const std::string& name_or_path) {
    return std::filesystem::path(name_or_path).extension() == ".toml" ||
           name_or_path.find('/') != std::string::npos;
}

}  // namespace

Result<Scene> resolveScene(const std::string& name_or_path) {
    if (namesSceneFile(name_or_path)) return loadSceneFile(name_or_path);
    return builtinScene(name_or_path);
}

Status checkSceneName(const std::string& name_or_path) {
    if (namesSceneFile(name_or_path)) {
        std::error_code ec;
        if (std::filesystem::is_regular_file(name_or_path, ec)) return Status::ok();
        return notFound(fmt::format("{}: no such scene file", name_or_path));
    }
    const std::vector<std::string> names = builtinSceneNames();
    if (std::find(names.begin(), names.end(), name_or_path) != names.end()) return Status::ok();
    return builtinScene(name_or_path).status();
}

PointCloud sampleSurfaces(const Scene& s, double spacing_m) {
    PLUMB_CHECK(spacing_m > 0.0) << "spacing_m = " << spacing_m;
    PointCloud cloud;
    auto occluded = [&](const Eigen::Vector3d& p, int skip_box, int skip_cyl) {
        for (size_t i = 0; i < s.boxes.size(); ++i) {
            if (static_cast<int>(i) != skip_box && insideBox(s.boxes[i], p, 1e-6)) return true;
        }
        for (size_t i = 0; i < s.cylinders.size(); ++i) {
            if (static_cast<int>(i) != skip_cyl && insideCylinder(s.cylinders[i], p, 1e-6)) {
                return true;
            }
        }
        return false;
    };
    auto add = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
        cloud.points.push_back(p.cast<float>());
        cloud.normals.push_back(n.cast<float>());
    };
    // Floor and ceiling: grid over the bounding box, kept inside the polygon.
    Eigen::Vector2d lo = s.polygon[0], hi = s.polygon[0];
    for (const auto& v : s.polygon) {
        lo = lo.cwiseMin(v);
        hi = hi.cwiseMax(v);
    }
    for (double y = lo.y() + 0.5 * spacing_m; y < hi.y(); y += spacing_m) {
        for (double x = lo.x() + 0.5 * spacing_m; x < hi.x(); x += spacing_m) {
            if (!insidePolygon(s.polygon, {x, y})) continue;
            const Eigen::Vector3d f(x, y, 0.0), c(x, y, s.height_m);
            if (!occluded(f, -1, -1)) add(f, Eigen::Vector3d::UnitZ());
            if (!occluded(c, -1, -1)) add(c, -Eigen::Vector3d::UnitZ());
        }
    }
    // Walls, minus openings.
    const int nw = s.numWalls();
    for (int k = 0; k < nw; ++k) {
        const Eigen::Vector2d a = s.polygon[k];
        const Eigen::Vector2d b = s.polygon[(k + 1) % nw];
        const double len = (b - a).norm();
        const Eigen::Vector2d dir = (b - a) / len;
        const Eigen::Vector3d n(-dir.y(), dir.x(), 0.0);
        for (double u = 0.5 * spacing_m; u < len; u += spacing_m) {
            for (double z = 0.5 * spacing_m; z < s.height_m; z += spacing_m) {
                bool in_opening = false;
                for (const Opening& o : s.openings) {
                    in_opening |= o.wall == k && u > o.offset_m && u < o.offset_m + o.width_m &&
                                  z > o.z_min_m && z < o.z_max_m;
                }
                if (in_opening) continue;
                const Eigen::Vector2d xy = a + u * dir;
                const Eigen::Vector3d p(xy.x(), xy.y(), z);
                if (!occluded(p, -1, -1)) add(p, n);
            }
        }
    }
    // Box faces (the bottom face is skipped when it rests on the floor).
    for (size_t i = 0; i < s.boxes.size(); ++i) {
        const Box& box = s.boxes[i];
        const Eigen::Matrix3d R =
            Eigen::AngleAxisd(box.yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
        const Eigen::Vector3d h = 0.5 * box.size_m;
        for (int axis = 0; axis < 3; ++axis) {
            for (int sign = -1; sign <= 1; sign += 2) {
                if (axis == 2 && sign < 0 && box.center_W.z() - h.z() < 1e-9) continue;
                const int a1 = (axis + 1) % 3;
                const int a2 = (axis + 2) % 3;
                Eigen::Vector3d n_local = Eigen::Vector3d::Zero();
                n_local[axis] = sign;
                for (double u = -h[a1] + 0.5 * spacing_m; u < h[a1]; u += spacing_m) {
                    for (double v = -h[a2] + 0.5 * spacing_m; v < h[a2]; v += spacing_m) {
                        Eigen::Vector3d q;
                        q[axis] = sign * h[axis];
                        q[a1] = u;
                        q[a2] = v;
                        const Eigen::Vector3d p = box.center_W + R * q;
                        if (!insidePolygon(s.polygon, p.head<2>())) continue;
                        if (!occluded(p, static_cast<int>(i), -1)) add(p, R * n_local);
                    }
                }
            }
        }
    }
    // Cylinder sides and top caps.
    for (size_t i = 0; i < s.cylinders.size(); ++i) {
        const Cylinder& c = s.cylinders[i];
        const int steps =
            std::max(8, static_cast<int>(std::ceil(2.0 * kPi * c.radius_m / spacing_m)));
        for (int k = 0; k < steps; ++k) {
            const double phi = 2.0 * kPi * (k + 0.5) / steps;
            const Eigen::Vector3d n(std::cos(phi), std::sin(phi), 0.0);
            for (double z = c.z_min_m + 0.5 * spacing_m; z < c.z_max_m; z += spacing_m) {
                const Eigen::Vector3d p(c.center_xy.x() + c.radius_m * n.x(),
                                        c.center_xy.y() + c.radius_m * n.y(), z);
                if (insidePolygon(s.polygon, p.head<2>()) &&
                    !occluded(p, -1, static_cast<int>(i))) {
                    add(p, n);
                }
            }
        }
        if (c.z_max_m < s.height_m - 1e-9) {
            for (double y = -c.radius_m + 0.5 * spacing_m; y < c.radius_m; y += spacing_m) {
                for (double x = -c.radius_m + 0.5 * spacing_m; x < c.radius_m; x += spacing_m) {
                    if (x * x + y * y >= c.radius_m * c.radius_m) continue;
                    const Eigen::Vector3d p(c.center_xy.x() + x, c.center_xy.y() + y, c.z_max_m);
                    if (!occluded(p, -1, static_cast<int>(i))) add(p, Eigen::Vector3d::UnitZ());
                }
            }
        }
    }
    return cloud;
}

}  // namespace plumb::sim
