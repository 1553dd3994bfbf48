// SPDX-License-Identifier: Apache-2.0
// Waiting at start for a live camera that is not plugged in (drivers/source.hpp): the virtual
// OpenNI2 device with plug_file is absent until the file exists, so a test plugs it in; a hot-plug
// arrival ends the pause between attempts; timeouts, stop requests and sources that are not
// cameras give specific errors instead of waiting.

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "drivers/openni2/openni2_source.hpp"
#include "drivers/openni2/sim_device.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/source.hpp"
#include "tests/testing/arrival_counter.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

using testing::ArrivalCounter;

const auto kNeverStop = [] { return false; };

TEST(CameraWait, LiveCameraUris) {
    EXPECT_TRUE(isLiveCameraUri("openni2"));
    EXPECT_TRUE(isLiveCameraUri("openni2:plumb-sim://living_room"));
    EXPECT_TRUE(isLiveCameraUri("openni2:PS1080/1d27/0601@1/4"));
    EXPECT_TRUE(isLiveCameraUri("v4l2:/dev/video2"));
    EXPECT_FALSE(isLiveCameraUri("openni2:/data/scan.oni"));
    EXPECT_FALSE(isLiveCameraUri("openni2:/data/SCAN.ONI"));
    EXPECT_FALSE(isLiveCameraUri("sim:living_room"));
    EXPECT_FALSE(isLiveCameraUri("dataset:/data/tum"));
    EXPECT_FALSE(isLiveCameraUri("/data/tum"));
}

TEST(CameraWait, TheRelayWakesTheWaitThenForwardsToTheSource) {
    ArrivalRelay relay;
    EXPECT_FALSE(relay.waitForArrival(1));
    relay.arrived();
    EXPECT_TRUE(relay.waitForArrival(1));   // kept until consumed ...
    EXPECT_FALSE(relay.waitForArrival(1));  // ... and consumed once
    ArrivalCounter source;
    relay.arrived();  // before the source opened: belongs to the wait, not the source
    relay.attach(&source);
    relay.arrived();
    relay.arrived();
    EXPECT_EQ(source.arrivals.load(), 2);
    EXPECT_FALSE(relay.waitForArrival(1));
    relay.attach(nullptr);
    relay.arrived();
    EXPECT_EQ(source.arrivals.load(), 2);
    EXPECT_TRUE(relay.waitForArrival(1));
}

TEST(CameraWait, AnAbsentCameraOpensWhenItArrives) {
    const auto dir = testing::freshTempDir("camera_wait_arrival");
    const auto plug = dir / "plugged";
    const std::string device =
        "plumb-sim://living_room?frames=300&seed=4&plug_file=" + plug.string();
    const std::string uri = "openni2:" + device;

    auto absent = openFrameSource(uri);
    ASSERT_FALSE(absent.isOk());
    EXPECT_EQ(absent.status().code(), StatusCode::kUnavailable) << absent.status().toString();

    // Attempts an hour apart and a minute's patience: only the arrival can make this open.
    CameraWait wait;
    wait.timeout_s = 60.0;
    wait.retry_ms = 3600 * 1000;
    ArrivalRelay relay;
    std::thread plug_in([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
        std::ofstream(plug) << "plugged in\n";
        relay.arrived();
    });
    auto source = openFrameSourceWhenPresent(uri, {}, wait, &relay, kNeverStop);
    plug_in.join();
    ASSERT_TRUE(source.isOk()) << source.status().toString();

    // It is the simulated camera, streaming the simulator's frames.
    auto frame = (*source)->next();
    ASSERT_TRUE(frame.isOk()) << frame.status().toString();
    auto* oni = dynamic_cast<openni2::OpenNI2Source*>(source->get());
    ASSERT_NE(oni, nullptr);
    auto spec = openni2::parseSimDeviceUri(device);
    ASSERT_TRUE(spec.isOk());
    EXPECT_EQ(spec->plug_file, plug.string());
    auto config = openni2::simConfigFor(*spec, 640, 480);
    ASSERT_TRUE(config.isOk());
    auto sim = sim::SimSource::create(*config);
    ASSERT_TRUE(sim.isOk());
    auto expected = (*sim)->render(static_cast<size_t>(oni->lastDeviceFrameIndex()));
    ASSERT_TRUE(expected.isOk());
    size_t differ = 0, valid = 0;
    for (size_t i = 0; i < frame->depth.size(); ++i) {
        const float e = openni2::pixelToDepth(
            openni2::depthToPixel(expected->frame.depth.pixels()[i], 1000.0), 1000.0);
        differ += frame->depth.pixels()[i] != e ? 1 : 0;
        valid += e > 0.0f ? 1 : 0;
    }
    EXPECT_GT(valid, frame->depth.size() / 3);
    EXPECT_EQ(differ, 0u);
}

TEST(CameraWait, GivesUpAfterTheTimeoutOrWhenStopped) {
    const auto dir = testing::freshTempDir("camera_wait_give_up");
    const std::string uri = "v4l2:" + (dir / "video0").string();
    CameraWait wait;
    wait.timeout_s = 0.3;
    wait.retry_ms = 50;
    auto timed_out = openFrameSourceWhenPresent(uri, {}, wait, nullptr, kNeverStop);
    ASSERT_FALSE(timed_out.isOk());
    EXPECT_EQ(timed_out.status().code(), StatusCode::kUnavailable);
    EXPECT_NE(timed_out.status().message().find("no camera plugged in within 0.3 s"),
              std::string::npos)
        << timed_out.status().toString();
    EXPECT_NE(timed_out.status().message().find("does not exist"), std::string::npos)
        << timed_out.status().toString();  // and why the last attempt failed

    wait.timeout_s = -1.0;  // forever, but a stop request ends it
    int polls = 0;
    ArrivalRelay relay;
    auto stopped =
        openFrameSourceWhenPresent(uri, {}, wait, &relay, [&polls] { return ++polls > 3; });
    ASSERT_FALSE(stopped.isOk());
    EXPECT_NE(stopped.status().message().find("stopped while waiting"), std::string::npos)
        << stopped.status().toString();
}

TEST(CameraWait, RecordingsDatasetsAndBadRequestsAreNotWaitedFor) {
    CameraWait forever;
    forever.timeout_s = -1.0;  // a wait here would never end: each must return at once
    auto dataset =
        openFrameSourceWhenPresent("dataset:/nonexistent/scan", {}, forever, nullptr, kNeverStop);
    ASSERT_FALSE(dataset.isOk());
    EXPECT_EQ(dataset.status().code(), StatusCode::kNotFound);
    auto oni = openFrameSourceWhenPresent("openni2:/nonexistent/scan.oni", {}, forever, nullptr,
                                          kNeverStop);
    ASSERT_FALSE(oni.isOk());
    EXPECT_EQ(oni.status().code(), StatusCode::kNotFound);
    SourceOptions bad_mode;
    bad_mode.depth_mode = "640x480";
    auto mode = openFrameSourceWhenPresent("v4l2:/nonexistent/video0", bad_mode, forever, nullptr,
                                           kNeverStop);
    ASSERT_FALSE(mode.isOk());
    EXPECT_EQ(mode.status().code(), StatusCode::kInvalidArgument);
    // A camera that is present opens on the first attempt (a finite wait, so that a missing
    // virtual device fails the test instead of hanging it).
    CameraWait minute;
    minute.timeout_s = 60.0;
    auto present = openFrameSourceWhenPresent("openni2:plumb-sim://living_room?frames=300", {},
                                              minute, nullptr, kNeverStop);
    EXPECT_TRUE(present.isOk()) << present.status().toString();
}

TEST(CameraWait, PlugFileIsPartOfTheVirtualDeviceUri) {
    auto spec = openni2::parseSimDeviceUri("plumb-sim://office?plug_file=/tmp/x");
    ASSERT_TRUE(spec.isOk());
    EXPECT_EQ(spec->plug_file, "/tmp/x");
    EXPECT_FALSE(openni2::parseSimDeviceUri("plumb-sim://office?plug_file=").isOk());
    EXPECT_TRUE(openni2::parseSimDeviceUri("plumb-sim://office").value().plug_file.empty());
}

}  // namespace
}  // namespace plumb
