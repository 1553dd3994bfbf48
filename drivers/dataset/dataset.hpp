// SPDX-License-Identifier: Apache-2.0
#pragma once

// Recorded depth datasets behind FrameSource. A folder's layout is detected from the files in it:
//
//   layout      files                                              scale  default intrinsics
//   TUM RGB-D   depth.txt (`timestamp path`), groundtruth.txt       5000   tum-fr1/2/3 from
//               (`t tx ty tz qx qy qz qw`, ~100 Hz)                        "freiburgN" in the
//                                                                          depth.txt comments or
//                                                                          the folder name, else
//                                                                          primesense
//   ICL-NUIM    depth.txt (`index path`), groundtruth.txt with the  5000   icl-nuim
//               frame index as first column                                (fy = -480: y-flip)
//   plumb       TUM layout + intrinsics.json (`plumb sim` output)   1000   intrinsics.json
//   Redwood     depth/*.png (ordered by the number in the name)     1000   primesense
//               + one `*.log` camera trajectory beside depth/
//   7-Scenes    frame-XXXXXX.depth.png + frame-XXXXXX.pose.txt      1000   7-scenes
//               (4x4 camera->world); raw 65535 = invalid
//
// Detection, in order: a `depth.txt` selects the TUM family. It is ICL-NUIM when every first
// column of depth.txt is an integer literal (digits only) and groundtruth.txt, when present, also
// starts with an integer literal (TUM stamps are Unix seconds with a fractional part and never
// qualify); otherwise it is plumb when intrinsics.json is present, else TUM RGB-D. Without
// depth.txt, `frame-*.depth.png` files select 7-Scenes, and a `depth/` folder of PNGs selects
// Redwood. Anything else is kUnsupported, naming the files looked for.
//
// Intrinsics: DatasetConfig::intrinsics (a cameraPreset name or a path to an intrinsics file, see
// intrinsics_file.hpp) > `intrinsics.json` in the folder (any layout) > the layout default.
// Depth scale: DatasetConfig::depth_scale > the depth_scale of the chosen intrinsics file > that
// of the folder's intrinsics.json > the layout default.
//
// Timestamps: TUM and plumb frames carry the stamps of depth.txt (seconds). ICL-NUIM, Redwood and
// 7-Scenes have no clock: timestamp_s is the frame number (ICL index, number in the file name),
// which is also the first column of their trajectories (reference §6.2: frame indices as stamps).
//
// Colour (Frame::colour, 8-bit RGB of the depth image's size; empty when the dataset has none):
//   TUM / plumb / ICL-NUIM: associations.txt when present (lines `stamp path stamp path`, the
//     pair whose path is listed in depth.txt is the depth, the other the colour; the order of
//     TUM's associate.py and of the ICL-NUIM release both work); else rgb.txt (`stamp path`),
//     associated with depth.txt by stamp like TUM's associate.py: pairs closer than
//     colour_max_difference_s (0.02 s), greedy by smallest difference, each colour image used at
//     most once (ICL-NUIM and plumb stamps are equal for a pair); else, for ICL-NUIM, rgb/N.png
//     for frame N when an rgb/ folder exists. A TUM depth frame without a colour image within the
//     tolerance has no colour (DatasetInfo::framesWithColour counts them).
//   7-Scenes: frame-XXXXXX.color.png beside each depth image when the folder has any. Its colour
//     camera is NOT registered to the depth camera (DatasetInfo::colour_registered is false, the
//     summary says so): the image is only resized to the depth size when they differ.
//   Redwood: the image in color/, rgb/ or image/ (the first that exists, .png or .jpg) whose
//     number equals the depth image's; a missing number is an error for that frame.
// A colour image that is missing, undecodable, not 8-bit RGB or of another size than the depth
// is an error for its frame, naming the file (kNotFound / kCorrupt), like a bad depth image.
// DatasetConfig::load_colour = false reads depth only, as for a dataset without colour.
//
// Ground truth (camera->world, T_W_C):
//   TUM / plumb: geodesic interpolation between the two GT samples around the frame's stamp when
//     they are at most gt_max_gap_s apart (io::poseAt); frames outside the GT span fall back to
//     the closest GT sample within gt_max_difference_s (io::associate, TUM's 0.02 s).
//   ICL-NUIM: the GT line whose index equals the frame index.
//   Redwood: the `.log` entry whose frame index equals the number in the PNG's name.
//   7-Scenes: the frame's own pose file; a missing file means no GT, a malformed or non-rigid one
//     is a kCorrupt error for that frame.

#include <Eigen/Geometry>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/camera/pinhole.hpp"
#include "common/core/status.hpp"
#include "common/frame/frame_source.hpp"

namespace plumb::dataset {

enum class Layout { kTumRgbd, kIclNuim, kPlumb, kRedwood, kSevenScenes };

/// "TUM RGB-D", "ICL-NUIM", "plumb", "Redwood", "7-Scenes".
const char* layoutName(Layout layout);

struct DatasetConfig {
    /// Intrinsics override: a cameraPreset name ("tum-fr3", "icl-nuim", ...) or a path to an
    /// intrinsics file (JSON or text); empty = the folder's intrinsics.json, else layout default.
    std::string intrinsics;
    /// Depth units per metre override (e.g. 1000 for mm); 0 = intrinsics file, else layout.
    double depth_scale = 0.0;
    /// Keep only the first this many frames; 0 = all.
    size_t max_frames = 0;
    /// TUM/plumb GT interpolation: the two GT samples around a frame may be at most this many
    /// seconds apart (TUM motion capture runs at 100 Hz, 0.01 s).
    double gt_max_gap_s = 0.05;
    /// TUM/plumb GT fallback outside the interpolation span: closest GT sample strictly within
    /// this many seconds (TUM associate.py default).
    double gt_max_difference_s = 0.02;
    /// Read the colour images the dataset ships; false = depth only (Frame::colour empty).
    bool load_colour = true;
    /// rgb.txt association: a colour stamp pairs with a depth stamp when they differ by strictly
    /// less than this many seconds (TUM associate.py default).
    double colour_max_difference_s = 0.02;
};

/// One listed frame, before its image is read.
struct DatasetFrame {
    double timestamp_s = 0.0;                   ///< seconds (TUM, plumb) or frame number (others)
    std::filesystem::path depth_path;           ///< path to open (root joined with the listed path)
    std::string name;                           ///< path as listed, relative to the dataset root
    std::optional<Eigen::Isometry3d> T_W_C_gt;  ///< camera->world ground truth, when known
    /// Colour image to open (root joined with the listed path); empty = no colour for this frame.
    std::filesystem::path colour_path;
    Status error;  ///< a problem found while scanning (malformed pose file); ok otherwise
};

/// What a dataset folder holds: layout, camera, depth scale, frame list with ground truth.
struct DatasetInfo {
    Layout layout = Layout::kTumRgbd;
    std::filesystem::path root;          ///< the dataset folder as given
    PinholeCamera camera;                ///< intrinsics of every frame
    std::string camera_source;           ///< where the intrinsics came from, for logs
    double depth_scale = 5000.0;         ///< depth units per metre
    std::string depth_scale_source;      ///< where the scale came from, for logs
    std::filesystem::path ground_truth;  ///< GT trajectory file (empty: none or per frame)
    std::vector<DatasetFrame> frames;    ///< in stream order
    /// Where the colour comes from ("associations.txt", "rgb.txt by timestamp within 0.02 s",
    /// "ignored (option)"); empty when the dataset has none.
    std::string colour_source;
    /// False when the colour camera is not registered to the depth camera (7-Scenes): pixel
    /// (u, v) of the colour only roughly sees what depth pixel (u, v) sees.
    bool colour_registered = true;

    /// Frames that carry a ground-truth pose.
    size_t framesWithGroundTruth() const;
    /// Frames that carry a colour image.
    size_t framesWithColour() const;
    /// One line: "TUM RGB-D dataset <root>: 252 frames, GT for 248 (98.4%), 640x480 fx=...
    /// (preset tum-fr3 ...), depth scale 5000 (layout default)", then the colour: ", colour for
    /// 99 frames (associations.txt)", with "not registered to depth" for 7-Scenes.
    std::string summary() const;
};

/// Detects the layout of `dir` and lists its frames and ground truth without decoding images.
/// Errors: kNotFound (no such folder), kUnsupported (no known layout; names what was looked
/// for), kCorrupt (malformed or empty depth.txt, naming file and line; malformed trajectory),
/// kInvalidArgument / kNotFound (bad intrinsics override or depth scale).
Result<DatasetInfo> scanDataset(const std::filesystem::path& dir, const DatasetConfig& config = {});

/// Reads frame `k` of `info` (depth in metres, colour when listed, GT pose, name, stamp;
/// Frame::index = k). Errors name the file: kNotFound (listed depth or colour file missing),
/// kCorrupt (undecodable, depth not 16-bit one channel, colour not 8-bit RGB, wrong size, or the
/// frame's scan-time error), kUnsupported (JPEG colour without OpenCV), kIoError.
Result<Frame> loadFrame(const DatasetInfo& info, size_t k);

/// FrameSource over a scanned dataset. next() returns each listed frame in order; a frame that
/// cannot be read yields its error and the following call moves on (canSkipErrors() is true).
/// Not thread-safe (one consumer).
class DatasetSource final : public FrameSource {
  public:
    explicit DatasetSource(DatasetInfo info) : info_(std::move(info)) {}

    /// scanDataset + construction.
    static Result<std::unique_ptr<DatasetSource>> open(const std::filesystem::path& dir,
                                                       const DatasetConfig& config = {});

    const PinholeCamera& camera() const override { return info_.camera; }
    Result<Frame> next() override;
    /// Moves past the next frame without reading its files.
    Status skip() override;
    std::optional<size_t> size() const override { return info_.frames.size(); }
    bool canSkipErrors() const override { return true; }
    std::string description() const override { return info_.summary(); }

    const DatasetInfo& info() const { return info_; }

  private:
    DatasetInfo info_;
    size_t next_ = 0;
};

}  // namespace plumb::dataset
