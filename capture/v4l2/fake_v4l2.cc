#include "capture/v4l2/fake_v4l2.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/mman.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "capture/v4l2/jpeg_codec.h"
#include "capture/v4l2/pixel_format.h"

namespace rouen {

namespace {

using v4l2_internal::BayerColour;
using v4l2_internal::EncodeJpeg;
using v4l2_internal::FourccToString;
using v4l2_internal::IsBayer;

constexpr int kPatch = 16;              // patch size, pixels
constexpr size_t kHistory = 64;         // frames whose truth is kept
constexpr double kExposureUnit = 1e-4;  // UVC exposure unit, seconds

int64_t MonotonicNs() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

// Reflectance of colour `c` in patch (px, py): 0.05 .. 0.80, a fixed hash of the patch.
double Reflectance(int px, int py, int c) {
  uint32_t h = static_cast<uint32_t>(px) * 73856093u ^ static_cast<uint32_t>(py) * 19349663u ^
               static_cast<uint32_t>(c + 1) * 83492791u;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  h ^= h >> 15;
  return 0.05 + 0.75 * static_cast<double>(h % 1001) / 1000.0;
}

uint8_t Quantise(double v) { return static_cast<uint8_t>(std::lround(std::clamp(v, 0.0, 255.0))); }

std::string IoctlName(unsigned long request) {
  switch (request) {
    case VIDIOC_QBUF:
      return "QBUF";
    case VIDIOC_DQBUF:
      return "DQBUF";
    case VIDIOC_QUERYBUF:
      return "QUERYBUF";
    case VIDIOC_REQBUFS:
      return "REQBUFS";
    case VIDIOC_STREAMON:
      return "STREAMON";
    case VIDIOC_STREAMOFF:
      return "STREAMOFF";
    case VIDIOC_S_FMT:
      return "S_FMT";
    case VIDIOC_S_CTRL:
      return "S_CTRL";
    default:
      return "ioctl " + std::to_string(request);
  }
}

}  // namespace

double FakeV4l2Frame::MeanRgb() const {
  if (rgb.empty()) return 0;
  double s = 0;
  for (uint8_t v : rgb) s += v;
  return s / static_cast<double>(rgb.size());
}

struct FakeV4l2Device::Node {
  struct Ctrl {
    uint32_t type;
    std::string name;
    int min, max, step, def, value;
    int writes = 0;
  };
  struct Buffer {
    std::unique_ptr<uint8_t[]> mem;
    size_t length = 0;
    uint32_t offset = 0;
    enum State { kUser, kQueued, kDone } state = kUser;
    uint32_t bytesused = 0, sequence = 0, flags = 0;
    int64_t timestamp_ns = 0;
    int maps = 0;
  };
  struct Pending {
    int from_frame;
    uint32_t id;
    int value;
  };

  FakeV4l2Options opt;
  bool gone = false;
  v4l2_pix_format fmt{};
  std::map<uint32_t, Ctrl> ctrls;
  std::map<uint32_t, int> effective;  // control values on the sensor (after latency)
  std::vector<Pending> pending;
  std::vector<std::unique_ptr<Buffer>> buffers;
  std::vector<std::unique_ptr<Buffer>> orphans;  // freed while mapped; live until munmap
  int owner = -1;                                // the fd that owns the buffer queue
  long calls = 0;                                // ioctl and poll calls (for eintr_every)
  bool streaming = false;
  std::deque<int> queued, done;
  int produced = 0;
  uint32_t sequence = 0;
  int64_t last_ts = 0;
  std::deque<FakeV4l2Frame> history;
  // Exposure on the sensor (raw units, fractional while ramping).
  double last_exposure_raw = 0, ramp_from = 0;
  int ramp_start = 0;

  explicit Node(FakeV4l2Options o) : opt(std::move(o)) {
    if (opt.video_capture) {
      ctrls[V4L2_CID_EXPOSURE_AUTO] = {V4L2_CTRL_TYPE_MENU,
                                       "Auto Exposure",
                                       0,
                                       3,
                                       1,
                                       V4L2_EXPOSURE_APERTURE_PRIORITY,
                                       V4L2_EXPOSURE_APERTURE_PRIORITY};
      ctrls[V4L2_CID_EXPOSURE_ABSOLUTE] = {
          V4L2_CTRL_TYPE_INTEGER, "Exposure Time, Absolute", opt.exposure_min,    opt.exposure_max,
          opt.exposure_step,      opt.exposure_default,      opt.exposure_default};
      if (opt.has_exposure_auto_priority) {
        ctrls[V4L2_CID_EXPOSURE_AUTO_PRIORITY] = {
            V4L2_CTRL_TYPE_BOOLEAN, "Exposure, Dynamic Framerate", 0, 1, 1, 0, 1};
      }
      if (opt.has_auto_white_balance) {
        ctrls[V4L2_CID_AUTO_WHITE_BALANCE] = {
            V4L2_CTRL_TYPE_BOOLEAN, "White Balance, Automatic", 0, 1, 1, 1, 1};
      }
      if (opt.has_gain) {
        ctrls[V4L2_CID_GAIN] = {V4L2_CTRL_TYPE_INTEGER, "Gain",        opt.gain_min,
                                opt.gain_max,           opt.gain_step, opt.gain_default,
                                opt.gain_default};
      }
      for (auto& [id, c] : ctrls) effective[id] = c.value;
      last_exposure_raw = ramp_from = opt.exposure_default;
      if (!opt.pixel_formats.empty() && !opt.frame_sizes.empty()) {
        fmt = TryFormat(opt.pixel_formats[0], opt.frame_sizes[0].first, opt.frame_sizes[0].second);
      }
    }
  }

  bool Supports(uint32_t pf) const {
    return std::find(opt.pixel_formats.begin(), opt.pixel_formats.end(), pf) !=
           opt.pixel_formats.end();
  }

  v4l2_pix_format TryFormat(uint32_t pf, int w, int h) const {
    v4l2_pix_format f{};
    f.pixelformat = Supports(pf) ? pf : opt.pixel_formats[0];
    auto best = opt.frame_sizes[0];
    if (opt.stepwise_sizes) {
      const auto snap = [](int v, int lo, int hi, int step) {
        v = std::clamp(v, lo, hi);
        return lo + (v - lo) / step * step;
      };
      best = {snap(w, opt.min_width, opt.max_width, opt.step_width),
              snap(h, opt.min_height, opt.max_height, opt.step_height)};
    }
    for (auto s : opt.stepwise_sizes ? decltype(opt.frame_sizes){} : opt.frame_sizes) {
      if (std::abs(s.first - w) + std::abs(s.second - h) <
          std::abs(best.first - w) + std::abs(best.second - h)) {
        best = s;
      }
    }
    f.width = static_cast<uint32_t>(best.first);
    f.height = static_cast<uint32_t>(best.second);
    f.field = V4L2_FIELD_NONE;
    const int bpp = v4l2_internal::BytesPerPixel(f.pixelformat);
    if (bpp > 0) {
      f.bytesperline = f.width * bpp + opt.bytesperline_padding;
      f.sizeimage = f.bytesperline * f.height;
    } else {
      f.bytesperline = 0;
      f.sizeimage = f.width * f.height * 3 + 4096;
    }
    f.colorspace =
        f.pixelformat == V4L2_PIX_FMT_MJPEG ? V4L2_COLORSPACE_JPEG : V4L2_COLORSPACE_SRGB;
    if (f.pixelformat == V4L2_PIX_FMT_YUYV) f.quantization = opt.yuyv_quantization;
    return f;
  }

  bool Busy() const { return !buffers.empty(); }

  void ReleaseBuffers() {
    for (auto& b : buffers) {
      if (b->maps > 0) orphans.push_back(std::move(b));
    }
    buffers.clear();
    queued.clear();
    done.clear();
  }

  double GainFor(int raw) const {
    if (opt.gain_max <= opt.gain_min) return 1.0;
    return 1.0 + static_cast<double>(raw - opt.gain_min) / (opt.gain_max - opt.gain_min) *
                     (opt.gain_at_max - 1.0);
  }

  // Renders frame `produced` into the first queued buffer; false if none can be produced.
  // Sets `gone` when the device vanishes instead.
  bool Produce() {
    if (gone || !streaming || queued.empty()) return false;
    for (;;) {
      if (opt.stall_after_frames >= 0 && produced >= opt.stall_after_frames) return false;
      if (opt.vanish_after_frames >= 0 && produced >= opt.vanish_after_frames) {
        gone = true;
        return false;
      }
      for (auto it = pending.begin(); it != pending.end();) {
        if (it->from_frame <= produced) {
          if (it->id == V4L2_CID_EXPOSURE_ABSOLUTE) {
            ramp_from = last_exposure_raw;
            ramp_start = produced;
          }
          effective[it->id] = it->value;
          it = pending.erase(it);
        } else {
          ++it;
        }
      }
      if (std::find(opt.dropped_frames.begin(), opt.dropped_frames.end(), produced) ==
          opt.dropped_frames.end()) {
        break;
      }
      ++produced;  // exposed, then lost
      ++sequence;
    }
    const int k = produced;
    FakeV4l2Frame fr;
    fr.sequence = sequence;
    fr.width = static_cast<int>(fmt.width);
    fr.height = static_cast<int>(fmt.height);
    fr.pixel_format = fmt.pixelformat;
    fr.gain_raw = effective.count(V4L2_CID_GAIN) ? effective[V4L2_CID_GAIN] : opt.gain_min;
    fr.gain = GainFor(fr.gain_raw);
    fr.auto_exposure = effective[V4L2_CID_EXPOSURE_AUTO] != V4L2_EXPOSURE_MANUAL;
    fr.auto_white_balance =
        effective.count(V4L2_CID_AUTO_WHITE_BALANCE) && effective[V4L2_CID_AUTO_WHITE_BALANCE];
    const int w = fr.width, h = fr.height;
    // Scene reflectances and their means (auto exposure and grey-world white balance).
    std::vector<double> refl(static_cast<size_t>(w) * h * 3);
    double mean[3] = {0, 0, 0};
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          const double r = Reflectance(x / kPatch, y / kPatch, c);
          refl[(static_cast<size_t>(y) * w + x) * 3 + c] = r;
          mean[c] += r / (static_cast<double>(w) * h);
        }
      }
    }
    if (fr.auto_exposure) {
      const double s = 118.0 / (opt.scene_dn_per_s * (mean[0] + mean[1] + mean[2]) / 3 * fr.gain *
                                kExposureUnit);
      fr.exposure_raw =
          std::clamp(static_cast<int>(std::lround(s)), opt.exposure_min, opt.exposure_max);
      fr.exposure_s = fr.exposure_raw * kExposureUnit;
    } else {
      // Linear ramp from the previous exposure over exposure_ramp_frames frames.
      const double target = effective[V4L2_CID_EXPOSURE_ABSOLUTE];
      const double t = std::min(
          1.0, (k - ramp_start + 1) / static_cast<double>(std::max(1, opt.exposure_ramp_frames)));
      const double raw = ramp_from + t * (target - ramp_from);
      fr.exposure_raw = static_cast<int>(std::lround(raw));
      fr.exposure_s = raw * kExposureUnit;
    }
    last_exposure_raw = fr.exposure_s / kExposureUnit;
    double wb[3] = {1, 1, 1};
    if (fr.auto_white_balance) {
      wb[0] = mean[1] / mean[0];
      wb[2] = mean[1] / mean[2];
    }
    const double scale = opt.scene_dn_per_s * fr.exposure_s * fr.gain;
    const bool grey = fmt.pixelformat == V4L2_PIX_FMT_GREY;
    std::vector<double> lin(refl.size());
    fr.rgb.resize(refl.size());
    for (size_t i = 0; i < refl.size(); i += 3) {
      for (int c = 0; c < 3; ++c) lin[i + c] = refl[i + c] * scale * wb[c];
      if (grey) {
        const uint8_t g = Quantise(0.299 * lin[i] + 0.587 * lin[i + 1] + 0.114 * lin[i + 2]);
        fr.rgb[i] = fr.rgb[i + 1] = fr.rgb[i + 2] = g;
      } else {
        for (int c = 0; c < 3; ++c) fr.rgb[i + c] = Quantise(lin[i + c]);
      }
    }

    Buffer& b = *buffers[queued.front()];
    const int index = queued.front();
    queued.pop_front();
    std::memset(b.mem.get(), 0, b.length);
    const size_t bpl = fmt.bytesperline;
    uint32_t used = fmt.sizeimage;
    const auto px = [&](int x, int y, int c) {
      return fr.rgb[(static_cast<size_t>(y) * w + x) * 3 + c];
    };
    if (grey) {
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) b.mem[y * bpl + x] = px(x, y, 0);
    } else if (IsBayer(fmt.pixelformat)) {
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          b.mem[y * bpl + x] = px(x, y, BayerColour(fmt.pixelformat, x, y));
    } else if (fmt.pixelformat == V4L2_PIX_FMT_YUYV) {
      // BT.601: Y' = 0.299 R' + 0.587 G' + 0.114 B'; Pb = (B' - Y') / 1.772,
      // Pr = (R' - Y') / 1.402 (R', G', B', Y' in 0..1; Pb, Pr in -0.5..0.5).
      const bool full = opt.yuyv_quantization == V4L2_QUANTIZATION_FULL_RANGE;
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x + 1 < w; x += 2) {
          double ys[2], pb = 0, pr = 0;
          for (int j = 0; j < 2; ++j) {
            const double r = px(x + j, y, 0) / 255.0, g = px(x + j, y, 1) / 255.0,
                         bl = px(x + j, y, 2) / 255.0;
            ys[j] = 0.299 * r + 0.587 * g + 0.114 * bl;
            pb += 0.5 * (bl - ys[j]) / 1.772;
            pr += 0.5 * (r - ys[j]) / 1.402;
          }
          uint8_t* q = &b.mem[y * bpl + 2 * x];
          for (int j = 0; j < 2; ++j) {
            q[2 * j] = Quantise(full ? 255.0 * ys[j] : 16.0 + 219.0 * ys[j]);
          }
          q[1] = Quantise(128.0 + (full ? 255.0 : 224.0) * pb);
          q[3] = Quantise(128.0 + (full ? 255.0 : 224.0) * pr);
        }
      }
    } else if (fmt.pixelformat == V4L2_PIX_FMT_MJPEG) {
      const std::vector<uint8_t> jpeg =
          EncodeJpeg(fr.rgb.data(), w, h, opt.jpeg_quality, opt.mjpeg_omit_huffman_tables);
      used = static_cast<uint32_t>(std::min(jpeg.size(), b.length));
      std::memcpy(b.mem.get(), jpeg.data(), used);
    }
    const bool corrupt = std::find(opt.corrupt_frames.begin(), opt.corrupt_frames.end(), k) !=
                         opt.corrupt_frames.end();
    if (corrupt) {
      used /= 2;
      for (uint32_t i = 0; i < used; i += 7) b.mem[i] = static_cast<uint8_t>(i * 31);
    }
    const bool error =
        std::find(opt.error_frames.begin(), opt.error_frames.end(), k) != opt.error_frames.end();
    // Start-of-frame timestamp, microseconds (struct timeval); wait until the clock has left
    // that microsecond so anything the caller does afterwards is stamped later.
    int64_t now = MonotonicNs();
    int64_t ts = std::max(now / 1000 * 1000, last_ts + 1000);
    while (MonotonicNs() < ts + 1000) {
    }
    last_ts = ts;
    b.bytesused = used;
    b.sequence = sequence++;
    b.timestamp_ns = ts;
    b.flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE |
              (error ? V4L2_BUF_FLAG_ERROR : 0u);
    b.state = Buffer::kDone;
    done.push_back(index);
    fr.timestamp_ns = ts;
    history.push_back(std::move(fr));
    if (history.size() > kHistory) history.pop_front();
    ++produced;
    return true;
  }

  void FillBuffer(int index, v4l2_buffer* out) const {
    const Buffer& b = *buffers[index];
    std::memset(out, 0, sizeof(*out));
    out->index = static_cast<uint32_t>(index);
    out->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    out->memory = V4L2_MEMORY_MMAP;
    out->length = static_cast<uint32_t>(b.length);
    out->m.offset = b.offset;
    out->bytesused = b.state == Buffer::kQueued ? 0 : b.bytesused;
    out->field = V4L2_FIELD_NONE;
    out->sequence = b.sequence;
    out->timestamp.tv_sec = b.timestamp_ns / 1000000000;
    out->timestamp.tv_usec = (b.timestamp_ns % 1000000000) / 1000;
    out->flags = b.flags;
    if (b.maps > 0) out->flags |= V4L2_BUF_FLAG_MAPPED;
    if (b.state == Buffer::kQueued) out->flags |= V4L2_BUF_FLAG_QUEUED;
    if (b.state == Buffer::kDone) out->flags |= V4L2_BUF_FLAG_DONE;
  }
};

FakeV4l2Device::FakeV4l2Device(FakeV4l2Options options) {
  nodes_.push_back(std::make_unique<Node>(std::move(options)));
}

FakeV4l2Device::FakeV4l2Device(std::vector<FakeV4l2Options> nodes) {
  for (auto& o : nodes) nodes_.push_back(std::make_unique<Node>(std::move(o)));
}

FakeV4l2Device::~FakeV4l2Device() = default;

FakeV4l2Device::Node* FakeV4l2Device::FindNode(const std::string& path) const {
  if (path.empty()) return nodes_.empty() ? nullptr : nodes_[0].get();
  for (auto& n : nodes_) {
    if (n->opt.path == path) return n.get();
  }
  return nullptr;
}

bool FakeV4l2Device::Interrupted(Node& n) {
  return n.opt.eintr_every > 0 && ++n.calls % n.opt.eintr_every == 0;
}

int FakeV4l2Device::Fail(int err) {
  errno = err;
  return -1;
}

int FakeV4l2Device::Misused(int err, const std::string& what) {
  misuse_.push_back(what + " (" + std::strerror(err) + ")");
  return Fail(err);
}

int FakeV4l2Device::Open(const std::string& path, int flags) {
  Node* n = FindNode(path);
  if (path.empty() || !n || n->gone) return Fail(ENOENT);
  if ((flags & O_ACCMODE) == O_WRONLY) return Fail(EINVAL);
  const int fd = next_fd_++;
  files_[fd] = {n, (flags & O_NONBLOCK) != 0};
  return fd;
}

int FakeV4l2Device::Close(int fd) {
  auto it = files_.find(fd);
  if (it == files_.end()) return Misused(EBADF, "close of unknown fd " + std::to_string(fd));
  Node* n = it->second.node;
  if (n->owner == fd) {
    n->streaming = false;
    n->ReleaseBuffers();
    n->owner = -1;
  }
  files_.erase(it);
  return 0;
}

void* FakeV4l2Device::Mmap(size_t length, int prot, int flags, int fd, off_t offset) {
  auto it = files_.find(fd);
  if (it == files_.end()) {
    Misused(EBADF, "mmap of unknown fd");
    return MAP_FAILED;
  }
  Node* n = it->second.node;
  if (n->gone) {
    Fail(ENODEV);
    return MAP_FAILED;
  }
  if (!(flags & MAP_SHARED) || !(prot & PROT_READ)) {
    Misused(EINVAL, "mmap without MAP_SHARED and PROT_READ");
    return MAP_FAILED;
  }
  for (auto& b : n->buffers) {
    if (b->offset == static_cast<uint32_t>(offset)) {
      if (length == 0 || length > b->length) {
        Misused(EINVAL, "mmap of " + std::to_string(length) + " bytes of a " +
                            std::to_string(b->length) + "-byte buffer");
        return MAP_FAILED;
      }
      ++b->maps;
      void* addr = b->mem.get();
      auto& m = mappings_[addr];
      m.node = n;
      m.length = length;
      ++m.count;
      return addr;
    }
  }
  Misused(EINVAL, "mmap of unknown offset " + std::to_string(offset));
  return MAP_FAILED;
}

int FakeV4l2Device::Munmap(void* addr, size_t length) {
  auto it = mappings_.find(addr);
  if (it == mappings_.end()) return Misused(EINVAL, "munmap of an address never mapped");
  if (length != it->second.length) {
    misuse_.push_back("munmap with length " + std::to_string(length) + " of a " +
                      std::to_string(it->second.length) + "-byte mapping");
  }
  Node* n = it->second.node;
  auto release = [&](std::vector<std::unique_ptr<Node::Buffer>>& list, bool erase) {
    for (auto b = list.begin(); b != list.end(); ++b) {
      if ((*b)->mem.get() == addr) {
        --(*b)->maps;
        if (erase && (*b)->maps == 0) list.erase(b);
        return true;
      }
    }
    return false;
  };
  if (!release(n->buffers, false)) release(n->orphans, true);
  if (--it->second.count == 0) mappings_.erase(it);
  return 0;
}

int FakeV4l2Device::Poll(int fd, short events, short* revents, int /*timeout_ms*/) {
  *revents = 0;
  auto it = files_.find(fd);
  if (it == files_.end()) {
    misuse_.push_back("poll of unknown fd");
    *revents = POLLNVAL;
    return 1;
  }
  Node* n = it->second.node;
  if (Interrupted(*n)) return Fail(EINTR);
  if (!n->gone && n->streaming && n->owner == fd && n->done.empty() &&
      n->opt.fill == FakeV4l2Options::Fill::kOnPoll) {
    n->Produce();
  }
  if (n->gone) {
    *revents = POLLERR | POLLHUP;
  } else if (!n->streaming || n->owner != fd) {
    *revents = POLLERR;
  } else if (!n->done.empty()) {
    *revents = static_cast<short>(events & (POLLIN | POLLRDNORM));
  }
  // Nothing ready: the timeout has (virtually) elapsed.
  return *revents ? 1 : 0;
}

std::vector<std::string> FakeV4l2Device::ListDevices() {
  std::vector<std::string> paths;
  for (auto& n : nodes_) {
    if (!n->gone) paths.push_back(n->opt.path);
  }
  std::sort(paths.begin(), paths.end());
  return paths;
}

void FakeV4l2Device::Unplug(const std::string& path) {
  if (Node* n = FindNode(path)) n->gone = true;
}

int FakeV4l2Device::OpenFds() const { return static_cast<int>(files_.size()); }

int FakeV4l2Device::Mappings() const {
  int total = 0;
  for (auto& [addr, m] : mappings_) total += m.count;
  return total;
}

int FakeV4l2Device::AllocatedBuffers(const std::string& path) const {
  Node* n = FindNode(path);
  return n ? static_cast<int>(n->buffers.size()) : 0;
}

bool FakeV4l2Device::Streaming(const std::string& path) const {
  Node* n = FindNode(path);
  return n && n->streaming;
}

int FakeV4l2Device::FramesProduced(const std::string& path) const {
  Node* n = FindNode(path);
  return n ? n->produced : 0;
}

std::optional<int> FakeV4l2Device::Control(uint32_t id, const std::string& path) const {
  Node* n = FindNode(path);
  if (!n || !n->ctrls.count(id)) return std::nullopt;
  return n->ctrls.at(id).value;
}

int FakeV4l2Device::ControlWrites(uint32_t id, const std::string& path) const {
  Node* n = FindNode(path);
  if (!n || !n->ctrls.count(id)) return 0;
  return n->ctrls.at(id).writes;
}

std::optional<FakeV4l2Frame> FakeV4l2Device::Frame(uint32_t sequence,
                                                   const std::string& path) const {
  Node* n = FindNode(path);
  if (!n) return std::nullopt;
  for (auto& f : n->history) {
    if (f.sequence == sequence) return f;
  }
  return std::nullopt;
}

double FakeV4l2Device::GainForRaw(int raw, const std::string& path) const {
  Node* n = FindNode(path);
  return n ? n->GainFor(raw) : 1.0;
}

int FakeV4l2Device::Ioctl(int fd, unsigned long request, void* arg) {
  auto it = files_.find(fd);
  if (it == files_.end()) return Misused(EBADF, IoctlName(request) + " on unknown fd");
  if (it->second.node->gone) return Fail(ENODEV);
  if (Interrupted(*it->second.node)) return Fail(EINTR);
  if (arg == nullptr) return Misused(EFAULT, IoctlName(request) + " with a null argument");
  return DoIoctl(fd, it->second, request, arg);
}

int FakeV4l2Device::DoIoctl(int fd, OpenFile& f, unsigned long request, void* arg) {
  Node& n = *f.node;
  const bool capture = n.opt.video_capture;
  const auto bad_type = [&](uint32_t type) {
    return type != V4L2_BUF_TYPE_VIDEO_CAPTURE || !capture;
  };
  switch (request) {
    case VIDIOC_QUERYCAP: {
      auto* cap = static_cast<v4l2_capability*>(arg);
      std::memset(cap, 0, sizeof(*cap));
      std::strncpy(reinterpret_cast<char*>(cap->driver), n.opt.driver.c_str(),
                   sizeof(cap->driver) - 1);
      std::strncpy(reinterpret_cast<char*>(cap->card), n.opt.card.c_str(), sizeof(cap->card) - 1);
      std::strncpy(reinterpret_cast<char*>(cap->bus_info), n.opt.bus_info.c_str(),
                   sizeof(cap->bus_info) - 1);
      cap->version = (6u << 16) | (1u << 8);  // 6.1.0
      cap->device_caps = (capture ? V4L2_CAP_VIDEO_CAPTURE : V4L2_CAP_META_CAPTURE) |
                         (n.opt.streaming ? V4L2_CAP_STREAMING : 0u) | V4L2_CAP_EXT_PIX_FORMAT;
      cap->capabilities = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_META_CAPTURE | V4L2_CAP_STREAMING |
                          V4L2_CAP_EXT_PIX_FORMAT | V4L2_CAP_DEVICE_CAPS;
      return 0;
    }
    case VIDIOC_ENUM_FMT: {
      auto* d = static_cast<v4l2_fmtdesc*>(arg);
      if (bad_type(d->type) || d->index >= n.opt.pixel_formats.size()) return Fail(EINVAL);
      const uint32_t pf = n.opt.pixel_formats[d->index];
      const uint32_t index = d->index, type = d->type;
      std::memset(d, 0, sizeof(*d));
      d->index = index;
      d->type = type;
      d->pixelformat = pf;
      d->flags = pf == V4L2_PIX_FMT_MJPEG ? V4L2_FMT_FLAG_COMPRESSED : 0u;
      const std::string desc = pf == V4L2_PIX_FMT_MJPEG  ? "Motion-JPEG"
                               : pf == V4L2_PIX_FMT_YUYV ? "YUYV 4:2:2"
                                                         : FourccToString(pf);
      std::strncpy(reinterpret_cast<char*>(d->description), desc.c_str(),
                   sizeof(d->description) - 1);
      return 0;
    }
    case VIDIOC_ENUM_FRAMESIZES: {
      auto* s = static_cast<v4l2_frmsizeenum*>(arg);
      if (!capture || !n.Supports(s->pixel_format)) return Fail(EINVAL);
      if (n.opt.stepwise_sizes) {
        if (s->index != 0) return Fail(EINVAL);
        s->type = V4L2_FRMSIZE_TYPE_STEPWISE;
        s->stepwise = {
            static_cast<uint32_t>(n.opt.min_width),  static_cast<uint32_t>(n.opt.max_width),
            static_cast<uint32_t>(n.opt.step_width), static_cast<uint32_t>(n.opt.min_height),
            static_cast<uint32_t>(n.opt.max_height), static_cast<uint32_t>(n.opt.step_height)};
        return 0;
      }
      if (s->index >= n.opt.frame_sizes.size()) return Fail(EINVAL);
      s->type = V4L2_FRMSIZE_TYPE_DISCRETE;
      s->discrete.width = static_cast<uint32_t>(n.opt.frame_sizes[s->index].first);
      s->discrete.height = static_cast<uint32_t>(n.opt.frame_sizes[s->index].second);
      return 0;
    }
    case VIDIOC_G_FMT: {
      auto* fm = static_cast<v4l2_format*>(arg);
      if (bad_type(fm->type)) return Fail(EINVAL);
      fm->fmt.pix = n.fmt;
      return 0;
    }
    case VIDIOC_TRY_FMT:
    case VIDIOC_S_FMT: {
      auto* fm = static_cast<v4l2_format*>(arg);
      if (bad_type(fm->type)) return Fail(EINVAL);
      if (request == VIDIOC_S_FMT && n.Busy()) {
        if (n.owner == fd) return Misused(EBUSY, "S_FMT while buffers are allocated");
        return Fail(EBUSY);
      }
      const v4l2_pix_format p =
          n.TryFormat(fm->fmt.pix.pixelformat, static_cast<int>(fm->fmt.pix.width),
                      static_cast<int>(fm->fmt.pix.height));
      fm->fmt.pix = p;
      if (request == VIDIOC_S_FMT) n.fmt = p;
      return 0;
    }
    case VIDIOC_QUERYCTRL: {
      auto* q = static_cast<v4l2_queryctrl*>(arg);
      uint32_t id = q->id;
      std::map<uint32_t, Node::Ctrl>::iterator c;
      if (id & V4L2_CTRL_FLAG_NEXT_CTRL) {
        c = n.ctrls.upper_bound(id & ~(V4L2_CTRL_FLAG_NEXT_CTRL | V4L2_CTRL_FLAG_NEXT_COMPOUND));
      } else {
        c = n.ctrls.find(id);
      }
      if (c == n.ctrls.end()) return Fail(EINVAL);
      std::memset(q, 0, sizeof(*q));
      q->id = c->first;
      q->type = c->second.type;
      std::strncpy(reinterpret_cast<char*>(q->name), c->second.name.c_str(), sizeof(q->name) - 1);
      q->minimum = c->second.min;
      q->maximum = c->second.max;
      q->step = c->second.step;
      q->default_value = c->second.def;
      if (c->first == V4L2_CID_EXPOSURE_ABSOLUTE &&
          n.ctrls[V4L2_CID_EXPOSURE_AUTO].value != V4L2_EXPOSURE_MANUAL) {
        q->flags |= V4L2_CTRL_FLAG_INACTIVE;
      }
      return 0;
    }
    case VIDIOC_QUERYMENU: {
      auto* m = static_cast<v4l2_querymenu*>(arg);
      if (m->id != V4L2_CID_EXPOSURE_AUTO || !n.ctrls.count(m->id)) return Fail(EINVAL);
      const char* name = m->index == V4L2_EXPOSURE_MANUAL              ? "Manual Mode"
                         : m->index == V4L2_EXPOSURE_APERTURE_PRIORITY ? "Aperture Priority Mode"
                                                                       : nullptr;
      if (!name) return Fail(EINVAL);
      std::memset(m->name, 0, sizeof(m->name));
      std::strncpy(reinterpret_cast<char*>(m->name), name, sizeof(m->name) - 1);
      return 0;
    }
    case VIDIOC_G_CTRL: {
      auto* c = static_cast<v4l2_control*>(arg);
      auto ct = n.ctrls.find(c->id);
      if (ct == n.ctrls.end()) return Fail(EINVAL);
      c->value = ct->second.value;
      return 0;
    }
    case VIDIOC_S_CTRL: {
      auto* c = static_cast<v4l2_control*>(arg);
      auto ct = n.ctrls.find(c->id);
      if (ct == n.ctrls.end()) return Fail(EINVAL);
      Node::Ctrl& ctrl = ct->second;
      int v = c->value;
      if (ctrl.type == V4L2_CTRL_TYPE_MENU) {
        if (v != V4L2_EXPOSURE_MANUAL && v != V4L2_EXPOSURE_APERTURE_PRIORITY) {
          return Fail(EINVAL);  // this camera's menu has only these two
        }
      } else {
        // uvcvideo: clamp to the range, then round to the step.
        v = std::clamp(v, ctrl.min, ctrl.max);
        v = ctrl.min +
            static_cast<int>(std::lround(static_cast<double>(v - ctrl.min) / ctrl.step)) *
                ctrl.step;
        if (v > ctrl.max) v -= ctrl.step;
      }
      if (c->id == V4L2_CID_EXPOSURE_ABSOLUTE) {
        if (n.ctrls[V4L2_CID_EXPOSURE_AUTO].value != V4L2_EXPOSURE_MANUAL) {
          return Misused(EACCES, "S_CTRL exposure time while auto exposure is on");
        }
        if (n.opt.exposure_cap > 0) v = std::min(v, n.opt.exposure_cap);
      }
      ctrl.value = v;
      ++ctrl.writes;
      c->value = v;
      n.pending.push_back({n.produced + n.opt.control_latency_frames, c->id, v});
      return 0;
    }
    case VIDIOC_REQBUFS: {
      auto* r = static_cast<v4l2_requestbuffers*>(arg);
      if (bad_type(r->type) || !n.opt.streaming) return Fail(EINVAL);
      if (r->memory != V4L2_MEMORY_MMAP) return Fail(EINVAL);
      if (n.owner != -1 && n.owner != fd) return Fail(EBUSY);
      if (n.streaming) return Misused(EBUSY, "REQBUFS while streaming");
      n.ReleaseBuffers();
      const uint32_t count = std::min<uint32_t>(r->count, static_cast<uint32_t>(n.opt.max_buffers));
      const size_t page = 4096;
      const size_t length = n.fmt.sizeimage;
      for (uint32_t i = 0; i < count; ++i) {
        auto b = std::make_unique<Node::Buffer>();
        b->length = length;
        b->mem = std::make_unique<uint8_t[]>(length);
        b->offset = static_cast<uint32_t>(i * ((length + page - 1) / page) * page);
        n.buffers.push_back(std::move(b));
      }
      n.owner = count > 0 ? fd : -1;
      r->count = count;
      r->capabilities = V4L2_BUF_CAP_SUPPORTS_MMAP;
      return 0;
    }
    case VIDIOC_QUERYBUF:
    case VIDIOC_QBUF:
    case VIDIOC_DQBUF: {
      auto* b = static_cast<v4l2_buffer*>(arg);
      const std::string name = IoctlName(request);
      if (bad_type(b->type)) return Misused(EINVAL, name + " with a wrong buffer type");
      if (n.owner != -1 && n.owner != fd) return Fail(EBUSY);
      if (request == VIDIOC_QUERYBUF) {
        if (b->index >= n.buffers.size()) {
          return Misused(EINVAL, "QUERYBUF of index " + std::to_string(b->index));
        }
        n.FillBuffer(static_cast<int>(b->index), b);
        return 0;
      }
      if (b->memory != V4L2_MEMORY_MMAP) return Misused(EINVAL, name + " with memory != MMAP");
      if (request == VIDIOC_QBUF) {
        if (b->index >= n.buffers.size()) {
          return Misused(EINVAL, "QBUF of index " + std::to_string(b->index) + " of " +
                                     std::to_string(n.buffers.size()) + " buffers");
        }
        Node::Buffer& buf = *n.buffers[b->index];
        if (buf.state != Node::Buffer::kUser) {
          return Misused(EINVAL,
                         "QBUF of buffer " + std::to_string(b->index) + " that is already queued");
        }
        buf.state = Node::Buffer::kQueued;
        n.queued.push_back(static_cast<int>(b->index));
        if (n.streaming && n.opt.fill == FakeV4l2Options::Fill::kOnQueue) n.Produce();
        n.FillBuffer(static_cast<int>(b->index), b);
        return 0;
      }
      // DQBUF
      if (!n.streaming) return Misused(EINVAL, "DQBUF while not streaming");
      if (n.done.empty() && n.opt.fill == FakeV4l2Options::Fill::kOnPoll) n.Produce();
      if (n.gone) return Fail(ENODEV);
      if (n.done.empty()) {
        if (f.nonblocking) return Fail(EAGAIN);
        return Misused(EIO, "blocking DQBUF with no frame coming (would hang)");
      }
      const int index = n.done.front();
      n.done.pop_front();
      n.buffers[index]->state = Node::Buffer::kUser;
      n.FillBuffer(index, b);
      return 0;
    }
    case VIDIOC_STREAMON:
    case VIDIOC_STREAMOFF: {
      auto* type = static_cast<int*>(arg);
      if (bad_type(static_cast<uint32_t>(*type))) return Fail(EINVAL);
      if (n.owner != -1 && n.owner != fd) return Fail(EBUSY);
      if (request == VIDIOC_STREAMOFF) {
        n.streaming = false;
        for (auto& buf : n.buffers) buf->state = Node::Buffer::kUser;
        n.queued.clear();
        n.done.clear();
        return 0;
      }
      if (n.buffers.empty()) return Misused(EINVAL, "STREAMON without buffers");
      if (n.streaming) return 0;
      n.streaming = true;
      if (n.opt.fill == FakeV4l2Options::Fill::kOnQueue) {
        while (n.Produce()) {
        }
      }
      return 0;
    }
    default:
      return Fail(ENOTTY);
  }
}

}  // namespace rouen
