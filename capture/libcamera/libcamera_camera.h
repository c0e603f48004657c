// A rouen Camera over libcamera (Raspberry Pi and other CSI cameras, UVC through libcamera's
// uvcvideo pipeline). Manual exposure and analogue gain are sent with every request; what a
// frame really had is read back from its metadata, and that is what Grab() returns.
//
// State machine (libcamera's): the constructor starts the shared CameraManager, finds and
// acquires the camera, generates, validates (reporting adjustments) and configures one
// stream, and allocates buffers; the first Grab() starts streaming with `request_count`
// requests in flight; the destructor stops, frees and releases.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "capture/device.h"

namespace rouen {

struct LibcameraOptions {
  std::string camera_id;  // libcamera camera id; empty = the first camera
  enum class Role { kStillCapture, kRaw };
  Role role = Role::kStillCapture;
  // libcamera pixel format name ("BGR888", "YUYV", "NV12", "SRGGB10", "SBGGR12_CSI2P", ...);
  // empty = the stream's default when rouen can convert it, else a supported offer.
  std::string pixel_format;
  int width = 0, height = 0;  // 0 = the stream's default size
  // Requests kept in flight (and buffers allocated); controls take a few frames to land.
  int request_count = 4;
  // Fresh frames examined per grab before returning the latest with whatever was applied.
  int max_frames_per_grab = 12;
  // Match tolerances for "the metadata shows the requested setting" (sensor quantisation).
  double exposure_rel_tol = 0.02;
  double exposure_abs_tol_s = 100e-6;
  double gain_rel_tol = 0.05;
  // Cameras whose metadata lacks exposure and gain: fresh frames to wait before trusting
  // that the controls landed.
  int settle_frames_without_metadata = 6;
  // Failed/cancelled requests in a row before a grab fails.
  int max_consecutive_failures = 8;
  // Grab timeout: this many seconds plus (max_frames_per_grab + request_count + 2) times
  // (exposure + 0.1 s).
  double grab_timeout_s = 5.0;
  // The clock of SensorTimestamp: V4L2 timestamps (libcamera 0.0.3) are CLOCK_MONOTONIC;
  // the two differ only by time spent suspended.
  enum class SensorClock { kMonotonic, kBoottime };
  SensorClock sensor_clock = SensorClock::kMonotonic;
  // Throws rouen::Error explaining what is wrong.
  void Validate() const;
};

struct LibcameraCameraInfo {
  std::string id;
  std::string model;  // properties::Model, empty when not reported
  // Every camera property as name and printed value ("Location", "2"), sorted by name.
  std::vector<std::pair<std::string, std::string>> properties;
  // Manual exposure support: "manual via AeEnable; exposure 14 us..2 s; gain 1..16".
  std::string exposure_controls;
  // Pixel formats the still-capture and raw streams offer, each with its size range and
  // whether rouen converts it: "NV12 64x64-4056x3040", "MJPEG 640x480-1920x1080 (unsupported)".
  std::vector<std::string> still_formats, raw_formats;
};

// The cameras the libcamera CameraManager reports (possibly none). Throws DeviceError when
// the manager cannot start.
std::vector<LibcameraCameraInfo> ListLibcameraCameras();

// The pixel formats rouen can convert from a libcamera stream.
std::vector<std::string> LibcameraSupportedFormats();

// What the last Grab() did, for the journal and the operator.
struct LibcameraGrabReport {
  double wanted_exposure_s = 0, wanted_gain = 1;
  double requested_exposure_s = 0, requested_gain = 1;    // carried by the returned request
  double applied_exposure_s = 0, applied_gain = 1;        // from metadata (or requested)
  bool exposure_reported = false, gain_reported = false;  // metadata had the value
  bool matched = false;           // applied matches wanted; false = fallback after the bound
  int frames_examined = 0;        // fresh frames looked at, including the returned one
  uint32_t sequence = 0;          // libcamera request sequence number
  bool sensor_timestamp = false;  // the UTC time came from SensorTimestamp
  std::string reason;
};

class LibcameraCamera : public Camera {
 public:
  // Throws DeviceError naming the camera (or saying there is none) on any failure.
  explicit LibcameraCamera(const LibcameraOptions& options = {});
  ~LibcameraCamera() override;
  LibcameraCamera(const LibcameraCamera&) = delete;
  LibcameraCamera& operator=(const LibcameraCamera&) = delete;

  std::string Id() const override;
  std::vector<ControlInfo> Controls() const override;
  // Clamped to the camera's ExposureTime range and quantised to whole µs; the sensor
  // quantises further (to lines), which the frame's metadata shows.
  double SetExposure(double seconds) override;
  // Clamped to the camera's AnalogueGain range.
  double SetGain(double gain) override;
  void SetNdFilter(double density) override;
  double NdFilter() const override;
  int ViewCount(Target) const override { return 1; }
  void Aim(Target, int) override {}
  // Returns the first fresh frame whose metadata matches the set exposure and gain, or after
  // max_frames_per_grab frames the latest one; exposure_s/gain are what was applied.
  // Throws DeviceError (timeout, disconnect, failed requests, unconvertible frame).
  CapturedFrame Grab() override;

  // What validate() adjusted in the requested configuration, and what the camera cannot do
  // (no manual exposure switch, ...), in words for the operator. Empty when all was taken.
  const std::vector<std::string>& Adjustments() const;
  // The configured stream, e.g. "NV12 1920x1080 stride 1920 buffers 4".
  std::string Configuration() const;
  const LibcameraGrabReport& LastGrab() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace rouen
