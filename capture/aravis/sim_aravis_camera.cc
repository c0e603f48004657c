// The simulated world through the Aravis driver.
//
// Each Grab(): the SimCamera renders and exposes the frame (same seed, same clock handling as a
// plain SimCamera, so the same frames in the same order); the frame is packed as RGB8 (the Fake
// camera of Aravis 0.8.26 offers RGB8, so the 3 channels travel unchanged: the sensor's output
// is integer digital numbers 0..255) and handed to the Fake camera's fill-pattern callback,
// which writes it into the next buffer the Fake camera fills, stamps the buffer's system
// timestamp with the simulated end of exposure, and only does so when the Fake camera's
// exposure and gain registers hold the values set for this frame. The AravisCamera then
// delivers it like any camera frame: status, frame-id gaps, pixel format and size checks,
// decoding, timestamp (end of exposure minus half the read-back exposure). A delivered frame
// whose timestamp is not this frame's (filled before the hand-over) is counted as stale and
// waited past; the driver's discard of in-flight buffers should make that count zero.
//
// Exposure: the SimCamera quantises to 1/3 stop (2^(n/3) s) and renders with that; the Fake
// camera's ExposureTimeAbs register holds whole microseconds (its converter truncates; we ask
// for the nearest), and the driver reports the read-back value: |reported - rendered| <=
// 0.5 us (0.33% at the shortest non-integer value, 2^(-38/3) s = 153.8 us; 1/8000 s = 125 us is
// exact). The range is [1/8000 s, 8 s] (8 s = the longest 1/3-stop value within the Fake
// camera's 10 s maximum).
// Gain: the Fake camera has GainRaw 0..10, taken as 1 dB per step (linear 1 .. 3.16); the
// read-back gain is given to the SimCamera, so rendered and reported gains agree exactly.
#include <arv.h>

#include <cmath>
#include <cstring>
#include <mutex>
#include <optional>

#include "capture/aravis/aravis_camera.h"
#include "capture/aravis/aravis_internal.h"
#include "capture/sim/sim_devices.h"

namespace rouen {
namespace {

class SimAravisCamera : public Camera {
 public:
  SimAravisCamera(std::shared_ptr<SimWorld> world, SimClock* clock, bool quick, uint64_t seed)
      : sim_(std::move(world), clock, quick, seed) {
    AravisOptions o;
    o.device_id = "Fake_1";
    o.enable_fake_interface = true;
    o.pixel_format = "RGB8";
    o.trigger = AravisTrigger::kFreeRun;  // the in-process Fake stream ignores triggers
    // The in-process Fake stream fills at most one buffer between two queue checks.
    o.settle_frames = 1;
    o.frame_rate = 200;
    o.buffers = 4;
    o.raw_gain_db_per_step = 1.0;
    arv_ = std::make_unique<AravisCamera>(o);
    ArvDevice* device = arv_camera_get_device(arv_->impl().camera);
    if (!ARV_IS_FAKE_DEVICE(device)) throw DeviceError(arv_->Id() + ": not the Fake camera");
    fake_ = arv_fake_device_get_fake_camera(ARV_FAKE_DEVICE(device));
    arv_fake_camera_set_fill_pattern(fake_, &SimAravisCamera::Fill, this);
    // Start from the SimCamera's settings.
    SetExposure(sim_.Controls()[0].value);
    SetGain(1.0);
  }

  ~SimAravisCamera() override {
    if (fake_) arv_fake_camera_set_fill_pattern(fake_, nullptr, nullptr);
    arv_.reset();  // joins the Fake stream thread
  }

  std::string Id() const override { return arv_->Id(); }

  std::vector<ControlInfo> Controls() const override {
    std::vector<ControlInfo> c = arv_->Controls();
    c[0].min = SimCamera::kMinExposure;
    c[0].max = kMaxExposure;
    return c;
  }

  double SetExposure(double seconds) override {
    if (!(seconds > 0) || !std::isfinite(seconds)) return arv_->SetExposure(seconds);  // throws
    const double rendered = sim_.SetExposure(std::min(seconds, kMaxExposure));
    // The Fake camera's GenICam converter truncates to whole microseconds: ask for the nearest
    // whole microsecond plus a quarter so that truncation (or rounding) lands on it.
    exposure_s_ = arv_->SetExposure((std::round(rendered * 1e6) + 0.25) * 1e-6);
    if (std::abs(exposure_s_ - rendered) > 0.5e-6 + 1e-12) {
      throw DeviceError(Id() + ": Fake camera holds " + std::to_string(exposure_s_) +
                        " s for a rendered exposure of " + std::to_string(rendered) + " s");
    }
    return exposure_s_;
  }

  double SetGain(double gain) override {
    gain_ = arv_->SetGain(gain);
    sim_.SetGain(gain_);
    return gain_;
  }

  void SetNdFilter(double density) override {
    sim_.SetNdFilter(density);
    arv_->SetNdFilter(density);
  }
  double NdFilter() const override { return sim_.NdFilter(); }
  int ViewCount(Target target) const override { return sim_.ViewCount(target); }
  void Aim(Target target, int view) override { sim_.Aim(target, view); }

  CapturedFrame Grab() override {
    CapturedFrame s = sim_.Grab();
    const int w = s.image.width, h = s.image.height;
    Pending p;
    p.width = w;
    p.height = h;
    p.bytes.resize(static_cast<size_t>(w) * h * 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) {
          const float v = s.image.at(x, y, s.image.channels == 3 ? c : 0);
          if (!(v >= 0 && v <= 255) || v != std::round(v)) {
            throw DeviceError(Id() + ": simulated sensor value " + std::to_string(v) +
                              " is not an 8-bit digital number");
          }
          p.bytes[(static_cast<size_t>(y) * w + x) * 3 + c] = static_cast<uint8_t>(v);
        }
    p.exposure_us = static_cast<uint32_t>(std::llround(exposure_s_ * 1e6));
    p.gain_raw = static_cast<uint32_t>(std::llround(20 * std::log10(gain_)));
    p.system_ns = static_cast<uint64_t>(s.utc.ns + std::llround(exposure_s_ * 0.5e9));
    arv_->SetRegion(w, h);
    {
      std::lock_guard<std::mutex> lock(mu_);
      pending_ = std::move(p);
    }
    CapturedFrame a;
    for (int attempt = 0;; ++attempt) {
      arv_->DiscardInFlight();
      a = arv_->Grab();
      if (a.utc == s.utc) break;
      ++stale_frames_;
      if (attempt == 3) {
        throw DeviceError(Id() + ": the Fake camera did not deliver the simulated frame");
      }
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      pending_.reset();
    }
    CapturedFrame out;
    out.image = std::move(a.image);
    out.hdr = false;
    out.exposure_s = a.exposure_s;
    out.gain = a.gain;
    out.nd_density = sim_.NdFilter();
    out.utc = a.utc;
    out.intrinsics = s.intrinsics;
    out.pose = s.pose;
    return out;
  }

  // The longest 1/3-stop exposure within the Fake camera's 10 s maximum.
  static constexpr double kMaxExposure = 8.0;

 private:
  struct Pending {
    std::vector<uint8_t> bytes;  // RGB8
    int width = 0, height = 0;
    uint32_t exposure_us = 0, gain_raw = 0;
    uint64_t system_ns = 0;  // simulated end of exposure
  };

  // Runs on the Fake stream thread, under the Fake camera's fill mutex.
  static void Fill(ArvBuffer* buffer, void* data, guint32 exposure_us, guint32 gain,
                   ArvPixelFormat format) {
    auto* self = static_cast<SimAravisCamera*>(data);
    std::lock_guard<std::mutex> lock(self->mu_);
    const std::optional<Pending>& p = self->pending_;
    if (!p || format != ARV_PIXEL_FORMAT_RGB_8_PACKED ||
        arv_buffer_get_image_width(buffer) != p->width ||
        arv_buffer_get_image_height(buffer) != p->height || exposure_us != p->exposure_us ||
        gain != p->gain_raw) {
      arv_buffer_set_system_timestamp(buffer, 1);  // not this frame: an impossible time
      return;
    }
    auto* dst = static_cast<uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    std::memcpy(dst, p->bytes.data(), p->bytes.size());
    arv_buffer_set_system_timestamp(buffer, p->system_ns);
  }

  SimCamera sim_;
  std::unique_ptr<AravisCamera> arv_;
  ArvFakeCamera* fake_ = nullptr;
  double exposure_s_ = 0, gain_ = 1;
  std::mutex mu_;
  std::optional<Pending> pending_;
  uint64_t stale_frames_ = 0;

 public:
  AravisStats Stats() const {
    AravisStats st = arv_->Stats();
    st.stale = stale_frames_;
    return st;
  }
};

}  // namespace

std::optional<AravisStats> AravisStatsOf(const Camera& camera) {
  if (const auto* a = dynamic_cast<const AravisCamera*>(&camera)) return a->Stats();
  if (const auto* s = dynamic_cast<const SimAravisCamera*>(&camera)) return s->Stats();
  return std::nullopt;
}

std::unique_ptr<Camera> OpenSimAravisCamera(std::shared_ptr<SimWorld> world, SimClock* clock,
                                            bool quick, uint64_t seed) {
  return std::make_unique<SimAravisCamera>(std::move(world), clock, quick, seed);
}

}  // namespace rouen
