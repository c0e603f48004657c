// Replay devices: serve a recorded session back through the Camera/Gps/Clock interfaces so
// the capture controller and everything downstream run exactly as in the field.
#pragma once

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "capture/device.h"
#include "core/session.h"

namespace rouen {

// The recorded session, indexed by bracket (slot, target, view).
class ReplaySource {
 public:
  explicit ReplaySource(const std::filesystem::path& session_dir);
  const Session& session() const { return session_; }
  const std::vector<UtcTime>& slot_times() const { return slot_times_; }
  // Frames of one bracket, in journal order.
  const std::vector<const FrameRecord*>* Group(const std::string& group) const;
  int ViewCount(Target target) const;

  int current_slot = 0;
  std::optional<GpsFix> last_gps;  // fix of the frame served last

 private:
  Session session_;
  std::vector<UtcTime> slot_times_;
  std::map<std::string, std::vector<const FrameRecord*>> groups_;
  std::map<Target, int> views_;
};

class ReplayClock : public Clock {
 public:
  explicit ReplayClock(std::shared_ptr<ReplaySource> src) : src_(std::move(src)) {}
  UtcTime Now() override { return now_; }
  // Jumps to a recorded slot; false when the session has no slot at `t`.
  bool JumpTo(UtcTime t) override;

 private:
  std::shared_ptr<ReplaySource> src_;
  UtcTime now_;
};

class ReplayCamera : public Camera {
 public:
  explicit ReplayCamera(std::shared_ptr<ReplaySource> src) : src_(std::move(src)) {}
  std::string Id() const override;
  std::vector<ControlInfo> Controls() const override;
  double SetExposure(double seconds) override;
  double SetGain(double gain) override { return gain_ = gain; }
  void SetNdFilter(double density) override { nd_ = density; }
  double NdFilter() const override { return nd_; }
  int ViewCount(Target target) const override { return src_->ViewCount(target); }
  void Aim(Target target, int view) override;
  // The recorded frame of the current bracket whose ND matches and whose exposure is closest
  // (in stops) to the one set. Throws DeviceError when the session has none.
  CapturedFrame Grab() override;

 private:
  std::shared_ptr<ReplaySource> src_;
  Target target_ = Target::kArchitecture;
  int view_ = 0;
  double exposure_ = 0.01, gain_ = 1, nd_ = 0;
};

class ReplayGps : public Gps {
 public:
  explicit ReplayGps(std::shared_ptr<ReplaySource> src) : src_(std::move(src)) {}
  std::string Id() const override { return "replay-gps"; }
  std::optional<GpsFix> Poll() override { return src_->last_gps; }

 private:
  std::shared_ptr<ReplaySource> src_;
};

}  // namespace rouen
