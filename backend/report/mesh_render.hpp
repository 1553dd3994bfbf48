// SPDX-License-Identifier: Apache-2.0
#pragma once

// A small software rasteriser for the report's pictures of the model: per-vertex colour,
// two-sided Lambert shading with one directional light, a z-buffer, an orthographic ("oblique
// top-down", or straight down for a plan view) or a perspective camera orbiting the mesh's
// bounding box. The mesh is given in an "up" frame U whose +z points against gravity (the layout
// frame L, or the world rotated so); the top of the model can be cut away (dollhouse view) so the
// ceiling does not hide the room. No I/O; pure functions, thread-safe.

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <vector>

#include "common/cloud/point_cloud.hpp"

namespace plumb::backend {

/// An 8-bit RGB image, row-major, rows top to bottom, 3 bytes per pixel.
struct RgbImage {
    int width = 0;
    int height = 0;
    std::vector<uint8_t> rgb;

    Color3u8 at(int x, int y) const {
        const size_t i = 3 * (static_cast<size_t>(y) * width + x);
        return {rgb[i], rgb[i + 1], rgb[i + 2]};
    }
    void set(int x, int y, const Color3u8& c) {
        const size_t i = 3 * (static_cast<size_t>(y) * width + x);
        rgb[i] = c.x();
        rgb[i + 1] = c.y();
        rgb[i + 2] = c.z();
    }
};

enum class RenderProjection {
    kOrthographic,  ///< parallel rays: the oblique top-down view, or a plan at 90 deg elevation
    kPerspective,   ///< pinhole camera at a distance that fits the bounding sphere
};

struct MeshRenderConfig {
    /// Image width, pixels.
    int width_px = 640;
    /// Image height, pixels.
    int height_px = 480;
    /// Camera model.
    RenderProjection projection = RenderProjection::kOrthographic;
    /// Angle of the camera above the horizontal plane of U, degrees (90: straight down).
    double elevation_deg = 50.0;
    /// Direction of the camera around +z of U, degrees from +x towards +y. At 90 deg elevation,
    /// -90 puts +x of U to the right of the image and +y up (a conventional plan).
    double azimuth_deg = -60.0;
    /// Vertical field of view of the perspective camera, degrees.
    double vertical_fov_deg = 45.0;
    /// Share of the image left as margin around the model, in [0, 0.5).
    double margin = 0.04;
    /// Triangles with a vertex higher than this z of U are not drawn (dollhouse cut), metres.
    /// Unset: `cut_top_fraction` of the mesh's height is cut instead.
    std::optional<double> cut_above_z_m;
    /// Share of the mesh's z extent cut from the top when `cut_above_z_m` is unset, in [0, 1).
    double cut_top_fraction = 0.0;
    /// Skip triangles seen from behind (winding clockwise on screen). Meshes wound
    /// counter-clockwise seen from the free space (TSDF surfaces) then show a room from inside
    /// through its near walls.
    bool cull_back_faces = false;
    /// Direction towards the light, frame U (need not be unit).
    Eigen::Vector3d light_direction_U = Eigen::Vector3d(0.3, -0.4, 1.0);
    /// Light reaching faces turned away from the light, in [0, 1].
    double ambient = 0.35;
    /// Colour of vertices when the mesh has none.
    Color3u8 default_colour = Color3u8(190, 190, 190);
    /// Background colour.
    Color3u8 background = Color3u8(255, 255, 255);
};

/// The picture and its camera, so callers can draw over it.
struct MeshRender {
    RgbImage image;
    /// Depth per pixel (distance along the viewing direction, metres; +inf where nothing was
    /// drawn), row-major like `image`.
    std::vector<float> depth;
    size_t triangles_drawn = 0;   ///< triangles that covered at least one pixel
    size_t triangles_culled = 0;  ///< cut away, behind the camera or back-facing
    /// U -> camera (x right, y down, z forward).
    Eigen::Isometry3d T_C_U = Eigen::Isometry3d::Identity();
    RenderProjection projection = RenderProjection::kOrthographic;
    double focal_px = 1.0;  ///< pixels per metre (orthographic) or focal length (perspective)
    Eigen::Vector2d principal_px = Eigen::Vector2d::Zero();

    /// Pixel (x right, y down; pixel centres at +0.5) and depth of a point of U; nullopt behind
    /// a perspective camera.
    std::optional<Eigen::Vector3d> project(const Eigen::Vector3d& p_U) const;
};

/// Renders `mesh` after mapping its vertices by `T_U_M` (mesh frame -> up frame). An empty mesh
/// gives the background. Preconditions (checked): positive image size.
MeshRender renderMesh(const TriangleMesh& mesh, const Eigen::Isometry3d& T_U_M,
                      const MeshRenderConfig& config = {});

}  // namespace plumb::backend
