#include "capture/usb/usb_hotplug.h"

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

#include "core/error.h"

namespace rouen {
namespace {

using Clock = std::chrono::steady_clock;

TEST(UsbHotplugOptions, ValidateExplainsItself) {
  UsbHotplugOptions o;
  EXPECT_NO_THROW(o.Validate());
  o.vendor_id = 0x10000;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.product_id = -2;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.poll_interval_s = 0;
  EXPECT_THROW(o.Validate(), Error);
  try {
    UsbHotplugMonitor m(nullptr, o);
    ADD_FAILURE() << "constructor accepted a zero poll interval";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("poll_interval_s"), std::string::npos);
  }
}

TEST(UsbHotplugMonitor, StartReportsSupportAndStopsPromptly) {
  const bool supported = UsbHotplugMonitor::Supported();
  UsbHotplugOptions o;
  o.poll_interval_s = 30;  // Stop() must not wait for the poll to time out
  UsbHotplugMonitor monitor([](UsbHotplugEvent, const UsbDeviceInfo&) {}, o);
  EXPECT_FALSE(monitor.running());
  for (int round = 0; round < 5; ++round) {
    SCOPED_TRACE(round);
    ASSERT_EQ(monitor.Start(), supported);
    EXPECT_EQ(monitor.running(), supported);
    EXPECT_EQ(monitor.Start(), supported) << "a second Start is harmless";
    const auto t0 = Clock::now();
    monitor.Stop();
    const double stop_s = std::chrono::duration<double>(Clock::now() - t0).count();
    EXPECT_LT(stop_s, 2.0) << "Stop() waited for the 30 s poll";
    EXPECT_FALSE(monitor.running());
    monitor.Stop();  // idempotent
  }
  if (!supported) GTEST_SKIP() << "libusb reports no hotplug support on this machine";
}

TEST(UsbHotplugMonitor, StopWithoutStartAndDestructorWhileRunning) {
  {
    UsbHotplugMonitor never(nullptr);
    never.Stop();
  }
  const auto t0 = Clock::now();
  {
    UsbHotplugMonitor m(nullptr);
    m.Start();
  }  // destructor stops and joins
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 2.0);
}

TEST(UsbHotplugMonitor, TwoMonitorsAtOnce) {
  UsbHotplugMonitor a(nullptr), b(nullptr);
  const bool supported = UsbHotplugMonitor::Supported();
  EXPECT_EQ(a.Start(), supported);
  EXPECT_EQ(b.Start(), supported);
  a.Stop();
  EXPECT_EQ(b.running(), supported);
  b.Stop();
}

TEST(UsbHotplugMonitor, EnumerateReportsEveryPresentDeviceAsArrived) {
  if (!UsbHotplugMonitor::Supported()) {
    GTEST_SKIP() << "libusb reports no hotplug support on this machine";
  }
  const size_t present = ListUsbDevices({.read_strings = false}).size();
  std::mutex mutex;
  std::condition_variable cv;
  size_t arrived = 0, left = 0;
  UsbHotplugOptions o;
  o.enumerate_existing = true;
  o.read_strings_on_arrival = false;
  o.poll_interval_s = 0.05;
  UsbHotplugMonitor monitor(
      [&](UsbHotplugEvent e, const UsbDeviceInfo& info) {
        std::lock_guard<std::mutex> lock(mutex);
        EXPECT_FALSE(info.port_path.empty());
        (e == UsbHotplugEvent::kArrived ? arrived : left)++;
        cv.notify_all();
      },
      o);
  ASSERT_TRUE(monitor.Start());
  {
    std::unique_lock<std::mutex> lock(mutex);
    cv.wait_for(lock, std::chrono::seconds(5), [&] { return arrived >= present; });
  }
  monitor.Stop();
  // Enumerated devices are queued while Start() registers, so they are all delivered before
  // the first poll ends; with no USB devices here that is none.
  EXPECT_EQ(arrived, present);
  EXPECT_EQ(left, 0u);
  EXPECT_EQ(monitor.events_delivered(), present);
}

// Delivery without hardware: events queued as libusb's callback queues them.
struct Recorder {
  std::mutex mutex;
  std::condition_variable cv;
  std::vector<std::pair<UsbHotplugEvent, UsbDeviceInfo>> events;
  std::vector<std::thread::id> threads;
  void Add(UsbHotplugEvent e, const UsbDeviceInfo& info) {
    std::lock_guard<std::mutex> lock(mutex);
    events.emplace_back(e, info);
    threads.push_back(std::this_thread::get_id());
    cv.notify_all();
  }
  bool WaitFor(size_t n) {
    std::unique_lock<std::mutex> lock(mutex);
    return cv.wait_for(lock, std::chrono::seconds(5), [&] { return events.size() >= n; });
  }
};

UsbDeviceInfo GpsInfo() {
  UsbDeviceInfo info;
  info.bus = 1;
  info.address = 7;
  info.port_path = "1-1.2";
  info.descriptors.vendor_id = 0x1546;
  info.descriptors.product_id = 0x01a8;
  info.classification = ClassifyUsbDevice(info.descriptors);
  return info;
}

TEST(UsbHotplugMonitor, DeliversEventsOnItsThreadWithTheDeviceInfo) {
  if (!UsbHotplugMonitor::Supported()) {
    GTEST_SKIP() << "libusb reports no hotplug support on this machine";
  }
  Recorder rec;
  UsbHotplugOptions o;
  o.poll_interval_s = 30;  // delivery must not wait for the poll to time out
  UsbHotplugMonitor monitor([&](UsbHotplugEvent e, const UsbDeviceInfo& i) { rec.Add(e, i); }, o);
  monitor.InjectEventForTesting(UsbHotplugEvent::kLeft, GpsInfo());  // not running: ignored
  ASSERT_TRUE(monitor.Start());
  const auto t0 = Clock::now();
  monitor.InjectEventForTesting(UsbHotplugEvent::kArrived, GpsInfo());
  monitor.InjectEventForTesting(UsbHotplugEvent::kLeft, GpsInfo());
  ASSERT_TRUE(rec.WaitFor(2));
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 2.0);
  monitor.Stop();
  ASSERT_EQ(rec.events.size(), 2u);
  EXPECT_EQ(rec.events[0].first, UsbHotplugEvent::kArrived);
  EXPECT_EQ(rec.events[1].first, UsbHotplugEvent::kLeft);
  EXPECT_EQ(rec.events[1].second.port_path, "1-1.2");
  EXPECT_EQ(rec.events[1].second.classification.kind, UsbDeviceKind::kGpsReceiver);
  EXPECT_NE(rec.threads[0], std::this_thread::get_id()) << "delivered on the event thread";
  EXPECT_EQ(monitor.events_delivered(), 2u);
  // After Stop nothing more is delivered.
  monitor.InjectEventForTesting(UsbHotplugEvent::kArrived, GpsInfo());
  EXPECT_EQ(monitor.events_delivered(), 2u);
}

TEST(UsbHotplugMonitor, StopFromInsideTheCallbackDoesNotDeadlock) {
  if (!UsbHotplugMonitor::Supported()) {
    GTEST_SKIP() << "libusb reports no hotplug support on this machine";
  }
  Recorder rec;
  UsbHotplugMonitor* self = nullptr;
  UsbHotplugMonitor m(
      [&](UsbHotplugEvent e, const UsbDeviceInfo& i) {
        self->Stop();  // e.g. the capture layer giving up when its camera leaves
        rec.Add(e, i);
      },
      UsbHotplugOptions{.poll_interval_s = 30});
  self = &m;
  ASSERT_TRUE(m.Start());
  m.InjectEventForTesting(UsbHotplugEvent::kLeft, GpsInfo());
  ASSERT_TRUE(rec.WaitFor(1));
  // The thread ends on its own; a restart finishes the old one and runs again.
  ASSERT_TRUE(m.Start());
  EXPECT_TRUE(m.running());
  m.InjectEventForTesting(UsbHotplugEvent::kArrived, GpsInfo());
  ASSERT_TRUE(rec.WaitFor(2));
  m.Stop();
  EXPECT_FALSE(m.running());
  EXPECT_EQ(m.events_delivered(), 2u);
}

TEST(UsbHotplugEventName, Names) {
  EXPECT_STREQ(UsbHotplugEventName(UsbHotplugEvent::kArrived), "arrived");
  EXPECT_STREQ(UsbHotplugEventName(UsbHotplugEvent::kLeft), "left");
}

}  // namespace
}  // namespace rouen
