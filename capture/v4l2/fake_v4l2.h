// A fake V4L2 camera (one or more /dev/videoN nodes) behind the V4l2Io seam, strict enough
// to catch driver bugs: it implements QUERYCAP, ENUM_FMT, G/S/TRY_FMT, ENUM_FRAMESIZES,
// QUERYCTRL (with V4L2_CTRL_FLAG_NEXT_CTRL), QUERYMENU, G/S_CTRL, REQBUFS, QUERYBUF, mmap,
// QBUF, DQBUF, STREAMON, STREAMOFF and poll the way uvcvideo + videobuf2 do, failing with
// their errno values (ENOTTY for unknown ioctls, EINVAL for unknown controls and bad
// arguments, EAGAIN, EBUSY, EACCES for an exposure time while auto exposure is on, ENODEV
// once unplugged). Calls that only a buggy driver makes are also recorded in Misuse().
//
// The scene is a grid of 16x16-pixel flat colour patches; a pixel's value is
//   round(clamp(reflectance * scene_dn_per_s * exposure_s * gain, 0, 255))
// per colour, with gain = 1 + (raw - min) / (max - min) * (gain_at_max - 1) and
// exposure_s = raw * 100 us. A control change made when P frames have been produced shows
// from frame P + control_latency_frames on. While auto exposure is on the fake exposes for
// a mean of about 118; while auto white balance is on it scales R and B to the grey world.
// Encodings: YUYV BT.601 (limited range unless yuyv_quantization is FULL_RANGE; Cb/Cr from
// the mean of each pixel pair), MJPEG JFIF 4:2:2 without Huffman tables, GREY
// round(0.299 R + 0.587 G + 0.114 B), 8-bit Bayer sampled from the RGB truth. Buffers carry
// CLOCK_MONOTONIC start-of-frame stamps (microseconds); producing a frame returns only once
// the clock has left the frame's microsecond, so stamps order with the caller's clock reads. Frames
// are produced synchronously inside the calls (no threads, no sleeping); poll() with nothing to
// report returns 0 at once as if its timeout had passed. Not thread-safe.
#pragma once

#include <linux/videodev2.h>

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "capture/v4l2/v4l2_io.h"

namespace rouen {

struct FakeV4l2Options {
  std::string path = "/dev/video0";
  std::string driver = "uvcvideo", card = "Fake UVC Camera", bus_info = "usb-fake-1";
  // A node without video capture is a UVC metadata node (V4L2_CAP_META_CAPTURE).
  bool video_capture = true;
  bool streaming = true;
  std::vector<uint32_t> pixel_formats = {V4L2_PIX_FMT_SGRBG8, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_GREY,
                                         V4L2_PIX_FMT_MJPEG};
  std::vector<std::pair<int, int>> frame_sizes = {{160, 120}, {64, 48}};  // discrete
  // Instead: a stepwise range (V4L2_FRMSIZE_TYPE_STEPWISE), as sensors behind non-UVC
  // drivers offer; frame_sizes[0] is then only the initial size.
  bool stepwise_sizes = false;
  int min_width = 32, min_height = 24, max_width = 192, max_height = 144;
  int step_width = 16, step_height = 8;
  int bytesperline_padding = 0;  // extra bytes at the end of each row (uncompressed formats)
  uint32_t yuyv_quantization = V4L2_QUANTIZATION_DEFAULT;  // DEFAULT = limited range
  int max_buffers = 8;                                     // REQBUFS grants at most this many
  int jpeg_quality = 95;
  bool mjpeg_omit_huffman_tables = true;

  // Controls, in UVC units (exposure: 100 us).
  int exposure_min = 3, exposure_max = 2047, exposure_step = 1, exposure_default = 156;
  int exposure_cap = 0;  // > 0: the device silently limits exposure to this (frame interval)
  bool has_exposure_auto_priority = true, has_auto_white_balance = true, has_gain = true;
  int gain_min = 0, gain_max = 255, gain_step = 1, gain_default = 0;
  double gain_at_max = 16;        // linear gain at gain_max (gain_min is 1)
  double scene_dn_per_s = 20000;  // DN per second of exposure at unit gain and reflectance
  int control_latency_frames = 3;
  // A new exposure reaches its value linearly over this many frames once its latency has
  // passed (1 = at once), like cameras whose auto-exposure loop smooths manual changes.
  int exposure_ramp_frames = 1;

  // When frames are produced: kOnQueue -- a queued buffer is filled at once while streaming
  // (a camera faster than its reader: done buffers wait with old frames); kOnPoll -- one
  // frame per poll() or DQBUF that finds none ready (a camera exactly as fast as the reader).
  enum class Fill { kOnQueue, kOnPoll };
  Fill fill = Fill::kOnQueue;
  int vanish_after_frames = -1;     // >= 0: unplugged when frame K+1 would be produced
  int stall_after_frames = -1;      // >= 0: no frame after K (poll() times out)
  std::vector<int> error_frames;    // frame indices delivered with V4L2_BUF_FLAG_ERROR
  std::vector<int> corrupt_frames;  // frame indices whose data is truncated garbage
  // Frame indices the camera exposes but drops (the sequence number skips them), as when
  // the USB bandwidth runs short.
  std::vector<int> dropped_frames;
  int eintr_every = 0;  // > 0: every n-th ioctl or poll fails with EINTR (a signal arrived)
};

// The truth of one produced frame (kept for the last 64 frames).
struct FakeV4l2Frame {
  uint32_t sequence = 0;
  int width = 0, height = 0;
  uint32_t pixel_format = 0;
  int exposure_raw = 0, gain_raw = 0;  // effective on the sensor (exposure rounded)
  double exposure_s = 0, gain = 1;     // exposure_s is exact while ramping
  bool auto_exposure = false, auto_white_balance = false;
  int64_t timestamp_ns = 0;  // CLOCK_MONOTONIC, start of frame
  // What a perfect decoder returns: 8-bit RGB, interleaved (GREY: the grey level x3).
  std::vector<uint8_t> rgb;
  double MeanRgb() const;
};

class FakeV4l2Device : public V4l2Io {
 public:
  explicit FakeV4l2Device(FakeV4l2Options options = {});
  // Several nodes, e.g. a capture node and its UVC metadata node. Paths must differ.
  explicit FakeV4l2Device(std::vector<FakeV4l2Options> nodes);
  ~FakeV4l2Device() override;

  int Open(const std::string& path, int flags) override;
  int Close(int fd) override;
  int Ioctl(int fd, unsigned long request, void* arg) override;
  void* Mmap(size_t length, int prot, int flags, int fd, off_t offset) override;
  int Munmap(void* addr, size_t length) override;
  int Poll(int fd, short events, short* revents, int timeout_ms) override;
  std::vector<std::string> ListDevices() override;

  // Unplugs a node now (every later call on it fails with ENODEV; poll gives POLLERR).
  void Unplug(const std::string& path);

  // Inspection for tests (node = the first one unless a path is given).
  int OpenFds() const;
  int Mappings() const;
  int AllocatedBuffers(const std::string& path = "") const;
  bool Streaming(const std::string& path = "") const;
  int FramesProduced(const std::string& path = "") const;
  // The control's current value as the device reports it (G_CTRL), or nothing.
  std::optional<int> Control(uint32_t id, const std::string& path = "") const;
  int ControlWrites(uint32_t id, const std::string& path = "") const;
  std::optional<FakeV4l2Frame> Frame(uint32_t sequence, const std::string& path = "") const;
  // The linear gain the fake applies for a raw gain value.
  double GainForRaw(int raw, const std::string& path = "") const;
  // Calls a correct driver never makes (a bad buffer index, DQBUF before STREAMON, mmap of
  // an unknown offset, a control write to an inactive control, use of a closed fd, ...).
  const std::vector<std::string>& Misuse() const { return misuse_; }

 private:
  struct Node;
  struct OpenFile {
    Node* node;
    bool nonblocking;
  };
  struct Mapping {
    Node* node = nullptr;
    int count = 0;  // live mappings of this address
    size_t length = 0;
  };
  Node* FindNode(const std::string& path) const;
  bool Interrupted(Node& n);
  int Fail(int err);
  int Misused(int err, const std::string& what);
  int DoIoctl(int fd, OpenFile& f, unsigned long request, void* arg);

  std::vector<std::unique_ptr<Node>> nodes_;
  std::map<int, OpenFile> files_;
  std::map<void*, Mapping> mappings_;
  int next_fd_ = 1000;
  std::vector<std::string> misuse_;
};

}  // namespace rouen
