// USB hotplug notifications, so the capture layer can notice a camera or GPS being unplugged
// during a capture (and a replacement arriving). One libusb context and one event thread per
// monitor; callbacks are delivered on that thread, outside libusb's own callback, with the
// device's info (for a device that left, its descriptors; strings cannot be read any more).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>

#include "capture/usb/usb_devices.h"

namespace rouen {

enum class UsbHotplugEvent { kArrived, kLeft };
const char* UsbHotplugEventName(UsbHotplugEvent event);  // "arrived", "left"

struct UsbHotplugOptions {
  int vendor_id = -1, product_id = -1;  // -1 = any
  // Also report every device already present as arrived (libusb's ENUMERATE flag).
  bool enumerate_existing = false;
  // Read manufacturer/product strings of arriving devices (opens them; may fail quietly).
  bool read_strings_on_arrival = true;
  // How long the event thread blocks in libusb at most (s); Stop() wakes it at once anyway.
  double poll_interval_s = 0.5;
  void Validate() const;  // throws rouen::Error
};

class UsbHotplugMonitor {
 public:
  using Callback = std::function<void(UsbHotplugEvent, const UsbDeviceInfo&)>;

  // libusb's report of whether this platform delivers hotplug events.
  static bool Supported();

  explicit UsbHotplugMonitor(Callback callback, UsbHotplugOptions options = {});
  ~UsbHotplugMonitor();  // Stop()
  UsbHotplugMonitor(const UsbHotplugMonitor&) = delete;
  UsbHotplugMonitor& operator=(const UsbHotplugMonitor&) = delete;

  // Starts the event thread. Returns false (and starts nothing) when hotplug is unsupported;
  // true when running (also when it already was). Throws rouen::DeviceError when libusb fails.
  bool Start();
  // Stops and joins the event thread; no callback runs after it returns. Events not yet
  // delivered are dropped. Idempotent. Called from inside a callback, it only asks the thread
  // to stop (the destructor or a later Stop() joins it).
  void Stop();
  bool running() const { return running_.load(); }
  // Callbacks delivered since construction.
  uint64_t events_delivered() const { return delivered_.load(); }
  // Queues an event exactly as libusb's callback does and wakes the event thread, so tests
  // can exercise delivery without USB hardware. Ignored when not running.
  void InjectEventForTesting(UsbHotplugEvent event, const UsbDeviceInfo& info);

  struct State;  // libusb context and pending events (internal)

 private:
  void Run();
  void Shutdown();  // with control_mutex_ held: stop, join, deregister, exit
  Callback callback_;
  UsbHotplugOptions options_;
  std::unique_ptr<State> state_;
  std::thread thread_;
  std::mutex control_mutex_;  // serialises Start/Stop
  std::atomic<bool> running_{false}, stop_{false};
  std::atomic<uint64_t> delivered_{0};
};

}  // namespace rouen
