// SPDX-License-Identifier: Apache-2.0
// USB depth-camera identification, hot-plug filtering and the device clock.

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <vector>

#include "drivers/calibrated_source.hpp"
#include "drivers/device_clock.hpp"
#include "drivers/usb/usb_devices.hpp"
#include "tests/testing/arrival_counter.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

TEST(UsbCameras, KnownIdsMatchExactlyThenByVendor) {
    const usb::KnownCamera* xtion = usb::matchDepthCamera(0x1d27, 0x0601);
    ASSERT_NE(xtion, nullptr);
    EXPECT_STREQ(xtion->api, "openni2");
    EXPECT_EQ(xtion->product_id, 0x0601);
    const usb::KnownCamera* d435 = usb::matchDepthCamera(0x8086, 0x0b07);
    ASSERT_NE(d435, nullptr);
    EXPECT_STREQ(d435->api, "v4l2");
    const usb::KnownCamera* new_orbbec = usb::matchDepthCamera(0x2bc5, 0x0999);
    ASSERT_NE(new_orbbec, nullptr);
    EXPECT_EQ(new_orbbec->product_id, 0);                       // vendor-wide row
    EXPECT_EQ(usb::matchDepthCamera(0x046d, 0xc52b), nullptr);  // a mouse receiver
    EXPECT_EQ(usb::matchDepthCamera(0x8086, 0x1234), nullptr);  // Intel, but not a camera
}

TEST(UsbCameras, ListingAndHotplugEitherWorkOrSayWhy) {
    auto cameras = usb::listUsbDepthCameras();
    if (!cameras.isOk()) {
        EXPECT_EQ(cameras.status().code(), StatusCode::kUnavailable);
        EXPECT_FALSE(cameras.status().message().empty());
    }
    std::vector<usb::UsbCamera> arrived;
    auto monitor = usb::HotplugMonitor::start([&](usb::UsbEvent e, const usb::UsbCamera& c) {
        if (e == usb::UsbEvent::kArrived) arrived.push_back(c);
    });
    if (!monitor.isOk()) {
        EXPECT_TRUE(monitor.status().code() == StatusCode::kUnavailable ||
                    monitor.status().code() == StatusCode::kUnsupported);
        return;
    }
    // Without a bus to drive, feed the callback's filter directly.
    arrived.clear();
    EXPECT_TRUE((*monitor)->dispatch(usb::UsbEvent::kArrived, 0x1d27, 0x0600, 1, 7));
    EXPECT_FALSE((*monitor)->dispatch(usb::UsbEvent::kArrived, 0x046d, 0xc52b, 1, 8));
    ASSERT_EQ(arrived.size(), 1u);
    EXPECT_EQ(arrived[0].address, 7);
    EXPECT_EQ(usb::toString(arrived[0]).rfind("1d27:0600 bus 1 addr 7", 0), 0u);
}

using testing::ArrivalCounter;

TEST(UsbCameras, ArrivalsReachTheSourceThroughItsDecorators) {
    PLUMB_REQUIRE_SHARED_DATA(path, "redwood-noise/dist-model.txt");
    auto table = DepthCalibration::load(path);
    ASSERT_TRUE(table.isOk()) << table.status().toString();
    auto counter = std::make_unique<ArrivalCounter>();
    ArrivalCounter* inner = counter.get();
    CalibratedSource source(std::move(counter), std::move(table).value());
    const auto handler = usb::forwardArrivals(source);
    usb::UsbCamera xtion;
    xtion.vendor_id = 0x1d27;
    xtion.product_id = 0x0601;
    handler(usb::UsbEvent::kLeft, xtion);
    EXPECT_EQ(inner->arrivals.load(), 0);  // a camera leaving is only logged
    handler(usb::UsbEvent::kArrived, xtion);
    handler(usb::UsbEvent::kArrived, xtion);
    EXPECT_EQ(inner->arrivals.load(), 2);
}

TEST(DeviceClock, RecoversTheOffsetFromTheFastestFrame) {
    // Device clock starts at 0; host = device + 1000 s + latency (>= 2 ms).
    DeviceClock clock;
    const double latencies[] = {0.010, 0.004, 0.002, 0.009, 0.002, 0.030};
    double last = 0.0;
    for (int k = 0; k < 6; ++k) {
        const uint64_t dev_us = static_cast<uint64_t>(k) * 33333;
        const double host = 1000.0 + dev_us * 1e-6 + latencies[k];
        const double t = clock.toHost(dev_us, host);
        EXPECT_GE(t, last);  // monotonic while learning
        EXPECT_LE(t, host);  // never after arrival
        last = t;
        if (k >= 2) {
            EXPECT_NEAR(t, 1000.0 + dev_us * 1e-6 + 0.002, 1e-9);
        }
    }
    // The camera is re-plugged: its clock restarts at 0.
    const double t = clock.toHost(0, 2000.0 + 0.003);
    EXPECT_EQ(clock.resets(), 1);
    EXPECT_NEAR(t, 2000.003, 1e-9);
}

}  // namespace
}  // namespace plumb
