// SPDX-License-Identifier: Apache-2.0
// plumb-device end to end on the virtual OpenNI2 device and on a replayed .oni recording: the
// program runs as a child process with LD_LIBRARY_PATH pointing at the build's openni2-runtime
// (so OpenNI2 loads the virtual device; under emulation it is started through the emulator),
// captures the requested frames, cuts fragments (written with --dump-dir), records the frames
// (--record, compared with the simulator's) and, with no backend to acknowledge the fragments,
// exits 1 after a short ack wait.

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <string>
#include <vector>

#include "drivers/dataset/dataset.hpp"
#include "drivers/openni2/openni2_source.hpp"
#include "drivers/openni2/sim_device.hpp"
#include "drivers/sim/sim_source.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

struct DeviceRun {
    int exit_code = -1;
    std::string output;
};

/// Runs plumb-device with `args`; `on_line` sees every output line as it is printed.
DeviceRun runDevice(const std::string& args,
                    const std::function<void(const std::string&)>& on_line = {}) {
    const std::string command =
        std::string(PLUMB_DEVICE_LAUNCHER) + " " + PLUMB_DEVICE_EXE + " " + args + " 2>&1";
    DeviceRun run;
    FILE* pipe = popen(command.c_str(), "r");
    if (pipe == nullptr) return run;
    std::array<char, 4096> buffer{};
    while (fgets(buffer.data(), buffer.size(), pipe) != nullptr) {
        run.output += buffer.data();
        if (on_line) on_line(buffer.data());
    }
    const int status = pclose(pipe);
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return run;
}

int capturedFrames(const std::string& output) {
    std::smatch m;
    static const std::regex kCaptured("frames: ([0-9]+) captured");
    return std::regex_search(output, m, kCaptured) ? std::stoi(m[1]) : -1;
}

size_t filesIn(const std::filesystem::path& dir) {
    size_t n = 0;
    if (!std::filesystem::exists(dir)) return 0;
    for (const auto& e : std::filesystem::directory_iterator(dir)) n += e.is_regular_file();
    return n;
}

/// Checks a `--record` folder against the simulator: recorded frame i came from device frame K
/// (capture.txt names it "openni2 frame K") and must equal the simulator's frame K + offset, pixel
/// for pixel in millimetres. Returns the number of frames compared.
size_t expectRecordingEqualsTheSimulator(const std::filesystem::path& dir,
                                         const std::string& device_uri, int offset) {
    std::vector<int> device_frames;
    std::ifstream capture(dir / "capture.txt");
    static const std::regex kName("openni2 frame ([0-9]+)$");
    for (std::string line; std::getline(capture, line);) {
        std::smatch m;
        if (line.empty() || line[0] == '#') continue;
        EXPECT_TRUE(std::regex_search(line, m, kName)) << line;
        device_frames.push_back(std::stoi(m[1]));
    }
    auto recording = dataset::DatasetSource::open(dir);
    EXPECT_TRUE(recording.isOk()) << recording.status().toString();
    if (!recording.isOk()) return 0;
    EXPECT_EQ((*recording)->size(), std::optional<size_t>(device_frames.size()));
    auto spec = openni2::parseSimDeviceUri(device_uri);
    EXPECT_TRUE(spec.isOk());
    auto config = openni2::simConfigFor(*spec, 640, 480);
    EXPECT_TRUE(config.isOk());
    auto sim = sim::SimSource::create(*config);
    EXPECT_TRUE(sim.isOk());
    if (!spec.isOk() || !config.isOk() || !sim.isOk()) return 0;
    size_t compared = 0;
    for (int device_frame : device_frames) {
        auto frame = (*recording)->next();
        EXPECT_TRUE(frame.isOk()) << frame.status().toString();
        auto expected = (*sim)->render(static_cast<size_t>(device_frame + offset));
        EXPECT_TRUE(expected.isOk());
        if (!frame.isOk() || !expected.isOk()) break;
        const DepthImage& want = expected->frame.depth;
        EXPECT_EQ(frame->depth.size(), want.size());
        size_t differ = 0, valid = 0;
        for (size_t i = 0; i < want.size() && i < frame->depth.size(); ++i) {
            const uint16_t mm = openni2::depthToPixel(want.pixels()[i], 1000.0);
            differ += frame->depth.pixels()[i] != openni2::pixelToDepth(mm, 1000.0) ? 1 : 0;
            valid += mm > 0 ? 1 : 0;
        }
        EXPECT_GT(valid, want.size() / 3) << "device frame " << device_frame;
        EXPECT_EQ(differ, 0u) << "device frame " << device_frame;
        ++compared;
    }
    return compared;
}

const char* kCommon =
    " --set stream.ack_wait_s=0.2 --set fusion.frames_per_fragment=5 --set capture.queue_frames=64"
    " --lcm-url udpm://239.255.76.67:7671?ttl=0 --log-level info";

TEST(PlumbDeviceOpenNI2, ListsTheVirtualDevice) {
    const DeviceRun run = runDevice("--list-devices");
    EXPECT_EQ(run.exit_code, 0) << run.output;
    EXPECT_NE(run.output.find("openni2:plumb-sim://living_room"), std::string::npos) << run.output;
}

TEST(PlumbDeviceOpenNI2, ScansTheVirtualDeviceThroughAnUnplug) {
    const auto dir = testing::freshTempDir("plumb_device_openni2");
    const DeviceRun run = runDevice(
        "--source 'openni2:plumb-sim://living_room?frames=60&unplug_at=6&unplug_frames=6'"
        " --frames 14 --dump-dir " +
        (dir / "dump").string() + " --record " + (dir / "frames").string() + kCommon);
    ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.output;
    EXPECT_EQ(capturedFrames(run.output), 14) << run.output;  // the scan resumed after the unplug
    EXPECT_NE(run.output.find("disconnected"), std::string::npos) << run.output;
    EXPECT_NE(run.output.find("the camera is back"), std::string::npos) << run.output;
    // A live camera: the device watches USB hot-plug, or says why it cannot.
    const bool watching = run.output.find("usb: watching") != std::string::npos;
    const bool cannot = run.output.find("usb: no hot-plug notifications (") != std::string::npos;
    EXPECT_TRUE(watching != cannot) << run.output;
    EXPECT_NE(run.output.find("14 processed (100 %), 0 dropped"), std::string::npos) << run.output;
    EXPECT_GE(filesIn(dir / "dump"), 2u) << run.output;  // a fragment closed at the unplug + more
    // The frames that came out of plumb-device are the simulator's, across the unplug.
    EXPECT_NE(run.output.find("recorded 14 frame(s)"), std::string::npos) << run.output;
    EXPECT_EQ(
        expectRecordingEqualsTheSimulator(
            dir / "frames", "plumb-sim://living_room?frames=60&unplug_at=6&unplug_frames=6", 0),
        14u);
}

TEST(PlumbDeviceOpenNI2, ScansAReplayedOniRecording) {
    const auto dir = testing::freshTempDir("plumb_device_oni");
    const std::string oni = (dir / "scan.oni").string();
    openni2::OpenNI2Config record;
    record.uri = "plumb-sim://living_room?frames=300&seed=9";
    ASSERT_TRUE(openni2::recordOni(record, oni, 10).isOk());
    const DeviceRun run =
        runDevice("--source openni2:" + oni + " --dump-dir " + (dir / "dump").string() +
                  " --record " + (dir / "frames").string() + kCommon);
    ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.output;
    EXPECT_GE(capturedFrames(run.output), 10) << run.output;               // every recorded frame
    EXPECT_EQ(run.output.find("usb: "), std::string::npos) << run.output;  // a file: no hot-plug
    EXPECT_GE(filesIn(dir / "dump"), 2u) << run.output;
    // The player numbers recorded frames from 1; the recording began with stream frame 0.
    EXPECT_GE(expectRecordingEqualsTheSimulator(dir / "frames", record.uri, -1), 10u);
}

TEST(PlumbDeviceOpenNI2, WaitsForACameraPluggedInAfterTheStart) {
    const auto dir = testing::freshTempDir("plumb_device_wait");
    const auto plug = dir / "plugged";
    const std::string source =
        " --source 'openni2:plumb-sim://living_room?frames=300&plug_file=" + plug.string() + "'";

    // Not plugged in and not asked to wait: a specific error and the way to wait.
    const DeviceRun absent = runDevice(source + " --frames 4" + kCommon);
    EXPECT_EQ(absent.exit_code, 1) << absent.output;
    EXPECT_NE(absent.output.find("cannot open source"), std::string::npos) << absent.output;
    EXPECT_NE(absent.output.find("--wait-for-camera"), std::string::npos) << absent.output;
    EXPECT_EQ(capturedFrames(absent.output), -1) << absent.output;

    // Asked to wait: the camera is plugged in once the device says it is waiting, and the scan
    // runs. The wait allows ten minutes, so only the plug-in can end it within the test timeout.
    bool plugged = false;
    const DeviceRun run =
        runDevice(source + " --wait-for-camera 600 --frames 12 --dump-dir " +
                      (dir / "dump").string() + kCommon,
                  [&](const std::string& line) {
                      if (!plugged && line.find("waiting for camera") != std::string::npos) {
                          std::ofstream(plug) << "plugged in\n";
                          plugged = true;
                      }
                  });
    EXPECT_TRUE(plugged) << run.output;
    ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.output;
    EXPECT_NE(run.output.find("is present after"), std::string::npos) << run.output;
    EXPECT_EQ(capturedFrames(run.output), 12) << run.output;
    EXPECT_GE(filesIn(dir / "dump"), 2u) << run.output;

    // A bad value is a command-line error.
    const DeviceRun bad = runDevice(source + " --wait-for-camera soon" + kCommon);
    EXPECT_EQ(bad.exit_code, 2) << bad.output;
    EXPECT_NE(bad.output.find("--wait-for-camera needs seconds"), std::string::npos) << bad.output;
}

}  // namespace
}  // namespace plumb
