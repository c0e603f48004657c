#include "capture/libcamera/libcamera_camera.h"

#include <libcamera/camera.h>
#include <libcamera/camera_manager.h>
#include <libcamera/control_ids.h>
#include <libcamera/formats.h>
#include <libcamera/framebuffer.h>
#include <libcamera/framebuffer_allocator.h>
#include <libcamera/property_ids.h>
#include <libcamera/request.h>
#include <libcamera/stream.h>
#include <sys/mman.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>

#include "capture/libcamera/frame_convert.h"
#include "capture/libcamera/libcamera_controls.h"
#include "capture/libcamera/request_tracker.h"
#include "core/error.h"

namespace rouen {
namespace {

namespace lc = libcamera;
using libcamera_internal::ExposureSetting;

// libcamera allows one CameraManager per process: listing and every open camera share it.
// It stops when the last user lets go.
std::shared_ptr<lc::CameraManager> SharedManager() {
  static std::mutex mutex;
  static std::weak_ptr<lc::CameraManager> weak;
  std::lock_guard<std::mutex> lock(mutex);
  if (auto manager = weak.lock()) return manager;
  static bool quieted = false;
  if (!quieted) {
    // Libraries never print: keep libcamera's INFO chatter off stderr unless the user asked
    // for it with libcamera's own environment variable.
    // libcamera reads the variable when its logger is first used, which is here.
    setenv("LIBCAMERA_LOG_LEVELS", "*:ERROR", /*overwrite=*/0);
    quieted = true;
  }
  auto manager = std::make_shared<lc::CameraManager>();
  const int ret = manager->start();
  if (ret != 0) {
    throw DeviceError("libcamera: the camera manager failed to start: " +
                      std::string(std::strerror(-ret)));
  }
  weak = manager;
  return manager;
}

int64_t ClockNs(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

// UTC ns of a sensor timestamp: the sensor clock is read on both sides of the realtime clock
// so the pair is simultaneous to within a few µs.
int64_t SensorToUtcNs(int64_t sensor_ns, LibcameraOptions::SensorClock which) {
  const clockid_t clock =
      which == LibcameraOptions::SensorClock::kBoottime ? CLOCK_BOOTTIME : CLOCK_MONOTONIC;
  const int64_t before = ClockNs(clock);
  const int64_t utc = ClockNs(CLOCK_REALTIME);
  const int64_t after = ClockNs(clock);
  return libcamera_internal::SensorTimestampToUtcNs(sensor_ns, before + (after - before) / 2, utc);
}

std::string PropertyName(unsigned id) {
  const auto& map = lc::properties::properties;
  const auto it = map.find(id);
  return it != map.end() ? it->second->name() : "property#" + std::to_string(id);
}

// One mmap of a dmabuf.
struct Mapping {
  void* address = MAP_FAILED;
  size_t length = 0;
};

libcamera_internal::RequestTrackerOptions TrackerOptions(const LibcameraOptions& o) {
  libcamera_internal::RequestTrackerOptions t;
  t.max_frames_per_grab = o.max_frames_per_grab;
  t.exposure_rel_tol = o.exposure_rel_tol;
  t.exposure_abs_tol_s = o.exposure_abs_tol_s;
  t.gain_rel_tol = o.gain_rel_tol;
  t.max_consecutive_failures = o.max_consecutive_failures;
  t.settle_frames_without_metadata = o.settle_frames_without_metadata;
  return t;
}

}  // namespace

void LibcameraOptions::Validate() const {
  auto fail = [](const std::string& what) { throw Error("libcamera options: " + what); };
  if (width < 0 || height < 0) fail("width and height must be >= 0 (0 = default)");
  if ((width == 0) != (height == 0)) fail("give both width and height, or neither");
  if (request_count < 1 || request_count > 32) fail("request_count must be in 1..32");
  if (!(grab_timeout_s > 0) || !std::isfinite(grab_timeout_s)) {
    fail("grab_timeout_s must be a positive number of seconds");
  }
  TrackerOptions(*this).Validate();
}

std::vector<LibcameraCameraInfo> ListLibcameraCameras() {
  const auto manager = SharedManager();
  std::vector<LibcameraCameraInfo> out;
  for (const std::shared_ptr<lc::Camera>& camera : manager->cameras()) {
    LibcameraCameraInfo info;
    info.id = camera->id();
    const lc::ControlList& props = camera->properties();
    if (const auto model = props.get(lc::properties::Model)) info.model = *model;
    for (const auto& [id, value] : props) {
      info.properties.emplace_back(PropertyName(id), value.toString());
    }
    std::sort(info.properties.begin(), info.properties.end());
    info.exposure_controls = libcamera_internal::DescribeExposureApi(camera->controls()).Summary();
    // Generating a configuration needs no acquisition; a camera busy elsewhere still lists.
    auto formats = [&](lc::StreamRole role) {
      std::vector<std::string> names;
      const auto config = camera->generateConfiguration({role});
      if (!config || config->empty()) return names;
      const lc::StreamFormats& f = config->at(0).formats();
      for (const lc::PixelFormat& pf : f.pixelformats()) {
        std::string name =
            pf.toString() + " " + f.range(pf).min.toString() + "-" + f.range(pf).max.toString();
        if (!libcamera_internal::IsSupportedFormat({pf.fourcc(), pf.modifier()})) {
          name += " (unsupported)";
        }
        names.push_back(std::move(name));
      }
      return names;
    };
    info.still_formats = formats(lc::StreamRole::StillCapture);
    info.raw_formats = formats(lc::StreamRole::Raw);
    out.push_back(std::move(info));
  }
  return out;
}

std::vector<std::string> LibcameraSupportedFormats() {
  return libcamera_internal::SupportedFormatNames();
}

struct LibcameraCamera::Impl {
  LibcameraOptions options;
  std::string name;  // "libcamera camera '<id>'" for messages
  std::shared_ptr<lc::CameraManager> manager;
  std::shared_ptr<lc::Camera> camera;
  bool acquired = false, configured = false, started = false;
  std::unique_ptr<lc::CameraConfiguration> config;
  lc::Stream* stream = nullptr;
  std::unique_ptr<lc::FrameBufferAllocator> allocator;
  std::vector<std::unique_ptr<lc::Request>> requests;
  std::vector<Mapping> mappings;
  std::map<const lc::FrameBuffer*, std::vector<libcamera_internal::PlaneBytes>> planes;
  libcamera_internal::FrameLayout layout;
  libcamera_internal::ExposureApi api;
  std::unique_ptr<libcamera_internal::RequestTracker> tracker;
  ExposureSetting wanted{1.0 / 250, 1.0};
  double nd = 0;
  std::vector<std::string> adjustments;
  LibcameraGrabReport last;
  std::mutex grab_mutex;  // one Grab at a time

  // Filled by libcamera's thread, drained by Grab().
  std::mutex mutex;
  std::condition_variable cv;
  std::deque<lc::Request*> completed;
  bool disconnected = false;

  void OnRequestCompleted(lc::Request* request) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      completed.push_back(request);
    }
    cv.notify_all();
  }
  void OnDisconnected() {
    {
      std::lock_guard<std::mutex> lock(mutex);
      disconnected = true;
    }
    cv.notify_all();
  }

  [[noreturn]] void Fail(const std::string& what) const { throw DeviceError(name + ": " + what); }

  void Open();
  void Configure();
  void MapBuffers();
  void Start();
  void Queue(lc::Request* request);
  void Close() noexcept;
};

void LibcameraCamera::Impl::Open() {
  manager = SharedManager();
  const auto cameras = manager->cameras();
  if (options.camera_id.empty()) {
    if (cameras.empty()) {
      throw DeviceError("libcamera: no camera found (the camera manager reports none)");
    }
    camera = cameras.front();
  } else {
    camera = manager->get(options.camera_id);
    if (!camera) {
      std::string known;
      for (const auto& c : cameras) known += (known.empty() ? "" : ", ") + c->id();
      throw DeviceError("libcamera camera '" + options.camera_id + "': not found (" +
                        (known.empty() ? std::string("no cameras") : "cameras: " + known) + ")");
    }
  }
  name = "libcamera camera '" + camera->id() + "'";
  if (const int ret = camera->acquire(); ret != 0) {
    camera.reset();
    Fail("cannot acquire (" + std::string(std::strerror(-ret)) + "; in use by another process?)");
  }
  acquired = true;
  camera->requestCompleted.connect(this, &Impl::OnRequestCompleted);
  camera->disconnected.connect(this, &Impl::OnDisconnected);
}

void LibcameraCamera::Impl::Configure() {
  const lc::StreamRole role = options.role == LibcameraOptions::Role::kRaw
                                  ? lc::StreamRole::Raw
                                  : lc::StreamRole::StillCapture;
  config = camera->generateConfiguration({role});
  if (!config || config->empty()) Fail("cannot generate a configuration for the stream role");
  lc::StreamConfiguration& sc = config->at(0);

  auto code = [](const lc::PixelFormat& pf) {
    return libcamera_internal::PixelCode{pf.fourcc(), pf.modifier()};
  };
  libcamera_internal::PixelCode wanted_format;
  if (!options.pixel_format.empty()) {
    const lc::PixelFormat pf = lc::PixelFormat::fromString(options.pixel_format);
    if (!pf.isValid()) Fail("unknown pixel format '" + options.pixel_format + "'");
    wanted_format = code(pf);
  }
  std::vector<libcamera_internal::PixelCode> offered;
  for (const lc::PixelFormat& pf : sc.formats().pixelformats()) offered.push_back(code(pf));
  const libcamera_internal::PixelCode chosen =
      libcamera_internal::ChooseFormat(wanted_format, code(sc.pixelFormat), offered);
  if (chosen.fourcc == 0) {
    std::string names;
    for (const auto& n : libcamera_internal::SupportedFormatNames()) names += " " + n;
    Fail("offers no pixel format rouen can convert (default " + sc.pixelFormat.toString() +
         "; supported:" + names + ")");
  }

  libcamera_internal::StreamSetting asked;
  const lc::PixelFormat chosen_pf(chosen.fourcc, chosen.modifier);
  asked.pixel_format = chosen_pf.toString();
  if (chosen != code(sc.pixelFormat) && wanted_format.fourcc == 0) {
    adjustments.push_back("pixel format " + sc.pixelFormat.toString() + " (default) -> " +
                          asked.pixel_format + " (rouen cannot convert the default)");
  }
  sc.pixelFormat = chosen_pf;
  if (options.width > 0) {
    sc.size = lc::Size(options.width, options.height);
    asked.width = options.width;
    asked.height = options.height;
  }
  sc.bufferCount = static_cast<unsigned>(options.request_count);
  asked.buffer_count = sc.bufferCount;

  switch (config->validate()) {
    case lc::CameraConfiguration::Invalid:
      Fail("configuration " + asked.pixel_format + " " +
           (asked.width > 0 ? std::to_string(asked.width) + "x" + std::to_string(asked.height)
                            : std::string("default size")) +
           " is invalid for this camera");
    case lc::CameraConfiguration::Adjusted:
    case lc::CameraConfiguration::Valid:
      break;
  }
  const lc::StreamConfiguration& got_sc = config->at(0);
  libcamera_internal::StreamSetting got;
  got.pixel_format = got_sc.pixelFormat.toString();
  got.width = static_cast<int>(got_sc.size.width);
  got.height = static_cast<int>(got_sc.size.height);
  got.buffer_count = got_sc.bufferCount;
  for (auto& a : libcamera_internal::DescribeStreamAdjustments(asked, got)) {
    adjustments.push_back(std::move(a));
  }
  if (!libcamera_internal::IsSupportedFormat(code(got_sc.pixelFormat))) {
    Fail("the camera adjusted the pixel format to " + got.pixel_format +
         ", which rouen cannot convert");
  }
  if (const int ret = camera->configure(config.get()); ret != 0) {
    Fail("configure failed (" + std::string(std::strerror(-ret)) + ")");
  }
  configured = true;
  stream = got_sc.stream();

  layout.format = code(got_sc.pixelFormat);
  layout.width = got.width;
  layout.height = got.height;
  layout.stride = static_cast<int>(got_sc.stride);
  layout.matrix = libcamera_internal::YcbcrMatrix::kRec601;
  layout.full_range = false;
  if (got_sc.colorSpace) {
    using CS = lc::ColorSpace;
    switch (got_sc.colorSpace->ycbcrEncoding) {
      case CS::YcbcrEncoding::Rec709:
        layout.matrix = libcamera_internal::YcbcrMatrix::kRec709;
        break;
      case CS::YcbcrEncoding::Rec2020:
        layout.matrix = libcamera_internal::YcbcrMatrix::kRec2020;
        break;
      default:
        break;
    }
    layout.full_range = got_sc.colorSpace->range == CS::Range::Full;
  }

  api = libcamera_internal::DescribeExposureApi(camera->controls());
  for (auto& n : api.Notes()) adjustments.push_back(std::move(n));
  wanted = libcamera_internal::ClampToApi(api, wanted);
}

void LibcameraCamera::Impl::MapBuffers() {
  allocator = std::make_unique<lc::FrameBufferAllocator>(camera);
  if (const int ret = allocator->allocate(stream); ret < 0) {
    Fail("cannot allocate buffers (" + std::string(std::strerror(-ret)) + ")");
  }
  const auto& buffers = allocator->buffers(stream);
  if (buffers.empty()) Fail("the allocator gave no buffers");
  for (const std::unique_ptr<lc::FrameBuffer>& buffer : buffers) {
    // Planes may share one dmabuf at different offsets: map each fd once, over its extent.
    std::map<int, size_t> extent;
    for (const lc::FrameBuffer::Plane& p : buffer->planes()) {
      const size_t offset = p.offset == lc::FrameBuffer::Plane::kInvalidOffset ? 0 : p.offset;
      extent[p.fd.get()] = std::max(extent[p.fd.get()], offset + p.length);
    }
    std::map<int, const uint8_t*> base;
    for (const auto& [fd, length] : extent) {
      void* address = mmap(nullptr, length, PROT_READ, MAP_SHARED, fd, 0);
      if (address == MAP_FAILED) {
        Fail("cannot map a frame buffer (" + std::string(std::strerror(errno)) + ")");
      }
      mappings.push_back({address, length});
      base[fd] = static_cast<const uint8_t*>(address);
    }
    std::vector<libcamera_internal::PlaneBytes> views;
    for (const lc::FrameBuffer::Plane& p : buffer->planes()) {
      const size_t offset = p.offset == lc::FrameBuffer::Plane::kInvalidOffset ? 0 : p.offset;
      views.push_back({base[p.fd.get()] + offset, p.length});
    }
    planes[buffer.get()] = std::move(views);
  }
  for (size_t i = 0; i < buffers.size(); ++i) {
    std::unique_ptr<lc::Request> request = camera->createRequest(i);
    if (!request) Fail("cannot create a request");
    if (const int ret = request->addBuffer(stream, buffers[i].get()); ret < 0) {
      Fail("cannot attach a buffer to a request (" + std::string(std::strerror(-ret)) + ")");
    }
    requests.push_back(std::move(request));
  }
}

void LibcameraCamera::Impl::Queue(lc::Request* request) {
  libcamera_internal::SetManualExposure(api, wanted, &request->controls());
  if (const int ret = camera->queueRequest(request); ret < 0) {
    Fail("cannot queue a request (" + std::string(std::strerror(-ret)) + ")");
  }
  tracker->OnQueued(request->cookie(), wanted);
}

void LibcameraCamera::Impl::Start() {
  if (const int ret = camera->start(); ret != 0) {
    Fail("cannot start streaming (" + std::string(std::strerror(-ret)) + ")");
  }
  started = true;
  tracker->SetStopping(false);
  for (auto& request : requests) Queue(request.get());
}

void LibcameraCamera::Impl::Close() noexcept {
  if (started) {
    if (tracker) tracker->SetStopping(true);
    camera->stop();  // completes every pending request as cancelled before returning
    started = false;
  }
  if (camera) {
    camera->requestCompleted.disconnect(this);
    camera->disconnected.disconnect(this);
  }
  {
    std::lock_guard<std::mutex> lock(mutex);
    completed.clear();
  }
  requests.clear();
  for (const Mapping& m : mappings) munmap(m.address, m.length);
  mappings.clear();
  planes.clear();
  if (allocator && stream) allocator->free(stream);
  allocator.reset();
  if (acquired) camera->release();
  acquired = false;
  camera.reset();
  config.reset();
  manager.reset();
}

LibcameraCamera::LibcameraCamera(const LibcameraOptions& options)
    : impl_(std::make_unique<Impl>()) {
  try {
    options.Validate();
  } catch (const Error& e) {
    throw DeviceError(e.what());
  }
  impl_->options = options;
  impl_->name = "libcamera camera '" + options.camera_id + "'";
  impl_->tracker = std::make_unique<libcamera_internal::RequestTracker>(TrackerOptions(options));
  try {
    impl_->Open();
    impl_->Configure();
    impl_->MapBuffers();
  } catch (...) {
    impl_->Close();
    throw;
  }
}

LibcameraCamera::~LibcameraCamera() { impl_->Close(); }

std::string LibcameraCamera::Id() const { return impl_->camera ? impl_->camera->id() : ""; }

std::vector<ControlInfo> LibcameraCamera::Controls() const {
  const auto& api = impl_->api;
  return {{"exposure_s", api.exposure_min_s.value_or(1e-6), api.exposure_max_s.value_or(1.0),
           impl_->wanted.exposure_s},
          {"gain", api.gain_min.value_or(1.0), api.gain_max.value_or(1.0), impl_->wanted.gain},
          {"nd_density", 0.0, 10.0, impl_->nd}};
}

double LibcameraCamera::SetExposure(double seconds) {
  if (!(seconds > 0) || !std::isfinite(seconds)) {
    throw DeviceError(impl_->name + ": exposure " + std::to_string(seconds) +
                      " s is not a positive number");
  }
  ExposureSetting s = impl_->wanted;
  s.exposure_s = seconds;
  impl_->wanted = libcamera_internal::ClampToApi(impl_->api, s);
  return impl_->wanted.exposure_s;
}

double LibcameraCamera::SetGain(double gain) {
  if (!(gain > 0) || !std::isfinite(gain)) {
    throw DeviceError(impl_->name + ": gain " + std::to_string(gain) + " is not a positive number");
  }
  ExposureSetting s = impl_->wanted;
  s.gain = gain;
  impl_->wanted = libcamera_internal::ClampToApi(impl_->api, s);
  return impl_->wanted.gain;
}

void LibcameraCamera::SetNdFilter(double density) {
  if (!(density >= 0) || !std::isfinite(density)) {
    throw DeviceError(impl_->name + ": ND density " + std::to_string(density) +
                      " is not a number >= 0");
  }
  impl_->nd = density;
}

double LibcameraCamera::NdFilter() const { return impl_->nd; }

const std::vector<std::string>& LibcameraCamera::Adjustments() const { return impl_->adjustments; }

std::string LibcameraCamera::Configuration() const {
  const auto& l = impl_->layout;
  return libcamera_internal::FormatName(l.format) + " " + std::to_string(l.width) + "x" +
         std::to_string(l.height) + " stride " + std::to_string(l.stride) + " buffers " +
         std::to_string(impl_->requests.size());
}

const LibcameraGrabReport& LibcameraCamera::LastGrab() const { return impl_->last; }

CapturedFrame LibcameraCamera::Grab() {
  Impl& m = *impl_;
  std::lock_guard<std::mutex> grab_lock(m.grab_mutex);
  {
    std::lock_guard<std::mutex> lock(m.mutex);
    if (m.disconnected) m.Fail("disconnected");
  }
  m.tracker->BeginGrab(m.wanted);
  if (!m.started) m.Start();

  const double per_frame_s = m.wanted.exposure_s + 0.1;
  const double timeout_s =
      m.options.grab_timeout_s +
      (m.options.max_frames_per_grab + m.options.request_count + 2) * per_frame_s;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(timeout_s));
  for (;;) {
    lc::Request* request = nullptr;
    {
      std::unique_lock<std::mutex> lock(m.mutex);
      if (!m.cv.wait_until(lock, deadline,
                           [&] { return !m.completed.empty() || m.disconnected; })) {
        m.Fail("no frame within " + std::to_string(timeout_s) + " s");
      }
      if (m.disconnected) m.Fail("disconnected");
      request = m.completed.front();
      m.completed.pop_front();
    }
    libcamera_internal::Completion c;
    c.cookie = request->cookie();
    lc::FrameBuffer* buffer = request->findBuffer(m.stream);
    if (request->status() == lc::Request::RequestCancelled) {
      c.status = libcamera_internal::CompletionStatus::kCancelled;
    } else if (buffer == nullptr || buffer->metadata().status != lc::FrameMetadata::FrameSuccess) {
      c.status = libcamera_internal::CompletionStatus::kFailed;
    }
    const auto meta = libcamera_internal::ReadAppliedMetadata(request->metadata());
    c.applied_exposure_s = meta.exposure_s;
    c.applied_gain = meta.gain;
    const libcamera_internal::Decision d = m.tracker->OnCompleted(c);

    auto requeue = [&] {
      request->reuse(lc::Request::ReuseBuffers);
      m.Queue(request);
    };
    switch (d.verdict) {
      case libcamera_internal::Verdict::kRequeue:
        requeue();
        continue;
      case libcamera_internal::Verdict::kDrop:
        continue;
      case libcamera_internal::Verdict::kFail:
        requeue();
        m.Fail(d.reason);
      case libcamera_internal::Verdict::kAccept:
      case libcamera_internal::Verdict::kAcceptFallback:
        break;
    }

    CapturedFrame frame;
    try {
      frame.image = libcamera_internal::ConvertFrame(m.layout, m.planes.at(buffer));
    } catch (const Error& e) {
      requeue();
      m.Fail(e.what());
    }
    frame.hdr = false;
    frame.exposure_s = d.applied.exposure_s;
    frame.gain = d.applied.gain;
    frame.nd_density = m.nd;
    // Mid-exposure: SensorTimestamp marks the start of the exposure of the first row.
    int64_t sensor_ns = 0;
    bool from_sensor = false;
    if (meta.sensor_timestamp_ns) {
      sensor_ns = *meta.sensor_timestamp_ns;
      from_sensor = true;
    } else if (buffer->metadata().timestamp != 0) {
      sensor_ns = static_cast<int64_t>(buffer->metadata().timestamp);
      from_sensor = true;
    }
    const int64_t half_exposure_ns = std::llround(d.applied.exposure_s * 0.5e9);
    frame.utc.ns = from_sensor ? SensorToUtcNs(sensor_ns, m.options.sensor_clock) + half_exposure_ns
                               : NowUtc().ns - half_exposure_ns;

    LibcameraGrabReport& r = m.last;
    r.wanted_exposure_s = m.wanted.exposure_s;
    r.wanted_gain = m.wanted.gain;
    r.requested_exposure_s = d.requested.exposure_s;
    r.requested_gain = d.requested.gain;
    r.applied_exposure_s = d.applied.exposure_s;
    r.applied_gain = d.applied.gain;
    r.exposure_reported = d.exposure_reported;
    r.gain_reported = d.gain_reported;
    r.matched = d.verdict == libcamera_internal::Verdict::kAccept;
    r.frames_examined = d.fresh_frames;
    r.sequence = request->sequence();
    r.sensor_timestamp = from_sensor;
    r.reason = d.reason;
    requeue();
    return frame;
  }
}

}  // namespace rouen
