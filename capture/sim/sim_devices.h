// Simulated devices over a shared SimWorld: a clock that jumps to the plan's slots, a camera
// (per-target optics and mounts, exposure/gain/ND controls, the SimSensor) and a GPS.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "capture/device.h"
#include "capture/sim/sensor.h"
#include "capture/sim/sim_world.h"
#include "core/error.h"

namespace rouen {

// Simulated time. Now() advances only when told (each grab advances it by the exposure plus
// 0.2 s of handling); JumpTo moves to a slot's start and makes it the lighting time.
class SimClock : public Clock {
 public:
  // Default start: 2026-08-25T20:00:00Z (13:00 PDT).
  SimClock();
  explicit SimClock(UtcTime start);
  UtcTime Now() override { return now_; }
  bool JumpTo(UtcTime t) override;
  void Advance(double seconds);
  // The instant the world is lit for: the last JumpTo target (or the start).
  UtcTime SlotTime() const { return slot_; }

 private:
  UtcTime now_, slot_;
};

class SimCamera : public Camera {
 public:
  // `clock` must outlive the camera. `quick`: 320x240 architecture views.
  SimCamera(std::shared_ptr<SimWorld> world, SimClock* clock, bool quick, uint64_t seed,
            const SensorParams& sensor = {});
  ~SimCamera() override;

  std::string Id() const override { return "sim0"; }
  std::vector<ControlInfo> Controls() const override;
  // Clamped to [1/8000, 30] s and quantised to 1/3-stop steps (2^(n/3) s).
  double SetExposure(double seconds) override;
  double SetGain(double gain) override;       // clamped to [1, 16]
  void SetNdFilter(double density) override;  // any density >= 0
  double NdFilter() const override { return nd_; }
  // Architecture: 4 views; landscape: 2 (tripod and mast); every other target: 1.
  int ViewCount(Target target) const override;
  void Aim(Target target, int view) override;
  // Renders (cached per target, view and slot) and exposes one frame at the clock's time.
  CapturedFrame Grab() override;

  const SimSensor& sensor() const { return sensor_; }
  const SimWorld& world() const { return *world_; }
  // The current aim's optics and mount at the clock's slot time.
  SimView CurrentView();
  // The true radiance the next Grab() exposes (cached).
  const Image& CurrentRadiance();
  // The true radiance a view of a target shows at a slot's instant, as the frames aimed there
  // expose it (cached: rendered once per target, view and slot). Makes `slot` the world's time.
  // The target's other views at that slot are rendered meanwhile on other threads, for the
  // frames that follow (a capture takes every view of a target).
  const Image& Radiance(Target target, int view, UtcTime slot);

  static constexpr double kMinExposure = 1.0 / 8000, kMaxExposure = 30.0;
  static constexpr double kMinGain = 1.0, kMaxGain = 16.0;

 private:
  std::shared_ptr<SimWorld> world_;
  SimClock* clock_;
  bool quick_;
  uint64_t seed_;
  SimSensor sensor_;
  double exposure_ = 1.0 / 250, gain_ = 1.0, nd_ = 0.0;
  Target target_ = Target::kArchitecture;
  int view_ = 0;
  uint64_t frames_ = 0;
  void CheckView(Target target, int view) const;  // throws DeviceError for no such view
  SimView ViewAt(Target target, int view);        // at the world's current time
  std::map<std::tuple<int, int, int64_t>, Image> cache_;
  struct Pending;  // the renders running for entries of cache_
  std::unique_ptr<Pending> pending_;
};

// Fixes at the world's site with Gaussian noise (sigma per horizontal axis ~1.8 m, so about
// 2.5 m RMS horizontally; 3 m vertically), 3-D mode, time from the clock.
class SimGps : public Gps {
 public:
  SimGps(std::shared_ptr<SimWorld> world, SimClock* clock, uint64_t seed,
         double sigma_horizontal_m = 1.8);
  std::string Id() const override { return "simgps"; }
  std::optional<GpsFix> Poll() override;

 private:
  std::shared_ptr<SimWorld> world_;
  SimClock* clock_;
  uint64_t seed_;
  double sigma_;
  uint64_t polls_ = 0;
};

}  // namespace rouen
