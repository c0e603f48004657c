#include "capture/usb/usb_hotplug.h"

#include <libusb.h>
#include <sys/time.h>

#include <cmath>
#include <utility>
#include <vector>

#include "capture/device.h"
#include "capture/usb/usb_internal.h"
#include "core/error.h"

namespace rouen {

struct UsbHotplugMonitor::State {
  libusb_context* ctx = nullptr;
  libusb_hotplug_callback_handle handle = 0;
  bool registered = false;
  // Filled inside libusb's callback (on whichever thread is handling events, or in
  // Start() for enumerated devices), drained by the event thread.
  struct Pending {
    UsbHotplugEvent event;
    UsbDeviceInfo info;
    libusb_device* device = nullptr;  // referenced for arrivals (to read strings later)
  };
  std::mutex mutex;
  std::vector<Pending> pending;

  void DropPending() {
    std::lock_guard<std::mutex> lock(mutex);
    for (Pending& p : pending) {
      if (p.device != nullptr) libusb_unref_device(p.device);
    }
    pending.clear();
  }
};

namespace {

// libusb's callback: only descriptor reads (cached, no I/O) happen here; the user callback
// runs later on the event thread, where opening the device is allowed.
int LIBUSB_CALL OnHotplug(libusb_context*, libusb_device* device, libusb_hotplug_event event,
                          void* user_data) {
  auto* state = static_cast<UsbHotplugMonitor::State*>(user_data);
  UsbHotplugMonitor::State::Pending p;
  p.event = event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED ? UsbHotplugEvent::kArrived
                                                         : UsbHotplugEvent::kLeft;
  p.info = usb_internal::DescribeDevice(device, /*read_strings=*/false);
  if (p.event == UsbHotplugEvent::kArrived) p.device = libusb_ref_device(device);
  std::lock_guard<std::mutex> lock(state->mutex);
  state->pending.push_back(std::move(p));
  return 0;  // stay registered
}

}  // namespace

const char* UsbHotplugEventName(UsbHotplugEvent event) {
  return event == UsbHotplugEvent::kArrived ? "arrived" : "left";
}

void UsbHotplugOptions::Validate() const {
  auto id_ok = [](int id) { return id == -1 || (id >= 0 && id <= 0xffff); };
  if (!id_ok(vendor_id) || !id_ok(product_id)) {
    throw Error("usb hotplug options: vendor_id and product_id must be -1 (any) or 0..0xffff");
  }
  if (!(poll_interval_s > 0) || !(poll_interval_s <= 60)) {
    throw Error("usb hotplug options: poll_interval_s must be in (0, 60] seconds");
  }
}

bool UsbHotplugMonitor::Supported() { return libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) != 0; }

UsbHotplugMonitor::UsbHotplugMonitor(Callback callback, UsbHotplugOptions options)
    : callback_(std::move(callback)), options_(options) {
  options_.Validate();
}

UsbHotplugMonitor::~UsbHotplugMonitor() { Stop(); }

bool UsbHotplugMonitor::Start() {
  std::lock_guard<std::mutex> lock(control_mutex_);
  if (running_ && !stop_) return true;
  Shutdown();  // a monitor stopped from inside a callback earlier is finished first
  if (!Supported()) return false;
  auto state = std::make_unique<State>();
  if (const int ret = libusb_init(&state->ctx); ret != 0) {
    throw DeviceError("libusb hotplug: cannot initialise (" + usb_internal::LibusbErrorText(ret) +
                      ")");
  }
  const int flags = options_.enumerate_existing ? LIBUSB_HOTPLUG_ENUMERATE : 0;
  const int ret = libusb_hotplug_register_callback(
      state->ctx,
      static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED |
                                        LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
      static_cast<libusb_hotplug_flag>(flags), options_.vendor_id, options_.product_id,
      LIBUSB_HOTPLUG_MATCH_ANY, OnHotplug, state.get(), &state->handle);
  if (ret != LIBUSB_SUCCESS) {
    state->DropPending();
    libusb_exit(state->ctx);
    if (ret == LIBUSB_ERROR_NOT_SUPPORTED) return false;
    throw DeviceError("libusb hotplug: cannot register a callback (" +
                      usb_internal::LibusbErrorText(ret) + ")");
  }
  state->registered = true;
  state_ = std::move(state);
  stop_ = false;
  running_ = true;
  thread_ = std::thread([this] { Run(); });
  return true;
}

void UsbHotplugMonitor::Run() {
  const double poll = options_.poll_interval_s;
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(std::floor(poll));
  tv.tv_usec = static_cast<suseconds_t>(std::lround((poll - std::floor(poll)) * 1e6));
  while (!stop_) {
    timeval t = tv;
    libusb_handle_events_timeout_completed(state_->ctx, &t, nullptr);
    std::vector<State::Pending> batch;
    {
      std::lock_guard<std::mutex> lock(state_->mutex);
      batch.swap(state_->pending);
    }
    for (State::Pending& p : batch) {
      if (!stop_) {
        if (p.device != nullptr && options_.read_strings_on_arrival) {
          usb_internal::ReadStrings(p.device, &p.info);
        }
        if (callback_) callback_(p.event, p.info);
        ++delivered_;
      }
      if (p.device != nullptr) libusb_unref_device(p.device);
    }
  }
  running_ = false;
}

void UsbHotplugMonitor::InjectEventForTesting(UsbHotplugEvent event, const UsbDeviceInfo& info) {
  std::lock_guard<std::mutex> lock(control_mutex_);
  if (!state_ || !running_) return;
  {
    std::lock_guard<std::mutex> pending_lock(state_->mutex);
    state_->pending.push_back({event, info, nullptr});
  }
  libusb_interrupt_event_handler(state_->ctx);
}

void UsbHotplugMonitor::Stop() {
  if (thread_.joinable() && std::this_thread::get_id() == thread_.get_id()) {
    stop_ = true;  // inside a callback: the thread ends after it returns
    return;
  }
  std::lock_guard<std::mutex> lock(control_mutex_);
  Shutdown();
}

void UsbHotplugMonitor::Shutdown() {
  stop_ = true;
  if (state_) libusb_interrupt_event_handler(state_->ctx);
  if (thread_.joinable()) thread_.join();
  running_ = false;
  if (state_) {
    if (state_->registered) libusb_hotplug_deregister_callback(state_->ctx, state_->handle);
    state_->DropPending();
    libusb_exit(state_->ctx);
    state_.reset();
  }
}

}  // namespace rouen
