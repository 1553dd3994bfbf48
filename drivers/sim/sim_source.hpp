// SPDX-License-Identifier: Apache-2.0
#pragma once

// The simulated handheld scanner: a FrameSource (`sim:<scene>`) that renders each frame of a
// generated (or loaded) trajectory through a Scene and applies the depth-noise model; the colour
// camera (drivers/sim/colour.hpp) sees the scene's textures, registered to the depth. Frame k is
// a pure function of (config, k): random access, any order, any thread count.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "common/frame/frame_source.hpp"
#include "common/io/trajectory.hpp"
#include "drivers/sim/colour.hpp"
#include "drivers/sim/noise.hpp"
#include "drivers/sim/render.hpp"
#include "drivers/sim/scene.hpp"
#include "drivers/sim/trajectory.hpp"

namespace plumb::sim {

struct SimConfig {
    /// A built-in scene name (builtinSceneNames) or a path to a `.toml` scene file.
    std::string scene = "living_room";
    /// Intrinsics and image size (default: PrimeSense 640x480, fx = fy = 525).
    PinholeCamera camera;
    /// Generated handheld trajectory (frame count, loop/no-loop, speeds, shake).
    TrajectoryConfig trajectory;
    /// A TUM trajectory file (camera->world) to use instead of the generated one; empty = none.
    std::string trajectory_file;
    /// Depth-noise model.
    NoiseConfig noise;
    /// The Redwood distortion table; empty = $PLUMB_NOISE_MODEL, then the shared-data default.
    std::string noise_model_path;
    /// Seed of the noise (the trajectory has its own seed in `trajectory`).
    uint64_t seed = 1;
    /// Colour camera: on, per-channel noise std 2 levels, constant exposure (ColourConfig).
    ColourConfig colour;
    /// Overrides the scene's own `texture` (unset: the scene's, textured for built-in rooms).
    std::optional<TextureMode> texture;
};

/// A frame with the clean render it was made from.
struct SimFrame {
    Frame frame;        ///< noisy depth, shaded grey image, colour, GT pose, timestamp k / rate
    RenderedView view;  ///< clean depth, view-angle cosines, primitive labels, clean colour
    double exposure_gain = 1.0;  ///< the colour camera's gain in this frame (exposureGain)
};

class SimSource final : public FrameSource {
  public:
    /// Resolves the scene (applying config.texture), builds or reads the trajectory, loads the
    /// distortion table when the noise needs it, checks the colour settings. Errors name what is
    /// wrong (unknown scene, bad file, missing table, bad colour setting).
    static Result<std::unique_ptr<SimSource>> create(const SimConfig& config);

    const PinholeCamera& camera() const override { return renderer_->camera(); }
    Result<Frame> next() override;
    /// Frame k depends on k alone: skipping does not render it.
    Status skip() override;
    std::optional<size_t> size() const override { return trajectory_.size(); }
    std::string description() const override;

    /// Frame k with its clean render; k < size(). Thread-safe.
    Result<SimFrame> render(size_t k) const;
    /// The same into `out`, reusing its image buffers: rendering frame after frame into one
    /// SimFrame allocates (and first-touches) no image memory. Thread-safe for distinct `out`.
    Status render(size_t k, SimFrame* out) const;

    const Scene& scene() const { return renderer_->caster().scene(); }
    /// The renderer (its scene, textures and shading settings).
    const Renderer& renderer() const { return *renderer_; }
    const io::Trajectory& trajectory() const { return trajectory_; }
    const SimConfig& config() const { return config_; }

  private:
    SimSource() = default;
    SimConfig config_;
    std::unique_ptr<Renderer> renderer_;
    std::unique_ptr<DepthNoiseModel> noise_;
    std::unique_ptr<ColourNoiseModel> colour_noise_;
    io::Trajectory trajectory_;
    std::string noise_source_;
    size_t next_ = 0;
    SimFrame scratch_;  // next(): keeps the clean render's buffers from frame to frame
};

/// Options of writeSimDataset.
struct SimDatasetOptions {
    /// Spacing of the dense ground-truth surface samples in gt_points.ply, metres.
    double gt_spacing_m = 0.01;
    /// Also write the clean depth (depth_clean/) and the grey images (gray/).
    bool write_clean = true;
    bool write_gray = true;
    /// Write the colour images (rgb/ and rgb.txt) when the source renders colour.
    bool write_rgb = true;
};

/// Writes every frame of `source` as a TUM-layout dataset that drivers/dataset reads back:
/// depth/NNNNN.png (uint16, mm), depth.txt, groundtruth.txt (TUM), trajectory.log (Redwood),
/// intrinsics.json (depth_scale 1000), gt_points.ply, layout.json, sim.json (scene, seeds, noise
/// and colour parameters), rgb/NNNNN.png (8-bit RGB, the noisy Frame::colour) with rgb.txt (TUM
/// list, the depth timestamps) when the source renders colour, optional depth_clean/ and gray/.
/// `dir` is created; existing files are replaced.
Status writeSimDataset(const SimSource& source, const std::filesystem::path& dir,
                       const SimDatasetOptions& options = {});

/// Parses a noise setting: "off", "redwood" or "on" (table distortion), "parametric" (§1.4.D),
/// "undistorted" (Redwood quantisation and noise without distortion). Updates `noise`.
Status parseNoiseMode(const std::string& mode, NoiseConfig* noise);
/// OK when parseNoiseMode accepts `mode` (for command lines that pass the mode on).
Status checkNoiseMode(const std::string& mode);

}  // namespace plumb::sim
