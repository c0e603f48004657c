#include "capture/v4l2/v4l2_camera.h"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/mman.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>

#include "capture/v4l2/jpeg_codec.h"
#include "capture/v4l2/pixel_format.h"

namespace rouen {

using v4l2_internal::BayerToRgb;
using v4l2_internal::BytesPerPixel;
using v4l2_internal::DecodeJpeg;
using v4l2_internal::FormatPreference;
using v4l2_internal::FourccFromString;
using v4l2_internal::FourccToString;
using v4l2_internal::GreyToRgb;
using v4l2_internal::JpegAvailable;
using v4l2_internal::YcbcrFromFormat;
using v4l2_internal::YuyvToRgb;

namespace {

constexpr double kExposureUnit = 1e-4;  // seconds per V4L2_CID_EXPOSURE_ABSOLUTE step

int64_t ClockNs(clockid_t clock) {
  timespec ts;
  clock_gettime(clock, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

int64_t FloorUs(int64_t ns) { return ns / 1000 * 1000; }

// CLOCK_REALTIME - CLOCK_MONOTONIC, sampling the monotonic clock on both sides.
int64_t RealtimeMinusMonotonicNs() {
  const int64_t m0 = ClockNs(CLOCK_MONOTONIC);
  const int64_t r = ClockNs(CLOCK_REALTIME);
  const int64_t m1 = ClockNs(CLOCK_MONOTONIC);
  return r - (m0 + (m1 - m0) / 2);
}

std::string ErrnoName(int err) {
  switch (err) {
    case ENODEV:
      return "ENODEV";
    case ENOENT:
      return "ENOENT";
    case EBUSY:
      return "EBUSY";
    case EINVAL:
      return "EINVAL";
    case EACCES:
      return "EACCES";
    case EPERM:
      return "EPERM";
    case ENOTTY:
      return "ENOTTY";
    case EAGAIN:
      return "EAGAIN";
    case EIO:
      return "EIO";
    case ENOMEM:
      return "ENOMEM";
    default:
      return "errno " + std::to_string(err);
  }
}

std::string ErrText(int err) {
  return std::string(std::strerror(err)) + " (" + ErrnoName(err) + ")";
}

uint32_t ParsePixelFormat(const std::string& name) {
  if (name == "MJPEG") return V4L2_PIX_FMT_MJPEG;
  if (name == "SBGGR8") return V4L2_PIX_FMT_SBGGR8;
  if (name == "SGBRG8") return V4L2_PIX_FMT_SGBRG8;
  if (name == "SGRBG8") return V4L2_PIX_FMT_SGRBG8;
  if (name == "SRGGB8") return V4L2_PIX_FMT_SRGGB8;
  return FourccFromString(name);
}

bool Decodable(uint32_t fourcc) {
  if (fourcc == V4L2_PIX_FMT_MJPEG) return JpegAvailable();
  return FormatPreference(fourcc) >= 0;
}

int IoctlRetry(V4l2Io& io, int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = io.Ioctl(fd, request, arg);
  } while (r < 0 && errno == EINTR);
  return r;
}

// Snaps `v` onto min + k * step within [min, max].
int Snap(double v, int min, int max, int step) {
  if (step < 1) step = 1;
  const double k =
      std::round((std::clamp(v, static_cast<double>(min), static_cast<double>(max)) - min) / step);
  int r = min + static_cast<int>(k) * step;
  if (r > max) r -= step;
  return std::max(r, min);
}

}  // namespace

void V4l2Options::Validate() const {
  if (device.empty()) throw Error("v4l2: device path is empty (e.g. /dev/video0)");
  if (width < 0 || height < 0 || (width == 0) != (height == 0)) {
    throw Error("v4l2 " + device + ": width and height must both be 0 (largest) or both > 0, not " +
                std::to_string(width) + "x" + std::to_string(height));
  }
  if (!pixel_format.empty() && ParsePixelFormat(pixel_format) == 0) {
    throw Error("v4l2 " + device + ": pixel format \"" + pixel_format +
                "\" is not a fourcc (YUYV, MJPG, GREY, SGRBG8, ...)");
  }
  if (buffers < 2 || buffers > 32) {
    throw Error("v4l2 " + device + ": buffers must be 2..32, not " + std::to_string(buffers));
  }
  if (control_latency_frames < 0 || control_latency_frames > 64) {
    throw Error("v4l2 " + device + ": control_latency_frames must be 0..64, not " +
                std::to_string(control_latency_frames));
  }
  if (!(timeout_s > 0) || !std::isfinite(timeout_s) || timeout_s > 3600) {
    throw Error("v4l2 " + device + ": timeout_s must be in (0, 3600] s");
  }
  if (!(gain_at_max >= 1) || !std::isfinite(gain_at_max)) {
    throw Error("v4l2 " + device + ": gain_at_max must be a finite linear gain >= 1");
  }
}

V4l2Camera::V4l2Camera(const V4l2Options& options, std::shared_ptr<V4l2Io> io)
    : options_(options), io_(std::move(io)), latency_(options.control_latency_frames) {
  options_.Validate();
  try {
    Setup();
  } catch (...) {
    Cleanup();
    throw;
  }
}

V4l2Camera::~V4l2Camera() { Cleanup(); }

void V4l2Camera::Fail(const std::string& what, int err) const {
  if (err == ENODEV) {
    throw DeviceError(options_.device + ": device vanished" +
                      (streaming_ ? " during streaming" : "") + " (ENODEV)");
  }
  throw DeviceError(options_.device + ": " + what + ": " + ErrText(err));
}

int V4l2Camera::Xioctl(unsigned long request, void* arg) {
  const int r = IoctlRetry(*io_, fd_, request, arg);
  if (r < 0 && errno == ENODEV) gone_ = true;
  return r;
}

void V4l2Camera::Setup() {
  const std::string& dev = options_.device;
  fd_ = io_->Open(dev, O_RDWR | O_NONBLOCK);
  if (fd_ < 0) {
    const int err = errno;
    std::string hint;
    if (err == ENOENT) hint = " (is the camera plugged in? `rouen devices` lists cameras)";
    if (err == EACCES) hint = " (is the user in the 'video' group?)";
    throw DeviceError(dev + ": cannot open: " + ErrText(err) + hint);
  }

  v4l2_capability cap{};
  if (Xioctl(VIDIOC_QUERYCAP, &cap) < 0) {
    const int err = errno;
    if (err == ENOTTY || err == EINVAL) {
      throw DeviceError(dev + ": not a V4L2 device (VIDIOC_QUERYCAP: " + ErrText(err) + ")");
    }
    Fail("VIDIOC_QUERYCAP", err);
  }
  card_ = reinterpret_cast<const char*>(cap.card);
  driver_ = reinterpret_cast<const char*>(cap.driver);
  const uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
  if (!(caps & V4L2_CAP_VIDEO_CAPTURE) || !(caps & V4L2_CAP_STREAMING)) {
    std::ostringstream os;
    os << dev << " (" << card_ << ", " << driver_ << ") is not a video capture device with "
       << "streaming I/O (capabilities 0x" << std::hex << caps << std::dec
       << ((caps & V4L2_CAP_META_CAPTURE) ? ": a metadata node; the camera is usually the "
                                            "node before it"
                                          : "")
       << ")";
    throw DeviceError(os.str());
  }

  // Formats.
  std::vector<uint32_t> formats;
  for (uint32_t i = 0;; ++i) {
    v4l2_fmtdesc d{};
    d.index = i;
    d.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (Xioctl(VIDIOC_ENUM_FMT, &d) < 0) {
      if (errno == EINVAL) break;
      Fail("VIDIOC_ENUM_FMT", errno);
    }
    formats.push_back(d.pixelformat);
  }
  std::string names;
  for (uint32_t f : formats) names += (names.empty() ? "" : ", ") + FourccToString(f);
  if (!options_.pixel_format.empty()) {
    fourcc_ = ParsePixelFormat(options_.pixel_format);
    if (std::find(formats.begin(), formats.end(), fourcc_) == formats.end()) {
      throw DeviceError(dev + ": pixel format " + options_.pixel_format +
                        " not offered (the camera has: " + names + ")");
    }
    if (!Decodable(fourcc_)) {
      throw DeviceError(dev + ": pixel format " + options_.pixel_format +
                        " cannot be decoded by this build (use YUYV, GREY, MJPG or 8-bit "
                        "Bayer)");
    }
  } else {
    int best = -1;
    for (uint32_t f : formats) {
      if (Decodable(f) && FormatPreference(f) > best) {
        best = FormatPreference(f);
        fourcc_ = f;
      }
    }
    if (best < 0) {
      throw DeviceError(dev + ": no pixel format this driver can decode (the camera has: " + names +
                        ")");
    }
  }

  // Frame size.
  std::vector<std::pair<int, int>> sizes;
  bool stepwise = false;
  v4l2_frmsizeenum range{};
  for (uint32_t i = 0;; ++i) {
    v4l2_frmsizeenum s{};
    s.index = i;
    s.pixel_format = fourcc_;
    if (Xioctl(VIDIOC_ENUM_FRAMESIZES, &s) < 0) {
      if (errno == EINVAL || errno == ENOTTY) break;
      Fail("VIDIOC_ENUM_FRAMESIZES", errno);
    }
    if (s.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
      sizes.emplace_back(s.discrete.width, s.discrete.height);
    } else {
      stepwise = true;
      range = s;
      break;
    }
  }
  int want_w = options_.width, want_h = options_.height;
  if (stepwise) {
    const auto& sw = range.stepwise;
    if (want_w == 0) {
      want_w = static_cast<int>(sw.max_width);
      want_h = static_cast<int>(sw.max_height);
    } else if (want_w < static_cast<int>(sw.min_width) || want_w > static_cast<int>(sw.max_width) ||
               want_h < static_cast<int>(sw.min_height) ||
               want_h > static_cast<int>(sw.max_height)) {
      throw DeviceError(dev + ": size " + std::to_string(want_w) + "x" + std::to_string(want_h) +
                        " outside the camera's range " + std::to_string(sw.min_width) + "x" +
                        std::to_string(sw.min_height) + " .. " + std::to_string(sw.max_width) +
                        "x" + std::to_string(sw.max_height));
    }
  } else if (!sizes.empty()) {
    if (want_w == 0) {
      auto largest = *std::max_element(sizes.begin(), sizes.end(), [](auto a, auto b) {
        return static_cast<int64_t>(a.first) * a.second < static_cast<int64_t>(b.first) * b.second;
      });
      want_w = largest.first;
      want_h = largest.second;
    } else if (std::find(sizes.begin(), sizes.end(), std::make_pair(want_w, want_h)) ==
               sizes.end()) {
      std::string list;
      for (auto s : sizes) {
        list +=
            (list.empty() ? "" : ", ") + std::to_string(s.first) + "x" + std::to_string(s.second);
      }
      throw DeviceError(dev + ": size " + std::to_string(want_w) + "x" + std::to_string(want_h) +
                        " not offered in " + FourccToString(fourcc_) + " (the camera has: " + list +
                        ")");
    }
  } else if (want_w == 0) {
    v4l2_format cur{};
    cur.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (Xioctl(VIDIOC_G_FMT, &cur) < 0) Fail("VIDIOC_G_FMT", errno);
    want_w = static_cast<int>(cur.fmt.pix.width);
    want_h = static_cast<int>(cur.fmt.pix.height);
  }

  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = static_cast<uint32_t>(want_w);
  fmt.fmt.pix.height = static_cast<uint32_t>(want_h);
  fmt.fmt.pix.pixelformat = fourcc_;
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (Xioctl(VIDIOC_S_FMT, &fmt) < 0) {
    if (errno == EBUSY) {
      throw DeviceError(dev + ": device busy (EBUSY): another program is using the camera");
    }
    Fail("VIDIOC_S_FMT", errno);
  }
  const v4l2_pix_format& p = fmt.fmt.pix;
  if (p.pixelformat != fourcc_ || static_cast<int>(p.width) != want_w ||
      static_cast<int>(p.height) != want_h) {
    throw DeviceError(dev + ": asked for " + FourccToString(fourcc_) + " " +
                      std::to_string(want_w) + "x" + std::to_string(want_h) + ", the driver set " +
                      FourccToString(p.pixelformat) + " " + std::to_string(p.width) + "x" +
                      std::to_string(p.height));
  }
  if (p.field != V4L2_FIELD_NONE && p.field != V4L2_FIELD_ANY) {
    throw DeviceError(dev + ": interlaced formats are not supported (field " +
                      std::to_string(p.field) + ")");
  }
  width_ = want_w;
  height_ = want_h;
  if ((fourcc_ == V4L2_PIX_FMT_YUYV && width_ % 2 != 0)) {
    throw DeviceError(dev + ": YUYV with an odd width (" + std::to_string(width_) + ")");
  }
  const size_t min_bpl = static_cast<size_t>(width_) * BytesPerPixel(fourcc_);
  bytes_per_line_ = std::max<size_t>(p.bytesperline, min_bpl);
  size_image_ = p.sizeimage;
  colorspace_ = p.colorspace;
  ycbcr_enc_ = p.ycbcr_enc;
  quantization_ = p.quantization;

  // Controls: manual exposure, fixed frame rate and white balance.
  const auto query = [&](uint32_t id, v4l2_queryctrl* q) {
    *q = {};
    q->id = id;
    if (Xioctl(VIDIOC_QUERYCTRL, q) < 0) {
      if (errno == EINVAL || errno == ENOTTY) return false;
      Fail("VIDIOC_QUERYCTRL", errno);
    }
    return !(q->flags & V4L2_CTRL_FLAG_DISABLED);
  };
  const auto set = [&](uint32_t id, int value, const char* name) {
    v4l2_control c{id, value};
    if (Xioctl(VIDIOC_S_CTRL, &c) < 0) Fail(std::string("cannot set ") + name, errno);
  };
  v4l2_queryctrl q{};
  if (query(V4L2_CID_EXPOSURE_AUTO, &q)) {
    v4l2_control c{V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL};
    if (Xioctl(VIDIOC_S_CTRL, &c) < 0) {
      Fail("cannot switch to manual exposure (V4L2_CID_EXPOSURE_AUTO)", errno);
    }
  }
  if (query(V4L2_CID_EXPOSURE_AUTO_PRIORITY, &q)) {
    set(V4L2_CID_EXPOSURE_AUTO_PRIORITY, 0, "V4L2_CID_EXPOSURE_AUTO_PRIORITY = 0");
  }
  if (query(V4L2_CID_AUTO_WHITE_BALANCE, &q)) {
    set(V4L2_CID_AUTO_WHITE_BALANCE, 0, "V4L2_CID_AUTO_WHITE_BALANCE = 0");
  }
  if (!query(V4L2_CID_EXPOSURE_ABSOLUTE, &q)) {
    throw DeviceError(dev +
                      ": the camera has no V4L2_CID_EXPOSURE_ABSOLUTE control; manual "
                      "exposure is needed for radiometric capture");
  }
  exp_min_ = std::max(1, q.minimum);
  exp_max_ = std::max(exp_min_, q.maximum);
  exp_step_ = std::max(1, q.step);
  v4l2_control g{V4L2_CID_EXPOSURE_ABSOLUTE, 0};
  if (Xioctl(VIDIOC_G_CTRL, &g) < 0) Fail("cannot read the exposure time", errno);
  exp_raw_ = g.value;
  if (query(V4L2_CID_GAIN, &q) && q.maximum > q.minimum) {
    has_gain_ = true;
    gain_min_ = q.minimum;
    gain_max_ = q.maximum;
    gain_step_ = std::max(1, q.step);
    v4l2_control gc{V4L2_CID_GAIN, 0};
    if (Xioctl(VIDIOC_G_CTRL, &gc) < 0) Fail("cannot read the gain", errno);
    gain_raw_ = gc.value;
  }

  // Buffers.
  v4l2_requestbuffers req{};
  req.count = static_cast<uint32_t>(options_.buffers);
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (Xioctl(VIDIOC_REQBUFS, &req) < 0) {
    if (errno == EBUSY) {
      throw DeviceError(dev + ": device busy (EBUSY): another program is streaming from it");
    }
    Fail("VIDIOC_REQBUFS (mmap streaming)", errno);
  }
  allocated_ = req.count > 0;
  if (req.count < 2) {
    throw DeviceError(dev + ": the driver granted " + std::to_string(req.count) +
                      " streaming buffers; at least 2 are needed");
  }
  buffers_.resize(req.count);
  for (uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = i;
    if (Xioctl(VIDIOC_QUERYBUF, &b) < 0) Fail("VIDIOC_QUERYBUF", errno);
    void* addr = io_->Mmap(b.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, b.m.offset);
    if (addr == MAP_FAILED) Fail("mmap of buffer " + std::to_string(i), errno);
    buffers_[i] = {addr, b.length};
  }
  for (uint32_t i = 0; i < req.count; ++i) Requeue(static_cast<int>(i));
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Xioctl(VIDIOC_STREAMON, &type) < 0) Fail("VIDIOC_STREAMON", errno);
  streaming_ = true;
  MarkChange();  // the switch to manual controls
}

void V4l2Camera::Cleanup() noexcept {
  if (fd_ < 0) return;
  const int saved = errno;
  if (streaming_) {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    IoctlRetry(*io_, fd_, VIDIOC_STREAMOFF, &type);
    streaming_ = false;
  }
  for (Buffer& b : buffers_) {
    if (b.data) io_->Munmap(b.data, b.length);
    b.data = nullptr;
  }
  buffers_.clear();
  if (allocated_) {
    v4l2_requestbuffers req{};
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    IoctlRetry(*io_, fd_, VIDIOC_REQBUFS, &req);  // fails harmlessly once the device is gone
    allocated_ = false;
  }
  io_->Close(fd_);
  fd_ = -1;
  errno = saved;
}

std::string V4l2Camera::pixel_format() const { return FourccToString(fourcc_); }

std::vector<ControlInfo> V4l2Camera::Controls() const {
  std::vector<ControlInfo> out;
  out.push_back({"exposure_s", exp_min_ * kExposureUnit,
                 Snap(exp_max_, exp_min_, exp_max_, exp_step_) * kExposureUnit,
                 exp_raw_ * kExposureUnit});
  const double gmax = has_gain_ ? options_.gain_at_max : 1.0;
  const double g = has_gain_ ? 1.0 + static_cast<double>(gain_raw_ - gain_min_) /
                                         (gain_max_ - gain_min_) * (options_.gain_at_max - 1.0)
                             : 1.0;
  out.push_back({"gain", 1.0, gmax, g});
  return out;
}

void V4l2Camera::MarkChange() {
  change_ns_ = FloorUs(ClockNs(CLOCK_MONOTONIC));
  have_first_after_change_ = false;
  frames_since_change_ = 0;
}

double V4l2Camera::SetExposure(double seconds) {
  if (gone_) Fail("", ENODEV);
  if (!(seconds > 0) || !std::isfinite(seconds)) {
    throw DeviceError(options_.device + ": exposure " + std::to_string(seconds) +
                      " s is not a positive time");
  }
  const int raw = Snap(seconds / kExposureUnit, exp_min_, exp_max_, exp_step_);
  v4l2_control c{V4L2_CID_EXPOSURE_ABSOLUTE, raw};
  if (Xioctl(VIDIOC_S_CTRL, &c) < 0) Fail("cannot set the exposure time", errno);
  c.value = 0;
  if (Xioctl(VIDIOC_G_CTRL, &c) < 0) Fail("cannot read back the exposure time", errno);
  if (c.value != exp_raw_) MarkChange();
  exp_raw_ = c.value;
  return exp_raw_ * kExposureUnit;
}

double V4l2Camera::SetGain(double gain) {
  if (gone_) Fail("", ENODEV);
  if (!std::isfinite(gain)) throw DeviceError(options_.device + ": gain is not finite");
  if (!has_gain_) return 1.0;
  const double span = options_.gain_at_max - 1.0;
  const double target =
      span > 0 ? gain_min_ + (gain - 1.0) / span * (gain_max_ - gain_min_) : gain_min_;
  const int raw = Snap(target, gain_min_, gain_max_, gain_step_);
  v4l2_control c{V4L2_CID_GAIN, raw};
  if (Xioctl(VIDIOC_S_CTRL, &c) < 0) Fail("cannot set the gain", errno);
  c.value = 0;
  if (Xioctl(VIDIOC_G_CTRL, &c) < 0) Fail("cannot read back the gain", errno);
  if (c.value != gain_raw_) MarkChange();
  gain_raw_ = c.value;
  return Controls()[1].value;
}

void V4l2Camera::SetNdFilter(double density) {
  if (!(density >= 0) || !std::isfinite(density)) {
    throw DeviceError(options_.device + ": ND density " + std::to_string(density) +
                      " is not a finite density >= 0");
  }
  nd_ = density;
}

void V4l2Camera::Requeue(int index) {
  v4l2_buffer b{};
  b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  b.memory = V4L2_MEMORY_MMAP;
  b.index = static_cast<uint32_t>(index);
  if (Xioctl(VIDIOC_QBUF, &b) < 0) Fail("VIDIOC_QBUF", errno);
}

V4l2Camera::Dequeued V4l2Camera::WaitAndDequeue() {
  const double wait_s = options_.timeout_s + 2.0 * exp_raw_ * kExposureUnit;
  const int64_t deadline = ClockNs(CLOCK_MONOTONIC) + static_cast<int64_t>(wait_s * 1e9);
  for (;;) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    if (Xioctl(VIDIOC_DQBUF, &b) == 0) {
      if (b.index >= buffers_.size()) {
        throw DeviceError(options_.device + ": the driver returned buffer " +
                          std::to_string(b.index) + " of " + std::to_string(buffers_.size()));
      }
      Dequeued d;
      d.index = static_cast<int>(b.index);
      d.sequence = b.sequence;
      d.flags = b.flags;
      d.bytesused = b.bytesused;
      if ((b.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
        d.timestamp_ns = static_cast<int64_t>(b.timestamp.tv_sec) * 1000000000 +
                         static_cast<int64_t>(b.timestamp.tv_usec) * 1000;
      } else {
        // No usable device stamp: the dequeue time, taken as the end of the frame.
        d.timestamp_ns = FloorUs(ClockNs(CLOCK_MONOTONIC));
        d.flags = (d.flags & ~V4L2_BUF_FLAG_TSTAMP_SRC_MASK) | V4L2_BUF_FLAG_TSTAMP_SRC_EOF;
      }
      return d;
    }
    const int err = errno;
    if (err != EAGAIN) Fail("VIDIOC_DQBUF", err);
    const int64_t remaining = deadline - ClockNs(CLOCK_MONOTONIC);
    std::ostringstream timeout;
    timeout << options_.device << ": timed out after " << wait_s << " s waiting for a frame";
    if (remaining <= 0) throw DeviceError(timeout.str());
    short revents = 0;
    const int r = io_->Poll(fd_, POLLIN, &revents,
                            static_cast<int>(std::min<int64_t>(remaining / 1000000 + 1, 1 << 30)));
    if (r < 0) {
      if (errno == EINTR) continue;
      Fail("poll", errno);
    }
    if (r == 0) throw DeviceError(timeout.str());
    if (revents & (POLLERR | POLLHUP | POLLNVAL)) {
      // Find out why from the queue itself: a vanished device answers ENODEV.
      v4l2_buffer probe{};
      probe.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      probe.memory = V4L2_MEMORY_MMAP;
      if (Xioctl(VIDIOC_DQBUF, &probe) == 0) {
        Requeue(static_cast<int>(probe.index));  // rare: an error raced with a frame
        continue;
      }
      if (errno == ENODEV || (revents & POLLHUP)) {
        gone_ = true;
        Fail("", ENODEV);
      }
      throw DeviceError(options_.device + ": poll reported an error on the stream (" +
                        ErrText(errno) + ")");
    }
  }
}

CapturedFrame V4l2Camera::Grab() {
  return GrabImpl(FloorUs(ClockNs(CLOCK_MONOTONIC)), latency_ + 1, nullptr);
}

CapturedFrame V4l2Camera::GrabNext(int* frames_since_change) {
  return GrabImpl(change_ns_, 1, frames_since_change);
}

CapturedFrame V4l2Camera::GrabImpl(int64_t not_before_ns, int min_frames_since_change,
                                   int* index_out) {
  if (gone_) Fail("", ENODEV);
  if (!streaming_) throw DeviceError(options_.device + ": not streaming");
  // Bounded: stale buffers, the latency frames and a few corrupt frames.
  const int max_frames = 2 * static_cast<int>(buffers_.size()) + latency_ + 16;
  int corrupt = 0;
  std::string last_problem;
  for (int n = 0; n < max_frames; ++n) {
    const Dequeued d = WaitAndDequeue();
    if (d.timestamp_ns >= change_ns_) {
      if (!have_first_after_change_) {
        have_first_after_change_ = true;
        first_after_change_ = d.sequence;
      }
      frames_since_change_ = static_cast<int>(d.sequence - first_after_change_) + 1;
    }
    bool usable = d.timestamp_ns >= not_before_ns && d.timestamp_ns >= change_ns_ &&
                  frames_since_change_ >= min_frames_since_change;
    CapturedFrame frame;
    if (usable) {
      const auto* data = static_cast<const uint8_t*>(buffers_[d.index].data);
      const size_t needed =
          bytes_per_line_ * (height_ - 1) + static_cast<size_t>(width_) * BytesPerPixel(fourcc_);
      if (d.flags & V4L2_BUF_FLAG_ERROR) {
        usable = false;
        last_problem = "frame flagged V4L2_BUF_FLAG_ERROR";
      } else if (fourcc_ == V4L2_PIX_FMT_MJPEG) {
        std::string error;
        const size_t n_bytes = std::min<size_t>(d.bytesused, buffers_[d.index].length);
        if (!DecodeJpeg(data, n_bytes, width_, height_, &frame.image, &error)) {
          usable = false;
          last_problem = error;
        }
      } else if (d.bytesused < needed || buffers_[d.index].length < needed) {
        usable = false;
        last_problem = "short frame (" + std::to_string(d.bytesused) + " of " +
                       std::to_string(needed) + " bytes)";
      } else if (fourcc_ == V4L2_PIX_FMT_YUYV) {
        YuyvToRgb(data, width_, height_, bytes_per_line_,
                  YcbcrFromFormat(colorspace_, ycbcr_enc_, quantization_), &frame.image);
      } else if (fourcc_ == V4L2_PIX_FMT_GREY) {
        GreyToRgb(data, width_, height_, bytes_per_line_, &frame.image);
      } else {
        BayerToRgb(data, width_, height_, bytes_per_line_, fourcc_, &frame.image);
      }
      if (!usable) ++corrupt;
    }
    try {
      Requeue(d.index);
    } catch (const DeviceError&) {
      if (!usable) throw;  // a good frame in hand is still returned; the next call fails
    }
    if (!usable) continue;
    const double exposure_s = exp_raw_ * kExposureUnit;
    const bool eof = (d.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_EOF;
    const int64_t mid_ns =
        d.timestamp_ns + static_cast<int64_t>((eof ? -0.5 : 0.5) * exposure_s * 1e9);
    frame.utc.ns = mid_ns + RealtimeMinusMonotonicNs();
    frame.exposure_s = exposure_s;
    frame.gain = Controls()[1].value;
    frame.nd_density = nd_;
    last_sequence_ = d.sequence;
    if (index_out) *index_out = frames_since_change_ - 1;
    return frame;
  }
  throw DeviceError(options_.device + ": no usable frame in " + std::to_string(max_frames) +
                    " frames (" + std::to_string(corrupt) + " corrupt" +
                    (last_problem.empty() ? "" : ", last: " + last_problem) +
                    "; or the frame timestamps are not CLOCK_MONOTONIC)");
}

std::unique_ptr<V4l2Camera> OpenV4l2Camera(const V4l2Options& options) {
  return OpenV4l2Camera(options, std::make_shared<SystemV4l2Io>());
}

std::unique_ptr<V4l2Camera> OpenV4l2Camera(const V4l2Options& options, std::shared_ptr<V4l2Io> io) {
  return std::make_unique<V4l2Camera>(options, std::move(io));
}

namespace {

double MeanLevel(const Image& image) {
  double s = 0;
  for (float v : image.data) s += v;
  return image.data.empty() ? 0 : s / static_cast<double>(image.data.size());
}

// Grabs `frames` frames in stream order after the last change; returns their means.
std::vector<double> StreamMeans(V4l2Camera& camera, int frames) {
  std::vector<double> means;
  int index = 0;
  while (static_cast<int>(means.size()) < frames) {
    const CapturedFrame f = camera.GrabNext(&index);
    // Dropped frames (sequence gaps) repeat the previous mean: they were exposed too.
    while (static_cast<int>(means.size()) < index && !means.empty()) {
      means.push_back(means.back());
    }
    if (static_cast<int>(means.size()) <= index) means.push_back(MeanLevel(f.image));
  }
  means.resize(frames);
  return means;
}

}  // namespace

int MeasureControlLatency(V4l2Camera& camera, int max_frames) {
  const std::string dev = camera.Id();
  if (max_frames < 4) throw Error(dev + ": MeasureControlLatency needs max_frames >= 4");
  struct Restore {
    V4l2Camera& cam;
    int latency;
    double exposure;
    ~Restore() {
      cam.set_control_latency_frames(latency);
      try {
        cam.SetExposure(exposure);
      } catch (const Error&) {
      }
    }
  } restore{camera, camera.control_latency_frames(), camera.Controls()[0].value};
  camera.set_control_latency_frames(0);
  const ControlInfo exposure = camera.Controls()[0];
  constexpr double kStep = 8.0;

  // A low exposure that leaves room for the step: mean 8..70 DN.
  double low = std::max(exposure.min, std::min(exposure.value, exposure.max / kStep));
  double low_mean = 0;
  for (int attempt = 0; attempt < 6; ++attempt) {
    low = camera.SetExposure(low);
    const std::vector<double> settle = StreamMeans(camera, max_frames);
    low_mean = settle.back();
    if (low_mean > 70 && low > exposure.min) {
      low = std::max(exposure.min, low * std::clamp(30.0 / low_mean, 1.0 / kStep, 0.5));
    } else if (low_mean < 8 && low * kStep < exposure.max) {
      low = std::min(exposure.max / kStep,
                     low * std::clamp(30.0 / std::max(low_mean, 0.5), 2.0, kStep));
    } else {
      break;
    }
  }
  const double high = camera.SetExposure(std::min(low * kStep, exposure.max));
  if (!(high >= 2 * low)) {
    throw DeviceError(dev + ": exposure range too small for a brightness step test");
  }
  const std::vector<double> means = StreamMeans(camera, max_frames);
  const double final_mean = means.back();
  if (!(final_mean > std::max(1.5 * low_mean, low_mean + 4))) {
    std::ostringstream os;
    os << dev << ": exposure step " << low << " s -> " << high << " s did not brighten the "
       << "image (mean " << low_mean << " -> " << final_mean << " DN); is the lens capped?";
    throw DeviceError(os.str());
  }
  const double tolerance = std::max(1.5, 0.03 * final_mean);
  int settled = max_frames - 1;
  while (settled > 0 && std::abs(means[settled - 1] - final_mean) <= tolerance) --settled;
  if (settled > max_frames - 3) {
    throw DeviceError(dev + ": brightness did not settle within " + std::to_string(max_frames) +
                      " frames of an exposure change");
  }
  return settled;
}

std::vector<V4l2DeviceInfo> ListV4l2Devices(V4l2Io& io) {
  std::vector<V4l2DeviceInfo> out;
  for (const std::string& path : io.ListDevices()) {
    V4l2DeviceInfo info;
    info.path = path;
    const int fd = io.Open(path, O_RDWR | O_NONBLOCK);
    if (fd < 0) {
      info.error = "cannot open: " + ErrText(errno);
      out.push_back(info);
      continue;
    }
    v4l2_capability cap{};
    if (IoctlRetry(io, fd, VIDIOC_QUERYCAP, &cap) < 0) {
      info.error = "VIDIOC_QUERYCAP: " + ErrText(errno);
    } else {
      info.driver = reinterpret_cast<const char*>(cap.driver);
      info.card = reinterpret_cast<const char*>(cap.card);
      info.bus_info = reinterpret_cast<const char*>(cap.bus_info);
      const uint32_t caps =
          (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
      info.can_capture = (caps & V4L2_CAP_VIDEO_CAPTURE) && (caps & V4L2_CAP_STREAMING);
      for (uint32_t i = 0; caps & V4L2_CAP_VIDEO_CAPTURE; ++i) {
        v4l2_fmtdesc d{};
        d.index = i;
        d.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (IoctlRetry(io, fd, VIDIOC_ENUM_FMT, &d) < 0) break;
        V4l2FormatInfo f;
        f.fourcc = FourccToString(d.pixelformat);
        f.description = reinterpret_cast<const char*>(d.description);
        f.compressed = (d.flags & V4L2_FMT_FLAG_COMPRESSED) != 0;
        f.supported = Decodable(d.pixelformat);
        for (uint32_t j = 0; j < 1024; ++j) {
          v4l2_frmsizeenum s{};
          s.index = j;
          s.pixel_format = d.pixelformat;
          if (IoctlRetry(io, fd, VIDIOC_ENUM_FRAMESIZES, &s) < 0) break;
          if (s.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
            f.sizes.emplace_back(s.discrete.width, s.discrete.height);
          } else {
            f.sizes.emplace_back(s.stepwise.min_width, s.stepwise.min_height);
            f.sizes.emplace_back(s.stepwise.max_width, s.stepwise.max_height);
            break;
          }
        }
        info.formats.push_back(std::move(f));
      }
    }
    io.Close(fd);
    out.push_back(std::move(info));
  }
  return out;
}

}  // namespace rouen
