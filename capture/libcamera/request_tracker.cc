#include "capture/libcamera/request_tracker.h"

#include <cmath>
#include <sstream>

#include "core/error.h"

namespace rouen::libcamera_internal {

void RequestTrackerOptions::Validate() const {
  auto fail = [](const std::string& what) {
    throw Error("libcamera request tracking options: " + what);
  };
  if (max_frames_per_grab < 1) fail("max_frames_per_grab must be at least 1");
  if (max_consecutive_failures < 1) fail("max_consecutive_failures must be at least 1");
  if (settle_frames_without_metadata < 1) {
    fail("settle_frames_without_metadata must be at least 1");
  }
  if (!(exposure_rel_tol >= 0) || !std::isfinite(exposure_rel_tol)) {
    fail("exposure_rel_tol must be a finite number >= 0");
  }
  if (!(exposure_abs_tol_s >= 0) || !std::isfinite(exposure_abs_tol_s)) {
    fail("exposure_abs_tol_s must be a finite number >= 0 (seconds)");
  }
  if (!(gain_rel_tol >= 0) || !std::isfinite(gain_rel_tol)) {
    fail("gain_rel_tol must be a finite number >= 0");
  }
}

RequestTracker::RequestTracker(RequestTrackerOptions options) : options_(options) {
  options_.Validate();
}

void RequestTracker::BeginGrab(const ExposureSetting& wanted) {
  wanted_ = wanted;
  ++generation_;
  fresh_frames_ = 0;
  consecutive_failures_ = 0;
}

void RequestTracker::OnQueued(uint64_t cookie, const ExposureSetting& requested) {
  in_flight_[cookie] = Queued{requested, generation_};
}

bool RequestTracker::Matches(const ExposureSetting& applied, const ExposureSetting& wanted) const {
  const double de = std::abs(applied.exposure_s - wanted.exposure_s);
  const double dg = std::abs(applied.gain - wanted.gain);
  return de <= options_.exposure_rel_tol * std::abs(wanted.exposure_s) +
                   options_.exposure_abs_tol_s &&
         dg <= options_.gain_rel_tol * std::abs(wanted.gain);
}

namespace {
std::string Describe(const ExposureSetting& s) {
  std::ostringstream out;
  out << s.exposure_s * 1e6 << " us x" << s.gain;
  return out.str();
}
}  // namespace

Decision RequestTracker::OnCompleted(const Completion& completion) {
  Decision d;
  const auto it = in_flight_.find(completion.cookie);
  if (it == in_flight_.end()) {
    d.verdict = Verdict::kDrop;
    d.reason =
        "completion for request " + std::to_string(completion.cookie) + " that is not in flight";
    return d;
  }
  const Queued queued = it->second;
  in_flight_.erase(it);
  d.requested = queued.requested;
  d.fresh = queued.generation == generation_;

  if (completion.status != CompletionStatus::kComplete) {
    const char* what = completion.status == CompletionStatus::kCancelled ? "cancelled" : "failed";
    if (stopping_) {
      d.verdict = Verdict::kDrop;
      d.reason = std::string("request ") + what + " while stopping";
      return d;
    }
    ++consecutive_failures_;
    d.fresh_frames = fresh_frames_;
    if (consecutive_failures_ >= options_.max_consecutive_failures) {
      d.verdict = Verdict::kFail;
      d.reason = std::to_string(consecutive_failures_) + " requests in a row " + what;
    } else {
      d.verdict = Verdict::kRequeue;
      d.reason = std::string("request ") + what;
    }
    return d;
  }
  consecutive_failures_ = 0;

  d.exposure_reported = completion.applied_exposure_s.has_value();
  d.gain_reported = completion.applied_gain.has_value();
  // What the frame really had. A camera that does not report a quantity is taken to have
  // applied what its request carried (the best knowledge there is).
  d.applied.exposure_s = completion.applied_exposure_s.value_or(queued.requested.exposure_s);
  d.applied.gain = completion.applied_gain.value_or(queued.requested.gain);

  const bool usable = d.fresh || options_.accept_stale_frames;
  if (usable) ++fresh_frames_;
  d.fresh_frames = fresh_frames_;
  if (!usable) {
    d.verdict = Verdict::kRequeue;
    d.reason = "queued before this grab began";
    return d;
  }
  // Without metadata a frame matches when its request carried the wanted controls: nothing
  // better is known (the journal then records the requested values).
  // Without metadata, wait for the settling frames too.
  const bool reported = d.exposure_reported || d.gain_reported;
  const bool matches = Matches(d.applied, wanted_) &&
                       (reported || fresh_frames_ >= options_.settle_frames_without_metadata);
  if (matches) {
    d.verdict = Verdict::kAccept;
    d.reason = "applied " + Describe(d.applied) + " matches wanted " + Describe(wanted_);
  } else if (fresh_frames_ >= options_.max_frames_per_grab) {
    d.verdict = Verdict::kAcceptFallback;
    d.reason = "after " + std::to_string(fresh_frames_) + " frames applied " + Describe(d.applied) +
               " still differs from wanted " + Describe(wanted_);
  } else {
    d.verdict = Verdict::kRequeue;
    d.reason = "applied " + Describe(d.applied) + " differs from wanted " + Describe(wanted_);
  }
  return d;
}

}  // namespace rouen::libcamera_internal
