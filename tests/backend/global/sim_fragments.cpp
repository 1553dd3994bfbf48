// SPDX-License-Identifier: Apache-2.0
#include "tests/backend/global/sim_fragments.hpp"

#include <algorithm>
#include <cmath>
#include <random>

#include "common/core/check.hpp"
#include "common/geometry/lie.hpp"
#include "drivers/sim/render.hpp"
#include "drivers/sim/trajectory.hpp"

namespace plumb::testing {

SimFragments makeSimFragments(const SimFragmentsOptions& o) {
    SimFragments out;
    Result<sim::Scene> scene = sim::builtinScene(o.scene);
    PLUMB_CHECK(scene.isOk()) << scene.status().toString();
    out.scene = scene.value();
    sim::TrajectoryConfig tc;
    tc.loop = o.loop;
    tc.num_frames = static_cast<size_t>(o.num_fragments * o.frames_per_fragment);
    tc.seed = o.seed;
    Result<io::Trajectory> traj = sim::generateTrajectory(out.scene, tc);
    PLUMB_CHECK(traj.isOk()) << traj.status().toString();
    Result<Layout> layout = makeRoomLayout(out.scene.polygon, out.scene.height_m);
    PLUMB_CHECK(layout.isOk()) << layout.status().toString();
    out.layout_gt = layout.value();

    const sim::RayCaster caster(out.scene);
    // A 640x480 camera with fx = fy = 525, subsampled to image_width x image_height rays.
    const double scale = static_cast<double>(o.image_width) / 640.0;
    const double f = 525.0 * scale;
    const double cx = 0.5 * (o.image_width - 1);
    const double cy = 0.5 * (o.image_height - 1);
    std::mt19937_64 rng(o.seed);
    std::normal_distribution<double> gauss(0.0, 1.0);
    const int step = std::max(1, o.frames_per_fragment / o.views_per_fragment);
    for (int k = 0; k < o.num_fragments; ++k) {
        Fragment frag;
        frag.id = static_cast<uint32_t>(k);
        const size_t first = static_cast<size_t>(k * o.frames_per_fragment);
        const Eigen::Isometry3d T_W_F = traj.value()[first].T_W_C;
        frag.T_W_F = T_W_F;
        frag.voxel_size_m = 0.01;
        std::vector<int> labels;
        for (int v = 0; v < o.views_per_fragment; ++v) {
            const size_t index = first + static_cast<size_t>(v * step);
            const Eigen::Isometry3d& T_W_C = traj.value()[index].T_W_C;
            const Eigen::Isometry3d T_F_C = T_W_F.inverse() * T_W_C;
            FragmentFrame ff;
            ff.frame_index = static_cast<int64_t>(index);
            ff.T_F_C = T_F_C;
            frag.frames.push_back(ff);
            for (int r = 0; r < o.image_height; ++r) {
                for (int c = 0; c < o.image_width; ++c) {
                    const Eigen::Vector3d d_C((c - cx) / f, (r - cy) / f, 1.0);
                    const sim::RayHit hit = caster.cast(T_W_C.translation(), T_W_C.linear() * d_C);
                    if (hit.label == sim::kNoPrimitive || hit.t <= 0.0 || hit.t > o.max_depth_m) {
                        continue;
                    }
                    double z = hit.t;
                    if (o.depth_noise) {
                        const double sigma = 0.0012 + 0.0019 * (z - 0.4) * (z - 0.4);
                        z += sigma * gauss(rng);
                    }
                    const Eigen::Vector3d p_C = z * d_C;
                    Eigen::Vector3d n_W = hit.normal_W;
                    if (o.normal_noise_deg > 0.0) {
                        const Eigen::Vector3d axis(gauss(rng), gauss(rng), gauss(rng));
                        n_W = lie::expSO3(axis *
                                          (o.normal_noise_deg * M_PI / 180.0 / std::sqrt(3.0))) *
                              n_W;
                    }
                    const Eigen::Vector3d p_F = T_F_C * p_C;
                    const Eigen::Vector3d n_F = T_W_F.linear().transpose() * n_W.normalized();
                    frag.points_F.points.push_back(p_F.cast<float>());
                    frag.points_F.normals.push_back(n_F.cast<float>());
                    labels.push_back(hit.label);
                }
            }
        }
        out.T_W_F_gt.push_back(T_W_F);
        out.fragments.push_back(std::move(frag));
        out.labels.push_back(std::move(labels));
    }
    return out;
}

Eigen::Isometry3d randomPerturbation(double angle_deg, double dist_m, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> gauss(0.0, 1.0);
    const Eigen::Vector3d axis = Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
    const Eigen::Vector3d dir = Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = lie::expSO3(axis * angle_deg * M_PI / 180.0);
    T.translation() = dir * dist_m;
    return T;
}

double cameraPositionRmse(const SimFragments& sim, const std::vector<Eigen::Isometry3d>& T_W_F) {
    double sum = 0.0;
    size_t n = 0;
    for (size_t k = 0; k < sim.fragments.size(); ++k) {
        for (const FragmentFrame& ff : sim.fragments[k].frames) {
            const Eigen::Vector3d est = (T_W_F[k] * ff.T_F_C).translation();
            const Eigen::Vector3d gt = (sim.T_W_F_gt[k] * ff.T_F_C).translation();
            sum += (est - gt).squaredNorm();
            ++n;
        }
    }
    return n > 0 ? std::sqrt(sum / static_cast<double>(n)) : 0.0;
}

namespace {

/// Exact distance from x (world) to the surface of the primitive with `label`.
double distanceToPrimitive(const sim::Scene& s, int label, const Eigen::Vector3d& x) {
    if (label == sim::floorLabel()) return std::abs(x.z());
    if (label == sim::ceilingLabel()) return std::abs(x.z() - s.height_m);
    const int nw = s.numWalls();
    if (label >= 2 && label < 2 + nw) {
        const int k = label - 2;
        const Eigen::Vector2d a = s.polygon[static_cast<size_t>(k)];
        const Eigen::Vector2d b = s.polygon[static_cast<size_t>((k + 1) % nw)];
        const Eigen::Vector2d e = (b - a).normalized();
        const Eigen::Vector2d n(-e.y(), e.x());
        return std::abs(n.dot(x.head<2>() - a));
    }
    const int nb = static_cast<int>(s.boxes.size());
    if (label >= 2 + nw && label < 2 + nw + nb) {
        const sim::Box& box = s.boxes[static_cast<size_t>(label - 2 - nw)];
        const Eigen::Vector3d d = x - box.center_W;
        const double c = std::cos(box.yaw_rad);
        const double sn = std::sin(box.yaw_rad);
        const Eigen::Vector3d local(c * d.x() + sn * d.y(), -sn * d.x() + c * d.y(), d.z());
        const Eigen::Vector3d q = local.cwiseAbs() - 0.5 * box.size_m;
        if (q.maxCoeff() <= 0.0) return -q.maxCoeff();
        return q.cwiseMax(0.0).norm();
    }
    const sim::Cylinder& cyl = s.cylinders[static_cast<size_t>(label - 2 - nw - nb)];
    const double dr = (x.head<2>() - cyl.center_xy).norm() - cyl.radius_m;
    const double dz = std::max(cyl.z_min_m - x.z(), x.z() - cyl.z_max_m);
    if (dr <= 0.0 && dz <= 0.0) return std::min(-dr, -dz);
    return Eigen::Vector2d(std::max(dr, 0.0), std::max(dz, 0.0)).norm();
}

}  // namespace

double meanReconstructionError(const SimFragments& sim, const std::vector<Eigen::Isometry3d>& T_W_F,
                               int label_filter) {
    double sum = 0.0;
    size_t n = 0;
    for (size_t k = 0; k < sim.fragments.size(); ++k) {
        const PointCloud& c = sim.fragments[k].points_F;
        for (size_t p = 0; p < c.size(); ++p) {
            const int label = sim.labels[k][p];
            if (label_filter >= 0 && label != label_filter) continue;
            const Eigen::Vector3d x = T_W_F[k] * c.points[p].cast<double>();
            sum += distanceToPrimitive(sim.scene, label, x);
            ++n;
        }
    }
    return n > 0 ? sum / static_cast<double>(n) : 0.0;
}

}  // namespace plumb::testing
