// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/trajectory.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "common/geometry/lie.hpp"
#include "common/geometry/polygon.hpp"
#include "drivers/sim/noise.hpp"

namespace plumb::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kStep = 0.01;  // arc-length sampling of the path, metres

double distanceToSegment(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                         const Eigen::Vector2d& b) {
    const Eigen::Vector2d e = b - a;
    const double t = std::clamp((p - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
    return (a + t * e - p).norm();
}

double distanceToWalls(const Scene& scene, const Eigen::Vector2d& p) {
    double best = std::numeric_limits<double>::infinity();
    const int n = scene.numWalls();
    for (int k = 0; k < n; ++k) {
        best = std::min(best, distanceToSegment(p, scene.polygon[k], scene.polygon[(k + 1) % n]));
    }
    return best;
}

// A smooth scalar: sum of three sinusoids with seeded frequencies in [f_lo, f_hi] Hz and phases;
// the amplitudes are split so that the sum's peak is at most `amplitude`.
struct Wobble {
    double freq[3];
    double phase[3];
    double amp[3];
    double operator()(double t) const {
        double v = 0.0;
        for (int i = 0; i < 3; ++i) v += amp[i] * std::sin(2.0 * kPi * freq[i] * t + phase[i]);
        return v;
    }
};

Wobble makeWobble(std::mt19937_64& rng, double amplitude, double f_lo, double f_hi) {
    std::uniform_real_distribution<double> freq(f_lo, f_hi);
    std::uniform_real_distribution<double> phase(0.0, 2.0 * kPi);
    Wobble w{};
    for (int i = 0; i < 3; ++i) {
        w.freq[i] = freq(rng);
        w.phase[i] = phase(rng);
        w.amp[i] = amplitude / 3.0;
    }
    return w;
}

// Dense arc-length samples of the path with heading and time.
struct PathSamples {
    std::vector<Eigen::Vector2d> xy;
    std::vector<double> heading;  // unwrapped, radians
    std::vector<double> time;     // seconds from the start
    double length = 0.0;
};

}  // namespace

Eigen::Matrix3d cameraRotation(double yaw_rad, double pitch_rad, double roll_rad) {
    const Eigen::Vector3d f(std::cos(pitch_rad) * std::cos(yaw_rad),
                            std::cos(pitch_rad) * std::sin(yaw_rad), std::sin(pitch_rad));
    const Eigen::Vector3d r(std::sin(yaw_rad), -std::cos(yaw_rad), 0.0);
    Eigen::Matrix3d R;
    R.col(0) = r;
    R.col(1) = f.cross(r);
    R.col(2) = f;
    return R * Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

Result<std::vector<Eigen::Vector2d>> pathControlPoints(const Scene& scene) {
    std::vector<Eigen::Vector2d> corners = scene.path_waypoints;
    if (corners.empty()) {
        // Offset every edge inward and intersect neighbouring offset lines.
        const int n = scene.numWalls();
        const double m = scene.path_inset_m;
        for (int k = 0; k < n; ++k) {
            const int j = (k + n - 1) % n;
            const Eigen::Vector2d a0 = scene.polygon[j], e0 = scene.polygon[k] - a0;
            const Eigen::Vector2d a1 = scene.polygon[k], e1 = scene.polygon[(k + 1) % n] - a1;
            const Eigen::Vector2d n0 = Eigen::Vector2d(-e0.y(), e0.x()).normalized();
            const Eigen::Vector2d n1 = Eigen::Vector2d(-e1.y(), e1.x()).normalized();
            const Eigen::Vector2d p0 = a0 + m * n0, p1 = a1 + m * n1;
            const double denom = cross2(e0, e1);
            if (std::abs(denom) < 1e-12 * e0.norm() * e1.norm()) {
                corners.push_back(p1);
                continue;
            }
            const double t = cross2(p1 - p0, e1) / denom;
            corners.push_back(p0 + t * e0);
        }
        for (size_t i = 0; i < corners.size(); ++i) {
            // An inset edge that flips direction means the offset collapsed the room.
            const Eigen::Vector2d e_in = corners[(i + 1) % corners.size()] - corners[i];
            const Eigen::Vector2d e_room = scene.polygon[(i + 1) % n] - scene.polygon[i];
            if (e_in.dot(e_room) <= 0.0 || !insidePolygon(scene.polygon, corners[i]) ||
                distanceToWalls(scene, corners[i]) < 0.5 * m - 1e-9) {
                return invalidArgument(fmt::format(
                    "scene '{}': path_inset_m = {} m is too large for the room (inset corner {} "
                    "leaves the room); give explicit path waypoints",
                    scene.name, m, i));
            }
        }
    }
    std::vector<Eigen::Vector2d> control;
    for (size_t i = 0; i < corners.size(); ++i) {
        const Eigen::Vector2d a = corners[i], b = corners[(i + 1) % corners.size()];
        const int pieces = std::max(1, static_cast<int>(std::ceil((b - a).norm() / 1.0)));
        for (int p = 0; p < pieces; ++p) control.push_back(a + (b - a) * (double(p) / pieces));
    }
    if (control.size() < 3) {
        return invalidArgument(
            fmt::format("scene '{}': the path needs >= 3 waypoints", scene.name));
    }
    return control;
}

namespace {

Status checkTrajectoryConfig(const TrajectoryConfig& cfg) {
    if (cfg.num_frames == 0 || !(cfg.rate_hz > 0.0) || !(cfg.min_speed_mps > 0.0) ||
        cfg.max_speed_mps < cfg.min_speed_mps || !(cfg.max_yaw_rate_dps > 0.0) ||
        !(cfg.max_accel_mps2 > 0.0) ||
        !(cfg.no_loop_fraction > 0.0 && cfg.no_loop_fraction <= 1.0)) {
        return invalidArgument(
            "trajectory config: need num_frames > 0, rate_hz > 0, 0 < min_speed <= max_speed, "
            "positive yaw-rate and acceleration limits, 0 < no_loop_fraction <= 1");
    }
    return Status::ok();
}

/// The path starts at the straightest control point (the first one on a straight stretch,
/// mid-edge on the built-in rooms): starting at a corner, the first views would look back into
/// the wall just turned from.
int straightestControlPoint(const std::vector<Eigen::Vector2d>& P) {
    const int n = static_cast<int>(P.size());
    int start = 0;
    double least_turn = kPi;
    for (int i = 0; i < n; ++i) {
        const Eigen::Vector2d in = P[i] - P[(i + n - 1) % n], out = P[(i + 1) % n] - P[i];
        const double turn = std::abs(std::atan2(cross2(in, out), in.dot(out)));
        if (turn < least_turn - 1e-9) {
            least_turn = turn;
            start = i;
        }
    }
    return start;
}

/// The closed uniform cubic B-spline through the control points from `start`, densely sampled,
/// then resampled every kStep of arc length over one lap (the loop) or no_loop_fraction of it.
/// Every sample must lie inside the room, at least 30 cm from the walls.
Result<PathSamples> samplePath(const std::vector<Eigen::Vector2d>& P, int start, const Scene& scene,
                               const TrajectoryConfig& cfg) {
    const int n = static_cast<int>(P.size());
    std::vector<Eigen::Vector2d> dense;
    constexpr int kPerSegment = 200;
    for (int j = 0; j < n; ++j) {
        const int i = (j + start) % n;
        const Eigen::Vector2d& p0 = P[(i + n - 1) % n];
        const Eigen::Vector2d& p1 = P[i];
        const Eigen::Vector2d& p2 = P[(i + 1) % n];
        const Eigen::Vector2d& p3 = P[(i + 2) % n];
        for (int k = 0; k < kPerSegment; ++k) {
            const double t = double(k) / kPerSegment;
            const double t2 = t * t, t3 = t2 * t;
            const double b0 = (1 - t) * (1 - t) * (1 - t) / 6.0;
            const double b1 = (3 * t3 - 6 * t2 + 4) / 6.0;
            const double b2 = (-3 * t3 + 3 * t2 + 3 * t + 1) / 6.0;
            const double b3 = t3 / 6.0;
            dense.push_back(b0 * p0 + b1 * p1 + b2 * p2 + b3 * p3);
        }
    }
    dense.push_back(dense.front());
    std::vector<double> cum(dense.size(), 0.0);
    for (size_t i = 1; i < dense.size(); ++i)
        cum[i] = cum[i - 1] + (dense[i] - dense[i - 1]).norm();
    const double loop_length = cum.back();
    const double length = cfg.loop ? loop_length : cfg.no_loop_fraction * loop_length;
    PathSamples path;
    path.length = length;
    const int num_samples = static_cast<int>(std::floor(length / kStep)) + 1;
    size_t seg = 0;
    for (int i = 0; i < num_samples; ++i) {
        const double s = std::min(i * kStep, loop_length);
        while (seg + 2 < cum.size() && cum[seg + 1] < s) ++seg;
        const double span = cum[seg + 1] - cum[seg];
        const double a = span > 0.0 ? (s - cum[seg]) / span : 0.0;
        path.xy.push_back(dense[seg] + a * (dense[seg + 1] - dense[seg]));
    }
    for (const Eigen::Vector2d& p : path.xy) {
        if (!insidePolygon(scene.polygon, p) || distanceToWalls(scene, p) < 0.3) {
            return invalidArgument(fmt::format(
                "scene '{}': the camera path passes within 30 cm of a wall at ({:.2f}, {:.2f})",
                scene.name, p.x(), p.y()));
        }
    }
    return path;
}

/// The heading of the path's tangent (central differences over +-10 cm), unwrapped.
void pathHeadings(bool loop, PathSamples* path) {
    const int m = static_cast<int>(path->xy.size());
    path->heading.resize(m);
    auto at = [&](int i) {
        if (loop) return path->xy[((i % (m - 1)) + (m - 1)) % (m - 1)];
        return path->xy[std::clamp(i, 0, m - 1)];
    };
    for (int i = 0; i < m; ++i) {
        const Eigen::Vector2d d = at(i + 10) - at(i - 10);
        path->heading[i] = std::atan2(d.y(), d.x());
        if (i > 0) {
            while (path->heading[i] - path->heading[i - 1] > kPi) path->heading[i] -= 2 * kPi;
            while (path->heading[i] - path->heading[i - 1] < -kPi) path->heading[i] += 2 * kPi;
        }
    }
}

/// The time profile of walking the path at a nominal speed, slowed where the yaw rate
/// |d heading / ds| * v would exceed max_yaw_rate_dps and limited in acceleration.
class SpeedProfile {
  public:
    SpeedProfile(const PathSamples& path, const TrajectoryConfig& cfg)
        : path_(path), cfg_(cfg), curvature_(path.xy.size(), 0.0) {
        const int m = static_cast<int>(path.xy.size());
        for (int i = 0; i < m; ++i) {
            const int i0 = std::max(0, i - 5), i1 = std::min(m - 1, i + 5);
            if (i1 > i0)
                curvature_[i] = std::abs(path.heading[i1] - path.heading[i0]) / ((i1 - i0) * kStep);
        }
    }

    /// Fills the time of each path sample at nominal speed v_nom; returns the total time.
    double operator()(double v_nom, std::vector<double>* time) const {
        const int m = static_cast<int>(path_.xy.size());
        const double omega = cfg_.max_yaw_rate_dps * kDeg;
        std::vector<double> v(m);
        for (int i = 0; i < m; ++i) v[i] = std::min(v_nom, omega / std::max(curvature_[i], 1e-9));
        for (int i = 1; i < m; ++i) {
            v[i] = std::min(v[i], std::sqrt(v[i - 1] * v[i - 1] + 2 * cfg_.max_accel_mps2 * kStep));
        }
        for (int i = m - 2; i >= 0; --i) {
            v[i] = std::min(v[i], std::sqrt(v[i + 1] * v[i + 1] + 2 * cfg_.max_accel_mps2 * kStep));
        }
        time->assign(m, 0.0);
        for (int i = 1; i < m; ++i) {
            const double ds = (path_.xy[i] - path_.xy[i - 1]).norm();
            (*time)[i] = (*time)[i - 1] + ds / (0.5 * (v[i - 1] + v[i]));
        }
        return time->back();
    }

  private:
    const PathSamples& path_;
    const TrajectoryConfig& cfg_;
    std::vector<double> curvature_;
};

/// Times the path so that num_frames frames at rate_hz cover it: the nominal speed within
/// [min_speed_mps, max_speed_mps] found by bisection. The loop variant runs an integer number of
/// laps when the speed range allows it, so that the last frame is back at the start; otherwise
/// (too few frames) a partial lap at full speed. When no whole number of laps fits the speed
/// range, the most laps at <= max speed are taken and the nominal speed may drop to half of
/// min_speed_mps. Fills path->time; returns the time of one pass.
double timePath(const TrajectoryConfig& cfg, PathSamples* path) {
    const SpeedProfile profile(*path, cfg);
    double target = (cfg.num_frames - 1) / cfg.rate_hz;
    double lo = cfg.min_speed_mps, hi = cfg.max_speed_mps;
    if (cfg.loop) {
        std::vector<double> scratch;
        const double slowest = profile(cfg.min_speed_mps, &scratch);
        const double fastest = profile(cfg.max_speed_mps, &scratch);
        if (target >= fastest) {
            double laps = std::max(1.0, std::ceil(target / slowest - 1e-9));
            if (target / laps < fastest) {
                laps = std::max(1.0, std::floor(target / fastest));
                lo = 0.5 * cfg.min_speed_mps;
            }
            target /= laps;
        }
    }
    std::vector<double> time;
    if (profile(hi, &time) >= target) {
        lo = hi;
    } else if (profile(lo, &time) <= target) {
        hi = lo;
    } else {
        for (int it = 0; it < 50; ++it) {
            const double mid = 0.5 * (lo + hi);
            if (profile(mid, &time) > target) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
    }
    return profile(0.5 * (lo + hi), &path->time);
}

/// The camera poses at the frame times along the timed path, with seeded shake and sway.
io::Trajectory posesAlongPath(const PathSamples& path, double total, const TrajectoryConfig& cfg) {
    const int m = static_cast<int>(path.xy.size());
    std::mt19937_64 rng(mixSeed(cfg.seed ^ 0x7472616A65637472ULL));
    Wobble shake_pos[3], shake_rot[3];
    for (auto& w : shake_pos) w = makeWobble(rng, cfg.shake_position_m, 0.3, 1.2);
    for (auto& w : shake_rot) w = makeWobble(rng, cfg.shake_rotation_deg * kDeg, 0.3, 1.2);
    std::uniform_real_distribution<double> phase(0.0, 2.0 * kPi);
    const double pitch_phase = phase(rng);
    const double height_phase = phase(rng);

    io::Trajectory out;
    out.reserve(cfg.num_frames);
    for (size_t k = 0; k < cfg.num_frames; ++k) {
        const double t = k / cfg.rate_hz;
        double tp = t;
        if (cfg.loop) {
            tp = std::fmod(t, total);
        } else {
            tp = std::min(t, total);
        }
        const size_t i = std::min<size_t>(
            std::upper_bound(path.time.begin(), path.time.end(), tp) - path.time.begin(), m - 1);
        const size_t i0 = i == 0 ? 0 : i - 1;
        const double span = path.time[i] - path.time[i0];
        const double a = span > 0.0 ? std::clamp((tp - path.time[i0]) / span, 0.0, 1.0) : 0.0;
        const Eigen::Vector2d xy = path.xy[i0] + a * (path.xy[i] - path.xy[i0]);
        const double heading = path.heading[i0] + a * (path.heading[i] - path.heading[i0]);
        const double yaw = heading + cfg.look_offset_deg * kDeg;
        const double pitch =
            (cfg.pitch_deg + cfg.pitch_sway_deg * std::sin(2 * kPi * t / 9.0 + pitch_phase)) * kDeg;
        const double z =
            cfg.height_m + cfg.height_sway_m * std::sin(2 * kPi * t / 7.0 + height_phase);
        Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
        T.translation() = Eigen::Vector3d(xy.x() + shake_pos[0](t), xy.y() + shake_pos[1](t),
                                          z + shake_pos[2](t));
        const Eigen::Vector3d rot(shake_rot[0](t), shake_rot[1](t), shake_rot[2](t));
        const double roll = cfg.roll_sway_deg * kDeg * std::sin(2 * kPi * t / 8.0);
        T.linear() = cameraRotation(yaw, pitch, roll) * lie::expSO3(rot);
        out.push_back({t, T});
    }
    return out;
}

}  // namespace

Result<io::Trajectory> generateTrajectory(const Scene& scene, const TrajectoryConfig& cfg) {
    PLUMB_RETURN_IF_ERROR(checkTrajectoryConfig(cfg));
    auto control_or = pathControlPoints(scene);
    if (!control_or.isOk()) return control_or.status();
    const std::vector<Eigen::Vector2d>& P = control_or.value();
    Result<PathSamples> path = samplePath(P, straightestControlPoint(P), scene, cfg);
    if (!path.isOk()) return path.status();
    pathHeadings(cfg.loop, &*path);
    const double total = timePath(cfg, &*path);
    return posesAlongPath(*path, total, cfg);
}

}  // namespace plumb::sim
