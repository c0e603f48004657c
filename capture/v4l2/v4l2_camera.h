// The V4L2 (UVC webcam) camera driver behind rouen's Camera interface, and device listing
// for `rouen devices`. All system calls go through a V4l2Io (v4l2_io.h), so the driver runs
// against FakeV4l2Device (fake_v4l2.h) in tests.
//
// Conventions:
//  - Exposure: V4L2_CID_EXPOSURE_ABSOLUTE in 100 us units, manual mode
//    (V4L2_CID_EXPOSURE_AUTO = V4L2_EXPOSURE_MANUAL, V4L2_CID_EXPOSURE_AUTO_PRIORITY = 0 and
//    V4L2_CID_AUTO_WHITE_BALANCE = 0 when the camera has them). The applied value is read
//    back from the device (cameras cap it by the frame interval silently).
//  - Gain: UVC gain has no unit; the control range [min, max] is mapped linearly onto
//    linear gain [1, gain_at_max]: gain = 1 + (raw - min) / (max - min) * (gain_at_max - 1).
//    The response calibration absorbs an error in gain_at_max only if gain stays fixed.
//  - Images: 3 channels, PixelUnits::kDigital on 0..255 (not rounded). YUYV is decoded with
//    the matrix and range the format reports (V4L2 defaults: BT.601, limited range
//    Y' 16..235, Cb/Cr 16..240); GREY is replicated; Bayer (SBGGR8/SGBRG8/SGRBG8/SRGGB8) is
//    demosaiced bilinearly; MJPEG is decoded by libjpeg-turbo (JFIF: BT.601 full range).
//  - Time: the buffer timestamp (CLOCK_MONOTONIC, start of frame for uvcvideo) plus half the
//    exposure (minus it for end-of-frame stamps), converted to UTC with the current
//    CLOCK_REALTIME - CLOCK_MONOTONIC offset.
//  - Freshness and control latency: Grab() returns a frame that started after Grab() was
//    called and, after an exposure/gain change, only after `control_latency_frames` frames
//    that started after the change have been discarded (UVC reports no per-frame exposure).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "capture/device.h"
#include "capture/v4l2/v4l2_io.h"

namespace rouen {

struct V4l2Options {
  std::string device = "/dev/video0";
  int width = 0, height = 0;  // 0 x 0 = the largest the format offers
  // "YUYV", "MJPG" (or "MJPEG"), "GREY", "SGRBG8" (also SBGGR8, SGBRG8, SRGGB8, or their
  // fourccs "GRBG", "BA81", "GBRG", "RGGB"); empty = best: raw Bayer > YUYV > GREY > MJPEG.
  std::string pixel_format;
  int buffers = 4;                 // mmap streaming buffers requested (2..32)
  int control_latency_frames = 2;  // frames discarded after an exposure/gain change (0..64)
  double timeout_s = 2.0;          // longest wait for one frame beyond its exposure, seconds
  double gain_at_max = 16.0;       // linear gain at the gain control's maximum (>= 1)
  // Throws rouen::Error explaining the first invalid field.
  void Validate() const;
};

struct V4l2FormatInfo {
  std::string fourcc;       // "YUYV", "MJPG", "GRBG", ...
  std::string description;  // the driver's
  bool compressed = false;
  bool supported = false;  // this driver can decode it
  // Discrete sizes; a stepwise/continuous range is given as its smallest and largest size.
  std::vector<std::pair<int, int>> sizes;
};

struct V4l2DeviceInfo {
  std::string path, driver, card, bus_info;
  bool can_capture = false;  // video capture with streaming I/O
  std::vector<V4l2FormatInfo> formats;
  std::string error;  // why the node could not be queried ("" when it could)
};

// One open, streaming camera. Not thread-safe: call it from one thread.
class V4l2Camera : public Camera {
 public:
  // Opens the device, sets the format and manual controls and starts streaming.
  // Throws rouen::Error for invalid options, DeviceError naming the device otherwise.
  V4l2Camera(const V4l2Options& options, std::shared_ptr<V4l2Io> io);
  ~V4l2Camera() override;
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  std::string Id() const override { return options_.device; }
  // "exposure_s" (seconds) and "gain" (linear) with their ranges and current values.
  std::vector<ControlInfo> Controls() const override;
  // Clamped to the control range and rounded to its step; returns the applied seconds.
  double SetExposure(double seconds) override;
  // Clamped and quantised through the documented mapping; 1 without a gain control.
  double SetGain(double gain) override;
  void SetNdFilter(double density) override;
  double NdFilter() const override { return nd_; }
  int ViewCount(Target) const override { return 1; }
  void Aim(Target, int) override {}
  // Throws DeviceError on a timeout, a vanished device or persistent corrupt frames.
  CapturedFrame Grab() override;

  // The next frame in stream order that started after the last control change, without
  // waiting for control latency or freshness; *frames_since_change is 0 for the first frame
  // after the change, 1 for the next, ... (dropped frames counted by sequence number).
  CapturedFrame GrabNext(int* frames_since_change);

  const std::string& card() const { return card_; }
  std::string pixel_format() const;  // fourcc in use
  int width() const { return width_; }
  int height() const { return height_; }
  int buffer_count() const { return static_cast<int>(buffers_.size()); }
  int control_latency_frames() const { return latency_; }
  void set_control_latency_frames(int frames) { latency_ = frames < 0 ? 0 : frames; }
  uint32_t last_sequence() const { return last_sequence_; }  // of the last frame returned

 private:
  struct Buffer {
    void* data = nullptr;
    size_t length = 0;
  };
  struct Dequeued {
    int index = -1;
    uint32_t sequence = 0, flags = 0, bytesused = 0;
    int64_t timestamp_ns = 0;  // CLOCK_MONOTONIC
  };
  [[noreturn]] void Fail(const std::string& what, int err) const;
  int Xioctl(unsigned long request, void* arg);
  void Setup();
  void Cleanup() noexcept;
  void MarkChange();
  Dequeued WaitAndDequeue();
  void Requeue(int index);
  CapturedFrame GrabImpl(int64_t not_before_ns, int min_frames_since_change, int* index_out);

  V4l2Options options_;
  std::shared_ptr<V4l2Io> io_;
  int fd_ = -1;
  bool streaming_ = false, gone_ = false;
  std::string card_, driver_;
  uint32_t fourcc_ = 0;
  int width_ = 0, height_ = 0;
  size_t bytes_per_line_ = 0, size_image_ = 0;
  uint32_t colorspace_ = 0, ycbcr_enc_ = 0, quantization_ = 0;
  std::vector<Buffer> buffers_;
  bool allocated_ = false;
  // Controls (raw device units).
  bool has_gain_ = false;
  int exp_min_ = 0, exp_max_ = 0, exp_step_ = 1, exp_raw_ = 0;
  int gain_min_ = 0, gain_max_ = 0, gain_step_ = 1, gain_raw_ = 0;
  double nd_ = 0;
  int latency_ = 0;
  // Control-change bookkeeping (CLOCK_MONOTONIC ns, microsecond-floored).
  int64_t change_ns_ = 0;
  bool have_first_after_change_ = false;
  uint32_t first_after_change_ = 0;
  int frames_since_change_ = 0;
  uint32_t last_sequence_ = 0;
};

// Opens a camera through `io` (the real system calls in the first overload).
std::unique_ptr<V4l2Camera> OpenV4l2Camera(const V4l2Options& options);
std::unique_ptr<V4l2Camera> OpenV4l2Camera(const V4l2Options& options, std::shared_ptr<V4l2Io> io);

// Measures the camera's control latency by a brightness step: settles at a low exposure
// (mean level aimed at 8..70 DN), steps the exposure up by 8x (less at the top of the range),
// and counts the frames after the change until the mean brightness has reached its new
// level (within 3% or 1.5 DN of the final frames). Returns the frames to discard (store it
// as the rig's control_latency_frames). Restores exposure and the camera's latency setting.
// Throws DeviceError when the step does not show within `max_frames` frames or does not
// change the brightness (lens capped, saturated scene).
int MeasureControlLatency(V4l2Camera& camera, int max_frames = 12);

// Every /dev/video* node `io` lists, with what it is; a node that cannot be opened or
// queried is listed with `error` set (never throws for a single node).
std::vector<V4l2DeviceInfo> ListV4l2Devices(V4l2Io& io);

}  // namespace rouen
