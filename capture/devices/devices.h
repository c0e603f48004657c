// Opens the devices a rig names (simulated, replay, or field drivers) and lists what is
// connected. This is the one place that knows every driver of the build.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "capture/controller.h"
#include "capture/operator_camera.h"
#include "capture/rig.h"
#include "core/mesh.h"

namespace rouen {

// Drivers compiled into this build ("v4l2", "nmea", "aravis", "libcamera", "usb", "gpsd",
// "gphoto2").
std::vector<std::string> BuiltDrivers();

class V4l2Io;

struct OpenRigOptions {
  std::filesystem::path from_session;  // replay rigs: the recorded session
  OperatorPrompt prompt;               // field rigs: asks the operator to aim / fit the ND
  // uvc-webcam rigs: the system calls to use (tests pass a fake V4L2 device); null = the
  // kernel's. Called again for every reopen after the camera was lost.
  std::function<std::shared_ptr<V4l2Io>()> v4l2_io;
};

struct RigDevices {
  std::shared_ptr<void> keep_alive;  // shared state the devices use (world, session)
  std::unique_ptr<Camera> camera;
  std::unique_ptr<Gps> gps;
  std::unique_ptr<Clock> clock;
  CapturePlan plan;  // possibly adjusted (replay: the recorded slots; field: one slot, now)
  std::optional<Mesh> model;  // the building model, when the rig knows it (sim)
  // Reopens a lost camera (field rigs), for CaptureDevices::reopen_camera.
  std::function<Camera*()> reopen_camera;
  std::vector<std::string> notes;  // what the driver adjusted or assumed, for the operator
  CaptureDevices Devices() const { return {camera.get(), gps.get(), clock.get(), reopen_camera}; }
};

// Throws rouen::Error naming the rig file when a device cannot be opened or the build lacks
// the rig's driver.
RigDevices OpenRig(const RigConfig& rig, const OpenRigOptions& options = {});

// What is connected, per driver, for `rouen devices`: {"drivers": [...], "cameras": [...],
// "gps": [...], "usb": [...], "errors": [...]}. Never throws for a driver that fails: the
// failure is listed under "errors".
nlohmann::json ListDevices();

// Reports USB devices plugged in or pulled out while it lives ("USB left: 046d:082d UVC camera
// ..."), so a field capture notices an unplug as it happens. Null when the build has no libusb
// or the platform no hotplug. Callbacks come from another thread.
std::shared_ptr<void> WatchUsb(std::function<void(const std::string&)> on_event);

// Frames a V4L2 camera needs before an exposure change shows (the brightness-step test), for
// the rig's [camera] control_latency_frames. Throws when the device cannot be opened or the
// build has no V4L2 driver.
int MeasureV4l2Latency(const std::string& device);

}  // namespace rouen
