// Internal to rouen_libcamera: the request/metadata bookkeeping of a manual-exposure grab,
// kept free of libcamera so it can be tested with synthetic completions.
//
// The camera streams with a few requests in flight. Each queued request carries the exposure
// controls wanted at the time it was queued; controls land some frames later, and the
// completed request's metadata tells what was really applied. A grab returns the first fresh
// frame (its request queued after the grab began, so it was exposed after the grab was asked
// for) whose metadata matches the wanted setting within the sensor's quantisation, or, after
// a bounded number of fresh frames, the latest one with whatever was applied.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "capture/libcamera/libcamera_controls.h"

namespace rouen::libcamera_internal {

struct RequestTrackerOptions {
  // Fresh successful frames examined before giving up on a match and returning the latest.
  int max_frames_per_grab = 12;
  // Match tolerances: |applied - wanted| <= rel * wanted + abs. Sensors quantise the exposure
  // to whole lines (tens of µs) and the gain to register steps (a few % at high gain).
  double exposure_rel_tol = 0.02;
  double exposure_abs_tol_s = 100e-6;
  double gain_rel_tol = 0.05;
  // Failed or cancelled completions in a row (while not stopping) before the grab fails.
  int max_consecutive_failures = 8;
  // Accept frames whose request was queued before the grab began (faster, but such frames
  // may have been exposed before the caller asked).
  bool accept_stale_frames = false;
  // A camera whose metadata reports neither exposure nor gain gives no proof the controls
  // landed: accept only from this many fresh frames on (UVC cameras take 1 to 6 frames). A
  // value above max_frames_per_grab means such frames always come back as fallbacks.
  int settle_frames_without_metadata = 6;
  // Throws rouen::Error explaining what is wrong.
  void Validate() const;
};

enum class CompletionStatus {
  kComplete,   // request completed and its buffer holds a good frame
  kCancelled,  // request cancelled (camera stopping or pipeline error)
  kFailed,     // request completed but the buffer is marked bad (FrameError)
};

struct Completion {
  uint64_t cookie = 0;
  CompletionStatus status = CompletionStatus::kComplete;
  // From the metadata; a camera that reports neither gives nullopt.
  std::optional<double> applied_exposure_s, applied_gain;
};

enum class Verdict {
  kAccept,          // return this frame: fresh, and the metadata shows the wanted setting
  kAcceptFallback,  // return this frame: the bound was reached; it has what was applied
  kRequeue,         // not this one: requeue the request carrying the wanted controls
  kDrop,            // do not requeue (unknown request, or cancelled while stopping)
  kFail,            // too many failures in a row: the grab fails
};

struct Decision {
  Verdict verdict = Verdict::kDrop;
  // What the completed request carried, and what its metadata says was applied (applied
  // falls back to the requested value for a quantity the metadata lacks; *_reported says
  // whether it came from metadata).
  ExposureSetting requested, applied;
  bool exposure_reported = false, gain_reported = false;
  bool fresh = false;
  int fresh_frames = 0;  // fresh successful frames seen in this grab, including this one
  std::string reason;    // why, in words (for the grab report and errors)
};

class RequestTracker {
 public:
  explicit RequestTracker(RequestTrackerOptions options = {});

  // A new grab wants `wanted` (already clamped/quantised as sent). Requests queued from now
  // on are fresh.
  void BeginGrab(const ExposureSetting& wanted);
  // The driver is stopping the camera: cancelled completions are dropped, not requeued.
  void SetStopping(bool stopping) { stopping_ = stopping; }

  // Request `cookie` was queued carrying `requested`. Queuing a cookie already in flight
  // replaces its record (a driver bug, but not fatal).
  void OnQueued(uint64_t cookie, const ExposureSetting& requested);
  // A request completed. The request is no longer in flight afterwards.
  Decision OnCompleted(const Completion& completion);

  bool Matches(const ExposureSetting& applied, const ExposureSetting& wanted) const;
  const ExposureSetting& wanted() const { return wanted_; }
  size_t InFlight() const { return in_flight_.size(); }
  uint64_t generation() const { return generation_; }
  int consecutive_failures() const { return consecutive_failures_; }

 private:
  struct Queued {
    ExposureSetting requested;
    uint64_t generation = 0;
  };
  RequestTrackerOptions options_;
  ExposureSetting wanted_;
  uint64_t generation_ = 0;
  std::map<uint64_t, Queued> in_flight_;
  int fresh_frames_ = 0;
  int consecutive_failures_ = 0;
  bool stopping_ = false;
};

}  // namespace rouen::libcamera_internal
