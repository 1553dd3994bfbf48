// SPDX-License-Identifier: Apache-2.0
#include "messages/fragment_codec.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "common/geometry/lie.hpp"
#include "messages/crc32.hpp"

namespace plumb::messages {
namespace {

constexpr uint16_t kFlagNormals = 1u << 0;
constexpr uint16_t kFlagColors = 1u << 1;
constexpr uint16_t kFlagFloatPositions = 1u << 2;
constexpr uint16_t kFlagOdometryInformation = 1u << 3;  // version 2
constexpr uint16_t kKnownFlagsV1 = kFlagNormals | kFlagColors | kFlagFloatPositions;
constexpr uint16_t kKnownFlags = kKnownFlagsV1 | kFlagOdometryInformation;
constexpr size_t kFrameBytes = 8 + 8 + 12 * 8 + 1;

/// An information matrix: finite, symmetric, with a non-negative diagonal.
bool validInformation(const Matrix6d& information) {
    return information.allFinite() &&
           (information - information.transpose())
               .isZero(1e-9 * (1.0 + information.cwiseAbs().maxCoeff())) &&
           information.diagonal().minCoeff() >= 0.0;
}
constexpr double kMaxCoordinateM = 1e6;  // |p| beyond this is absurd for a room scan

static_assert(std::endian::native == std::endian::little, "the codec assumes a little-endian host");

class Writer {
  public:
    template <typename T>
    void put(T v) {
        const size_t at = out_.size();
        out_.resize(at + sizeof(T));
        std::memcpy(out_.data() + at, &v, sizeof(T));
    }
    void putPose(const Eigen::Isometry3d& T) {
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 4; ++c) put<double>(T.matrix()(r, c));
        }
    }
    std::vector<uint8_t>& bytes() { return out_; }

  private:
    std::vector<uint8_t> out_;
};

class Reader {
  public:
    explicit Reader(std::span<const uint8_t> in) : in_(in) {}
    size_t remaining() const { return in_.size() - pos_; }
    template <typename T>
    Status get(T& v, const char* what) {
        if (remaining() < sizeof(T)) {
            return corrupt(fmt::format("fragment: truncated at {} (byte {})", what, pos_));
        }
        std::memcpy(&v, in_.data() + pos_, sizeof(T));
        pos_ += sizeof(T);
        return Status::ok();
    }
    Status getFinite(double& v, const char* what) {
        PLUMB_RETURN_IF_ERROR(get(v, what));
        if (!std::isfinite(v)) return corrupt(fmt::format("fragment: {} is not finite", what));
        return Status::ok();
    }
    Status getPose(Eigen::Isometry3d& T, const char* what) {
        T.setIdentity();
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 4; ++c) PLUMB_RETURN_IF_ERROR(getFinite(T.matrix()(r, c), what));
        }
        if (!lie::isValidPose(T, 1e-6)) {
            return corrupt(fmt::format("fragment: {} is not a rigid transform", what));
        }
        return Status::ok();
    }
    const uint8_t* take(size_t n) {
        const uint8_t* p = in_.data() + pos_;
        pos_ += n;
        return p;
    }

  private:
    std::span<const uint8_t> in_;
    size_t pos_ = 0;
};

float signNotZero(float v) { return v >= 0.0f ? 1.0f : -1.0f; }

// Octahedral projection of a unit vector onto [-1, 1]^2 (lower hemisphere folded outwards).
Eigen::Vector2f octahedralProject(const Eigen::Vector3f& n) {
    const float l1 = std::abs(n.x()) + std::abs(n.y()) + std::abs(n.z());
    Eigen::Vector2f p(n.x() / l1, n.y() / l1);
    if (n.z() < 0.0f) {
        p = Eigen::Vector2f((1.0f - std::abs(p.y())) * signNotZero(p.x()),
                            (1.0f - std::abs(p.x())) * signNotZero(p.y()));
    }
    return p;
}

int16_t toSnorm16(float v) {
    return static_cast<int16_t>(std::lround(std::clamp(v, -1.0f, 1.0f) * 32767.0f));
}

}  // namespace

std::pair<int16_t, int16_t> encodeOctahedral(const Eigen::Vector3f& n) {
    const Eigen::Vector3d unit = n.cast<double>().normalized();
    const Eigen::Vector2f p = octahedralProject(unit.cast<float>()) * 32767.0f;
    const float fx = std::floor(p.x()), fy = std::floor(p.y());
    std::pair<int16_t, int16_t> best{0, 0};
    double best_dot = -2.0;
    // Of the four grid neighbours, keep the one whose decoded normal is closest to n (compared in
    // double: float dot products cannot resolve angles below ~3e-4 rad).
    for (const float cx : {fx, fx + 1.0f}) {
        for (const float cy : {fy, fy + 1.0f}) {
            const auto qx = toSnorm16(cx / 32767.0f), qy = toSnorm16(cy / 32767.0f);
            const double d = decodeOctahedral(qx, qy).cast<double>().dot(unit);
            if (d > best_dot) {
                best_dot = d;
                best = {qx, qy};
            }
        }
    }
    return best;
}

Eigen::Vector3f decodeOctahedral(int16_t x, int16_t y) {
    const float px = std::max(x / 32767.0f, -1.0f), py = std::max(y / 32767.0f, -1.0f);
    Eigen::Vector3f n(px, py, 1.0f - std::abs(px) - std::abs(py));
    if (n.z() < 0.0f) {
        const float ox = n.x(), oy = n.y();
        n.x() = (1.0f - std::abs(oy)) * signNotZero(ox);
        n.y() = (1.0f - std::abs(ox)) * signNotZero(oy);
    }
    return n.normalized();
}

double positionStep(const std::vector<Eigen::Vector3f>& points, const FragmentCodecConfig& config) {
    if (points.empty()) return config.max_position_step_m;
    Eigen::Vector3d lo = points[0].cast<double>(), hi = lo;
    for (const auto& p : points) {
        lo = lo.cwiseMin(p.cast<double>());
        hi = hi.cwiseMax(p.cast<double>());
    }
    const double extent = (hi - lo).maxCoeff();
    if (extent == 0.0) return config.max_position_step_m;
    const double step = extent / 65535.0;
    return step <= config.max_position_step_m ? step : 0.0;
}

Result<std::vector<uint8_t>> encodeFragment(const Fragment& fragment,
                                            const FragmentCodecConfig& config) {
    const PointCloud& cloud = fragment.points_F;
    if (!cloud.isConsistent()) {
        return invalidArgument(fmt::format("fragment {}: {} points but {} normals and {} colours",
                                           fragment.id, cloud.points.size(), cloud.normals.size(),
                                           cloud.colors.size()));
    }
    if (cloud.size() > std::numeric_limits<uint32_t>::max() ||
        fragment.frames.size() > std::numeric_limits<uint32_t>::max()) {
        return invalidArgument(fmt::format("fragment {}: too many points or frames", fragment.id));
    }
    if (!lie::isValidPose(fragment.T_W_F, 1e-6)) {
        return invalidArgument(
            fmt::format("fragment {}: T_W_F is not a rigid transform", fragment.id));
    }
    for (size_t i = 0; i < cloud.size(); ++i) {
        if (!cloud.points[i].allFinite() ||
            cloud.points[i].cast<double>().cwiseAbs().maxCoeff() > kMaxCoordinateM) {
            return invalidArgument(
                fmt::format("fragment {}: point {} is not finite or absurdly far", fragment.id, i));
        }
        if (cloud.hasNormals() &&
            (!cloud.normals[i].allFinite() || cloud.normals[i].norm() < 1e-6f)) {
            return invalidArgument(
                fmt::format("fragment {}: normal {} is not finite or zero", fragment.id, i));
        }
    }
    if (!std::isfinite(fragment.voxel_size_m) || fragment.voxel_size_m < 0.0 ||
        !std::isfinite(fragment.tracking_quality) || fragment.tracking_quality < 0.0 ||
        fragment.tracking_quality > 1.0) {
        return invalidArgument(
            fmt::format("fragment {}: voxel size {} or tracking quality {} out of range",
                        fragment.id, fragment.voxel_size_m, fragment.tracking_quality));
    }
    const bool with_information = !fragment.odometry_information.isZero(0.0);
    if (with_information && !validInformation(fragment.odometry_information)) {
        return invalidArgument(fmt::format(
            "fragment {}: odometry information is not a finite symmetric matrix", fragment.id));
    }
    for (const FragmentFrame& f : fragment.frames) {
        if (!std::isfinite(f.timestamp_s) || !lie::isValidPose(f.T_F_C, 1e-6)) {
            return invalidArgument(fmt::format("fragment {}: frame {} has a bad time or pose",
                                               fragment.id, f.frame_index));
        }
    }

    const double step = positionStep(cloud.points, config);
    const bool float_positions = step == 0.0;
    const bool with_colors = config.include_colors && cloud.hasColors();
    uint16_t flags = 0;
    if (cloud.hasNormals()) flags |= kFlagNormals;
    if (with_colors) flags |= kFlagColors;
    if (float_positions) flags |= kFlagFloatPositions;
    if (with_information) flags |= kFlagOdometryInformation;

    Writer w;
    w.bytes().reserve(128 + fragment.frames.size() * kFrameBytes + cloud.size() * 13);
    w.put<uint32_t>(kFragmentMagic);
    w.put<uint16_t>(with_information ? uint16_t{2} : uint16_t{1});
    w.put<uint16_t>(flags);
    w.put<uint32_t>(fragment.id);
    w.put<uint32_t>(fragment.segment);
    w.put<uint8_t>(static_cast<uint8_t>(fragment.end));
    w.putPose(fragment.T_W_F);
    w.put<double>(fragment.voxel_size_m);
    w.put<double>(fragment.tracking_quality);
    if (with_information) {
        for (int row = 0; row < 6; ++row) {
            for (int col = row; col < 6; ++col)
                w.put<double>(fragment.odometry_information(row, col));
        }
    }
    w.put<uint32_t>(static_cast<uint32_t>(fragment.frames.size()));
    for (const FragmentFrame& f : fragment.frames) {
        w.put<int64_t>(f.frame_index);
        w.put<double>(f.timestamp_s);
        w.putPose(f.T_F_C);
        w.put<uint8_t>(f.tracking_ok ? 1 : 0);
    }
    w.put<uint32_t>(static_cast<uint32_t>(cloud.size()));
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();
    if (!cloud.empty()) {
        origin = cloud.points[0].cast<double>();
        for (const auto& p : cloud.points) origin = origin.cwiseMin(p.cast<double>());
    }
    for (int k = 0; k < 3; ++k) w.put<double>(origin[k]);
    w.put<double>(float_positions ? 0.0 : step);
    for (const auto& p : cloud.points) {
        for (int k = 0; k < 3; ++k) {
            if (float_positions) {
                w.put<float>(p[k]);
            } else {
                const double q = std::round((static_cast<double>(p[k]) - origin[k]) / step);
                w.put<uint16_t>(static_cast<uint16_t>(std::clamp(q, 0.0, 65535.0)));
            }
        }
    }
    if (flags & kFlagNormals) {
        for (const auto& n : cloud.normals) {
            const auto [x, y] = encodeOctahedral(n);
            w.put<int16_t>(x);
            w.put<int16_t>(y);
        }
    }
    if (with_colors) {
        for (const auto& c : cloud.colors) {
            w.put<uint8_t>(c[0]);
            w.put<uint8_t>(c[1]);
            w.put<uint8_t>(c[2]);
        }
    }
    w.put<uint32_t>(crc32(w.bytes()));
    return std::move(w.bytes());
}

Result<Fragment> decodeFragment(std::span<const uint8_t> bytes) {
    if (bytes.size() < 16) {
        return corrupt(fmt::format("fragment: truncated ({} bytes)", bytes.size()));
    }
    uint32_t stored_crc = 0;
    std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
    const auto body = bytes.first(bytes.size() - 4);
    Reader r(body);
    uint32_t magic = 0;
    uint16_t version = 0, flags = 0;
    PLUMB_RETURN_IF_ERROR(r.get(magic, "magic"));
    if (magic != kFragmentMagic) return corrupt("fragment: bad magic (not a plumb fragment)");
    PLUMB_RETURN_IF_ERROR(r.get(version, "version"));
    if (version < 1 || version > kFragmentCodecVersion) {
        return unsupported(fmt::format("fragment: codec version {} (this build reads {})", version,
                                       kFragmentCodecVersion));
    }
    const uint32_t computed_crc = crc32(body);
    if (computed_crc != stored_crc) {
        return corrupt(fmt::format("fragment: CRC mismatch (stored {:08x}, computed {:08x})",
                                   stored_crc, computed_crc));
    }
    PLUMB_RETURN_IF_ERROR(r.get(flags, "flags"));
    if (flags & ~(version == 1 ? kKnownFlagsV1 : kKnownFlags)) {
        return corrupt(fmt::format("fragment: unknown flags {:#x} for version {}", flags, version));
    }

    Fragment f;
    uint8_t end = 0;
    PLUMB_RETURN_IF_ERROR(r.get(f.id, "id"));
    PLUMB_RETURN_IF_ERROR(r.get(f.segment, "segment"));
    PLUMB_RETURN_IF_ERROR(r.get(end, "end"));
    if (end > static_cast<uint8_t>(FragmentEnd::kEndOfStream)) {
        return corrupt(fmt::format("fragment {}: unknown end reason {}", f.id, end));
    }
    f.end = static_cast<FragmentEnd>(end);
    PLUMB_RETURN_IF_ERROR(r.getPose(f.T_W_F, "T_W_F"));
    PLUMB_RETURN_IF_ERROR(r.getFinite(f.voxel_size_m, "voxel_size_m"));
    PLUMB_RETURN_IF_ERROR(r.getFinite(f.tracking_quality, "tracking_quality"));
    if (f.voxel_size_m < 0.0 || f.voxel_size_m > 1.0 || f.tracking_quality < 0.0 ||
        f.tracking_quality > 1.0) {
        return corrupt(fmt::format("fragment {}: voxel size {} or tracking quality {} absurd", f.id,
                                   f.voxel_size_m, f.tracking_quality));
    }
    if (flags & kFlagOdometryInformation) {
        for (int row = 0; row < 6; ++row) {
            for (int col = row; col < 6; ++col) {
                double v = 0.0;
                PLUMB_RETURN_IF_ERROR(r.getFinite(v, "odometry_information"));
                f.odometry_information(row, col) = v;
                f.odometry_information(col, row) = v;
            }
        }
        if (!validInformation(f.odometry_information)) {
            return corrupt(fmt::format("fragment {}: odometry information is absurd", f.id));
        }
    }
    uint32_t num_frames = 0;
    PLUMB_RETURN_IF_ERROR(r.get(num_frames, "num_frames"));
    if (num_frames > r.remaining() / kFrameBytes) {
        return corrupt(fmt::format("fragment {}: {} frames do not fit in {} bytes", f.id,
                                   num_frames, r.remaining()));
    }
    f.frames.resize(num_frames);
    for (FragmentFrame& fr : f.frames) {
        uint8_t ok = 0;
        PLUMB_RETURN_IF_ERROR(r.get(fr.frame_index, "frame_index"));
        PLUMB_RETURN_IF_ERROR(r.getFinite(fr.timestamp_s, "frame timestamp"));
        PLUMB_RETURN_IF_ERROR(r.getPose(fr.T_F_C, "T_F_C"));
        PLUMB_RETURN_IF_ERROR(r.get(ok, "tracking_ok"));
        if (ok > 1) return corrupt(fmt::format("fragment {}: tracking_ok is {}", f.id, ok));
        fr.tracking_ok = ok == 1;
    }
    uint32_t num_points = 0;
    PLUMB_RETURN_IF_ERROR(r.get(num_points, "num_points"));
    Eigen::Vector3d origin;
    double step = 0.0;
    for (int k = 0; k < 3; ++k) PLUMB_RETURN_IF_ERROR(r.getFinite(origin[k], "origin"));
    PLUMB_RETURN_IF_ERROR(r.getFinite(step, "step"));
    const bool float_positions = flags & kFlagFloatPositions;
    if (origin.cwiseAbs().maxCoeff() > kMaxCoordinateM ||
        (float_positions ? step != 0.0 : !(step > 0.0 && step <= 1.0))) {
        return corrupt(fmt::format("fragment {}: absurd origin or step {}", f.id, step));
    }
    const size_t per_point = (float_positions ? 12 : 6) + ((flags & kFlagNormals) ? 4 : 0) +
                             ((flags & kFlagColors) ? 3 : 0);
    if (static_cast<size_t>(num_points) * per_point != r.remaining()) {
        return corrupt(fmt::format("fragment {}: {} points of {} bytes but {} bytes remain", f.id,
                                   num_points, per_point, r.remaining()));
    }
    PointCloud& cloud = f.points_F;
    cloud.reserve(num_points, flags & kFlagNormals, flags & kFlagColors);
    cloud.points.resize(num_points);
    for (auto& p : cloud.points) {
        for (int k = 0; k < 3; ++k) {
            if (float_positions) {
                float v = 0.0f;
                std::memcpy(&v, r.take(4), 4);
                if (!std::isfinite(v) || std::abs(v) > kMaxCoordinateM) {
                    return corrupt(fmt::format("fragment {}: point coordinate {}", f.id, v));
                }
                p[k] = v;
            } else {
                uint16_t q = 0;
                std::memcpy(&q, r.take(2), 2);
                p[k] = static_cast<float>(origin[k] + q * step);
            }
        }
    }
    if (flags & kFlagNormals) {
        cloud.normals.resize(num_points);
        for (auto& n : cloud.normals) {
            int16_t x = 0, y = 0;
            std::memcpy(&x, r.take(2), 2);
            std::memcpy(&y, r.take(2), 2);
            n = decodeOctahedral(x, y);
        }
    }
    if (flags & kFlagColors) {
        cloud.colors.resize(num_points);
        for (auto& c : cloud.colors) {
            const uint8_t* p = r.take(3);
            c = Color3u8(p[0], p[1], p[2]);
        }
    }
    return f;
}

}  // namespace plumb::messages
