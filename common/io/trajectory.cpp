// SPDX-License-Identifier: Apache-2.0
#include "common/io/trajectory.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <tuple>

#include "common/io/text_file.hpp"

namespace plumb::io {
namespace {

namespace fs = std::filesystem;

/// A quaternion whose norm differs from 1 by more than this is rejected (TUM files print 4
/// decimals, which moves the norm by at most ~1e-4).
constexpr double kQuaternionNormTolerance = 1e-3;
/// A `.log` matrix whose rotation is further than this from orthonormal (max abs entry of
/// R^T R - I), or whose last row differs from (0 0 0 1) by more, is rejected.
constexpr double kRotationTolerance = 1e-3;

/// One non-blank, non-comment line of a text file, split into tokens.
struct Line {
    int number = 0;  ///< 1-based line number in the file
    std::vector<std::string_view> tokens;
};

/// The file content and its lines; the string_views in `lines` point into `text`.
struct TextFile {
    std::string text;
    std::vector<Line> lines;
};

/// Reads `path` and splits it into lines of tokens separated by spaces, tabs or commas (TUM's
/// associate.py accepts all three). Blank lines and lines starting with '#' are dropped.
Result<TextFile> readTextFile(const fs::path& path, const char* what) {
    std::error_code ec;
    if (!fs::exists(path, ec)) {
        return notFound(fmt::format("{}: {} file does not exist", path.string(), what));
    }
    if (fs::is_directory(path, ec)) {
        return invalidArgument(
            fmt::format("{}: is a directory, expected a {} file", path.string(), what));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        return ioError(
            fmt::format("{}: cannot open {} file: {}", path.string(), what, std::strerror(errno)));
    }
    TextFile file;
    std::ostringstream buffer;
    buffer << in.rdbuf();
    if (in.bad()) return ioError(fmt::format("{}: read error", path.string()));
    file.text = buffer.str();

    const std::string_view text(file.text);
    size_t begin = 0;
    int number = 0;
    while (begin < text.size()) {
        size_t end = text.find('\n', begin);
        if (end == std::string_view::npos) end = text.size();
        ++number;
        const std::string_view raw = text.substr(begin, end - begin);
        begin = end + 1;
        Line line;
        line.number = number;
        size_t pos = 0;
        while (pos < raw.size()) {
            while (pos < raw.size() && std::strchr(" \t\r,", raw[pos]) != nullptr) ++pos;
            size_t stop = pos;
            while (stop < raw.size() && std::strchr(" \t\r,", raw[stop]) == nullptr) ++stop;
            if (stop > pos) line.tokens.push_back(raw.substr(pos, stop - pos));
            pos = stop;
        }
        if (line.tokens.empty() || line.tokens.front().front() == '#') continue;
        file.lines.push_back(std::move(line));
    }
    return file;
}

std::string where(const fs::path& path, const Line& line) {
    return fmt::format("{}:{}", path.string(), line.number);
}

/// Parses every token of `line` as a finite double; `expected` tokens exactly.
Status parseNumbers(const fs::path& path, const Line& line, size_t expected, const char* layout,
                    double* out) {
    if (line.tokens.size() != expected) {
        return corrupt(fmt::format("{}: expected {} columns ({}), found {}", where(path, line),
                                   expected, layout, line.tokens.size()));
    }
    for (size_t k = 0; k < expected; ++k) {
        const std::string_view token = line.tokens[k];
        double value = 0.0;
        const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
        if (ec != std::errc() || ptr != token.data() + token.size()) {
            return corrupt(fmt::format("{}: column {} is not a number: '{}'", where(path, line),
                                       k + 1, token));
        }
        if (!std::isfinite(value)) {
            return corrupt(
                fmt::format("{}: column {} is not finite: '{}'", where(path, line), k + 1, token));
        }
        out[k] = value;
    }
    return Status::ok();
}

/// Parses the `i j n` metadata line of a `.log` / `.info` entry.
Status parseMetadata(const fs::path& path, const Line& line, int out[3]) {
    if (line.tokens.size() != 3) {
        return corrupt(fmt::format("{}: expected 3 integers of metadata (i j n), found {} columns",
                                   where(path, line), line.tokens.size()));
    }
    for (size_t k = 0; k < 3; ++k) {
        const std::string_view token = line.tokens[k];
        int value = 0;
        const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
        if (ec != std::errc() || ptr != token.data() + token.size()) {
            return corrupt(fmt::format("{}: metadata column {} is not an integer: '{}'",
                                       where(path, line), k + 1, token));
        }
        out[k] = value;
    }
    return Status::ok();
}

/// One `.log` / `.info` entry: metadata plus `rows` x `rows` numbers.
struct Block {
    int meta[3] = {0, 0, 0};
    int line = 0;  ///< line number of the metadata line
    std::vector<double> values;
};

/// Splits a `.log` (rows = 4) or `.info` (rows = 6) file into blocks of 1 + rows lines.
Result<std::vector<Block>> parseBlocks(const fs::path& path, const TextFile& file, size_t rows,
                                       const char* what) {
    std::vector<Block> blocks;
    const std::vector<Line>& lines = file.lines;
    for (size_t k = 0; k < lines.size(); k += rows + 1) {
        Block block;
        block.line = lines[k].number;
        PLUMB_RETURN_IF_ERROR(parseMetadata(path, lines[k], block.meta));
        if (k + rows >= lines.size()) {
            return corrupt(fmt::format(
                "{}: truncated {} entry: the entry starting at line {} needs {} matrix rows, "
                "the file ends after {}",
                path.string(), what, block.line, rows, lines.size() - k - 1));
        }
        block.values.resize(rows * rows);
        for (size_t r = 0; r < rows; ++r) {
            const std::string layout = fmt::format("row {} of a {}x{} matrix", r + 1, rows, rows);
            PLUMB_RETURN_IF_ERROR(parseNumbers(path, lines[k + 1 + r], rows, layout.c_str(),
                                               block.values.data() + r * rows));
        }
        blocks.push_back(std::move(block));
    }
    return blocks;
}

/// Turns a parsed 4x4 block into a rigid transform, rejecting non-rigid matrices.
Result<Eigen::Isometry3d> blockToPose(const fs::path& path, const Block& block) {
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) M(r, c) = block.values[static_cast<size_t>(r * 4 + c)];
    }
    Eigen::Isometry3d T;
    T.matrix() = M;
    if (!lie::isValidPose(T, kRotationTolerance)) {
        return corrupt(fmt::format(
            "{}:{}: the 4x4 matrix of this entry is not a rigid transform (rotation not "
            "orthonormal with det +1, or last row not 0 0 0 1)",
            path.string(), block.line));
    }
    T.matrix().row(3) << 0.0, 0.0, 0.0, 1.0;
    return lie::orthonormalized(T);
}

void appendMatrixRows(std::string* text, const Eigen::MatrixXd& M) {
    for (Eigen::Index r = 0; r < M.rows(); ++r) {
        for (Eigen::Index c = 0; c < M.cols(); ++c) {
            // "{}" is the shortest representation that parses back to the same double.
            fmt::format_to(std::back_inserter(*text), "{}{}", c == 0 ? "" : " ", M(r, c));
        }
        text->push_back('\n');
    }
}

Status checkWritablePose(const fs::path& path, const Eigen::Isometry3d& T, size_t index) {
    if (!lie::isValidPose(T, kRotationTolerance)) {
        return invalidArgument(
            fmt::format("{}: pose {} is not a finite rigid transform; refusing to write it",
                        path.string(), index));
    }
    return Status::ok();
}

}  // namespace

Result<Trajectory> readTumTrajectory(const std::filesystem::path& path) {
    Result<TextFile> file = readTextFile(path, "TUM trajectory");
    if (!file.isOk()) return file.status();
    Trajectory trajectory;
    trajectory.reserve(file->lines.size());
    for (const Line& line : file->lines) {
        double v[8];
        PLUMB_RETURN_IF_ERROR(parseNumbers(path, line, 8, "timestamp tx ty tz qx qy qz qw", v));
        Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);  // Eigen takes w first; TUM stores it last
        const double norm = q.norm();
        if (std::abs(norm - 1.0) > kQuaternionNormTolerance) {
            return corrupt(fmt::format("{}: quaternion (qx qy qz qw) has norm {}, expected 1",
                                       where(path, line), norm));
        }
        q.normalize();
        StampedPose pose;
        pose.timestamp_s = v[0];
        pose.T_W_C.linear() = q.toRotationMatrix();
        pose.T_W_C.translation() = Eigen::Vector3d(v[1], v[2], v[3]);
        trajectory.push_back(pose);
    }
    if (trajectory.empty()) {
        return corrupt(fmt::format("{}: TUM trajectory contains no poses", path.string()));
    }
    return trajectory;
}

Status writeTumTrajectory(const std::filesystem::path& path, const Trajectory& trajectory) {
    std::string text = "# timestamp tx ty tz qx qy qz qw\n";
    for (size_t k = 0; k < trajectory.size(); ++k) {
        const StampedPose& pose = trajectory[k];
        PLUMB_RETURN_IF_ERROR(checkWritablePose(path, pose.T_W_C, k));
        if (!std::isfinite(pose.timestamp_s)) {
            return invalidArgument(
                fmt::format("{}: pose {} has a non-finite timestamp", path.string(), k));
        }
        Eigen::Quaterniond q(pose.T_W_C.rotation());
        if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // same rotation; canonical sign
        const Eigen::Vector3d t = pose.T_W_C.translation();
        fmt::format_to(std::back_inserter(text), "{} {} {} {} {} {} {} {}\n", pose.timestamp_s,
                       t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
    }
    return writeText(path, text);
}

Result<Trajectory> readLogTrajectory(const std::filesystem::path& path) {
    Result<TextFile> file = readTextFile(path, ".log trajectory");
    if (!file.isOk()) return file.status();
    Result<std::vector<Block>> blocks = parseBlocks(path, *file, 4, ".log");
    if (!blocks.isOk()) return blocks.status();
    Trajectory trajectory;
    trajectory.reserve(blocks->size());
    for (const Block& block : *blocks) {
        Result<Eigen::Isometry3d> T = blockToPose(path, block);
        if (!T.isOk()) return T.status();
        trajectory.push_back(StampedPose{static_cast<double>(block.meta[0]), *T});
    }
    if (trajectory.empty()) {
        return corrupt(fmt::format("{}: .log trajectory contains no poses", path.string()));
    }
    return trajectory;
}

Status writeLogTrajectory(const std::filesystem::path& path, const Trajectory& trajectory) {
    std::string text;
    for (size_t k = 0; k < trajectory.size(); ++k) {
        PLUMB_RETURN_IF_ERROR(checkWritablePose(path, trajectory[k].T_W_C, k));
        fmt::format_to(std::back_inserter(text), "{} {} {}\n", k, k, k + 1);
        appendMatrixRows(&text, trajectory[k].T_W_C.matrix());
    }
    return writeText(path, text);
}

Result<std::vector<RegistrationEntry>> readRegistrationLog(const std::filesystem::path& path) {
    Result<TextFile> file = readTextFile(path, "registration .log");
    if (!file.isOk()) return file.status();
    Result<std::vector<Block>> blocks = parseBlocks(path, *file, 4, ".log");
    if (!blocks.isOk()) return blocks.status();
    std::vector<RegistrationEntry> entries;
    entries.reserve(blocks->size());
    for (const Block& block : *blocks) {
        Result<Eigen::Isometry3d> T = blockToPose(path, block);
        if (!T.isOk()) return T.status();
        entries.push_back(RegistrationEntry{block.meta[0], block.meta[1], block.meta[2], *T});
    }
    return entries;
}

Status writeRegistrationLog(const std::filesystem::path& path,
                            const std::vector<RegistrationEntry>& entries) {
    std::string text;
    for (size_t k = 0; k < entries.size(); ++k) {
        const RegistrationEntry& e = entries[k];
        PLUMB_RETURN_IF_ERROR(checkWritablePose(path, e.T_i_j, k));
        fmt::format_to(std::back_inserter(text), "{} {} {}\n", e.i, e.j, e.num_fragments);
        appendMatrixRows(&text, e.T_i_j.matrix());
    }
    return writeText(path, text);
}

Result<std::vector<InformationEntry>> readInformationFile(const std::filesystem::path& path) {
    Result<TextFile> file = readTextFile(path, ".info");
    if (!file.isOk()) return file.status();
    Result<std::vector<Block>> blocks = parseBlocks(path, *file, 6, ".info");
    if (!blocks.isOk()) return blocks.status();
    std::vector<InformationEntry> entries;
    entries.reserve(blocks->size());
    for (const Block& block : *blocks) {
        InformationEntry e{block.meta[0], block.meta[1], block.meta[2], Matrix6d::Zero()};
        for (int r = 0; r < 6; ++r) {
            for (int c = 0; c < 6; ++c) {
                e.information(r, c) = block.values[static_cast<size_t>(r * 6 + c)];
            }
        }
        entries.push_back(e);
    }
    return entries;
}

Status writeInformationFile(const std::filesystem::path& path,
                            const std::vector<InformationEntry>& entries) {
    std::string text;
    for (size_t k = 0; k < entries.size(); ++k) {
        const InformationEntry& e = entries[k];
        if (!e.information.allFinite()) {
            return invalidArgument(fmt::format(
                "{}: information matrix {} is not finite; refusing to write it", path.string(), k));
        }
        fmt::format_to(std::back_inserter(text), "{} {} {}\n", e.i, e.j, e.num_fragments);
        appendMatrixRows(&text, e.information);
    }
    return writeText(path, text);
}

std::vector<std::pair<size_t, size_t>> associate(const std::vector<double>& stamps_a,
                                                 const std::vector<double>& stamps_b,
                                                 double max_difference_s, double offset_s) {
    // Candidates are found through b sorted by stamp; the greedy pass then follows associate.py:
    // sort all candidate pairs by (|a - (b + offset)|, a, b) and accept a pair when neither side
    // is used yet.
    std::vector<size_t> order_b(stamps_b.size());
    for (size_t k = 0; k < order_b.size(); ++k) order_b[k] = k;
    std::sort(order_b.begin(), order_b.end(), [&](size_t x, size_t y) {
        return std::tie(stamps_b[x], x) < std::tie(stamps_b[y], y);
    });

    struct Candidate {
        double difference;
        size_t a;
        size_t b;
    };
    std::vector<Candidate> candidates;
    for (size_t a = 0; a < stamps_a.size(); ++a) {
        const double target = stamps_a[a] - offset_s;  // b + offset == a
        auto it = std::lower_bound(order_b.begin(), order_b.end(), target - max_difference_s,
                                   [&](size_t b, double t) { return stamps_b[b] < t; });
        for (; it != order_b.end() && stamps_b[*it] <= target + max_difference_s; ++it) {
            const double difference = std::abs(stamps_a[a] - (stamps_b[*it] + offset_s));
            if (difference < max_difference_s) candidates.push_back({difference, a, *it});
        }
    }
    std::sort(candidates.begin(), candidates.end(), [&](const Candidate& x, const Candidate& y) {
        return std::tie(x.difference, stamps_a[x.a], stamps_b[x.b], x.a, x.b) <
               std::tie(y.difference, stamps_a[y.a], stamps_b[y.b], y.a, y.b);
    });

    std::vector<bool> used_a(stamps_a.size(), false), used_b(stamps_b.size(), false);
    std::vector<std::pair<size_t, size_t>> matches;
    for (const Candidate& c : candidates) {
        if (used_a[c.a] || used_b[c.b]) continue;
        used_a[c.a] = used_b[c.b] = true;
        matches.emplace_back(c.a, c.b);
    }
    std::sort(matches.begin(), matches.end());
    return matches;
}

std::optional<Eigen::Isometry3d> poseAt(const Trajectory& sorted, double t, double max_gap_s) {
    if (sorted.empty() || !std::isfinite(t)) return std::nullopt;
    if (t < sorted.front().timestamp_s || t > sorted.back().timestamp_s) return std::nullopt;
    const auto it =
        std::lower_bound(sorted.begin(), sorted.end(), t,
                         [](const StampedPose& p, double s) { return p.timestamp_s < s; });
    if (it->timestamp_s == t) return it->T_W_C;  // exact sample (also covers the first one)
    const StampedPose& after = *it;
    const StampedPose& before = *(it - 1);  // it != begin: t > front and no exact match
    const double gap = after.timestamp_s - before.timestamp_s;
    if (gap > max_gap_s) return std::nullopt;
    const double alpha = (t - before.timestamp_s) / gap;
    return lie::interpolate(before.T_W_C, after.T_W_C, alpha);
}

}  // namespace plumb::io
