// SPDX-License-Identifier: Apache-2.0
#include "backend/model/final_model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <future>
#include <limits>
#include <unordered_map>

#include "common/cloud/kd_tree.hpp"
#include "common/core/parallel.hpp"
#include "common/tsdf/surface.hpp"
#include "common/tsdf/tsdf_volume.hpp"

namespace plumb::backend {

Status FinalModelConfig::validate() const {
    if (!(voxel_size_m > 0.0) || voxel_size_m > 0.5)
        return invalidArgument(
            fmt::format("final_model.voxel_size_m must be in (0, 0.5] m, got {}", voxel_size_m));
    if (!(truncation_m >= 2.0 * voxel_size_m))
        return invalidArgument(
            fmt::format("final_model.truncation_m ({}) must be at least two voxels ({})",
                        truncation_m, 2.0 * voxel_size_m));
    if (!(max_depth_m > 0.0)) return invalidArgument("final_model.max_depth_m must be positive");
    if (frame_stride < 1) return invalidArgument("final_model.frame_stride must be >= 1");
    if (surface_frame_stride < 1)
        return invalidArgument("final_model.surface_frame_stride must be >= 1");
    if (!(min_raw_frame_share > 0.0 && min_raw_frame_share <= 1.0))
        return invalidArgument(fmt::format(
            "final_model.min_raw_frame_share must be in (0, 1], got {}", min_raw_frame_share));
    if (allocation_stride_px < 1 || allocation_stride_px > 8)
        return invalidArgument("final_model.allocation_stride_px must be in [1, 8]");
    if (splat_radius_px < 0 || splat_radius_px > 8)
        return invalidArgument("final_model.splat_radius_px must be in [0, 8]");
    if (!(fragment_colour_radius_m >= 0.0 && fragment_colour_radius_m <= 1.0))
        return invalidArgument(
            fmt::format("final_model.fragment_colour_radius_m must be in [0, 1] m, got {}",
                        fragment_colour_radius_m));
    return Status::ok();
}

void describe(config::Schema& s, FinalModelConfig& c) {
    s.field("voxel_size_m", c.voxel_size_m, "voxel edge of the final volume", "m")
        .positive()
        .max(0.5);
    s.field("truncation_m", c.truncation_m, "TSDF truncation distance", "m").positive();
    s.field("max_depth_m", c.max_depth_m, "depth beyond this is not integrated", "m").positive();
    s.field("frame_stride", c.frame_stride,
            "integrate every k-th frame (1 = all); raw frames in between are skipped unread where "
            "the source allows (datasets, the simulator)")
        .min(1);
    s.field("surface_frame_stride", c.surface_frame_stride,
            "fragment surfaces only: every k-th tracked frame of each fragment (its first "
            "included) is rendered and integrated")
        .min(1);
    s.field("min_raw_frame_share", c.min_raw_frame_share,
            "plumb-backend: the stored raw frames are re-integrated when every fragment has at "
            "least this share of its tracked frames among them; else the fragment surfaces are "
            "fused")
        .positive()
        .max(1.0);
    s.field("allocation_stride_px", c.allocation_stride_px,
            "pixel stride of block allocation (1 = every pixel)", "px")
        .range(1, 8);
    s.field("fragment_colour_radius_m", c.fragment_colour_radius_m,
            "raw frames without colour, coloured fragments: a mesh vertex takes the colour of "
            "the nearest fragment point within this distance (0: mesh left uncoloured)",
            "m")
        .range(0.0, 1.0);
    s.field("min_weight", c.min_weight, "voxels observed fewer times are not meshed").min(0.0);
    s.field("splat_radius_px", c.splat_radius_px,
            "splat radius when rendering fragment points into synthetic depth frames", "px")
        .min(0)
        .max(8);
    s.field("num_threads", c.num_threads, "worker threads (0 = all); results do not depend on it")
        .min(0);
}

io::Trajectory frameTrajectory(const std::vector<Fragment>& fragments,
                               const std::vector<Eigen::Isometry3d>& T_W_F) {
    PLUMB_CHECK(fragments.size() == T_W_F.size())
        << fragments.size() << " fragments but " << T_W_F.size() << " poses";
    io::Trajectory trajectory;
    for (size_t i = 0; i < fragments.size(); ++i) {
        for (const FragmentFrame& f : fragments[i].frames) {
            if (!f.tracking_ok) continue;
            io::StampedPose p;
            p.timestamp_s = f.timestamp_s;
            p.T_W_C = T_W_F[i] * f.T_F_C;
            trajectory.push_back(p);
        }
    }
    return trajectory;
}

DepthImage renderPointsToDepth(const PointCloud& points_F, const PinholeCamera& camera,
                               const Eigen::Isometry3d& T_F_C, int splat_radius_px,
                               ColourImage* colour) {
    DepthImage depth(camera.width, camera.height, 0.0f);
    const bool with_colour = colour != nullptr && points_F.hasColors();
    if (colour != nullptr)
        *colour = with_colour ? ColourImage(camera.width, camera.height) : ColourImage();
    const Eigen::Isometry3f T_C_F = T_F_C.inverse().cast<float>();
    const Eigen::Matrix3f R_C_F = T_C_F.linear();
    const Eigen::Vector3f centre_F = T_F_C.translation().cast<float>();
    const bool have_normals = points_F.normals.size() == points_F.points.size();
    const int r = splat_radius_px;
    const auto fx = static_cast<float>(camera.fx), fy = static_cast<float>(camera.fy);
    const auto cx = static_cast<float>(camera.cx), cy = static_cast<float>(camera.cy);
    for (size_t k = 0; k < points_F.points.size(); ++k) {
        const Eigen::Vector3f& p_F = points_F.points[k];
        if (have_normals && points_F.normals[k].dot(centre_F - p_F) <= 0.0f) continue;  // back face
        const Eigen::Vector3f p_C = T_C_F * p_F;
        if (p_C.z() <= 0.0f) continue;
        const float u_f = fx * p_C.x() / p_C.z() + cx;
        const float v_f = fy * p_C.y() / p_C.z() + cy;
        if (!(u_f > -r - 1.0f && u_f < camera.width + r && v_f > -r - 1.0f &&
              v_f < camera.height + r))
            continue;
        const int u0 = static_cast<int>(std::floor(u_f + 0.5f));
        const int v0 = static_cast<int>(std::floor(v_f + 0.5f));
        // Tangent-plane splat: pixel (u, v) gets the depth where its ray meets the point's plane,
        // n . (z ray(u, v)) = n . p, so that a slanted surface's splats do not stand out of it
        // towards the camera. The inverse depth on a plane is affine in (u, v); over a splat a
        // few pixels wide the depth is taken to first order about the centre pixel, and kept
        // within kMaxSlope splat widths of the point's own depth (rays grazing the plane).
        constexpr float kMaxSlope = 4.0f;
        float z0 = p_C.z(), dz_du = 0.0f, dz_dv = 0.0f;
        const float max_step = kMaxSlope * static_cast<float>(r + 1) * p_C.z() / fx;
        if (have_normals && r > 0) {
            const Eigen::Vector3f n_C = R_C_F * points_F.normals[k];
            const float n_dot_p = n_C.dot(p_C);  // < 0: the point faces the camera
            const float ray_x = (static_cast<float>(u0) - cx) / fx;
            const float ray_y = (static_cast<float>(v0) - cy) / fy;
            const float w0 = (n_C.x() * ray_x + n_C.y() * ray_y + n_C.z()) / n_dot_p;  // 1 / z
            if (w0 > 0.0f && std::abs(1.0f / w0 - p_C.z()) <= max_step) {
                z0 = 1.0f / w0;
                dz_du = -z0 * z0 * n_C.x() / (fx * n_dot_p);
                dz_dv = -z0 * z0 * n_C.y() / (fy * n_dot_p);
            }
        }
        for (int v = std::max(v0 - r, 0); v <= std::min(v0 + r, camera.height - 1); ++v) {
            for (int u = std::max(u0 - r, 0); u <= std::min(u0 + r, camera.width - 1); ++u) {
                const float planar =
                    z0 + dz_du * static_cast<float>(u - u0) + dz_dv * static_cast<float>(v - v0);
                const float z = std::abs(planar - p_C.z()) <= max_step ? planar : p_C.z();
                float& d = depth(u, v);
                if (d == 0.0f || z < d) {
                    d = z;
                    if (with_colour) {
                        const Color3u8& c = points_F.colors[k];
                        (*colour)(u, v) = {c.x(), c.y(), c.z()};
                    }
                }
            }
        }
    }
    return depth;
}

bool colourFromFragmentPoints(const std::vector<Fragment>& fragments,
                              const std::vector<Eigen::Isometry3d>& T_W_F, double radius_m,
                              int num_threads, TriangleMesh* mesh) {
    PLUMB_CHECK(fragments.size() == T_W_F.size())
        << fragments.size() << " fragments but " << T_W_F.size() << " poses";
    size_t total = 0;
    for (const Fragment& f : fragments) total += f.points_F.hasColors() ? f.points_F.size() : 0;
    std::vector<Eigen::Vector3f> points;
    std::vector<Color3u8> colours;
    points.reserve(total);
    colours.reserve(total);
    for (size_t i = 0; i < fragments.size(); ++i) {
        const PointCloud& cloud = fragments[i].points_F;
        if (!cloud.hasColors()) continue;
        const Eigen::Isometry3f T = T_W_F[i].cast<float>();
        for (size_t k = 0; k < cloud.points.size(); ++k) {
            points.push_back(T * cloud.points[k]);
            colours.push_back(cloud.colors[k]);
        }
    }
    if (points.empty() || mesh->vertices.empty()) return false;
    const PointKdTree<float> tree(points);
    const auto max_dist_sq = static_cast<float>(radius_m * radius_m);
    mesh->colors.assign(mesh->vertices.size(), Color3u8(128, 128, 128));
    parallelFor(num_threads, mesh->vertices.size(), [&](size_t v) {
        uint32_t nearest = 0;
        float dist_sq = 0.0f;
        tree.index().knnSearch(mesh->vertices[v].data(), 1, &nearest, &dist_sq);
        if (dist_sq <= max_dist_sq) mesh->colors[v] = colours[nearest];
    });
    return true;
}

namespace {

tsdf::TsdfConfig volumeConfig(const FinalModelConfig& config) {
    tsdf::TsdfConfig c;
    c.voxel_size_m = static_cast<float>(config.voxel_size_m);
    c.truncation_m = static_cast<float>(config.truncation_m);
    c.max_depth_m = static_cast<float>(config.max_depth_m);
    c.allocation_stride_px = config.allocation_stride_px;
    c.num_threads = config.num_threads;
    return c;
}

FinalModel finish(const tsdf::TsdfVolume& volume, const FinalModelConfig& config, size_t frames,
                  bool raw) {
    tsdf::SurfaceConfig surface;
    surface.min_weight = static_cast<float>(config.min_weight);
    surface.num_threads = config.num_threads;
    FinalModel model;
    model.mesh = tsdf::extractMesh(volume, surface);
    model.frames_integrated = frames;
    model.blocks = volume.numBlocks();
    model.from_raw_frames = raw;
    return model;
}

}  // namespace

namespace {

Status checkVariants(const std::vector<Fragment>& fragments,
                     const std::vector<std::vector<Eigen::Isometry3d>>& T_W_F) {
    if (T_W_F.empty()) return invalidArgument("final model: no set of poses");
    for (const std::vector<Eigen::Isometry3d>& T : T_W_F)
        if (fragments.size() != T.size())
            return invalidArgument(
                fmt::format("{} fragments but {} poses", fragments.size(), T.size()));
    return Status::ok();
}

std::vector<FinalModel> finishAll(const std::vector<tsdf::TsdfVolume>& volumes,
                                  const FinalModelConfig& config, size_t frames, bool raw) {
    std::vector<FinalModel> models(volumes.size());
    parallelFor(config.num_threads, volumes.size(),
                [&](size_t v) { models[v] = finish(volumes[v], config, frames, raw); });
    return models;
}

std::vector<tsdf::TsdfVolume> volumesFor(size_t variants, const FinalModelConfig& config) {
    std::vector<tsdf::TsdfVolume> volumes;
    volumes.reserve(variants);
    for (size_t v = 0; v < variants; ++v) volumes.emplace_back(volumeConfig(config));
    return volumes;
}

/// Integrates one frame of fragment `fragment` (at T_F_C in it) into every variant's volume, the
/// volumes side by side: each integration is parallel inside, and while one allocates its new
/// blocks (a serial step) the other's voxels keep the second core busy.
Status integrateAll(std::vector<tsdf::TsdfVolume>& volumes, const DepthImage& depth,
                    const PinholeCamera& camera,
                    const std::vector<std::vector<Eigen::Isometry3d>>& T_W_F, size_t fragment,
                    const Eigen::Isometry3d& T_F_C, const ColourImage* colour, int num_threads) {
    std::vector<Status> status(volumes.size(), Status::ok());
    parallelFor(num_threads, volumes.size(), [&](size_t v) {
        Result<tsdf::IntegrationStats> stats =
            volumes[v].integrate(depth, camera, T_W_F[v][fragment] * T_F_C, colour);
        if (!stats.isOk()) status[v] = stats.status();
    });
    for (const Status& s : status) PLUMB_RETURN_IF_ERROR(s);
    return Status::ok();
}

/// The frames of `fragment` whose views of its surface are integrated: tracked, on the global
/// frame_stride, and every surface_frame_stride-th of those (the first included).
std::vector<const FragmentFrame*> surfaceViews(const Fragment& fragment,
                                               const FinalModelConfig& config) {
    std::vector<const FragmentFrame*> views;
    size_t tracked = 0;
    for (const FragmentFrame& f : fragment.frames) {
        if (!f.tracking_ok || f.frame_index % config.frame_stride != 0) continue;
        if (tracked++ % static_cast<size_t>(config.surface_frame_stride) == 0) views.push_back(&f);
    }
    return views;
}

}  // namespace

Result<std::vector<FinalModel>> integrateRawFrames(
    FrameSource& source, const std::vector<Fragment>& fragments,
    const std::vector<std::vector<Eigen::Isometry3d>>& T_W_F, const FinalModelConfig& config,
    const ProgressCallback& progress) {
    PLUMB_RETURN_IF_ERROR(config.validate());
    PLUMB_RETURN_IF_ERROR(checkVariants(fragments, T_W_F));
    // Frame index -> (fragment, T_F_C) of every tracked frame.
    std::unordered_map<int64_t, std::pair<size_t, Eigen::Isometry3d>> frame_of;
    for (size_t i = 0; i < fragments.size(); ++i)
        for (const FragmentFrame& f : fragments[i].frames)
            if (f.tracking_ok) frame_of.emplace(f.frame_index, std::make_pair(i, f.T_F_C));
    if (frame_of.empty()) return invalidArgument("no tracked frame in any fragment");

    std::vector<tsdf::TsdfVolume> volumes = volumesFor(T_W_F.size(), config);
    size_t integrated = 0;
    size_t coloured = 0;  // of those, with colour
    size_t seen = 0;      // frames read or skipped
    size_t passed = 0;    // of those, handed to the integration loop (progress)
    // Every frame_stride-th frame is read, the others skipped (not decoded where the source
    // allows). The next frame is read (decoded, simulated, undistorted) while this one is
    // integrated; one call at a time and in order, so the source sees a plain loop's calls.
    const size_t stride = static_cast<size_t>(config.frame_stride);
    auto read = [&source, &seen, stride]() -> Result<Frame> {
        while (seen % stride != 0) {
            const Status s = source.skip();
            if (!s.isOk()) return s;
            ++seen;
        }
        Result<Frame> frame = source.next();
        if (frame.isOk()) ++seen;
        return frame;
    };
    std::future<Result<Frame>> next = std::async(std::launch::async, read);
    for (;;) {
        Result<Frame> frame = next.get();
        report(progress, seen - passed);
        passed = seen;
        if (!frame.isOk()) {
            if (frame.status().code() == StatusCode::kOutOfRange) break;
            return Status(frame.status().code(),
                          "re-integrating raw frames: " + frame.status().message());
        }
        next = std::async(std::launch::async, read);
        const auto it = frame_of.find(frame->index);
        if (it == frame_of.end()) continue;
        // Colour of another size than the depth (a source that does not register it) is left out.
        const bool colour = !frame->colour.empty() &&
                            frame->colour.width() == frame->depth.width() &&
                            frame->colour.height() == frame->depth.height();
        const auto& [fragment, T_F_C] = it->second;
        const Status s = integrateAll(volumes, frame->depth, source.camera(), T_W_F, fragment,
                                      T_F_C, colour ? &frame->colour : nullptr, config.num_threads);
        if (!s.isOk()) return s;
        ++integrated;
        if (colour) ++coloured;
    }
    if (integrated == 0)
        return failedPrecondition(fmt::format(
            "none of the {} frames of {} matches a fragment frame", seen, source.description()));
    std::vector<FinalModel> models = finishAll(volumes, config, integrated, true);
    if (coloured == 0 && config.fragment_colour_radius_m > 0.0) {
        // Side by side: each variant's k-d tree is built on one thread.
        parallelFor(config.num_threads, models.size(), [&](size_t v) {
            models[v].colour_from_fragments =
                colourFromFragmentPoints(fragments, T_W_F[v], config.fragment_colour_radius_m,
                                         config.num_threads, &models[v].mesh);
        });
    }
    return models;
}

Result<std::vector<FinalModel>> fuseFragmentSurfaces(
    const std::vector<Fragment>& fragments,
    const std::vector<std::vector<Eigen::Isometry3d>>& T_W_F, const PinholeCamera& camera,
    const FinalModelConfig& config, const ProgressCallback& progress) {
    PLUMB_RETURN_IF_ERROR(config.validate());
    PLUMB_RETURN_IF_ERROR(camera.validate());
    PLUMB_RETURN_IF_ERROR(checkVariants(fragments, T_W_F));
    std::vector<tsdf::TsdfVolume> volumes = volumesFor(T_W_F.size(), config);
    size_t integrated = 0;
    for (size_t i = 0; i < fragments.size(); ++i) {
        const Fragment& fragment = fragments[i];
        const std::vector<const FragmentFrame*> views = surfaceViews(fragment, config);
        // A fragment's synthetic frames are rendered side by side (each render is serial), up to
        // kBatch at a time (about 2 MB each at 640x480), then integrated in order.
        constexpr size_t kBatch = 16;
        std::vector<DepthImage> depth(std::min(views.size(), kBatch));
        std::vector<ColourImage> colour(depth.size());
        for (size_t first = 0; first < views.size(); first += kBatch) {
            const size_t count = std::min(kBatch, views.size() - first);
            parallelFor(config.num_threads, count, [&](size_t k) {
                depth[k] = renderPointsToDepth(fragment.points_F, camera, views[first + k]->T_F_C,
                                               config.splat_radius_px, &colour[k]);
            });
            for (size_t k = 0; k < count; ++k) {
                PLUMB_RETURN_IF_ERROR(
                    integrateAll(volumes, depth[k], camera, T_W_F, i, views[first + k]->T_F_C,
                                 colour[k].empty() ? nullptr : &colour[k], config.num_threads));
                ++integrated;
            }
        }
        report(progress);
    }
    if (integrated == 0) return invalidArgument("no tracked frame in any fragment");
    return finishAll(volumes, config, integrated, false);
}

}  // namespace plumb::backend
