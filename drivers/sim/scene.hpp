// SPDX-License-Identifier: Apache-2.0
#pragma once

// The simulated room: analytic primitives in the world frame W (z up, floor at z = 0, reference
// §1.2). A room is a 2-D polygon extruded from the floor to the ceiling (vertical walls at any
// angle, convex or not), furnished with yawed boxes and vertical cylinders; openings (doors,
// windows) are rectangles cut out of walls, through which a ray leaves the room and returns
// nothing. Scenes come from the built-in list or from a TOML description (parseSceneToml).
//
// Appearance: every surface has a grey reflectance (`albedo`, the grey image) and an RGB base
// colour with a procedural pattern (the colour image, drivers/sim/texture.hpp): plaster and
// framed pictures on the walls, wood or tiles on the floor, faint noise on the ceiling, solid,
// noise, stripes or checker on furniture. `texture = plain` keeps one uniform colour per surface.
//
// Thread-safety: pure functions of their arguments (no shared state): thread-safe.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "common/cloud/point_cloud.hpp"
#include "common/core/status.hpp"
#include "common/geometry/polygon.hpp"

namespace plumb::sim {

/// RGB reflectance, each channel in [0, 1] (linear: the simulated camera has no gamma).
using Colour = Eigen::Vector3f;

/// Whether surfaces carry their patterns (textured) or one uniform colour each (plain: the
/// texture-poor rooms in which depth-only and photometric tracking can fail).
enum class TextureMode { kTextured, kPlain };

/// Floor patterns: wooden planks along the world x axis, or square tiles with grout lines.
enum class FloorPattern { kWood, kTiles };

/// Patterns of boxes and cylinders (all in the surface's own metric coordinates).
enum class FurniturePattern {
    kSolid,    ///< the base colour
    kNoise,    ///< mottled: value noise, cells 12, 6 and 3 cm, brightness std ~12 %
    kStripes,  ///< bands 5 cm wide, every 10 cm, at 50 % brightness (horizontal on sides)
    kChecker,  ///< 8 cm squares, alternate ones at 45 % brightness
};

/// Names used in TOML and on command lines: "textured"/"plain", "wood"/"tiles",
/// "solid"/"noise"/"stripes"/"checker". The parsers return nullopt for any other name.
const char* textureModeName(TextureMode mode);
std::optional<TextureMode> parseTextureMode(const std::string& name);
const char* floorPatternName(FloorPattern pattern);
std::optional<FloorPattern> parseFloorPattern(const std::string& name);
const char* furniturePatternName(FurniturePattern pattern);
std::optional<FurniturePattern> parseFurniturePattern(const std::string& name);

/// A box standing anywhere in the room, rotated about the vertical axis.
struct Box {
    Eigen::Vector3d center_W = Eigen::Vector3d::Zero();  ///< box centre in W, metres
    Eigen::Vector3d size_m = Eigen::Vector3d::Ones();    ///< full extents along its own x, y, z
    double yaw_rad = 0.0;  ///< rotation about +z from W's x axis to the box's x axis
    float albedo = 0.6F;   ///< grey-image reflectance in [0, 1]
    Colour colour = Colour::Constant(0.6F);               ///< colour-image base reflectance
    FurniturePattern pattern = FurniturePattern::kSolid;  ///< colour-image pattern
};

/// A vertical cylinder (pillar, bin, lamp post) with flat caps.
struct Cylinder {
    Eigen::Vector2d center_xy = Eigen::Vector2d::Zero();  ///< axis position on the floor, metres
    double radius_m = 0.2;                                ///< radius, metres
    double z_min_m = 0.0;                                 ///< bottom cap height, metres
    double z_max_m = 1.0;                                 ///< top cap height, metres
    float albedo = 0.5F;                                  ///< grey-image reflectance in [0, 1]
    Colour colour = Colour::Constant(0.5F);               ///< colour-image base reflectance
    FurniturePattern pattern = FurniturePattern::kSolid;  ///< colour-image pattern
};

/// A rectangular hole in one wall (door or window).
struct Opening {
    int wall = 0;           ///< wall index k = polygon edge vertex k -> vertex k+1
    double offset_m = 0.0;  ///< distance along the wall from its start vertex to the hole
    double width_m = 0.9;   ///< hole width along the wall, metres
    double z_min_m = 0.0;   ///< sill height (0 for a door), metres
    double z_max_m = 2.0;   ///< lintel height, metres
};

struct Scene {
    std::string name;
    /// Floor outline, counter-clockwise seen from above (+z), metres. Simple, >= 3 vertices.
    std::vector<Eigen::Vector2d> polygon;
    double height_m = 2.6;  ///< floor-to-ceiling distance, metres
    std::vector<Box> boxes;
    std::vector<Cylinder> cylinders;
    std::vector<Opening> openings;
    /// Optional closed path (x, y) for the handheld trajectory, counter-clockwise; empty = derive
    /// it from the polygon inset by `path_inset_m`.
    std::vector<Eigen::Vector2d> path_waypoints;
    double path_inset_m = 1.0;  ///< distance of the derived path from the walls, metres
    float wall_albedo = 0.8F;   ///< reflectance of walls, floor 0.6x, ceiling 0.9x of this
    /// Colour image: base colours of walls, floor and ceiling (RGB reflectance in [0, 1]).
    Colour wall_colour = Colour(0.80F, 0.77F, 0.70F);
    Colour floor_colour = Colour(0.55F, 0.38F, 0.24F);
    Colour ceiling_colour = Colour(0.86F, 0.86F, 0.84F);
    FloorPattern floor_pattern = FloorPattern::kWood;
    /// Framed pictures (high-contrast patterns) per wall, where the wall has room for them.
    int pictures_per_wall = 3;
    /// Textured (patterns, pictures) or plain (one uniform colour per surface).
    TextureMode texture = TextureMode::kTextured;
    /// Seed of the procedural patterns and picture placement: the room's look, which stays the
    /// same for every noise seed and frame.
    uint64_t texture_seed = 1;

    int numWalls() const { return static_cast<int>(polygon.size()); }
};

/// Primitive labels used in label images and GT points: floor 0, ceiling 1, wall k -> 2 + k, then
/// boxes, then cylinders; kNoPrimitive where a ray hits nothing (through an opening).
constexpr int kNoPrimitive = -1;
/// Upper bound of Scene::pictures_per_wall.
constexpr int kMaxPicturesPerWall = 12;
inline int floorLabel() { return 0; }
inline int ceilingLabel() { return 1; }
inline int wallLabel(int k) { return 2 + k; }
inline int boxLabel(const Scene& s, int i) { return 2 + s.numWalls() + i; }
inline int cylinderLabel(const Scene& s, int i) {
    return 2 + s.numWalls() + static_cast<int>(s.boxes.size()) + i;
}

/// Checks the scene: polygon simple and counter-clockwise with edges >= 1 cm, positive height,
/// primitives finite with positive sizes and inside the floor-to-ceiling range, openings inside
/// their walls, colours in [0, 1], 0 <= pictures_per_wall <= kMaxPicturesPerWall. Errors say
/// which element is wrong.
Status validateScene(const Scene& scene);

/// Names of the built-in scenes: living_room, weak_manhattan, l_shape, corridor.
std::vector<std::string> builtinSceneNames();

/// A built-in scene by name; kNotFound lists the valid names.
Result<Scene> builtinScene(const std::string& name);

/// Parses a scene description (TOML). `source` names the text in error messages. Format:
///
///   name = "office"
///   height_m = 2.7
///   polygon = [[0, 0], [5, 0], [5, 4], [0, 4]]       # counter-clockwise, metres
///   path = [[1, 1], [4, 1], [4, 3], [1, 3]]          # optional trajectory waypoints
///   path_inset_m = 1.0                               # optional
///   texture = "textured"           # optional: "textured" (default) or "plain" (uniform colours)
///   texture_seed = 1               # optional: seed of patterns and picture placement
///   wall_colour = [0.80, 0.77, 0.70]     # optional RGB reflectances in [0, 1] (defaults shown)
///   floor_colour = [0.55, 0.38, 0.24]
///   ceiling_colour = [0.86, 0.86, 0.84]
///   floor_pattern = "wood"         # optional: "wood" (default) or "tiles"
///   pictures_per_wall = 3          # optional: framed pictures per wall, 0-12 (default 3)
///   [[box]]      center = [x, y, z], size = [sx, sy, sz], yaw_deg = 0, albedo = 0.6,
///                colour = [r, g, b], pattern = "solid"
///   [[cylinder]] center = [x, y], radius_m = 0.2, z_min_m = 0, z_max_m = 1, albedo = 0.5,
///                colour = [r, g, b], pattern = "solid"
///   [[opening]]  wall = 0, offset_m = 1, width_m = 0.9, z_min_m = 0, z_max_m = 2
///
/// A box's or cylinder's `colour` defaults to the grey of its `albedo`; `pattern` is "solid"
/// (default), "noise", "stripes" or "checker" (FurniturePattern). Unknown keys, and unknown
/// names for texture, floor_pattern and pattern, are errors that name the key, the source and
/// the line. The result is validated.
Result<Scene> parseSceneToml(const std::string& text, const std::string& source);

/// Reads and parses a scene file (see parseSceneToml).
Result<Scene> loadSceneFile(const std::filesystem::path& path);

/// A built-in name or a path to a `.toml` scene file.
Result<Scene> resolveScene(const std::string& name_or_path);

/// Checks a scene argument without loading it: Ok for a built-in name or, when resolveScene takes
/// the argument as a file (a `.toml` extension or a '/'), an existing file. NotFound otherwise,
/// listing the built-in scenes. Whether the file parses is resolveScene's to say.
Status checkSceneName(const std::string& name_or_path);

/// Dense ground-truth surface samples in W on a square grid of `spacing_m` on every visible
/// surface (floor, ceiling, walls minus openings, box faces, cylinder sides and top caps); points
/// inside boxes or cylinders (e.g. floor under furniture) are left out. Normals point out of the
/// surfaces into free space.
PointCloud sampleSurfaces(const Scene& scene, double spacing_m);

/// Whether (x, y) lies inside the floor polygon (common/geometry/polygon.hpp).
using plumb::insidePolygon;

}  // namespace plumb::sim
