// SPDX-License-Identifier: Apache-2.0
#include "backend/app/backend_cli.hpp"

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "backend/ingest/ingest_run.hpp"
#include "backend/ingest/raw_frame_store.hpp"
#include "common/camera/pinhole.hpp"
#include "common/config/config.hpp"
#include "common/core/logging.hpp"
#include "common/core/usage.hpp"
#include "messages/lcm_link.hpp"

#if __has_include("backend/pipeline/pipeline.hpp")
#include "backend/pipeline/pipeline.hpp"
#define PLUMB_BACKEND_HAS_PIPELINE 1
#endif

namespace plumb::backend {
namespace {

constexpr const char* kUsage =
    " (--live | --log LOG | --fragments DIR) --out DIR [options]\n"
    "\n"
    "  --live               receive fragments from plumb-device over LCM, persist and acknowledge\n"
    "  --log LOG            process an lcm-logger log deterministically at full speed; a log\n"
    "                       that is empty, damaged or cut short, or holds no complete\n"
    "                       fragment, is an error (exit 1) after what is intact is stored\n"
    "  --fragments DIR      the fragment store (default <out>/fragments); alone: reconstruct\n"
    "                       from an existing store\n"
    "  --out DIR            output directory (metrics.json, camera_info.json, ...)\n"
    "  --until-end          live: stop when every device session being finished (--session, else\n"
    "                       every device heard from that did not go silent) announced the end of\n"
    "                       its scan and has every fragment stored; each session is then listed\n"
    "  --session ID         the device session to finish (repeatable; plumb-device logs its id)\n"
    "                       and to reconstruct (default: the newest in the store; the others are\n"
    "                       named in a warning)\n"
    "  --expect N           live: stop once N fragments are in the store\n"
    "  --timeout S          live: give up after S seconds (exit 1)\n"
    "  --linger S           live: keep acknowledging for S seconds after the end (default 1)\n"
    "  --no-finalise        stop after ingest (no reconstruction)\n"
    "  --no-raw-frames      neither keep the raw frames devices stream nor re-integrate the\n"
    "                       ones kept: the final model fuses the fragment surfaces\n"
    "  --raw-frames-reserve GIB\n"
    "                       keep raw frames only while this much disk stays free for the\n"
    "                       fragments (default 2)\n"
    "  --gt DIR             ground truth to score against (groundtruth.txt or trajectory.log,\n"
    "                       gt_points.ply, layout.json)\n"
    "  --lcm-url URL        LCM URL (default udpm://239.255.76.67:7667?ttl=0, stays on host);\n"
    "                       udpm URLs without recv_buf_size get recv_buf_size=4194304\n"
    "  --allow-remote       allow an LCM URL that can leave this machine\n"
    "  --key-file FILE      shared key (hex): only authenticated messages are accepted\n"
    "  --key-id N           identifier of the key (default 1)\n"
    "  --config FILE        pipeline configuration (TOML); --set KEY=VALUE overrides\n"
    "  --log-level L        trace|debug|info|warn|error|off (default info)\n"
    "\n"
    "The ingest keeps the raw frames a device streams (plumb-device --set\n"
    "stream.raw_frame_every=1; about 0.7 MB a VGA frame with colour, 0.3 MB depth only) in\n"
    "<fragments>/raw_frames, while 2 GiB stay free for the fragments. The final model\n"
    "re-integrates them at the optimised poses when every fragment has at least\n"
    "final_model.min_raw_frame_share (0.2: every 4th frame) of its tracked frames among them;\n"
    "else it fuses the fragments' surfaces (less accurate: BENCHMARKS.md). The log says which.\n"
    "Depth-only raw frames of a coloured scan are coloured from the fragments' points.\n";

std::atomic<int> g_stop_requests{0};
extern "C" void onSignal(int) { g_stop_requests.fetch_add(1); }

const char* g_program = "plumb-backend";

bool parseDouble(const std::string& text, double* out) {
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0' || !(v >= 0.0)) return false;
    *out = v;
    return true;
}

/// The command line of plumb-backend (every option but --config/--set).
struct BackendArgs {
    bool live = false, finalise = true;
    std::string log_path, fragments_dir, out_dir, gt_dir;
    backend::IngestRunOptions options;
    /// A receive buffer of a few raw frames (stream.raw_frame_every = 1 at VGA: about 0.7 MB
    /// each), capped by the kernel at net.core.rmem_max.
    messages::LinkOptions link_options = [] {
        messages::LinkOptions o;
        o.recv_buffer_bytes = int64_t{4} << 20;
        return o;
    }();
    std::optional<log::Level> level;  // unset: the level the process already runs at
};

/// Parses `args` into `out`. Returns the exit status when the program is done (--help: 0, a
/// usage error: 2), nothing when it should run.
std::optional<int> parseArguments(const std::vector<std::string>& args, BackendArgs* out) {
    backend::IngestRunOptions& options = out->options;
    messages::LinkOptions& link_options = out->link_options;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&](std::string* v) {
            if (i + 1 >= args.size()) return false;
            *v = args[++i];
            return true;
        };
        std::string v;
        double d = 0.0;
        if (a == "--help" || a == "-h") {
            std::printf("usage: %s%s", g_program, kUsage);
            return 0;
        } else if (a == "--live") {
            out->live = true;
        } else if (a == "--log") {
            if (!value(&out->log_path)) return usageError(g_program, "--log needs a file");
        } else if (a == "--fragments") {
            if (!value(&out->fragments_dir))
                return usageError(g_program, "--fragments needs a directory");
        } else if (a == "--out") {
            if (!value(&out->out_dir)) return usageError(g_program, "--out needs a directory");
        } else if (a == "--until-end") {
            options.until_end = true;
        } else if (a == "--session") {
            if (!value(&v) || !parseDouble(v, &d) || d < 1 || d != static_cast<int64_t>(d))
                return usageError(g_program,
                                  "--session needs a positive integer (a device's session id)");
            options.sessions.insert(static_cast<int64_t>(d));
        } else if (a == "--expect") {
            if (!value(&v) || !parseDouble(v, &d) || d < 1 || d != static_cast<int64_t>(d))
                return usageError(g_program, "--expect needs a positive integer");
            options.expect = static_cast<int64_t>(d);
        } else if (a == "--timeout") {
            if (!value(&v) || !parseDouble(v, &options.timeout_s))
                return usageError(g_program, "--timeout needs seconds >= 0");
        } else if (a == "--linger") {
            if (!value(&v) || !parseDouble(v, &options.linger_s))
                return usageError(g_program, "--linger needs seconds >= 0");
        } else if (a == "--gt") {
            if (!value(&out->gt_dir)) return usageError(g_program, "--gt needs a directory");
        } else if (a == "--no-finalise" || a == "--no-finalize") {
            out->finalise = false;
        } else if (a == "--no-raw-frames") {
            options.ingest.keep_raw_frames = false;
        } else if (a == "--raw-frames-reserve") {
            if (!value(&v) || !parseDouble(v, &d) || !(d >= 0.0) || d > 1e6)
                return usageError(g_program, "--raw-frames-reserve needs GiB >= 0");
            options.ingest.raw_frames_min_free_bytes =
                static_cast<uint64_t>(d * static_cast<double>(uint64_t{1} << 30));
        } else if (a == "--lcm-url") {
            if (!value(&link_options.url)) return usageError(g_program, "--lcm-url needs a value");
        } else if (a == "--allow-remote") {
            link_options.allow_remote = true;
        } else if (a == "--key-file") {
            if (!value(&v)) return usageError(g_program, "--key-file needs a value");
            link_options.key_file = v;
        } else if (a == "--key-id") {
            if (!value(&v) || !parseDouble(v, &d) || d > INT32_MAX)
                return usageError(g_program, "--key-id needs a non-negative 32-bit integer");
            link_options.key_id = static_cast<int32_t>(d);
        } else if (a == "--log-level") {
            log::Level parsed = log::Level::kInfo;
            if (!value(&v) || !log::parseLevel(v, &parsed))
                return usageError(g_program, "--log-level needs trace|debug|info|warn|error|off");
            out->level = parsed;
        } else {
            return usageError(g_program, "unknown argument '" + a + "'");
        }
    }
    if (out->live && !out->log_path.empty())
        return usageError(g_program, "--live and --log exclude each other");
    if (!out->live && out->log_path.empty() && out->fragments_dir.empty())
        return usageError(g_program, "one of --live, --log LOG or --fragments DIR is required");
    if (out->out_dir.empty()) return usageError(g_program, "--out is required");
    options.out_dir = out->out_dir;
    options.fragments_dir = out->fragments_dir.empty()
                                ? std::filesystem::path(out->out_dir) / "fragments"
                                : std::filesystem::path(out->fragments_dir);
    return std::nullopt;
}

/// Live or log ingest; returns the exit status (0, or 1 with the reason logged).
int ingest(const BackendArgs& a) {
    const backend::IngestRunOptions& options = a.options;
    Result<backend::IngestRunResult> result = Status(StatusCode::kInternal, "not run");
    if (a.live) {
        auto link = messages::LcmLink::open(a.link_options);
        if (!link.isOk()) {
            log::error("{}", link.status().toString());
            return 1;
        }
        log::info("listening on {}{}; store {}", (*link)->url(),
                  (*link)->authenticated() ? " (authenticated)" : "",
                  options.fragments_dir.string());
        result = backend::runLiveIngest(**link, options, g_stop_requests);
    } else {
        messages::AuthConfig auth;
        if (!a.link_options.key_file.empty()) {
            auto key = messages::readKeyFile(a.link_options.key_file);
            if (!key.isOk()) {
                log::error("{}", key.status().toString());
                return 1;
            }
            auth.key = std::move(key).value();
            auth.key_id = a.link_options.key_id;
        }
        result = backend::runLogIngest(a.log_path, options, auth);
    }
    if (!result.isOk()) {
        log::error("{}", result.status().toString());
        return 1;
    }
    const nlohmann::json& m = result->metrics;
    log::info(
        "ingest: {} fragment(s) in store, {} received, {} duplicate, {} rejected; "
        "chunks lost {} recovered {}; messages rejected {}",
        result->fragments_in_store, m["fragments_received"].get<uint64_t>(),
        m["fragments_duplicate"].get<uint64_t>(), m["fragments_rejected"].get<uint64_t>(),
        m["chunks_lost"].get<uint64_t>(), m["chunks_recovered"].get<uint64_t>(),
        m["messages_rejected"].dump());
    int code = 0;
    if (result->timed_out) {
        log::error("timed out before the scan was complete");
        code = 1;
    }
    if (!result->log_damage.isOk()) {
        log::error("{}", result->log_damage.message());
        code = 1;
    }
    return code;
}

#ifdef PLUMB_BACKEND_HAS_PIPELINE
/// Lets the final model re-integrate the raw frames the ingest kept for the fragments of
/// `input`, which are of `session` (backend/ingest/raw_frame_store.hpp), when every fragment
/// has at least `min_share` of its tracked frames among them and they are of the camera's
/// size; else it fuses the fragment surfaces, and the log says why.
void attachRawFrames(const std::filesystem::path& fragments_dir, int64_t session, double min_share,
                     backend::PipelineInput* input) {
    auto stored = backend::listRawFrames(backend::rawFramesDir(fragments_dir));
    if (!stored.isOk()) {
        log::warn("{}; the final model fuses the fragment surfaces", stored.status().message());
        return;
    }
    if (stored->empty()) {
        log::info(
            "final model: from the fragment surfaces (no raw frames were kept; "
            "plumb-device --set stream.raw_frame_every=4 --set stream.raw_frame_colour=false "
            "streams every 4th frame's depth, for a more accurate mesh)");
        return;
    }
    backend::RawFrameCoverage coverage =
        backend::rawFrameCoverage(*stored, input->fragments, session);
    if (coverage.min_fragment_share < min_share) {
        log::info(
            "final model: from the fragment surfaces: {} of the {} tracked frames have a "
            "raw frame, fragment {} only {:.1f} % of its own (final_model."
            "min_raw_frame_share is {:.1f} %)",
            coverage.matched, coverage.tracked_frames, coverage.min_fragment_id,
            100.0 * coverage.min_fragment_share, 100.0 * min_share);
        return;
    }
    // A frame of another size than the camera (camera_info.json missing) would be left out one
    // by one: check the first.
    auto first = backend::openRawFrameSource({coverage.frames.front()}, input->camera)->next();
    if (!first.isOk()) {
        log::warn(
            "final model: from the fragment surfaces: the raw frames do not read as the "
            "camera's ({})",
            first.status().message());
        return;
    }
    const std::string stride = coverage.stride > 1
                                   ? fmt::format(" (one in {}: stream.raw_frame_every = {})",
                                                 coverage.stride, coverage.stride)
                                   : std::string();
    log::info("final model: re-integrating the raw frames kept, {} of the {} tracked frames{}",
              coverage.matched, coverage.tracked_frames, stride);
    // Frames the device's stride predicts and the store does not hold (1 % of slack for
    // fragments whose length is not a multiple of the stride).
    const double expected =
        static_cast<double>(coverage.tracked_frames) / static_cast<double>(coverage.stride);
    const bool frames_missing = static_cast<double>(coverage.matched) < 0.99 * expected;
    if (coverage.matched == coverage.tracked_frames) {
        log::info(
            "the raw frames are a scan of their own: `plumb reconstruct store:{} "
            "--self-calibrate` tracks them again and learns the camera's depth distortion",
            fragments_dir.string());
    } else if (frames_missing) {
        log::info(
            "final model: about {:.0f} raw frames the device streamed are missing, lost on "
            "the network or not kept: udpm drops whole frames when the receive buffer "
            "overflows (sysctl net.core.rmem_max of at least 4194304 keeps them); the ingest's "
            "metrics.json counts the frames not kept",
            expected - static_cast<double>(coverage.matched));
    }
    input->open_raw_frames = [frames = std::move(coverage.frames),
                              camera = input->camera]() -> Result<std::unique_ptr<FrameSource>> {
        return backend::openRawFrameSource(frames, camera);
    };
}

/// Reconstructs one session of the store (chooseSession) into the output directory; returns
/// the exit status.
int finalise(const BackendArgs& a, const backend::PipelineConfig& pipeline_config) {
    const backend::IngestRunOptions& options = a.options;
    auto store = messages::FragmentStore::open(options.fragments_dir);
    if (!store.isOk()) {
        log::error("{}", store.status().toString());
        return 1;
    }
    std::string others;
    auto session = backend::chooseSession(**store, options.sessions, &others);
    if (!session.isOk()) {
        log::error("{}", session.status().toString());
        return 1;
    }
    if (!others.empty()) log::warn("{}", others);
    auto fragments = backend::loadStoredFragments(**store, *session);
    if (!fragments.isOk()) {
        log::error("{}", fragments.status().toString());
        return 1;
    }
    backend::PipelineInput input;
    input.fragments = std::move(fragments).value();
    input.description = options.fragments_dir.string();
    input.config_toml = config::toToml(pipeline_config, "plumb-backend configuration");
    if (!a.gt_dir.empty()) {
        auto gt = backend::loadGroundTruth(a.gt_dir);
        if (!gt.isOk()) {
            log::error("{}", gt.status().toString());
            return 1;
        }
        input.ground_truth = std::move(gt).value();
    }
    auto camera =
        backend::readCameraInfo({std::filesystem::path(a.out_dir) / "camera_info.json",
                                 options.fragments_dir.parent_path() / "camera_info.json"});
    if (camera.isOk()) {
        input.camera = *camera;
    } else {
        log::warn("{}; assuming the primesense intrinsics", camera.status().toString());
        input.camera = *cameraPreset("primesense");
    }
    if (options.ingest.keep_raw_frames) {
        attachRawFrames(options.fragments_dir, *session,
                        pipeline_config.final_model.min_raw_frame_share, &input);
    } else {
        log::info("final model: from the fragment surfaces (--no-raw-frames)");
    }
    auto ran = backend::runPipeline(input, pipeline_config, a.out_dir, true);
    if (!ran.isOk()) {
        log::error("{}", ran.status().toString());
        return 1;
    }
    std::fputs(backend::summarize(*ran).c_str(), stdout);
    return 0;
}
#endif

}  // namespace

int runBackendCommand(std::vector<std::string> args, const char* program) {
    g_program = program;
    auto config_args = config::extractConfigArgs(args);
    if (!config_args.isOk()) return usageError(g_program, config_args.status().message());
    BackendArgs a;
    if (const std::optional<int> exit_code = parseArguments(args, &a)) return *exit_code;
    const backend::IngestRunOptions& options = a.options;
    if (a.live && !options.until_end && options.expect == 0 && options.timeout_s == 0) {
        log::info("no --until-end, --expect or --timeout: receiving until SIGINT/SIGTERM");
    }
    log::setupLogging(g_program, a.level);
#ifdef PLUMB_BACKEND_HAS_PIPELINE
    // Checked before any work: a configuration that does not load is a bad command line.
    backend::PipelineConfig pipeline_config;
    if (Status s = config::load(*config_args, pipeline_config); !s.isOk()) {
        return usageError(g_program, s.message());
    }
#endif
    struct sigaction sa {};
    sa.sa_handler = onSignal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);

    if (a.live || !a.log_path.empty()) {
        if (const int code = ingest(a); code != 0) return code;
    }
    if (!a.finalise) return 0;
#ifdef PLUMB_BACKEND_HAS_PIPELINE
    return finalise(a, pipeline_config);
#else
    log::info("no reconstruction pipeline in this build; stopping after ingest");
    return 0;
#endif
}

}  // namespace plumb::backend
