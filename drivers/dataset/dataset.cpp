// SPDX-License-Identifier: Apache-2.0
#include "drivers/dataset/dataset.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <system_error>
#include <utility>

#include "common/core/parallel.hpp"
#include "common/geometry/lie.hpp"
#include "common/io/trajectory.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/dataset/intrinsics_file.hpp"

namespace plumb::dataset {
namespace fs = std::filesystem;

namespace {

constexpr const char* kDepthList = "depth.txt";
constexpr const char* kColourList = "rgb.txt";
constexpr const char* kAssociations = "associations.txt";
constexpr const char* kGroundTruth = "groundtruth.txt";
constexpr const char* kIntrinsicsJson = "intrinsics.json";
constexpr const char* kSevenScenesPrefix = "frame-";
constexpr const char* kSevenScenesDepthSuffix = ".depth.png";
constexpr const char* kSevenScenesPoseSuffix = ".pose.txt";
constexpr const char* kSevenScenesColourSuffix = ".color.png";
/// Redwood colour folders, in the order they are looked for.
constexpr const char* kRedwoodColourFolders[] = {"color", "rgb", "image"};
/// 7-Scenes marks missing depth with the largest 16-bit value.
constexpr uint16_t kSevenScenesInvalid = 65535;

bool isIntegerLiteral(const std::string& s) {
    return !s.empty() &&
           std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

bool parseFinite(const std::string& token, double* value) {
    const char* end = token.data() + token.size();
    const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
    return ec == std::errc() && ptr == end && std::isfinite(*value);
}

std::string toLower(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

bool endsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::vector<std::string> splitWhitespace(const std::string& line) {
    std::vector<std::string> tokens;
    std::istringstream in(line);
    std::string t;
    while (in >> t) tokens.push_back(t);
    return tokens;
}

/// The text lines of a file, '\r' stripped.
Result<std::vector<std::string>> readLines(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return ioError(fmt::format("cannot open {}", path.string()));
    std::vector<std::string> lines;
    std::string line;
    while (std::getline(in, line)) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        lines.push_back(line);
    }
    if (in.bad()) return ioError(fmt::format("cannot read {}", path.string()));
    return lines;
}

bool isCommentOrBlank(const std::string& line) {
    const auto first = line.find_first_not_of(" \t");
    return first == std::string::npos || line[first] == '#';
}

/// The folder's own name (also for "dir/" and "."), lower case.
std::string folderName(const fs::path& dir) {
    std::error_code ec;
    fs::path p = fs::weakly_canonical(fs::absolute(dir, ec), ec);
    if (p.filename().empty()) p = p.parent_path();
    return toLower(p.filename().string());
}

/// 1, 2 or 3 when `text` names a TUM Freiburg sensor ("freiburg2", "fr3_" ...), else 0.
int freiburgNumber(const std::string& text) {
    const std::string s = toLower(text);
    for (const std::string key : {"freiburg", "fr"}) {
        for (size_t pos = s.find(key); pos != std::string::npos; pos = s.find(key, pos + 1)) {
            const size_t digit = pos + key.size();
            if (digit >= s.size() || s[digit] < '1' || s[digit] > '3') continue;
            const bool starts_word =
                pos == 0 || !std::isalnum(static_cast<unsigned char>(s[pos - 1]));
            const bool ends_word =
                digit + 1 >= s.size() || !std::isalnum(static_cast<unsigned char>(s[digit + 1]));
            if (key == "freiburg" || (starts_word && ends_word)) return s[digit] - '0';
        }
    }
    return 0;
}

/// Trailing decimal digits of a file stem ("000123" -> 123, "depth_7" -> 7); nullopt without.
std::optional<int64_t> trailingNumber(const std::string& stem) {
    size_t begin = stem.size();
    while (begin > 0 && std::isdigit(static_cast<unsigned char>(stem[begin - 1]))) --begin;
    if (begin == stem.size() || stem.size() - begin > 18) return std::nullopt;
    return std::stoll(stem.substr(begin));
}

struct Listing {
    std::vector<DatasetFrame> frames;
    std::vector<std::string> stamp_tokens;  ///< first column of depth.txt, verbatim
    std::string comments;                   ///< all comment text of depth.txt
};

/// Parses a `stamp path` list (depth.txt, rgb.txt): '#' comments and blank lines skipped;
/// `what` ("depth frames", "colour images") names the entries in errors.
Result<Listing> readStampedList(const fs::path& dir, const char* file, const char* what) {
    const fs::path path = dir / file;
    auto lines = readLines(path);
    if (!lines.isOk()) return lines.status();
    Listing out;
    for (size_t i = 0; i < lines->size(); ++i) {
        const std::string& line = (*lines)[i];
        if (isCommentOrBlank(line)) {
            out.comments += line + "\n";
            continue;
        }
        const std::vector<std::string> tokens = splitWhitespace(line);
        double stamp = 0.0;
        if (tokens.size() != 2 || !parseFinite(tokens[0], &stamp)) {
            return corrupt(fmt::format("{}:{}: expected 'timestamp path', got '{}'", path.string(),
                                       i + 1, line));
        }
        DatasetFrame frame;
        frame.timestamp_s = stamp;
        frame.name = tokens[1];
        frame.depth_path = dir / tokens[1];
        out.frames.push_back(std::move(frame));
        out.stamp_tokens.push_back(tokens[0]);
    }
    if (out.frames.empty()) {
        return corrupt(
            fmt::format("{}: lists no {} (expected 'timestamp path' lines)", path.string(), what));
    }
    return out;
}

bool isImageFile(const fs::path& path) {
    const std::string ext = toLower(path.extension().string());
    return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
}

/// associations.txt: `stamp path stamp path` per line. Returns, for every depth.txt path that a
/// line pairs, the colour path it pairs with (the line's other path). Lines that pair no listed
/// depth image are skipped; a file that pairs none at all, or a depth image twice, is kCorrupt.
Result<std::map<std::string, std::string>> readAssociations(
    const fs::path& path, const std::vector<DatasetFrame>& frames) {
    auto lines = readLines(path);
    if (!lines.isOk()) return lines.status();
    std::set<std::string> depth_names;
    for (const auto& f : frames) depth_names.insert(f.name);
    std::map<std::string, std::string> colour_of_depth;
    for (size_t i = 0; i < lines->size(); ++i) {
        const std::string& line = (*lines)[i];
        if (isCommentOrBlank(line)) continue;
        const std::vector<std::string> tokens = splitWhitespace(line);
        double a = 0.0;
        double b = 0.0;
        if (tokens.size() != 4 || !parseFinite(tokens[0], &a) || !parseFinite(tokens[2], &b)) {
            return corrupt(fmt::format("{}:{}: expected 'timestamp path timestamp path', got '{}'",
                                       path.string(), i + 1, line));
        }
        std::string depth;
        std::string colour;
        if (depth_names.count(tokens[1]) != 0) {
            depth = tokens[1];
            colour = tokens[3];
        } else if (depth_names.count(tokens[3]) != 0) {
            depth = tokens[3];
            colour = tokens[1];
        } else {
            continue;  // a depth image depth.txt does not list (a trimmed sequence)
        }
        if (!colour_of_depth.emplace(depth, colour).second) {
            return corrupt(
                fmt::format("{}:{}: pairs {} a second time", path.string(), i + 1, depth));
        }
    }
    if (colour_of_depth.empty()) {
        return corrupt(fmt::format("{}: pairs none of the depth images listed in {}", path.string(),
                                   kDepthList));
    }
    return colour_of_depth;
}

/// Colour of the TUM family (header comment): associations.txt, else rgb.txt by stamp, else
/// ICL-NUIM's rgb/N.png. Sets colour_path of the frames that get one; returns the description
/// for DatasetInfo::colour_source ("" = the folder has no colour).
Result<std::string> attachTumFamilyColour(const fs::path& dir, Layout layout,
                                          const std::vector<std::string>& stamp_tokens,
                                          const DatasetConfig& config,
                                          std::vector<DatasetFrame>* frames) {
    std::error_code ec;
    if (fs::is_regular_file(dir / kAssociations, ec)) {
        auto pairs = readAssociations(dir / kAssociations, *frames);
        if (!pairs.isOk()) return pairs.status();
        for (DatasetFrame& f : *frames) {
            const auto it = pairs->find(f.name);
            if (it != pairs->end()) f.colour_path = dir / it->second;
        }
        return std::string(kAssociations);
    }
    if (fs::is_regular_file(dir / kColourList, ec)) {
        if (!(std::isfinite(config.colour_max_difference_s) &&
              config.colour_max_difference_s > 0.0)) {
            return invalidArgument(fmt::format("colour association tolerance {} s is not positive",
                                               config.colour_max_difference_s));
        }
        auto colour = readStampedList(dir, kColourList, "colour images");
        if (!colour.isOk()) return colour.status();
        std::vector<double> depth_stamps;
        depth_stamps.reserve(frames->size());
        for (const auto& f : *frames) depth_stamps.push_back(f.timestamp_s);
        std::vector<double> colour_stamps;
        colour_stamps.reserve(colour->frames.size());
        for (const auto& c : colour->frames) colour_stamps.push_back(c.timestamp_s);
        for (const auto& [d, c] :
             io::associate(depth_stamps, colour_stamps, config.colour_max_difference_s)) {
            (*frames)[d].colour_path = colour->frames[c].depth_path;
        }
        return fmt::format("{} by timestamp within {:g} s", kColourList,
                           config.colour_max_difference_s);
    }
    if (layout == Layout::kIclNuim && fs::is_directory(dir / "rgb", ec)) {
        for (size_t k = 0; k < frames->size(); ++k) {
            (*frames)[k].colour_path = dir / "rgb" / (stamp_tokens[k] + ".png");
        }
        return std::string("rgb/N.png by frame index");
    }
    return std::string();
}

/// First column of the first data line of a TUM-style trajectory ("" when there is none).
Result<std::string> firstStampToken(const fs::path& path) {
    auto lines = readLines(path);
    if (!lines.isOk()) return lines.status();
    for (const std::string& line : *lines) {
        if (isCommentOrBlank(line)) continue;
        const auto tokens = splitWhitespace(line);
        return tokens.empty() ? std::string() : tokens.front();
    }
    return std::string();
}

std::vector<double> stampsOf(const io::Trajectory& trajectory) {
    std::vector<double> stamps;
    stamps.reserve(trajectory.size());
    for (const auto& p : trajectory) stamps.push_back(p.timestamp_s);
    return stamps;
}

/// Attaches GT whose stamps equal the frames' numbers (ICL-NUIM indices, Redwood `.log`).
void attachByIndex(const io::Trajectory& gt, std::vector<DatasetFrame>* frames) {
    std::vector<double> stamps;
    for (const auto& f : *frames) stamps.push_back(f.timestamp_s);
    // Frame numbers are integers: any tolerance below 1 pairs equal numbers only.
    for (const auto& [a, b] : io::associate(stamps, stampsOf(gt), 0.5)) {
        (*frames)[a].T_W_C_gt = gt[b].T_W_C;
    }
}

/// TUM/plumb GT: interpolation inside the GT span, closest sample within the tolerance outside.
void attachByTime(io::Trajectory gt, const DatasetConfig& config,
                  std::vector<DatasetFrame>* frames) {
    std::stable_sort(gt.begin(), gt.end(), [](const io::StampedPose& a, const io::StampedPose& b) {
        return a.timestamp_s < b.timestamp_s;
    });
    std::vector<size_t> missing;
    std::vector<double> missing_stamps;
    for (size_t k = 0; k < frames->size(); ++k) {
        DatasetFrame& f = (*frames)[k];
        f.T_W_C_gt = io::poseAt(gt, f.timestamp_s, config.gt_max_gap_s);
        if (!f.T_W_C_gt) {
            missing.push_back(k);
            missing_stamps.push_back(f.timestamp_s);
        }
    }
    if (missing.empty()) return;
    for (const auto& [a, b] :
         io::associate(missing_stamps, stampsOf(gt), config.gt_max_difference_s)) {
        (*frames)[missing[a]].T_W_C_gt = gt[b].T_W_C;
    }
}

struct Scan {
    Layout layout = Layout::kTumRgbd;
    std::vector<DatasetFrame> frames;
    std::string colour_source;  ///< "" = no colour
    bool colour_registered = true;
    fs::path ground_truth;
    PinholeCamera default_camera;
    std::string default_camera_name;
    double default_depth_scale = 5000.0;
};

Result<Scan> scanTumFamily(const fs::path& dir, const DatasetConfig& config) {
    auto listing = readStampedList(dir, kDepthList, "depth frames");
    if (!listing.isOk()) return listing.status();
    Scan scan;
    const fs::path gt_path = dir / kGroundTruth;
    std::error_code ec;
    const bool has_gt = fs::is_regular_file(gt_path, ec);

    bool icl =
        std::all_of(listing->stamp_tokens.begin(), listing->stamp_tokens.end(), isIntegerLiteral);
    if (icl && has_gt) {
        auto first = firstStampToken(gt_path);
        if (!first.isOk()) return first.status();
        icl = isIntegerLiteral(*first);
    }
    if (icl) {
        scan.layout = Layout::kIclNuim;
        scan.default_camera_name = "icl-nuim";
        scan.default_depth_scale = 5000.0;
    } else if (fs::is_regular_file(dir / kIntrinsicsJson, ec)) {
        scan.layout = Layout::kPlumb;
        scan.default_camera_name = "primesense";
        scan.default_depth_scale = 1000.0;
    } else {
        scan.layout = Layout::kTumRgbd;
        const int fr = std::max(freiburgNumber(listing->comments), freiburgNumber(folderName(dir)));
        scan.default_camera_name = fr > 0 ? fmt::format("tum-fr{}", fr) : "primesense";
        scan.default_depth_scale = 5000.0;
    }
    scan.default_camera = cameraPreset(scan.default_camera_name).value();
    scan.frames = std::move(listing->frames);
    if (config.load_colour) {
        auto colour =
            attachTumFamilyColour(dir, scan.layout, listing->stamp_tokens, config, &scan.frames);
        if (!colour.isOk()) return colour.status();
        scan.colour_source = std::move(colour).value();
    }

    if (has_gt) {
        auto gt = io::readTumTrajectory(gt_path);
        if (!gt.isOk()) return gt.status();
        scan.ground_truth = gt_path;
        if (scan.layout == Layout::kIclNuim) {
            attachByIndex(*gt, &scan.frames);
        } else {
            attachByTime(std::move(*gt), config, &scan.frames);
        }
    }
    return scan;
}

/// Reads a 7-Scenes pose file: 16 numbers, the row-major 4x4 camera->world matrix.
Result<Eigen::Isometry3d> readSevenScenesPose(const fs::path& path) {
    std::ifstream in(path);
    if (!in) return ioError(fmt::format("cannot open pose file {}", path.string()));
    std::vector<double> values;
    std::string token;
    while (in >> token) {
        double v = 0.0;
        if (!parseFinite(token, &v)) {
            return corrupt(fmt::format("{}: '{}' is not a finite number", path.string(), token));
        }
        values.push_back(v);
    }
    if (values.size() != 16) {
        return corrupt(fmt::format("{}: expected 16 numbers (4x4 camera->world), found {}",
                                   path.string(), values.size()));
    }
    Eigen::Matrix4d m;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) m(r, c) = values[4 * r + c];
    }
    if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6) {
        return corrupt(fmt::format("{}: last row is not 0 0 0 1", path.string()));
    }
    Eigen::Isometry3d T_W_C;
    T_W_C.matrix() = m;
    if (!lie::isValidPose(T_W_C, 1e-3)) {
        return corrupt(fmt::format("{}: rotation is not orthonormal", path.string()));
    }
    return lie::orthonormalized(T_W_C);
}

Result<Scan> scanSevenScenes(const fs::path& dir, std::vector<std::pair<int64_t, std::string>> ids,
                             const DatasetConfig& config) {
    Scan scan;
    scan.layout = Layout::kSevenScenes;
    scan.default_camera_name = "7-scenes";
    scan.default_camera = cameraPreset(scan.default_camera_name).value();
    scan.default_depth_scale = 1000.0;
    std::sort(ids.begin(), ids.end());
    for (const auto& [id, stem] : ids) {
        DatasetFrame frame;
        frame.timestamp_s = static_cast<double>(id);
        frame.name = stem + kSevenScenesDepthSuffix;
        frame.depth_path = dir / frame.name;
        const fs::path pose_path = dir / (stem + kSevenScenesPoseSuffix);
        std::error_code ec;
        if (fs::exists(pose_path, ec)) {
            auto pose = readSevenScenesPose(pose_path);
            if (pose.isOk()) {
                frame.T_W_C_gt = *pose;
            } else {
                frame.error = pose.status();
            }
        }
        scan.frames.push_back(std::move(frame));
    }
    // Colour: every frame's frame-XXXXXX.color.png once the folder has any (a missing one is then
    // that frame's error). Unregistered: recorded by a second camera beside the depth camera.
    if (config.load_colour) {
        std::error_code ec;
        const bool has_colour = std::any_of(ids.begin(), ids.end(), [&](const auto& id) {
            return fs::exists(dir / (id.second + kSevenScenesColourSuffix), ec);
        });
        if (has_colour) {
            for (size_t k = 0; k < ids.size(); ++k) {
                scan.frames[k].colour_path = dir / (ids[k].second + kSevenScenesColourSuffix);
            }
            scan.colour_source = fmt::format("frame-XXXXXX{}", kSevenScenesColourSuffix);
            scan.colour_registered = false;
        }
    }
    return scan;
}

/// Redwood colour: the first of color/, rgb/, image/ holding images; each depth frame gets the
/// image with the same number, and a frame without one gets a kNotFound error.
Status attachRedwoodColour(const fs::path& dir, Scan* scan) {
    std::error_code ec;
    for (const char* folder : kRedwoodColourFolders) {
        const fs::path colour_dir = dir / folder;
        if (!fs::is_directory(colour_dir, ec)) continue;
        std::map<int64_t, std::string> by_number;
        for (const auto& entry : fs::directory_iterator(colour_dir, ec)) {
            if (!entry.is_regular_file(ec) || !isImageFile(entry.path())) continue;
            const std::string file = entry.path().filename().string();
            const auto number = trailingNumber(entry.path().stem().string());
            if (!number) {
                return unsupported(fmt::format(
                    "{}: Redwood colour images must be numbered (e.g. 000123.jpg) to be paired",
                    entry.path().string()));
            }
            const auto [it, inserted] = by_number.emplace(*number, file);
            if (!inserted) {
                return unsupported(fmt::format("{}: {} and {} both have number {}",
                                               colour_dir.string(), it->second, file, *number));
            }
        }
        if (ec)
            return ioError(fmt::format("cannot list {}: {}", colour_dir.string(), ec.message()));
        if (by_number.empty()) continue;
        for (DatasetFrame& f : scan->frames) {
            const auto it = by_number.find(static_cast<int64_t>(f.timestamp_s));
            if (it != by_number.end()) {
                f.colour_path = colour_dir / it->second;
            } else if (f.error.isOk()) {
                f.error = notFound(fmt::format("{}: no colour image numbered {} (for {})",
                                               colour_dir.string(),
                                               static_cast<int64_t>(f.timestamp_s), f.name));
            }
        }
        scan->colour_source = fmt::format("{}/ by number", folder);
        return Status::ok();
    }
    return Status::ok();
}

Result<Scan> scanRedwood(const fs::path& dir, std::vector<std::pair<int64_t, std::string>> pngs,
                         const DatasetConfig& config) {
    Scan scan;
    scan.layout = Layout::kRedwood;
    scan.default_camera_name = "primesense";
    scan.default_camera = cameraPreset(scan.default_camera_name).value();
    scan.default_depth_scale = 1000.0;
    std::sort(pngs.begin(), pngs.end());
    for (const auto& [id, file] : pngs) {
        DatasetFrame frame;
        frame.timestamp_s = static_cast<double>(id);
        frame.name = "depth/" + file;
        frame.depth_path = dir / "depth" / file;
        scan.frames.push_back(std::move(frame));
    }
    std::vector<fs::path> logs;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        if (entry.is_regular_file(ec) && toLower(entry.path().extension().string()) == ".log") {
            logs.push_back(entry.path());
        }
    }
    std::sort(logs.begin(), logs.end());
    if (logs.size() > 1) {
        std::string names;
        for (const auto& l : logs) names += (names.empty() ? "" : ", ") + l.filename().string();
        return unsupported(
            fmt::format("{}: several .log trajectories beside depth/ ({}); keep exactly one",
                        dir.string(), names));
    }
    if (logs.size() == 1) {
        auto gt = io::readLogTrajectory(logs.front());
        if (!gt.isOk()) return gt.status();
        scan.ground_truth = logs.front();
        attachByIndex(*gt, &scan.frames);
    }
    if (config.load_colour) PLUMB_RETURN_IF_ERROR(attachRedwoodColour(dir, &scan));
    return scan;
}

/// Finds the layout of `dir` and lists its frames (camera and scale are chosen afterwards).
Result<Scan> detectAndScan(const fs::path& dir, const DatasetConfig& config) {
    std::error_code ec;
    if (fs::is_regular_file(dir / kDepthList, ec)) return scanTumFamily(dir, config);

    std::vector<std::pair<int64_t, std::string>> seven_scenes;
    bool has_sequence_folders = false;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        const std::string file = entry.path().filename().string();
        if (entry.is_directory(ec) && file.rfind("seq-", 0) == 0) has_sequence_folders = true;
        if (!entry.is_regular_file(ec) || file.rfind(kSevenScenesPrefix, 0) != 0 ||
            !endsWith(file, kSevenScenesDepthSuffix)) {
            continue;
        }
        const std::string stem =
            file.substr(0, file.size() - std::string(kSevenScenesDepthSuffix).size());
        const std::string digits = stem.substr(std::string(kSevenScenesPrefix).size());
        if (!isIntegerLiteral(digits) || digits.size() > 18) continue;
        seven_scenes.emplace_back(std::stoll(digits), stem);
    }
    if (ec) return ioError(fmt::format("cannot list {}: {}", dir.string(), ec.message()));
    if (!seven_scenes.empty()) return scanSevenScenes(dir, std::move(seven_scenes), config);

    const fs::path depth_dir = dir / "depth";
    if (fs::is_directory(depth_dir, ec)) {
        std::vector<std::pair<int64_t, std::string>> pngs;
        for (const auto& entry : fs::directory_iterator(depth_dir, ec)) {
            if (!entry.is_regular_file(ec) ||
                toLower(entry.path().extension().string()) != ".png") {
                continue;
            }
            const auto number = trailingNumber(entry.path().stem().string());
            if (!number) {
                return unsupported(fmt::format(
                    "{}: Redwood depth images must be numbered (e.g. 000123.png) to be ordered",
                    entry.path().string()));
            }
            pngs.emplace_back(*number, entry.path().filename().string());
        }
        if (!pngs.empty()) return scanRedwood(dir, std::move(pngs), config);
    }
    return unsupported(fmt::format(
        "{}: no known dataset layout; looked for depth.txt (TUM RGB-D, ICL-NUIM, plumb), "
        "frame-XXXXXX.depth.png (7-Scenes{}) and depth/*.png with a *.log trajectory "
        "(Redwood / augmented ICL-NUIM)",
        dir.string(),
        has_sequence_folders ? "; this folder has seq-* sub-folders: open one of them" : ""));
}

struct CameraChoice {
    PinholeCamera camera;
    std::string camera_source;
    double depth_scale = 0.0;
    std::string depth_scale_source;
};

/// Applies the priorities: option > intrinsics file > layout default (header comment).
Result<CameraChoice> chooseCamera(const fs::path& dir, const DatasetConfig& config,
                                  const Scan& scan) {
    CameraChoice choice;
    bool camera_set = false;
    std::optional<double> file_scale;
    std::string file_scale_source;
    if (!config.intrinsics.empty()) {
        auto preset = cameraPreset(config.intrinsics);
        std::error_code ec;
        if (preset.isOk()) {
            choice.camera = *preset;
            choice.camera_source = fmt::format("preset {} (option)", config.intrinsics);
        } else if (fs::is_regular_file(config.intrinsics, ec)) {
            auto file = readIntrinsicsFile(config.intrinsics, scan.default_camera);
            if (!file.isOk()) return file.status();
            choice.camera = file->camera;
            choice.camera_source = fmt::format("file {} (option)", config.intrinsics);
            file_scale = file->depth_scale;
            file_scale_source = choice.camera_source;
        } else {
            return notFound(
                fmt::format("intrinsics '{}' is neither a camera preset nor an existing file ({})",
                            config.intrinsics, preset.status().message()));
        }
        camera_set = true;
    }
    const bool scale_set = config.depth_scale != 0.0;
    const fs::path json = dir / kIntrinsicsJson;
    std::error_code ec;
    if ((!camera_set || (!scale_set && !file_scale)) && fs::is_regular_file(json, ec)) {
        auto file = readIntrinsicsFile(json, scan.default_camera);
        if (!file.isOk()) return file.status();
        if (!camera_set) {
            choice.camera = file->camera;
            choice.camera_source = fmt::format("file {}", json.string());
            camera_set = true;
        }
        if (!file_scale && file->depth_scale) {
            file_scale = file->depth_scale;
            file_scale_source = fmt::format("file {}", json.string());
        }
    }
    if (!camera_set) {
        choice.camera = scan.default_camera;
        choice.camera_source =
            fmt::format("{} default, preset {}", layoutName(scan.layout), scan.default_camera_name);
    }
    if (scale_set) {
        if (!(std::isfinite(config.depth_scale) && config.depth_scale > 0.0)) {
            return invalidArgument(
                fmt::format("depth scale {} is not a positive number", config.depth_scale));
        }
        choice.depth_scale = config.depth_scale;
        choice.depth_scale_source = "option";
    } else if (file_scale) {
        choice.depth_scale = *file_scale;
        choice.depth_scale_source = file_scale_source;
    } else {
        choice.depth_scale = scan.default_depth_scale;
        choice.depth_scale_source = fmt::format("{} default", layoutName(scan.layout));
    }
    return choice;
}

}  // namespace

const char* layoutName(Layout layout) {
    switch (layout) {
        case Layout::kTumRgbd:
            return "TUM RGB-D";
        case Layout::kIclNuim:
            return "ICL-NUIM";
        case Layout::kPlumb:
            return "plumb";
        case Layout::kRedwood:
            return "Redwood";
        case Layout::kSevenScenes:
            return "7-Scenes";
    }
    return "unknown";
}

size_t DatasetInfo::framesWithGroundTruth() const {
    return static_cast<size_t>(std::count_if(frames.begin(), frames.end(),
                                             [](const auto& f) { return f.T_W_C_gt.has_value(); }));
}

size_t DatasetInfo::framesWithColour() const {
    return static_cast<size_t>(std::count_if(frames.begin(), frames.end(),
                                             [](const auto& f) { return !f.colour_path.empty(); }));
}

std::string DatasetInfo::summary() const {
    const size_t with_gt = framesWithGroundTruth();
    const double percent = frames.empty() ? 0.0 : 100.0 * with_gt / frames.size();
    std::string colour = "no colour";
    if (!colour_source.empty()) {
        const size_t with_colour = framesWithColour();
        colour = with_colour == 0
                     ? fmt::format("colour {}", colour_source)
                     : fmt::format("colour for {} frames ({}{})", with_colour, colour_source,
                                   colour_registered ? ""
                                                     : "; not registered to depth, resized to the "
                                                       "depth size where it differs");
    }
    return fmt::format(
        "{} dataset {}: {} frames, GT for {} ({:.1f}%), {} ({}), depth scale {} ({}), {}",
        layoutName(layout), root.string(), frames.size(), with_gt, percent, camera.toString(),
        camera_source, depth_scale, depth_scale_source, colour);
}

Result<DatasetInfo> scanDataset(const fs::path& dir, const DatasetConfig& config) {
    std::error_code ec;
    if (!fs::exists(dir, ec))
        return notFound(fmt::format("dataset folder {} does not exist", dir.string()));
    if (!fs::is_directory(dir, ec)) {
        return invalidArgument(fmt::format("dataset path {} is not a folder", dir.string()));
    }
    auto scan = detectAndScan(dir, config);
    if (!scan.isOk()) return scan.status();
    auto choice = chooseCamera(dir, config, *scan);
    if (!choice.isOk()) return choice.status();

    DatasetInfo info;
    info.layout = scan->layout;
    info.root = dir;
    info.camera = choice->camera;
    info.camera_source = std::move(choice->camera_source);
    info.depth_scale = choice->depth_scale;
    info.depth_scale_source = std::move(choice->depth_scale_source);
    info.ground_truth = scan->ground_truth;
    info.frames = std::move(scan->frames);
    info.colour_source = config.load_colour ? scan->colour_source : "ignored (option)";
    info.colour_registered = scan->colour_registered;
    if (config.max_frames > 0 && info.frames.size() > config.max_frames) {
        info.frames.resize(config.max_frames);
    }
    return info;
}

Result<Frame> loadFrame(const DatasetInfo& info, size_t k) {
    if (k >= info.frames.size()) {
        return outOfRange(
            fmt::format("frame {} of {} frames in {}", k, info.frames.size(), info.root.string()));
    }
    const DatasetFrame& entry = info.frames[k];
    if (!entry.error.isOk()) return entry.error;
    // The depth and the colour image are decoded side by side: decoding is serial within an
    // image and is most of a frame's reading.
    Result<Depth16Image> raw = Depth16Image();
    Result<ColourImage> colour = ColourImage();
    parallelFor(0, entry.colour_path.empty() ? 1 : 2, [&](int task) {
        if (task == 0) {
            raw = readDepthPng(entry.depth_path, info.camera.width, info.camera.height);
        } else {
            // Registered colour must match the depth size; unregistered colour (7-Scenes) is
            // only brought to it.
            colour =
                readColourImage(entry.colour_path, info.camera.width, info.camera.height,
                                info.colour_registered ? ColourSize::kExact : ColourSize::kResize);
        }
    });
    if (!raw.isOk()) return raw.status();
    if (!colour.isOk()) return colour.status();
    if (info.layout == Layout::kSevenScenes) {
        for (uint16_t& d : raw->pixels()) {
            if (d == kSevenScenesInvalid) d = 0;
        }
    }
    Frame frame;
    frame.colour = std::move(colour).value();
    frame.index = static_cast<int64_t>(k);
    frame.timestamp_s = entry.timestamp_s;
    frame.depth = toMetres(*raw, info.depth_scale);
    frame.name = entry.name;
    frame.T_W_C_gt = entry.T_W_C_gt;
    return frame;
}

Result<std::unique_ptr<DatasetSource>> DatasetSource::open(const fs::path& dir,
                                                           const DatasetConfig& config) {
    auto info = scanDataset(dir, config);
    if (!info.isOk()) return info.status();
    return std::make_unique<DatasetSource>(std::move(*info));
}

Result<Frame> DatasetSource::next() {
    if (next_ >= info_.frames.size()) {
        return outOfRange(
            fmt::format("end of {} ({} frames)", info_.root.string(), info_.frames.size()));
    }
    return loadFrame(info_, next_++);
}

Status DatasetSource::skip() {
    if (next_ >= info_.frames.size()) {
        return outOfRange(
            fmt::format("end of {} ({} frames)", info_.root.string(), info_.frames.size()));
    }
    ++next_;
    return Status::ok();
}

}  // namespace plumb::dataset
