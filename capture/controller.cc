#include "capture/controller.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "core/angles.h"
#include "core/error.h"
#include "core/json_text.h"
#include "core/text.h"

namespace rouen {

void BracketOptions::Validate() const {
  auto bad = [](const std::string& what) { throw Error("bracket plan: " + what); };
  if (!(step_stops >= 0.33 && step_stops <= 4)) bad("step_stops must be within 0.33..4");
  if (!(min_exposure_s > 0) || !(max_exposure_s > min_exposure_s) || !std::isfinite(max_exposure_s))
    bad("exposure limits must satisfy 0 < min_exposure_s < max_exposure_s");
  if (max_frames < 1 || max_frames > 32) bad("max_frames must be within 1..32");
  if (!(saturation_dn > noise_floor_dn) || saturation_dn > 255 || noise_floor_dn < 0)
    bad("need 0 <= noise_floor_dn < saturation_dn <= 255");
  if (!(max_saturated_fraction >= 0 && max_saturated_fraction < 1)) bad("max_saturated_fraction");
  if (!(max_dark_fraction >= 0 && max_dark_fraction < 1)) bad("max_dark_fraction");
}

void CapturePlan::Validate() const {
  bracket.Validate();
  if (slots.empty()) throw Error("capture plan: no time-of-day slots");
  if (targets.empty()) throw Error("capture plan: no targets");
  if (!(sun_nd_density >= 0 && sun_nd_density < 10)) throw Error("capture plan: sun ND density");
  for (double e : aureole_exposures_s)
    if (!(e > 0) || !std::isfinite(e)) throw Error("capture plan: aureole exposures must be > 0");
  if (!(start_exposure_s > 0) || !(sun_start_exposure_s > 0))
    throw Error("capture plan: start exposures must be > 0");
  if (first_slot < 0) throw Error("capture plan: first_slot must be >= 0");
}

nlohmann::json PlanToJson(const CapturePlan& p) {
  nlohmann::json j;
  j["slots"] = nlohmann::json::array();
  for (UtcTime t : p.slots) j["slots"].push_back(t.Iso8601(9));
  j["targets"] = nlohmann::json::array();
  for (Target t : p.targets) j["targets"].push_back(TargetName(t));
  j["sun_nd_density"] = p.sun_nd_density;
  j["sun_start_exposure_s"] = p.sun_start_exposure_s;
  j["sun_extra_longer_frames"] = p.sun_extra_longer_frames;
  j["aureole_exposures_s"] = p.aureole_exposures_s;
  j["start_exposure_s"] = p.start_exposure_s;
  j["sun_exclusion_deg"] = p.sun_exclusion_deg;
  const BracketOptions& b = p.bracket;
  j["bracket"] = {{"step_stops", b.step_stops},
                  {"min_exposure_s", b.min_exposure_s},
                  {"max_exposure_s", b.max_exposure_s},
                  {"max_frames", b.max_frames},
                  {"saturation_dn", b.saturation_dn},
                  {"noise_floor_dn", b.noise_floor_dn},
                  {"max_saturated_fraction", b.max_saturated_fraction},
                  {"max_dark_fraction", b.max_dark_fraction}};
  return j;
}

CapturePlan PlanFromJson(const nlohmann::json& j) {
  CapturePlan p;
  try {
    p.slots.clear();
    for (const auto& s : j.at("slots")) p.slots.push_back(ParseIso8601(s.get<std::string>()));
    p.targets.clear();
    for (const auto& s : j.at("targets")) p.targets.push_back(ParseTarget(s.get<std::string>()));
    p.sun_nd_density = j.at("sun_nd_density").get<double>();
    p.sun_start_exposure_s = j.at("sun_start_exposure_s").get<double>();
    p.sun_extra_longer_frames =
        JsonGet<int>(j.at("sun_extra_longer_frames"), "sun_extra_longer_frames");
    p.aureole_exposures_s = j.at("aureole_exposures_s").get<std::vector<double>>();
    p.start_exposure_s = j.at("start_exposure_s").get<double>();
    p.sun_exclusion_deg = j.at("sun_exclusion_deg").get<double>();
    const auto& b = j.at("bracket");
    p.bracket.step_stops = b.at("step_stops").get<double>();
    p.bracket.min_exposure_s = b.at("min_exposure_s").get<double>();
    p.bracket.max_exposure_s = b.at("max_exposure_s").get<double>();
    p.bracket.max_frames = JsonGet<int>(b.at("max_frames"), "bracket.max_frames");
    p.bracket.saturation_dn = b.at("saturation_dn").get<double>();
    p.bracket.noise_floor_dn = b.at("noise_floor_dn").get<double>();
    p.bracket.max_saturated_fraction = b.at("max_saturated_fraction").get<double>();
    p.bracket.max_dark_fraction = b.at("max_dark_fraction").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("capture plan in session.json: ") + e.what());
  }
  p.Validate();
  return p;
}

CaptureController::CaptureController(CaptureDevices devices, CapturePlan plan, Site fallback_site,
                                     DeviceLossOptions loss)
    : dev_(std::move(devices)), plan_(std::move(plan)), fallback_site_(fallback_site), loss_(loss) {
  if (!dev_.camera || !dev_.clock) throw Error("capture: a camera and a clock are required");
  if (!(loss_.reconnect_timeout_s > 0) || !(loss_.retry_interval_s > 0))
    throw Error("capture: reconnect timeout and retry interval must be > 0");
  plan_.Validate();
}

void CaptureController::PollGps(SessionWriter& writer) {
  if (!dev_.gps) return;
  try {
    std::optional<GpsFix> fix = dev_.gps->Poll();
    gps_error_.clear();
    if (fix) {
      // A receiver that loses its fix keeps the last good position (the site does not move).
      if (fix->valid()) {
        last_fix_ = *fix;
      } else if (!last_fix_) {
        progress_.gps_status = "no fix yet";
      }
      clock_offset_.Add(*fix);
    }
  } catch (const DeviceError& e) {
    gps_error_ = e.what();
    progress_.gps_status = std::string("error: ") + e.what();
  }
  // Field rigs: frame times are the laptop's; record its offset from GPS time as it firms up.
  std::optional<double> offset = clock_offset_.Offset();
  if (offset && dev_.clock->IsLaptopClock() &&
      std::abs(*offset - writer.info().clock_offset_s) > 1e-3) {
    SessionInfo info = writer.info();
    info.clock_offset_s = *offset;
    info.extra["clock_offset"] = {
        {"source", "gps"}, {"fixes", clock_offset_.count()}, {"spread_s", clock_offset_.Spread()}};
    writer.UpdateInfo(info);
  }
}

void CaptureController::PollCameraStatus(SessionWriter& writer) {
  CameraStatus st;
  try {
    st = dev_.camera->Status();
  } catch (const DeviceError&) {
    return;  // the bracket's first frame meets the same failure and handles it
  }
  std::string text;
  if (st.battery_percent)
    text = "battery " + std::to_string(std::lround(*st.battery_percent)) + "%";
  if (st.free_bytes)
    text += (text.empty() ? "" : ", ") + Formatted("card %.1f GB free", *st.free_bytes / 1e9);
  progress_.camera_status = text;
  // The camera's clock against GPS time, as the laptop's is kept (PollGps): the time its files'
  // EXIF carries, should they be imported from the card later. Read to the second (PTP's
  // DateTime) against the laptop's clock; a reading within 1.5 s of the kept one is the same
  // clock read again, while the laptop's own offset from GPS firms up beneath it.
  if (!st.clock || !dev_.clock->IsLaptopClock() || !clock_offset_.Offset()) return;
  const UtcTime laptop_now = dev_.clock->Now();
  double vs_laptop = static_cast<double>(st.clock->ns - laptop_now.ns) * 1e-9;
  const nlohmann::json& known = writer.info().extra.value("camera_clock", nlohmann::json());
  const bool same = known.is_object() && known.value("device", "") == dev_.camera->Id() &&
                    std::abs(known.value("camera_minus_laptop_s", 1e9) - vs_laptop) < 1.5;
  if (same) vs_laptop = known.value("camera_minus_laptop_s", vs_laptop);
  const double vs_gps = vs_laptop - writer.info().clock_offset_s;
  if (same && std::abs(known.value("offset_s", 1e9) - vs_gps) < 1e-6) return;
  SessionInfo info = writer.info();
  info.extra["camera_clock"] = {
      {"device", dev_.camera->Id()},
      {"offset_s", vs_gps},
      {"camera_minus_laptop_s", vs_laptop},
      {"resolution_s", 1},
      {"read_utc", laptop_now.PlusSeconds(writer.info().clock_offset_s).Iso8601(3)},
      {"meaning", "camera clock minus GPS time"}};
  writer.UpdateInfo(info);
}

namespace {

// A frame a driver hands over cut short or with impossible metadata is a device failure (the
// bracket is redone after a reconnect or on --resume), never a journalled frame.
void CheckGrabbedFrame(const CapturedFrame& f, const std::string& camera,
                       const std::string& group) {
  const Image& im = f.image;
  const size_t expected = static_cast<size_t>(std::max(im.width, 0)) * std::max(im.height, 0) *
                          std::max(im.channels, 0);
  if (im.width <= 0 || im.height <= 0 || im.channels <= 0 || im.data.size() != expected) {
    throw DeviceError(camera + ": " + group + ": partial frame (" + std::to_string(im.width) + "x" +
                      std::to_string(im.height) + "x" + std::to_string(im.channels) + ", " +
                      std::to_string(im.data.size()) + " values)");
  }
  if (!(f.exposure_s >= 0) || !std::isfinite(f.exposure_s) || !(f.gain > 0) ||
      !std::isfinite(f.gain)) {
    throw DeviceError(camera + ": " + group + ": frame with impossible exposure " +
                      std::to_string(f.exposure_s) + " s or gain " + std::to_string(f.gain));
  }
}

}  // namespace

bool CaptureController::Recover(const DeviceError& e, const std::string& group,
                                CaptureSummary& summary) {
  summary.warnings.push_back(group + ": camera lost: " + e.what());
  progress_.event = std::string("camera lost: ") + e.what();
  if (progress_fn_) progress_fn_(progress_);
  progress_.event.clear();
  if (loss_.policy == DeviceLostPolicy::kStop || !dev_.reopen_camera) return false;
  const UtcTime deadline = NowUtc().PlusSeconds(loss_.reconnect_timeout_s);
  std::string last_error = e.what();
  while (!(stop_ && stop_->load())) {
    try {
      if (Camera* cam = dev_.reopen_camera()) {
        dev_.camera = cam;
        ++summary.reconnects;
        progress_.event = "camera back: " + cam->Id() + "; redoing " + group;
        if (progress_fn_) progress_fn_(progress_);
        progress_.event.clear();
        return true;
      }
    } catch (const DeviceError& again) {
      last_error = again.what();
    }
    if (NowUtc() >= deadline) break;
    // Waiting for a device to come back is real time, not a test artefact.
    std::this_thread::sleep_for(std::chrono::duration<double>(loss_.retry_interval_s));
  }
  summary.warnings.push_back(group + ": camera did not come back within " +
                             std::to_string(loss_.reconnect_timeout_s) + " s: " + last_error);
  return false;
}

void CaptureController::Notify(double exposure_s, double saturated_fraction) {
  progress_.exposure_s = exposure_s;
  progress_.saturated_fraction = saturated_fraction;
  if (progress_fn_) progress_fn_(progress_);
}

void CaptureController::Meter(const CapturedFrame& frame, Target target, double* saturated,
                              double* dark, double* max_dn) const {
  const Image& im = frame.image;
  // Pixels within sun_exclusion_deg of the sun are not of interest for sky/landscape/
  // architecture views (the sun itself is measured through the ND filter).
  bool exclude_sun = target != Target::kSun && frame.intrinsics && frame.pose;
  Eigen::Vector3d sun_cam;
  double cos_excl = std::cos(plan_.sun_exclusion_deg * kPi / 180);
  if (exclude_sun) {
    SunPosition sp = ComputeSunPosition(frame.utc, CurrentSite());
    sun_cam = frame.pose->rotation.transpose() * sp.DirectionEnu();
  }
  // A fisheye's image circle (inscribed): outside it the sensor sees the lens barrel.
  const bool fisheye = frame.intrinsics && frame.intrinsics->projection == Projection::kFisheye;
  const double circle_r2 =
      fisheye ? std::pow(std::min(frame.intrinsics->cx, frame.intrinsics->cy), 2) : 0;
  size_t n = 0, nsat = 0, ndark = 0;
  float mx = 0;
  const int stride = std::max(1, std::min(im.width, im.height) / 160);  // metering subsample
  for (int y = 0; y < im.height; y += stride) {
    for (int x = 0; x < im.width; x += stride) {
      if (fisheye) {
        double dx = x + 0.5 - frame.intrinsics->cx, dy = y + 0.5 - frame.intrinsics->cy;
        if (dx * dx + dy * dy > circle_r2) continue;
      }
      if (exclude_sun) {
        Eigen::Vector3d d = Unproject(*frame.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
        if (d.dot(sun_cam) > cos_excl) continue;
      }
      float lo = 255, hi = 0;
      for (int c = 0; c < im.channels; ++c) {
        lo = std::min(lo, im.at(x, y, c));
        hi = std::max(hi, im.at(x, y, c));
      }
      ++n;
      if (hi >= plan_.bracket.saturation_dn) ++nsat;
      if (lo <= plan_.bracket.noise_floor_dn) ++ndark;
      mx = std::max(mx, hi);
    }
  }
  *saturated = n ? double(nsat) / n : 0;
  *dark = n ? double(ndark) / n : 0;
  *max_dn = mx;
}

Site CaptureController::CurrentSite() const {
  return last_fix_ && last_fix_->valid()
             ? Site{last_fix_->lat_deg, last_fix_->lon_deg, last_fix_->height_m}
             : fallback_site_;
}

void CheckPlanDaylight(const CapturePlan& plan, const std::vector<UtcTime>& times,
                       const Site& site) {
  const bool daylight = std::any_of(plan.targets.begin(), plan.targets.end(), [](Target t) {
    return t == Target::kSun || t == Target::kAureole || t == Target::kSky ||
           t == Target::kLandscape;
  });
  if (!daylight || plan.allow_night) return;
  for (size_t k = 0; k < times.size(); ++k) {
    const std::string night = SunDownProblem(times[k], site);
    if (night.empty()) continue;
    throw Error(
        "slot " + std::to_string(plan.first_slot + static_cast<int>(k)) + " at " +
        times[k].Iso8601(0) + ": " + night +
        "; its sun, sky and landscape photographs need daylight: capture between sunrise "
        "and sunset (rouen plan lists the day's times), or pass --allow-night for a rehearsal");
  }
}

FrameRecord CaptureController::Journal(SessionWriter& writer, const CapturedFrame& frame, int slot,
                                       Target target, const std::string& group) {
  FrameRecord r;
  r.device = dev_.camera->Id();
  r.target = target;
  r.group = group;
  r.slot = slot;
  r.utc =
      dev_.clock->IsLaptopClock() ? frame.utc.PlusSeconds(writer.info().clock_offset_s) : frame.utc;
  r.hdr = frame.hdr;
  r.exposure_s = frame.exposure_s;
  r.gain = frame.gain;
  r.nd_density = frame.nd_density;
  r.intrinsics = frame.intrinsics;
  r.pose = frame.pose;
  PollGps(writer);
  if (last_fix_ && last_fix_->valid()) {
    r.gps = *last_fix_;
    progress_.gps_status =
        gps_error_.empty()
            ? "3D fix, " + std::to_string(last_fix_->satellites) + " satellites"
            : "error: " + gps_error_ + " (frames keep the last fix; the site does not move)";
  } else if (progress_.gps_status.rfind("error", 0) != 0) {
    progress_.gps_status = "no fix (fallback site)";
  }
  SunPosition sp = ComputeSunPosition(r.utc, CurrentSite());
  r.sun_azimuth_deg = sp.azimuth_deg;
  r.sun_elevation_deg = sp.elevation_deg;
  FrameRecord out = writer.Append(r, frame.image);
  ++progress_.frames_total;
  return out;
}

bool CaptureController::CaptureGroup(SessionWriter& writer, int slot, Target target, int view,
                                     CaptureSummary& summary) {
  const std::string group = BracketName(slot, target, view);
  Camera& cam = *dev_.camera;
  const BracketOptions& b = plan_.bracket;
  const double step = std::pow(2.0, b.step_stops);
  auto stopped = [&] { return stop_ && stop_->load(); };
  auto grab = [&](double exposure) -> CapturedFrame {
    double applied = cam.SetExposure(exposure);
    CapturedFrame f = cam.Grab();
    CheckGrabbedFrame(f, cam.Id(), group);
    if (std::abs(f.exposure_s - applied) > 1e-6 * applied)
      summary.warnings.push_back(group + ": camera reported exposure " +
                                 std::to_string(f.exposure_s) + " s for a requested " +
                                 std::to_string(applied) + " s; journalled the reported value");
    Journal(writer, f, slot, target, group);
    ++summary.frames;
    return f;
  };

  progress_.target = target;
  progress_.view = view;
  PollCameraStatus(writer);
  cam.Aim(target, view);
  cam.SetGain(1.0);

  if (target == Target::kAureole) {
    cam.SetNdFilter(0);
    for (double e : plan_.aureole_exposures_s) {
      if (stopped()) return false;
      CapturedFrame f = grab(e);
      double sat, dark, mx;
      Meter(f, target, &sat, &dark, &mx);
      Notify(f.exposure_s, sat);
    }
    return true;
  }

  if (target == Target::kSun) {
    // §3.1: the sun through ND filters, shortening the exposure until the disc is unsaturated.
    cam.SetNdFilter(plan_.sun_nd_density);
    double e = plan_.sun_start_exposure_s;
    int frames = 0;
    double sat, dark, mx;
    CapturedFrame f;
    while (true) {
      if (stopped()) return false;
      f = grab(e);
      ++frames;
      Meter(f, target, &sat, &dark, &mx);
      Notify(f.exposure_s, sat);
      if (mx < b.saturation_dn) break;
      if (f.exposure_s <= b.min_exposure_s * 1.0001 || frames >= b.max_frames) {
        summary.warnings.push_back(group +
                                   ": sun disc still saturated at the shortest exposure; "
                                   "use a denser ND filter");
        break;
      }
      e = f.exposure_s / step;
    }
    const double unsaturated = f.exposure_s;
    // Longer frames to bring the limb and the background above the noise floor.
    e = unsaturated;
    for (int i = 0; i < plan_.sun_extra_longer_frames && frames < b.max_frames; ++i) {
      if (stopped()) return false;
      e *= step;
      if (e > b.max_exposure_s) break;
      f = grab(e);
      ++frames;
      Meter(f, target, &sat, &dark, &mx);
      Notify(f.exposure_s, sat);
    }
    cam.SetNdFilter(0);
    return true;
  }

  // Sky, landscape, architecture: bracket until the brightest pixels of interest are
  // unsaturated and the darkest are above the noise floor.
  cam.SetNdFilter(0);
  double sat, dark, mx;
  int frames = 0;
  const double start = std::clamp(plan_.start_exposure_s, b.min_exposure_s, b.max_exposure_s);
  CapturedFrame f = grab(start);
  ++frames;
  Meter(f, target, &sat, &dark, &mx);
  Notify(f.exposure_s, sat);
  double first_sat = sat, first_dark = dark;
  double e = f.exposure_s;
  while (sat > b.max_saturated_fraction && frames < b.max_frames) {
    if (stopped()) return false;
    if (e <= b.min_exposure_s * 1.0001) {
      summary.warnings.push_back(group + ": highlights saturated at the shortest exposure");
      break;
    }
    e = std::max(b.min_exposure_s, e / step);
    f = grab(e);
    ++frames;
    double d2;
    Meter(f, target, &sat, &d2, &mx);
    Notify(f.exposure_s, sat);
  }
  e = start;
  dark = first_dark;
  (void)first_sat;
  while (dark > b.max_dark_fraction && frames < b.max_frames) {
    if (stopped()) return false;
    if (e >= b.max_exposure_s * 0.9999) {
      summary.warnings.push_back(group + ": shadows under the noise floor at the longest exposure");
      break;
    }
    e = std::min(b.max_exposure_s, e * step);
    f = grab(e);
    ++frames;
    double s2;
    Meter(f, target, &s2, &dark, &mx);
    Notify(f.exposure_s, s2);
  }
  if (frames >= b.max_frames && (sat > b.max_saturated_fraction || dark > b.max_dark_fraction))
    summary.warnings.push_back(group + ": bracket stopped at max_frames before covering the range");
  return true;
}

CaptureSummary CaptureController::Run(SessionWriter& writer,
                                      const std::function<void(const CaptureProgress&)>& progress,
                                      const std::atomic<bool>* stop) {
  progress_fn_ = progress;
  stop_ = stop;
  CaptureSummary summary;
  progress_ = CaptureProgress{};
  progress_.slots = plan_.first_slot + static_cast<int>(plan_.slots.size());
  progress_.frames_total = static_cast<int>(writer.frames().size());
  PollGps(writer);
  // Refused before the first frame: a field rig's one slot is now, a simulated rig's its plan.
  if (dev_.clock->IsLaptopClock())
    CheckPlanDaylight(plan_, {dev_.clock->Now().PlusSeconds(writer.info().clock_offset_s)},
                      CurrentSite());
  else
    CheckPlanDaylight(plan_, plan_.slots, CurrentSite());

  // Resume: every group already journalled is complete except the last one, which was in
  // flight when the previous run stopped and is captured again.
  std::set<std::string> done;
  for (const FrameRecord& f : writer.frames()) done.insert(f.group);
  if (!writer.frames().empty()) done.erase(writer.frames().back().group);

  for (int k = 0; k < static_cast<int>(plan_.slots.size()); ++k) {
    const int s = plan_.first_slot + k;  // the slot's index in the session
    progress_.slot = s;
    dev_.clock->JumpTo(plan_.slots[k]);
    for (Target t : plan_.targets) {
      int views = std::max(1, dev_.camera->ViewCount(t));
      for (int v = 0; v < views; ++v) {
        if (done.count(BracketName(s, t, v))) continue;
        if (stop && stop->load()) {
          summary.stopped = true;
          return summary;
        }
        bool finished = false;
        while (true) {
          try {
            finished = CaptureGroup(writer, s, t, v, summary);
            break;
          } catch (const DeviceError& e) {
            // The frames of this bracket already journalled stay; a resumed or reconnected
            // capture redoes the bracket (its last group is always redone).
            if (!Recover(e, BracketName(s, t, v), summary)) {
              summary.stopped = true;
              summary.camera_lost = true;
              return summary;
            }
          }
        }
        if (!finished) {
          summary.stopped = true;
          return summary;
        }
      }
    }
    ++summary.slots_done;
  }
  return summary;
}

}  // namespace rouen
