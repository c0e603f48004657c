// The capture controller: runs a plan per time-of-day slot (sun through an ND filter,
// aureole bands, sky, landscape, architecture views), brackets each view adaptively and
// journals every frame with its GPS fix and the sun position at its timestamp.
#pragma once

#include <atomic>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "capture/clock.h"
#include "capture/device.h"
#include "core/session.h"
#include "core/solar.h"

namespace rouen {

struct BracketOptions {
  double step_stops = 2.0;  // exposure ratio between bracket frames, in stops
  double min_exposure_s = 1.0 / 8000;
  double max_exposure_s = 30.0;
  int max_frames = 8;                    // per view
  double saturation_dn = 250;            // a pixel at or above this is saturated
  double noise_floor_dn = 16;            // a pixel at or below this is too noisy to measure
  double max_saturated_fraction = 2e-4;  // of the pixels of interest
  double max_dark_fraction = 2e-3;
  void Validate() const;  // throws rouen::Error
};

struct CapturePlan {
  std::vector<UtcTime> slots;  // simulated rigs jump to these; real rigs use "now" (one slot)
  // Session index of slots[0]: a field rig adds one time-of-day slot per run to a session.
  // Not stored in session.json (the journal's frames carry their slot).
  int first_slot = 0;
  std::vector<Target> targets = {Target::kSun, Target::kAureole, Target::kSky, Target::kLandscape,
                                 Target::kArchitecture};
  double sun_nd_density = 4.5;  // ND filter for the sun frames (optical density)
  double sun_start_exposure_s = 1.0 / 1000;
  int sun_extra_longer_frames = 2;  // frames above the unsaturated one, for HDR
  std::vector<double> aureole_exposures_s = {1.0 / 8000, 1.0 / 2000, 1.0 / 500};
  double start_exposure_s = 1.0 / 250;
  double sun_exclusion_deg = 4.0;  // pixels this close to the sun are not "of interest"
  BracketOptions bracket;
  // A rehearsal at night or indoors (a rig tried out the evening before): the frames serve no
  // solve, and the daylight check (CheckPlanDaylight) is skipped. Not stored with the plan.
  bool allow_night = false;
  void Validate() const;
};

// What the capture does when the camera is lost (unplugged, powered off, cable pulled).
enum class DeviceLostPolicy {
  kStop,       // stop; everything journalled so far stays; --resume continues later
  kReconnect,  // wait up to reconnect_timeout_s for the camera, reopen it, redo the bracket
};

struct CaptureProgress {
  int slot = 0, slots = 0;
  Target target = Target::kSun;
  int view = 0;
  int frames_total = 0;
  double exposure_s = 0;
  double saturated_fraction = 0;  // of the last frame's pixels of interest
  std::string gps_status;
  // The camera's own battery and card ("battery 80%, card 31.9 GB free"), empty when it reports
  // neither (Camera::Status).
  std::string camera_status;
  std::string event;  // a one-off message (camera lost, reconnected, ...), else empty
};

struct CaptureSummary {
  int frames = 0;
  int slots_done = 0;
  bool stopped = false;      // stop flag seen or camera lost; everything written is journalled
  bool camera_lost = false;  // stopped because the camera failed and was not recovered
  int reconnects = 0;
  std::vector<std::string> warnings;
};

struct CaptureDevices {
  Camera* camera = nullptr;
  Gps* gps = nullptr;  // may be null: the fallback site is used, with a warning
  Clock* clock = nullptr;
  // Reopens the camera after a DeviceError (kReconnect): returns the new camera (owned by the
  // caller, replacing `camera`), or null when it is not back yet; may throw DeviceError.
  std::function<Camera*()> reopen_camera = nullptr;
};

struct DeviceLossOptions {
  DeviceLostPolicy policy = DeviceLostPolicy::kStop;
  double reconnect_timeout_s = 60;
  double retry_interval_s = 1.0;  // between reopen attempts
};

class CaptureController {
 public:
  CaptureController(CaptureDevices devices, CapturePlan plan, Site fallback_site,
                    DeviceLossOptions loss = {});

  // Captures every slot of the plan into `writer`. Groups already complete in the writer
  // (from an interrupted run) are skipped, so a resumed capture continues where it stopped.
  CaptureSummary Run(SessionWriter& writer,
                     const std::function<void(const CaptureProgress&)>& progress,
                     const std::atomic<bool>* stop);

 private:
  bool CaptureGroup(SessionWriter& writer, int slot, Target target, int view,
                    CaptureSummary& summary);
  FrameRecord Journal(SessionWriter& writer, const CapturedFrame& frame, int slot, Target target,
                      const std::string& group);
  void Notify(double exposure_s, double saturated_fraction);
  void PollGps(SessionWriter& writer);
  // Camera::Status before each bracket: the progress line's battery and card, and (field rigs)
  // the camera clock's offset from GPS time in the session's info.
  void PollCameraStatus(SessionWriter& writer);
  Site CurrentSite() const;  // the last GPS fix's, else the fallback
  // After a DeviceError: reopens the camera per the policy; false when capture must stop.
  bool Recover(const DeviceError& e, const std::string& group, CaptureSummary& summary);
  // Fractions of saturated and dark pixels among the pixels of interest.
  void Meter(const CapturedFrame& frame, Target target, double* saturated, double* dark,
             double* max_dn) const;

  CaptureDevices dev_;
  CapturePlan plan_;
  Site fallback_site_;
  std::function<void(const CaptureProgress&)> progress_fn_;
  const std::atomic<bool>* stop_ = nullptr;
  CaptureProgress progress_;
  std::optional<GpsFix> last_fix_;
  std::string gps_error_;  // the receiver's last error, cleared by the next answer
  DeviceLossOptions loss_;
  ClockOffsetEstimator clock_offset_;
};

// Throws rouen::Error when the plan photographs the sun, its aureole, the sky or the landscape
// (§3 measures the sun in every slot) and the sun's whole disc is below the horizon at `site`
// at one of `times` (slot plan.first_slot + k), naming the slot, its time and the sun's
// elevation: a capture at night would journal frames no solve can use. Nothing when
// plan.allow_night.
void CheckPlanDaylight(const CapturePlan& plan, const std::vector<UtcTime>& times,
                       const Site& site);

// The plan as stored in session.json ("plan"), so a replay runs the recorded plan.
nlohmann::json PlanToJson(const CapturePlan& plan);
CapturePlan PlanFromJson(const nlohmann::json& j);  // throws rouen::Error

}  // namespace rouen
