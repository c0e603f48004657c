#include "capture/sim/sim_devices.h"

#include <tbb/task_group.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/angles.h"
#include "core/hash_random.h"

namespace rouen {
namespace {

double Normal(uint64_t h) {
  double n1 = 0, n2 = 0;
  HashNormals(h, &n1, &n2);
  return n1;
}

UtcTime DefaultStart() { return FromCivil(CivilTime{2026, 8, 25, 20, 0, 0.0}); }

}  // namespace

SimClock::SimClock() : SimClock(DefaultStart()) {}
SimClock::SimClock(UtcTime start) : now_(start), slot_(start) {}

bool SimClock::JumpTo(UtcTime t) {
  now_ = t;
  slot_ = t;
  return true;
}

void SimClock::Advance(double seconds) {
  if (!(seconds >= 0) || !std::isfinite(seconds)) {
    throw Error("sim clock: cannot advance by " + std::to_string(seconds) + " s");
  }
  now_ = now_.PlusSeconds(seconds);
}

struct SimCamera::Pending {
  std::map<std::tuple<int, int, int64_t>, Image>* cache;
  std::map<std::tuple<int, int, int64_t>, std::unique_ptr<tbb::task_group>> renders;
  // Waits for the render of `key` if one is running; on its error, drops its cache entry and
  // rethrows.
  void Wait(const std::tuple<int, int, int64_t>& key) {
    const auto it = renders.find(key);
    if (it == renders.end()) return;
    const std::unique_ptr<tbb::task_group> group = std::move(it->second);
    renders.erase(it);
    try {
      group->wait();
    } catch (...) {
      cache->erase(key);
      throw;
    }
  }
  void WaitAll() {
    while (!renders.empty()) Wait(renders.begin()->first);
  }
};

SimCamera::SimCamera(std::shared_ptr<SimWorld> world, SimClock* clock, bool quick, uint64_t seed,
                     const SensorParams& sensor)
    : world_(std::move(world)),
      clock_(clock),
      quick_(quick),
      seed_(seed),
      sensor_(sensor),
      pending_(std::make_unique<Pending>(Pending{&cache_, {}})) {
  if (!world_ || !clock_) throw Error("sim camera: needs a world and a clock");
}

SimCamera::~SimCamera() {
  for (auto& [key, group] : pending_->renders) {
    try {
      group->wait();
    } catch (...) {
      // An image no frame will use.
    }
  }
}

std::vector<ControlInfo> SimCamera::Controls() const {
  return {{"exposure_s", kMinExposure, kMaxExposure, exposure_},
          {"gain", kMinGain, kMaxGain, gain_},
          {"nd_density", 0.0, 10.0, nd_}};
}

double SimCamera::SetExposure(double seconds) {
  if (!(seconds > 0) || !std::isfinite(seconds)) {
    throw DeviceError("sim0: exposure " + std::to_string(seconds) + " s is not positive");
  }
  const double thirds = std::round(3.0 * std::log2(seconds));
  exposure_ = std::clamp(std::exp2(thirds / 3.0), kMinExposure, kMaxExposure);
  return exposure_;
}

double SimCamera::SetGain(double gain) {
  if (!std::isfinite(gain)) throw DeviceError("sim0: gain is not finite");
  gain_ = std::clamp(gain, kMinGain, kMaxGain);
  return gain_;
}

void SimCamera::SetNdFilter(double density) {
  if (!(density >= 0) || !std::isfinite(density)) {
    throw DeviceError("sim0: ND density " + std::to_string(density) + " must be >= 0");
  }
  nd_ = density;
}

int SimCamera::ViewCount(Target target) const {
  switch (target) {
    case Target::kArchitecture:
      return 4;
    case Target::kLandscape:
      return 2;
    default:
      return 1;
  }
}

void SimCamera::CheckView(Target target, int view) const {
  if (view < 0 || view >= ViewCount(target)) {
    throw DeviceError(std::string("sim0: target ") + TargetName(target) + " has no view " +
                      std::to_string(view));
  }
}

void SimCamera::Aim(Target target, int view) {
  CheckView(target, view);
  target_ = target;
  view_ = view;
}

SimView SimCamera::CurrentView() {
  world_->SetTime(clock_->SlotTime());
  return ViewAt(target_, view_);
}

SimView SimCamera::ViewAt(Target target, int view) {
  switch (target) {
    case Target::kSun:
      return world_->SunView();
    case Target::kAureole:
    case Target::kSky:
      return world_->SkyView();
    case Target::kLandscape:
      return world_->LandscapeViews()[view];
    case Target::kArchitecture:
      return world_->ArchitectureViews(quick_)[view];
    case Target::kCalibration:
      return world_->ArchitectureViews(quick_)[0];
  }
  return world_->ArchitectureViews(quick_)[0];
}

const Image& SimCamera::CurrentRadiance() { return Radiance(target_, view_, clock_->SlotTime()); }

const Image& SimCamera::Radiance(Target target, int view, UtcTime slot) {
  CheckView(target, view);
  // Aureole frames show the same sky as sky frames.
  const int t =
      target == Target::kAureole ? static_cast<int>(Target::kSky) : static_cast<int>(target);
  const auto key = std::make_tuple(t, view, slot.ns);
  pending_->Wait(key);
  auto it = cache_.find(key);
  if (it != cache_.end()) return it->second;
  // The renders running use the world's current time: they end before it changes.
  if (!world_->HasTime() || !(world_->Time() == slot)) pending_->WaitAll();
  world_->SetTime(slot);
  const SimView v = ViewAt(target, view);
  it = cache_.emplace(key, world_->RenderRadiance(v.intrinsics, v.pose)).first;
  for (int other = 0; other < ViewCount(target); ++other) {
    const auto other_key = std::make_tuple(t, other, slot.ns);
    if (cache_.count(other_key)) continue;
    Image* out = &cache_[other_key];
    const SimView ov = ViewAt(target, other);
    auto group = std::make_unique<tbb::task_group>();
    group->run([this, out, ov] { *out = world_->RenderRadiance(ov.intrinsics, ov.pose); });
    pending_->renders.emplace(other_key, std::move(group));
  }
  return it->second;
}

CapturedFrame SimCamera::Grab() {
  const Image& radiance = CurrentRadiance();
  const SimView v = CurrentView();
  CapturedFrame f;
  f.image =
      sensor_.Capture(radiance, exposure_, gain_, nd_, MixHash(seed_ * 1000003ULL + frames_++));
  f.hdr = false;
  f.exposure_s = exposure_;
  f.gain = gain_;
  f.nd_density = nd_;
  f.utc = clock_->Now().PlusSeconds(0.5 * exposure_);
  f.intrinsics = v.intrinsics;
  f.pose = v.pose;
  clock_->Advance(exposure_ + 0.2);
  return f;
}

SimGps::SimGps(std::shared_ptr<SimWorld> world, SimClock* clock, uint64_t seed,
               double sigma_horizontal_m)
    : world_(std::move(world)), clock_(clock), seed_(seed), sigma_(sigma_horizontal_m) {
  if (!world_ || !clock_) throw Error("sim gps: needs a world and a clock");
  if (!(sigma_ >= 0) || !std::isfinite(sigma_)) throw Error("sim gps: bad noise sigma");
}

std::optional<GpsFix> SimGps::Poll() {
  const Site& site = world_->site();
  const uint64_t h = MixHash(seed_ * 0x51ED27ULL + polls_++);
  const double north = sigma_ * Normal(MixHash(h + 1));
  const double east = sigma_ * Normal(MixHash(h + 2));
  const double up = 1.7 * sigma_ * Normal(MixHash(h + 3));
  // Metres to degrees on the WGS84 ellipsoid (meridian and prime-vertical radii).
  const double a = 6378137.0, e2 = 6.69437999014e-3;
  const double lat = site.lat_deg * kPi / 180;
  const double w = std::sqrt(1 - e2 * std::sin(lat) * std::sin(lat));
  const double m_radius = a * (1 - e2) / (w * w * w), n_radius = a / w;
  GpsFix f;
  f.utc = clock_->Now();
  f.lat_deg = site.lat_deg + north / m_radius * 180 / kPi;
  f.lon_deg = site.lon_deg + east / (n_radius * std::cos(lat)) * 180 / kPi;
  f.height_m = site.height_m + up;
  f.mode = 3;
  f.satellites = 9;
  f.hdop = 0.9;
  return f;
}

}  // namespace rouen
