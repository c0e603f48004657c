// Device interfaces the capture controller drives. Drivers (sim, replay, and later v4l2,
// libcamera, aravis, gps) implement them; nothing downstream knows which one made a frame.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/error.h"
#include "core/image.h"
#include "core/session.h"
#include "core/time.h"

namespace rouen {

// A device failure the capture loop can recover from or report (unplugged, timeout, corrupt
// frame). The message names the device.
class DeviceError : public Error {
 public:
  using Error::Error;
};

struct ControlInfo {
  std::string name;  // "exposure_s", "gain", ...
  double min = 0, max = 0, value = 0;
};

struct CapturedFrame {
  Image image;  // kDigital (8-bit LDR) or kRadiance (HDR camera)
  bool hdr = false;
  double exposure_s = 0;  // as applied by the device
  double gain = 1;
  double nd_density = 0;
  UtcTime utc;  // mid-exposure
  std::optional<Intrinsics> intrinsics;
  std::optional<Pose> pose;  // when the device knows it (sim, replay, calibrated mount)
};

// What a camera says of itself between frames; a camera that does not report a field leaves
// it empty.
struct CameraStatus {
  std::optional<double> battery_percent;  // 0..100
  std::optional<int64_t> free_bytes;      // on the card it writes to
  std::optional<int64_t> free_images;     // as the camera estimates them
  std::optional<UtcTime> clock;           // its own clock (to the second), read as UTC
};

class Camera {
 public:
  virtual ~Camera() = default;
  virtual std::string Id() const = 0;
  virtual std::vector<ControlInfo> Controls() const = 0;
  // Set a control; the value actually applied (clamped to range, quantised) is returned.
  virtual double SetExposure(double seconds) = 0;
  virtual double SetGain(double gain) = 0;
  // The ND filter in front of the lens (optical density, 0 = none). Real rigs: the operator
  // fits it when prompted; simulated rigs apply it.
  virtual void SetNdFilter(double density) = 0;
  virtual double NdFilter() const = 0;
  // Points the camera at view `view` of a target (simulated/replay mounts; real rigs prompt
  // the operator). ViewCount says how many views the device has for the target.
  virtual int ViewCount(Target target) const = 0;
  virtual void Aim(Target target, int view) = 0;
  // Grabs one frame with the current settings. Throws DeviceError.
  virtual CapturedFrame Grab() = 0;
  // Battery, card and clock as the camera reports them (DSLRs over PTP); nothing by default.
  // Throws DeviceError.
  virtual CameraStatus Status() { return {}; }
};

class Gps {
 public:
  virtual ~Gps() = default;
  virtual std::string Id() const = 0;
  // Latest fix, or nothing when there is none yet. Throws DeviceError on device failure.
  virtual std::optional<GpsFix> Poll() = 0;
};

// Where frame times come from. The real clock is the laptop's; a simulated clock can jump to
// the start of a planned time-of-day slot.
class Clock {
 public:
  virtual ~Clock() = default;
  virtual UtcTime Now() = 0;
  // Simulated clocks jump to `t`; the real clock cannot and returns false.
  virtual bool JumpTo(UtcTime t) = 0;
  // True for the laptop's clock, whose frame times are corrected by the offset to GPS time;
  // simulated and replayed times are already on the GPS time scale.
  virtual bool IsLaptopClock() const { return false; }
};

}  // namespace rouen
