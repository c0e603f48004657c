#include "capture/replay/replay_devices.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "capture/controller.h"
#include "core/error.h"

namespace rouen {

ReplaySource::ReplaySource(const std::filesystem::path& session_dir)
    : session_(Session::Load(session_dir)) {
  if (session_.frames().empty())
    throw Error("replay: session " + session_dir.string() + " has no frames");
  std::map<int, UtcTime> first;
  for (const FrameRecord& f : session_.frames()) {
    groups_[f.group].push_back(&f);
    views_[f.target] = std::max(views_[f.target], 0);
    if (!first.count(f.slot) || f.utc < first[f.slot]) first[f.slot] = f.utc;
  }
  // View counts from the group names ("slotK/target/viewV").
  for (const auto& [name, frames] : groups_) {
    auto pos = name.rfind("/view");
    if (pos == std::string::npos) continue;
    int v = std::atoi(name.c_str() + pos + 5);
    Target t = frames.front()->target;
    views_[t] = std::max(views_[t], v + 1);
  }
  const nlohmann::json& extra = session_.info().extra;
  if (extra.contains("plan") && extra["plan"].contains("slots")) {
    for (const auto& s : extra["plan"]["slots"])
      slot_times_.push_back(ParseIso8601(s.get<std::string>()));
  } else {
    for (const auto& [slot, t] : first) {
      if (slot != static_cast<int>(slot_times_.size()))
        throw Error("replay: session " + session_dir.string() + " has no frames for slot " +
                    std::to_string(slot_times_.size()));
      slot_times_.push_back(t);
    }
  }
}

const std::vector<const FrameRecord*>* ReplaySource::Group(const std::string& group) const {
  auto it = groups_.find(group);
  return it == groups_.end() ? nullptr : &it->second;
}

int ReplaySource::ViewCount(Target target) const {
  auto it = views_.find(target);
  return it == views_.end() ? 0 : it->second;
}

bool ReplayClock::JumpTo(UtcTime t) {
  const auto& slots = src_->slot_times();
  for (size_t i = 0; i < slots.size(); ++i) {
    if (slots[i] == t) {
      src_->current_slot = static_cast<int>(i);
      now_ = t;
      return true;
    }
  }
  return false;
}

std::string ReplayCamera::Id() const {
  const auto& frames = src_->session().frames();
  return frames.empty() ? "replay" : frames.front().device;
}

std::vector<ControlInfo> ReplayCamera::Controls() const {
  double lo = std::numeric_limits<double>::max(), hi = 0;
  for (const FrameRecord& f : src_->session().frames()) {
    if (f.hdr) continue;
    lo = std::min(lo, f.exposure_s);
    hi = std::max(hi, f.exposure_s);
  }
  if (hi == 0) lo = 0;
  return {{"exposure_s", lo, hi, exposure_}, {"gain", 1, 1, gain_}};
}

double ReplayCamera::SetExposure(double seconds) {
  exposure_ = seconds;
  return seconds;
}

void ReplayCamera::Aim(Target target, int view) {
  target_ = target;
  view_ = view;
}

CapturedFrame ReplayCamera::Grab() {
  const std::string group = BracketName(src_->current_slot, target_, view_);
  const auto* frames = src_->Group(group);
  if (!frames) throw DeviceError("replay: the recorded session has no bracket " + group);
  const FrameRecord* best = nullptr;
  double best_d = std::numeric_limits<double>::max();
  for (const FrameRecord* f : *frames) {
    if (std::abs(f->nd_density - nd_) > 1e-6) continue;
    double d = f->hdr ? 0 : std::abs(std::log2(f->exposure_s / exposure_));
    if (d < best_d) {
      best_d = d;
      best = f;
    }
  }
  if (!best)
    throw DeviceError("replay: bracket " + group + " has no frame with ND density " +
                      std::to_string(nd_));
  CapturedFrame out;
  out.image = src_->session().LoadFrame(*best);
  out.hdr = best->hdr;
  out.exposure_s = best->exposure_s;
  out.gain = best->gain;
  out.nd_density = best->nd_density;
  out.utc = best->utc.PlusSeconds(-src_->session().info().clock_offset_s);
  out.intrinsics = best->intrinsics;
  out.pose = best->pose;
  src_->last_gps = best->gps;
  return out;
}

}  // namespace rouen
