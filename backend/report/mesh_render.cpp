// SPDX-License-Identifier: Apache-2.0
#include "backend/report/mesh_render.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/core/check.hpp"

namespace plumb::backend {

namespace {

constexpr double kDegToRad = M_PI / 180.0;

/// Unit vector from the model towards the camera, frame U.
Eigen::Vector3d towardsCamera(const MeshRenderConfig& config) {
    const double el = config.elevation_deg * kDegToRad;
    const double az = config.azimuth_deg * kDegToRad;
    return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

/// Camera axes in U: z forward (= -towards), x right (horizontal, defined at any elevation),
/// y = z x x (down on the image).
Eigen::Matrix3d cameraAxes_U(const MeshRenderConfig& config) {
    const double az = config.azimuth_deg * kDegToRad;
    const Eigen::Vector3d z = -towardsCamera(config);
    const Eigen::Vector3d x(-std::sin(az), std::cos(az), 0.0);
    const Eigen::Vector3d y = z.cross(x).normalized();
    Eigen::Matrix3d R_U_C;
    R_U_C.col(0) = x;
    R_U_C.col(1) = y;
    R_U_C.col(2) = z;
    return R_U_C;
}

}  // namespace

std::optional<Eigen::Vector3d> MeshRender::project(const Eigen::Vector3d& p_U) const {
    const Eigen::Vector3d p_C = T_C_U * p_U;
    if (projection == RenderProjection::kOrthographic)
        return Eigen::Vector3d(principal_px.x() + focal_px * p_C.x(),
                               principal_px.y() + focal_px * p_C.y(), p_C.z());
    if (p_C.z() <= 1e-6) return std::nullopt;
    return Eigen::Vector3d(principal_px.x() + focal_px * p_C.x() / p_C.z(),
                           principal_px.y() + focal_px * p_C.y() / p_C.z(), p_C.z());
}

namespace {

/// The dollhouse cut: the triangles whose vertices are valid and not above the cut height (the
/// ceiling cut away), in mesh order; marks their vertices in `used` and counts the others as
/// culled.
std::vector<const Eigen::Vector3i*> keptTriangles(const TriangleMesh& mesh,
                                                  const std::vector<Eigen::Vector3d>& p_U,
                                                  const MeshRenderConfig& config,
                                                  std::vector<char>* used, MeshRender* out) {
    double z_lo = std::numeric_limits<double>::infinity(), z_hi = -z_lo;
    for (const auto& p : p_U) {
        z_lo = std::min(z_lo, p.z());
        z_hi = std::max(z_hi, p.z());
    }
    const double cut_z = config.cut_above_z_m
                             ? *config.cut_above_z_m
                             : z_hi - std::clamp(config.cut_top_fraction, 0.0, 1.0) * (z_hi - z_lo);
    std::vector<const Eigen::Vector3i*> kept;
    kept.reserve(mesh.triangles.size());
    used->assign(p_U.size(), 0);
    for (const Eigen::Vector3i& t : mesh.triangles) {
        bool ok = true;
        for (int k = 0; k < 3; ++k) {
            const int i = t[k];
            if (i < 0 || static_cast<size_t>(i) >= p_U.size() || !p_U[i].allFinite() ||
                p_U[i].z() > cut_z + 1e-9)
                ok = false;
        }
        if (!ok) {
            ++out->triangles_culled;
            continue;
        }
        kept.push_back(&t);
        for (int k = 0; k < 3; ++k) (*used)[t[k]] = 1;
    }
    return kept;
}

/// Places the camera so that the used vertices fill the image but for the margin: sets
/// out->T_C_U, focal_px and principal_px; returns the camera's position in U.
Eigen::Vector3d frameCamera(const std::vector<Eigen::Vector3d>& p_U, const std::vector<char>& used,
                            const MeshRenderConfig& config, MeshRender* out) {
    const int w = config.width_px;
    const int h = config.height_px;
    const Eigen::Matrix3d R_U_C = cameraAxes_U(config);
    const Eigen::Vector3d towards_U = towardsCamera(config);
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    Eigen::Vector3d hi = -lo;
    for (size_t i = 0; i < p_U.size(); ++i) {
        if (!used[i]) continue;
        lo = lo.cwiseMin(p_U[i]);
        hi = hi.cwiseMax(p_U[i]);
    }
    const Eigen::Vector3d centre_U = 0.5 * (lo + hi);
    const double radius = std::max(0.5 * (hi - lo).norm(), 1e-3);
    const double usable = std::clamp(1.0 - 2.0 * config.margin, 0.05, 1.0);
    Eigen::Vector3d camera_U;
    if (config.projection == RenderProjection::kOrthographic) {
        camera_U = centre_U + towards_U * (radius + 1.0);
        Eigen::Isometry3d T_U_C = Eigen::Isometry3d::Identity();
        T_U_C.linear() = R_U_C;
        T_U_C.translation() = camera_U;
        out->T_C_U = T_U_C.inverse();
        Eigen::Vector2d c_lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
        Eigen::Vector2d c_hi = -c_lo;
        for (size_t i = 0; i < p_U.size(); ++i) {
            if (!used[i]) continue;
            const Eigen::Vector2d q = (out->T_C_U * p_U[i]).head<2>();
            c_lo = c_lo.cwiseMin(q);
            c_hi = c_hi.cwiseMax(q);
        }
        const Eigen::Vector2d span = (c_hi - c_lo).cwiseMax(1e-6);
        out->focal_px = std::min(usable * w / span.x(), usable * h / span.y());
        const Eigen::Vector2d mid = 0.5 * (c_lo + c_hi);
        out->principal_px = Eigen::Vector2d(0.5 * w, 0.5 * h) - out->focal_px * mid;
    } else {
        const double half_v = 0.5 * std::clamp(config.vertical_fov_deg, 5.0, 170.0) * kDegToRad;
        const double half_h = std::atan(std::tan(half_v) * w / h);
        const double half_min = std::min(half_v, half_h) * usable;
        camera_U = centre_U + towards_U * (radius / std::sin(half_min));
        Eigen::Isometry3d T_U_C = Eigen::Isometry3d::Identity();
        T_U_C.linear() = R_U_C;
        T_U_C.translation() = camera_U;
        out->T_C_U = T_U_C.inverse();
        out->focal_px = 0.5 * h / std::tan(half_v);
    }
    return camera_U;
}

/// Fills one projected triangle (screen x, y and depth per vertex) into the z-buffered image:
/// colour interpolated from the vertices' `col`, times the triangle's `shade`. True when a
/// pixel was drawn.
bool rasteriseTriangle(const Eigen::Vector3d& s0, const Eigen::Vector3d& s1,
                       const Eigen::Vector3d& s2, const Eigen::Vector3d (&col)[3], double shade,
                       bool perspective, MeshRender* out) {
    const int w = out->image.width;
    const int h = out->image.height;
    // Edge functions in screen space; the area's sign gives the orientation.
    const double area =
        (s1.x() - s0.x()) * (s2.y() - s0.y()) - (s2.x() - s0.x()) * (s1.y() - s0.y());
    if (std::abs(area) < 1e-12) return false;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({s0.x(), s1.x(), s2.x()}))));
    const int x1 = std::min(w - 1, static_cast<int>(std::ceil(std::max({s0.x(), s1.x(), s2.x()}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({s0.y(), s1.y(), s2.y()}))));
    const int y1 = std::min(h - 1, static_cast<int>(std::ceil(std::max({s0.y(), s1.y(), s2.y()}))));
    if (x0 > x1 || y0 > y1) return false;
    bool drew = false;
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            const double px = x + 0.5, py = y + 0.5;
            // Barycentric weights of vertex 0, 1, 2 (each the sub-triangle opposite it).
            const double w0 =
                ((s1.x() - px) * (s2.y() - py) - (s2.x() - px) * (s1.y() - py)) / area;
            const double w1 =
                ((s2.x() - px) * (s0.y() - py) - (s0.x() - px) * (s2.y() - py)) / area;
            const double w2 = 1.0 - w0 - w1;
            if (w0 < 0.0 || w1 < 0.0 || w2 < 0.0) continue;
            // Depth: affine in screen space for parallel rays, 1/z affine for a pinhole.
            const double z = perspective ? 1.0 / (w0 / s0.z() + w1 / s1.z() + w2 / s2.z())
                                         : w0 * s0.z() + w1 * s1.z() + w2 * s2.z();
            float& zbuf = out->depth[static_cast<size_t>(y) * w + x];
            if (!(z < zbuf)) continue;
            zbuf = static_cast<float>(z);
            const Eigen::Vector3d rgb = shade * (w0 * col[0] + w1 * col[1] + w2 * col[2]);
            out->image.set(x, y, rgb.cwiseMax(0.0).cwiseMin(255.0).array().round().cast<uint8_t>());
            drew = true;
        }
    }
    return drew;
}

}  // namespace

MeshRender renderMesh(const TriangleMesh& mesh, const Eigen::Isometry3d& T_U_M,
                      const MeshRenderConfig& config) {
    PLUMB_CHECK(config.width_px > 0 && config.height_px > 0)
        << "image size " << config.width_px << "x" << config.height_px;
    const int w = config.width_px;
    const int h = config.height_px;
    MeshRender out;
    out.projection = config.projection;
    out.image.width = w;
    out.image.height = h;
    out.image.rgb.resize(3 * static_cast<size_t>(w) * h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) out.image.set(x, y, config.background);
    out.depth.assign(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity());
    out.principal_px = Eigen::Vector2d(0.5 * w, 0.5 * h);

    std::vector<Eigen::Vector3d> p_U(mesh.vertices.size());
    for (size_t i = 0; i < p_U.size(); ++i) p_U[i] = T_U_M * mesh.vertices[i].cast<double>();
    std::vector<char> used;
    const std::vector<const Eigen::Vector3i*> kept = keptTriangles(mesh, p_U, config, &used, &out);
    if (kept.empty()) return out;
    const Eigen::Vector3d camera_U = frameCamera(p_U, used, config, &out);

    const Eigen::Vector3d towards_U = towardsCamera(config);
    const Eigen::Vector3d light_U =
        config.light_direction_U.norm() > 1e-12 ? config.light_direction_U.normalized() : towards_U;
    const bool has_colour = mesh.colors.size() == mesh.vertices.size();
    const bool perspective = config.projection == RenderProjection::kPerspective;
    for (const Eigen::Vector3i* tp : kept) {
        const Eigen::Vector3i& t = *tp;
        const Eigen::Vector3d& a = p_U[t[0]];
        const Eigen::Vector3d& b = p_U[t[1]];
        const Eigen::Vector3d& c = p_U[t[2]];
        Eigen::Vector3d n = (b - a).cross(c - a);
        if (n.norm() < 1e-15) {
            ++out.triangles_culled;
            continue;
        }
        n.normalize();
        const Eigen::Vector3d view = perspective ? (camera_U - (a + b + c) / 3.0) : towards_U;
        if (config.cull_back_faces && n.dot(view) < 0.0) {
            ++out.triangles_culled;
            continue;
        }
        const std::optional<Eigen::Vector3d> s[3] = {out.project(a), out.project(b),
                                                     out.project(c)};
        if (!s[0] || !s[1] || !s[2]) {
            ++out.triangles_culled;
            continue;
        }
        const double shade = config.ambient + (1.0 - config.ambient) * std::abs(n.dot(light_U));
        Eigen::Vector3d col[3];
        for (int k = 0; k < 3; ++k)
            col[k] = has_colour ? mesh.colors[t[k]].cast<double>()
                                : config.default_colour.cast<double>();
        if (rasteriseTriangle(*s[0], *s[1], *s[2], col, shade, perspective, &out))
            ++out.triangles_drawn;
    }
    return out;
}

}  // namespace plumb::backend
