// SPDX-License-Identifier: Apache-2.0
#include "drivers/sim/sim_source.hpp"

#include <fmt/format.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <system_error>

#include "common/io/ply.hpp"
#include "common/io/text_file.hpp"
#include "common/layout/layout.hpp"
#include "common/layout/layout_json.hpp"
#include "drivers/dataset/depth_png.hpp"
#include "drivers/dataset/intrinsics_file.hpp"

namespace plumb::sim {
namespace {

constexpr double kDepthScale = 1000.0;  // depth PNG units per metre (mm)

const char* distortionName(DistortionKind kind) {
    switch (kind) {
        case DistortionKind::kNone:
            return "none";
        case DistortionKind::kTable:
            return "table";
        case DistortionKind::kParametric:
            return "parametric";
    }
    return "?";
}

}  // namespace

Status parseNoiseMode(const std::string& mode, NoiseConfig* noise) {
    if (mode == "off") {
        noise->enabled = false;
    } else if (mode == "redwood" || mode == "on") {
        noise->enabled = true;
        noise->distortion = DistortionKind::kTable;
    } else if (mode == "parametric") {
        noise->enabled = true;
        noise->distortion = DistortionKind::kParametric;
    } else if (mode == "undistorted") {
        noise->enabled = true;
        noise->distortion = DistortionKind::kNone;
    } else {
        return invalidArgument(fmt::format(
            "unknown noise mode '{}' (use off, redwood, parametric or undistorted)", mode));
    }
    return Status::ok();
}

Status checkNoiseMode(const std::string& mode) {
    NoiseConfig scratch;
    return parseNoiseMode(mode, &scratch);
}

Result<std::unique_ptr<SimSource>> SimSource::create(const SimConfig& config) {
    PLUMB_RETURN_IF_ERROR(config.camera.validate());
    PLUMB_RETURN_IF_ERROR(validateColourConfig(config.colour));
    auto scene = resolveScene(config.scene);
    if (!scene.isOk()) return scene.status();
    if (config.texture) scene->texture = *config.texture;
    std::unique_ptr<SimSource> source(new SimSource());
    source->config_ = config;
    if (config.trajectory_file.empty()) {
        auto trajectory = generateTrajectory(*scene, config.trajectory);
        if (!trajectory.isOk()) return trajectory.status();
        source->trajectory_ = std::move(trajectory).value();
    } else {
        auto trajectory = io::readTumTrajectory(config.trajectory_file);
        if (!trajectory.isOk()) return trajectory.status();
        if (trajectory->empty()) {
            return invalidArgument(
                fmt::format("{}: the trajectory has no poses", config.trajectory_file));
        }
        for (size_t i = 0; i < trajectory->size(); ++i) {
            const Eigen::Vector3d p = (*trajectory)[i].T_W_C.translation();
            if (!insidePolygon(scene->polygon, p.head<2>()) || p.z() <= 0.0 ||
                p.z() >= scene->height_m) {
                return invalidArgument(fmt::format(
                    "{}: pose {} at ({:.3f}, {:.3f}, {:.3f}) is outside the room of scene '{}'",
                    config.trajectory_file, i, p.x(), p.y(), p.z(), scene->name));
            }
        }
        source->trajectory_ = std::move(trajectory).value();
        if (config.trajectory.num_frames > 0 &&
            source->trajectory_.size() > config.trajectory.num_frames) {
            source->trajectory_.resize(config.trajectory.num_frames);
        }
    }
    std::optional<DistortionTable> table;
    source->noise_source_ = "none";
    if (config.noise.enabled && config.noise.distortion == DistortionKind::kTable) {
        auto path = findNoiseModelFile(config.noise_model_path);
        if (!path.isOk()) return path.status();
        auto loaded = DistortionTable::load(*path);
        if (!loaded.isOk()) return loaded.status();
        table = std::move(loaded).value();
        source->noise_source_ = path->string();
    }
    RenderConfig render_config;
    render_config.colour = config.colour.enabled;
    source->renderer_ = std::make_unique<Renderer>(*scene, config.camera, render_config);
    source->noise_ = std::make_unique<DepthNoiseModel>(config.noise, std::move(table),
                                                       config.camera.cx, config.camera.cy);
    source->colour_noise_ = std::make_unique<ColourNoiseModel>(config.colour);
    return source;
}

Result<SimFrame> SimSource::render(size_t k) const {
    SimFrame out;
    PLUMB_RETURN_IF_ERROR(render(k, &out));
    return out;
}

Status SimSource::render(size_t k, SimFrame* out) const {
    if (k >= trajectory_.size()) {
        return outOfRange(fmt::format("simulated frame {} requested, the sequence has {}", k,
                                      trajectory_.size()));
    }
    const io::StampedPose& pose = trajectory_[k];
    renderer_->render(pose.T_W_C, &out->view);
    out->frame.index = static_cast<int64_t>(k);
    out->frame.timestamp_s = pose.timestamp_s;
    noise_->apply(out->view.depth, out->view.cos_view, config_.seed, k, &out->frame.depth);
    out->frame.gray = out->view.gray;  // copy-assignment reuses the buffer
    if (config_.colour.enabled) {
        out->exposure_gain = colour_noise_->gain(config_.seed, k);
        colour_noise_->apply(out->view.colour, config_.seed, k, &out->frame.colour);
    } else {
        out->exposure_gain = 1.0;
        out->frame.colour = ColourImage();
    }
    out->frame.name = fmt::format("sim:{}/{:05d}", scene().name, k);
    out->frame.T_W_C_gt = pose.T_W_C;
    return Status::ok();
}

Result<Frame> SimSource::next() {
    if (next_ >= trajectory_.size()) {
        return outOfRange(fmt::format("end of the simulated sequence ({} frames)", next_));
    }
    // The clean view stays in scratch_ for the next frame; the frame itself goes to the caller.
    PLUMB_RETURN_IF_ERROR(render(next_++, &scratch_));
    return std::move(scratch_.frame);
}

Status SimSource::skip() {
    if (next_ >= trajectory_.size()) {
        return outOfRange(fmt::format("end of the simulated sequence ({} frames)", next_));
    }
    ++next_;
    return Status::ok();
}

std::string SimSource::description() const {
    const NoiseConfig& n = config_.noise;
    return fmt::format(
        "simulated scan of '{}' ({} frames, {} trajectory, {}, noise {}{}, colour {})",
        scene().name, trajectory_.size(),
        config_.trajectory_file.empty() ? (config_.trajectory.loop ? "loop" : "no-loop")
                                        : config_.trajectory_file,
        camera().toString(), n.enabled ? "on" : "off",
        n.enabled ? fmt::format(", distortion {}", distortionName(n.distortion)) : std::string(),
        config_.colour.enabled ? textureModeName(scene().texture) : "off");
}

Status writeSimDataset(const SimSource& source, const std::filesystem::path& dir,
                       const SimDatasetOptions& options) {
    std::error_code ec;
    std::filesystem::create_directories(dir / "depth", ec);
    if (!ec && options.write_clean) std::filesystem::create_directories(dir / "depth_clean", ec);
    if (!ec && options.write_gray) std::filesystem::create_directories(dir / "gray", ec);
    const bool write_rgb = options.write_rgb && source.config().colour.enabled;
    if (!ec && write_rgb) std::filesystem::create_directories(dir / "rgb", ec);
    if (ec) {
        return ioError(
            fmt::format("{}: cannot create the output folders: {}", dir.string(), ec.message()));
    }
    std::string depth_txt = "# depth maps\n# simulated by plumb sim\n# timestamp filename\n";
    std::string rgb_txt = "# color images\n# simulated by plumb sim\n# timestamp filename\n";
    io::Trajectory gt;
    const size_t n = *source.size();
    for (size_t k = 0; k < n; ++k) {
        auto rendered = source.render(k);
        if (!rendered.isOk()) return rendered.status();
        const SimFrame& f = *rendered;
        const std::string name = fmt::format("{:05d}.png", k);
        PLUMB_RETURN_IF_ERROR(
            dataset::writeDepthPng(dir / "depth" / name, toRaw(f.frame.depth, kDepthScale)));
        if (options.write_clean) {
            PLUMB_RETURN_IF_ERROR(dataset::writeDepthPng(dir / "depth_clean" / name,
                                                         toRaw(f.view.depth, kDepthScale)));
        }
        if (options.write_gray) {
            PLUMB_RETURN_IF_ERROR(dataset::writeGrayPng(dir / "gray" / name, f.frame.gray));
        }
        if (write_rgb) {
            PLUMB_RETURN_IF_ERROR(dataset::writeColourPng(dir / "rgb" / name, f.frame.colour));
            rgb_txt += fmt::format("{:.6f} rgb/{}\n", f.frame.timestamp_s, name);
        }
        depth_txt += fmt::format("{:.6f} depth/{}\n", f.frame.timestamp_s, name);
        gt.push_back({f.frame.timestamp_s, *f.frame.T_W_C_gt});
    }
    PLUMB_RETURN_IF_ERROR(io::writeText(dir / "depth.txt", depth_txt));
    if (write_rgb) PLUMB_RETURN_IF_ERROR(io::writeText(dir / "rgb.txt", rgb_txt));
    PLUMB_RETURN_IF_ERROR(io::writeTumTrajectory(dir / "groundtruth.txt", gt));
    PLUMB_RETURN_IF_ERROR(io::writeLogTrajectory(dir / "trajectory.log", gt));
    PLUMB_RETURN_IF_ERROR(
        dataset::writeIntrinsicsJson(dir / "intrinsics.json", source.camera(), kDepthScale));
    const Scene& scene = source.scene();
    PLUMB_RETURN_IF_ERROR(
        io::writePointCloud(dir / "gt_points.ply", sampleSurfaces(scene, options.gt_spacing_m)));
    auto layout = makeRoomLayout(scene.polygon, scene.height_m);
    if (!layout.isOk()) return layout.status();
    PLUMB_RETURN_IF_ERROR(io::writeLayoutJson(dir / "layout.json", *layout));

    const SimConfig& c = source.config();
    const NoiseConfig& nc = c.noise;
    nlohmann::ordered_json meta;
    meta["format"] = "plumb-sim-1";
    meta["scene"] = scene.name;
    meta["frames"] = n;
    meta["rate_hz"] = c.trajectory.rate_hz;
    meta["trajectory"] =
        c.trajectory_file.empty() ? (c.trajectory.loop ? "loop" : "no-loop") : c.trajectory_file;
    meta["trajectory_seed"] = c.trajectory.seed;
    meta["noise_seed"] = c.seed;
    meta["depth_scale"] = kDepthScale;
    meta["gt_spacing_m"] = options.gt_spacing_m;
    nlohmann::ordered_json noise;
    noise["enabled"] = nc.enabled;
    noise["distortion"] = distortionName(nc.distortion);
    noise["jitter_std_px"] = nc.jitter_std_px;
    noise["disparity_noise_std"] = nc.disparity_noise_std;
    noise["baseline_focal_px_m"] = nc.baseline_focal_px_m;
    noise["disparity_subpixel_steps"] = nc.disparity_subpixel_steps;
    noise["k1"] = nc.k1;
    noise["k2"] = nc.k2;
    noise["min_depth_m"] = nc.min_depth_m;
    noise["max_depth_m"] = nc.max_depth_m;
    noise["missing_data"] = nc.missing_data;
    noise["grazing_cos_drop"] = nc.grazing_cos_drop;
    noise["grazing_cos_keep"] = nc.grazing_cos_keep;
    noise["edge_relative_range"] = nc.edge_relative_range;
    noise["random_dropout"] = nc.random_dropout;
    noise["distortion_table"] =
        source.config().noise.enabled && nc.distortion == DistortionKind::kTable
            ? std::filesystem::path(c.noise_model_path.empty() ? "dist-model.txt"
                                                               : c.noise_model_path)
                  .filename()
                  .string()
            : std::string();
    meta["noise"] = noise;
    const ColourConfig& cc = c.colour;
    nlohmann::ordered_json colour;
    colour["enabled"] = cc.enabled;
    colour["written"] = write_rgb;
    colour["texture"] = textureModeName(scene.texture);
    colour["texture_seed"] = scene.texture_seed;
    colour["floor_pattern"] = floorPatternName(scene.floor_pattern);
    colour["pictures_per_wall"] = scene.pictures_per_wall;
    colour["ambient"] = source.renderer().config().ambient;
    colour["noise_std_levels"] = cc.noise_std_levels;
    colour["exposure_log_std"] = cc.exposure_log_std;
    colour["exposure_period_frames"] = cc.exposure_period_frames;
    nlohmann::ordered_json jumps = nlohmann::ordered_json::array();
    for (const ExposureJump& j : cc.exposure_jumps) {
        jumps.push_back({{"frame", j.frame}, {"factor", j.factor}});
    }
    colour["exposure_jumps"] = jumps;
    colour["response"] = "linear";
    meta["colour"] = colour;
    PLUMB_RETURN_IF_ERROR(io::writeText(dir / "sim.json", meta.dump(2) + "\n"));
    return Status::ok();
}

}  // namespace plumb::sim
