#include "capture/gphoto2/testing/sim_ptpip_camera.h"

#include <bit>
#include <string>

#include "core/error.h"
#include "core/hash_random.h"

namespace rouen {

SimPtpIpCamera::SimPtpIpCamera(std::shared_ptr<SimWorld> world, SimClock* clock, bool quick,
                               uint64_t seed, Gphoto2Options camera,
                               PtpIpResponderOptions responder)
    : sim_(std::move(world), clock, quick, seed),
      clock_(clock),
      seed_(seed),
      options_(std::move(camera)) {
  responder.frame = [this](const PtpShot& shot) { return Expose(shot); };
  responder_ = std::make_unique<PtpIpResponder>(std::move(responder));
  options_.port = responder_->PortPath();
  options_.model = "PTP/IP Camera";
  driver_ = std::make_unique<Gphoto2Camera>(options_);
}

SimPtpIpCamera::~SimPtpIpCamera() {
  driver_.reset();     // closes the PTP session while the responder still answers
  responder_.reset();  // joins its thread: no callback runs after this
}

std::string SimPtpIpCamera::Id() const { return driver_->Id(); }
std::vector<ControlInfo> SimPtpIpCamera::Controls() const { return driver_->Controls(); }
double SimPtpIpCamera::SetExposure(double seconds) { return driver_->SetExposure(seconds); }
double SimPtpIpCamera::SetGain(double gain) { return driver_->SetGain(gain); }

void SimPtpIpCamera::SetNdFilter(double density) {
  driver_->SetNdFilter(density);  // validates; the driver reports it with each frame
  std::lock_guard<std::mutex> lock(mu_);
  nd_ = density;
}

double SimPtpIpCamera::NdFilter() const {
  std::lock_guard<std::mutex> lock(mu_);
  return nd_;
}

int SimPtpIpCamera::ViewCount(Target target) const { return sim_.ViewCount(target); }
void SimPtpIpCamera::Aim(Target target, int view) {
  sim_.Aim(target, view);  // throws DeviceError for a view the mounts do not have
  target_ = target;
  view_ = view;
}

Image SimPtpIpCamera::Expose(const PtpShot& shot) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!pending_)
    throw Error("sim PTP/IP camera: a capture was triggered outside Grab()");  // a test bug
  const Pending& p = *pending_;
  uint64_t h = MixHash(seed_ * 0x9E3779B97F4A7C15ULL + static_cast<uint64_t>(p.slot_ns));
  h = MixHash(h + static_cast<uint64_t>(p.target) * 64 + static_cast<uint64_t>(p.view));
  h = MixHash(h + std::bit_cast<uint64_t>(shot.exposure_s));
  h = MixHash(h + static_cast<uint64_t>(shot.iso));
  h = MixHash(h + std::bit_cast<uint64_t>(nd_));
  Image im =
      sim_.sensor().Capture(*p.radiance, shot.exposure_s, shot.iso / options_.base_iso, nd_, h);
  shots_.push_back({shot, p.target, p.view, nd_, UtcTime{p.slot_ns}});
  return im;
}

CapturedFrame SimPtpIpCamera::Grab() {
  const Image& radiance = sim_.CurrentRadiance();  // renders on this thread
  const SimView view = sim_.CurrentView();
  {
    std::lock_guard<std::mutex> lock(mu_);
    pending_ = Pending{&radiance, target_, view_, clock_->SlotTime().ns};
  }
  CapturedFrame f;
  try {
    f = driver_->Grab();
  } catch (...) {
    std::lock_guard<std::mutex> lock(mu_);
    pending_.reset();
    throw;
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    pending_.reset();
    f.nd_density = nd_;
  }
  f.intrinsics = view.intrinsics;
  f.pose = view.pose;
  f.utc = clock_->Now().PlusSeconds(0.5 * f.exposure_s);
  clock_->Advance(f.exposure_s + 0.2);
  return f;
}

void SimPtpIpCamera::Reopen() {
  // The new connection first: when the camera is not back, the old driver stays (and keeps
  // saying the connection was lost).
  auto next = std::make_unique<Gphoto2Camera>(options_);
  driver_ = std::move(next);
  std::lock_guard<std::mutex> lock(mu_);
  driver_->SetNdFilter(nd_);
}

std::vector<SimPtpIpShot> SimPtpIpCamera::Shots() const {
  std::lock_guard<std::mutex> lock(mu_);
  return shots_;
}

}  // namespace rouen
