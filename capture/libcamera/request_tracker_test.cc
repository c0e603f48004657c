#include "capture/libcamera/request_tracker.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>

#include "core/error.h"

namespace rouen::libcamera_internal {
namespace {

Completion Done(uint64_t cookie, std::optional<double> exposure_s, std::optional<double> gain) {
  Completion c;
  c.cookie = cookie;
  c.status = CompletionStatus::kComplete;
  c.applied_exposure_s = exposure_s;
  c.applied_gain = gain;
  return c;
}

Completion Bad(uint64_t cookie, CompletionStatus status) {
  Completion c;
  c.cookie = cookie;
  c.status = status;
  return c;
}

TEST(RequestTrackerOptions, RejectsNonsense) {
  RequestTrackerOptions o;
  EXPECT_NO_THROW(o.Validate());
  o.max_frames_per_grab = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.max_consecutive_failures = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.exposure_rel_tol = -0.1;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.exposure_abs_tol_s = std::nan("");
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.gain_rel_tol = -1;
  EXPECT_THROW(o.Validate(), Error);
  EXPECT_THROW(RequestTracker{o}, Error) << "constructor validates";
  o.gain_rel_tol = 0;
  EXPECT_NO_THROW(o.Validate()) << "exact matching is allowed";
  try {
    o = {};
    o.max_frames_per_grab = -2;
    o.Validate();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("max_frames_per_grab"), std::string::npos);
  }
}

TEST(RequestTracker, MatchToleranceFollowsSensorQuantisation) {
  RequestTrackerOptions o;  // 2% + 100 µs on exposure, 5% on gain
  RequestTracker t(o);
  const ExposureSetting wanted{0.010, 2.0};
  // Exposure: bound = 0.02 * 10 ms + 0.1 ms = 0.3 ms.
  EXPECT_TRUE(t.Matches({0.010, 2.0}, wanted));
  EXPECT_TRUE(t.Matches({0.01029, 2.0}, wanted));
  EXPECT_TRUE(t.Matches({0.00971, 2.0}, wanted));
  EXPECT_FALSE(t.Matches({0.01031, 2.0}, wanted));
  EXPECT_FALSE(t.Matches({0.0090, 2.0}, wanted));
  // Gain: bound = 0.05 * 2 = 0.1.
  EXPECT_TRUE(t.Matches({0.010, 2.09}, wanted));
  EXPECT_TRUE(t.Matches({0.010, 1.91}, wanted));
  EXPECT_FALSE(t.Matches({0.010, 2.11}, wanted));
  // Very short exposures: the absolute part dominates (a few sensor lines).
  EXPECT_TRUE(t.Matches({80e-6, 1.0}, {20e-6, 1.0}));
  EXPECT_FALSE(t.Matches({130e-6, 1.0}, {20e-6, 1.0}));
}

TEST(RequestTracker, AcceptsFirstFreshFrameShowingTheWantedSetting) {
  RequestTracker t;
  t.BeginGrab({0.01, 1.0});
  for (uint64_t c = 0; c < 4; ++c) t.OnQueued(c, {0.01, 1.0});
  EXPECT_EQ(t.InFlight(), 4u);
  // The controls land on the third frame.
  Decision d = t.OnCompleted(Done(0, 0.02, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  EXPECT_TRUE(d.fresh);
  EXPECT_EQ(d.fresh_frames, 1);
  d = t.OnCompleted(Done(1, 0.02, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  d = t.OnCompleted(Done(2, 0.00998, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kAccept) << d.reason;
  EXPECT_EQ(d.fresh_frames, 3);
  EXPECT_DOUBLE_EQ(d.applied.exposure_s, 0.00998);  // the metadata, not the request
  EXPECT_DOUBLE_EQ(d.requested.exposure_s, 0.01);
  EXPECT_TRUE(d.exposure_reported);
  EXPECT_TRUE(d.gain_reported);
  EXPECT_EQ(t.InFlight(), 1u);
}

TEST(RequestTracker, FramesQueuedBeforeTheGrabAreNotAccepted) {
  RequestTracker t;
  t.BeginGrab({0.01, 1.0});
  t.OnQueued(7, {0.01, 1.0});
  t.OnQueued(8, {0.01, 1.0});
  t.BeginGrab({0.01, 1.0});  // second grab with the same setting
  // Request 7 was exposed for the right time but before this grab was asked for.
  Decision d = t.OnCompleted(Done(7, 0.01, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  EXPECT_FALSE(d.fresh);
  EXPECT_EQ(d.fresh_frames, 0) << "stale frames do not count towards the bound";
  t.OnQueued(7, {0.01, 1.0});  // requeued: now fresh
  d = t.OnCompleted(Done(8, 0.01, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  d = t.OnCompleted(Done(7, 0.01, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kAccept);
  EXPECT_TRUE(d.fresh);
}

TEST(RequestTracker, StaleFramesAcceptedWhenAllowed) {
  RequestTrackerOptions o;
  o.accept_stale_frames = true;
  RequestTracker t(o);
  t.BeginGrab({0.01, 1.0});
  t.OnQueued(1, {0.01, 1.0});
  t.BeginGrab({0.01, 1.0});
  const Decision d = t.OnCompleted(Done(1, 0.01, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kAccept);
  EXPECT_FALSE(d.fresh);
}

TEST(RequestTracker, FallsBackAfterTheBoundWithWhatWasApplied) {
  RequestTrackerOptions o;
  o.max_frames_per_grab = 3;
  RequestTracker t(o);
  t.BeginGrab({30.0, 1.0});  // a sensor that cannot reach 30 s
  for (uint64_t c = 0; c < 3; ++c) t.OnQueued(c, {30.0, 1.0});
  EXPECT_EQ(t.OnCompleted(Done(0, 1.5, 1.0)).verdict, Verdict::kRequeue);
  EXPECT_EQ(t.OnCompleted(Done(1, 2.0, 1.0)).verdict, Verdict::kRequeue);
  const Decision d = t.OnCompleted(Done(2, 2.0, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kAcceptFallback);
  EXPECT_DOUBLE_EQ(d.applied.exposure_s, 2.0);
  EXPECT_EQ(d.fresh_frames, 3);
  EXPECT_NE(d.reason.find("differs"), std::string::npos);
}

TEST(RequestTracker, MissingMetadataFallsBackToTheRequestedControls) {
  RequestTrackerOptions o;
  o.settle_frames_without_metadata = 1;
  RequestTracker t(o);
  t.BeginGrab({0.02, 4.0});
  t.OnQueued(0, {0.01, 4.0});  // carried an older setting
  t.OnQueued(1, {0.02, 4.0});
  Decision d = t.OnCompleted(Done(0, std::nullopt, std::nullopt));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  EXPECT_FALSE(d.exposure_reported);
  EXPECT_DOUBLE_EQ(d.applied.exposure_s, 0.01);
  d = t.OnCompleted(Done(1, std::nullopt, std::nullopt));
  EXPECT_EQ(d.verdict, Verdict::kAccept);
  EXPECT_FALSE(d.exposure_reported);
  EXPECT_FALSE(d.gain_reported);
  EXPECT_DOUBLE_EQ(d.applied.gain, 4.0);
}

TEST(RequestTracker, WithoutMetadataWaitsForTheSettlingFrames) {
  RequestTrackerOptions o;
  o.settle_frames_without_metadata = 4;
  RequestTracker t(o);
  t.BeginGrab({0.02, 1.0});
  for (uint64_t c = 0; c < 6; ++c) t.OnQueued(c, {0.02, 1.0});
  for (uint64_t c = 0; c < 3; ++c) {
    EXPECT_EQ(t.OnCompleted(Done(c, std::nullopt, std::nullopt)).verdict, Verdict::kRequeue)
        << "frame " << c << " may still have the old exposure";
  }
  const Decision d = t.OnCompleted(Done(3, std::nullopt, std::nullopt));
  EXPECT_EQ(d.verdict, Verdict::kAccept);
  EXPECT_EQ(d.fresh_frames, 4);
  // With metadata there is no such wait.
  t.BeginGrab({0.02, 1.0});
  t.OnQueued(9, {0.02, 1.0});
  EXPECT_EQ(t.OnCompleted(Done(9, 0.02, std::nullopt)).verdict, Verdict::kAccept);
  o.settle_frames_without_metadata = 0;
  EXPECT_THROW(o.Validate(), Error);
}

TEST(RequestTracker, PartialMetadataMixesReportedAndRequested) {
  RequestTracker t;
  t.BeginGrab({0.02, 4.0});
  t.OnQueued(0, {0.02, 4.0});
  const Decision d = t.OnCompleted(Done(0, 0.0201, std::nullopt));
  EXPECT_EQ(d.verdict, Verdict::kAccept);
  EXPECT_TRUE(d.exposure_reported);
  EXPECT_FALSE(d.gain_reported);
  EXPECT_DOUBLE_EQ(d.applied.exposure_s, 0.0201);
  EXPECT_DOUBLE_EQ(d.applied.gain, 4.0);
}

TEST(RequestTracker, CancelledAndFailedRequestsAreRequeuedUntilTooMany) {
  RequestTrackerOptions o;
  o.max_consecutive_failures = 3;
  RequestTracker t(o);
  t.BeginGrab({0.01, 1.0});
  for (uint64_t c = 0; c < 6; ++c) t.OnQueued(c, {0.01, 1.0});
  Decision d = t.OnCompleted(Bad(0, CompletionStatus::kFailed));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  EXPECT_EQ(d.fresh_frames, 0) << "a bad frame is not a frame";
  d = t.OnCompleted(Bad(1, CompletionStatus::kCancelled));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  EXPECT_EQ(t.consecutive_failures(), 2);
  // A good frame resets the run.
  d = t.OnCompleted(Done(2, 0.05, 1.0));
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
  EXPECT_EQ(t.consecutive_failures(), 0);
  EXPECT_EQ(t.OnCompleted(Bad(3, CompletionStatus::kFailed)).verdict, Verdict::kRequeue);
  EXPECT_EQ(t.OnCompleted(Bad(4, CompletionStatus::kFailed)).verdict, Verdict::kRequeue);
  d = t.OnCompleted(Bad(5, CompletionStatus::kFailed));
  EXPECT_EQ(d.verdict, Verdict::kFail);
  EXPECT_NE(d.reason.find("3 requests in a row failed"), std::string::npos) << d.reason;
}

TEST(RequestTracker, CancelledWhileStoppingIsDropped) {
  RequestTracker t;
  t.BeginGrab({0.01, 1.0});
  for (uint64_t c = 0; c < 20; ++c) t.OnQueued(c, {0.01, 1.0});
  t.SetStopping(true);
  for (uint64_t c = 0; c < 20; ++c) {
    EXPECT_EQ(t.OnCompleted(Bad(c, CompletionStatus::kCancelled)).verdict, Verdict::kDrop);
  }
  EXPECT_EQ(t.InFlight(), 0u);
  EXPECT_EQ(t.consecutive_failures(), 0);
}

TEST(RequestTracker, UnknownOrDuplicateCompletionsAreDropped) {
  RequestTracker t;
  t.BeginGrab({0.01, 1.0});
  t.OnQueued(1, {0.01, 1.0});
  EXPECT_EQ(t.OnCompleted(Done(99, 0.01, 1.0)).verdict, Verdict::kDrop);
  EXPECT_EQ(t.OnCompleted(Done(1, 0.01, 1.0)).verdict, Verdict::kAccept);
  const Decision again = t.OnCompleted(Done(1, 0.01, 1.0));
  EXPECT_EQ(again.verdict, Verdict::kDrop);
  EXPECT_NE(again.reason.find("not in flight"), std::string::npos);
}

TEST(RequestTracker, BeginGrabResetsTheFrameCount) {
  RequestTrackerOptions o;
  o.max_frames_per_grab = 2;
  RequestTracker t(o);
  t.BeginGrab({0.01, 1.0});
  t.OnQueued(0, {0.01, 1.0});
  t.OnQueued(1, {0.01, 1.0});
  EXPECT_EQ(t.OnCompleted(Done(0, 0.5, 1.0)).verdict, Verdict::kRequeue);
  t.BeginGrab({0.01, 1.0});
  t.OnQueued(0, {0.01, 1.0});
  EXPECT_EQ(t.OnCompleted(Done(1, 0.5, 1.0)).verdict, Verdict::kRequeue);  // stale
  const Decision d = t.OnCompleted(Done(0, 0.5, 1.0));
  EXPECT_EQ(d.fresh_frames, 1);
  EXPECT_EQ(d.verdict, Verdict::kRequeue);
}

// A synthetic streaming camera driven exactly as the driver drives the tracker: `depth`
// requests in flight, completed in queue order; controls carried by frame n take effect on
// frame n + `delay` (sensor control latency), so the metadata of frame n shows the controls of
// the request queued `delay` frames earlier. A grab must return the first fresh frame that
// really has the wanted setting, never an earlier one, and record exactly that setting.
class FakeStream {
 public:
  FakeStream(int depth, int delay) : delay_(delay) {
    for (int i = 0; i < delay; ++i) history_.push_back(initial_);
    tracker_.BeginGrab(initial_);
    for (int i = 0; i < depth; ++i) Queue(static_cast<uint64_t>(i), initial_);
  }

  struct Result {
    Decision decision;
    int completions = 0;           // completions handled in this grab
    int first_matching_seen = -1;  // index of the first fresh frame that had the setting
  };

  Result Grab(const ExposureSetting& wanted) {
    tracker_.BeginGrab(wanted);
    const uint64_t generation = tracker_.generation();
    Result r;
    for (int n = 0; n < 1000; ++n) {
      const auto [cookie, requested, gen] = in_flight_.front();
      in_flight_.pop_front();
      // Controls land `delay_` frames late.
      history_.push_back(requested);
      const ExposureSetting applied = history_.front();
      history_.pop_front();
      if (r.first_matching_seen < 0 && gen == generation && tracker_.Matches(applied, wanted)) {
        r.first_matching_seen = r.completions;
      }
      ++r.completions;
      r.decision = tracker_.OnCompleted(Done(cookie, applied.exposure_s, applied.gain));
      Queue(cookie, wanted);  // the driver requeues every request with the wanted controls
      if (r.decision.verdict == Verdict::kAccept ||
          r.decision.verdict == Verdict::kAcceptFallback) {
        return r;
      }
    }
    ADD_FAILURE() << "grab never finished";
    return r;
  }

 private:
  void Queue(uint64_t cookie, const ExposureSetting& s) {
    tracker_.OnQueued(cookie, s);
    in_flight_.push_back({cookie, s, tracker_.generation()});
  }
  struct InFlight {
    uint64_t cookie;
    ExposureSetting requested;
    uint64_t generation;
  };
  RequestTracker tracker_;
  int delay_;
  ExposureSetting initial_{1.0 / 60, 1.0};
  std::deque<InFlight> in_flight_;
  std::deque<ExposureSetting> history_;
};

TEST(RequestTracker, BracketOnAStreamingCameraWithControlLatency) {
  for (int depth : {1, 2, 4, 6}) {
    for (int delay : {0, 1, 2, 3}) {
      SCOPED_TRACE(testing::Message() << "depth " << depth << " delay " << delay);
      FakeStream stream(depth, delay);
      // A bracket with repeats (a repeat needs fresh frames too) and a gain change.
      const ExposureSetting bracket[] = {{1.0 / 1000, 1.0}, {1.0 / 250, 1.0}, {1.0 / 250, 1.0},
                                         {1.0 / 60, 1.0},   {1.0 / 60, 4.0},  {1.0 / 15, 2.0}};
      for (const ExposureSetting& s : bracket) {
        const FakeStream::Result r = stream.Grab(s);
        ASSERT_EQ(r.decision.verdict, Verdict::kAccept) << r.decision.reason;
        EXPECT_TRUE(r.decision.fresh);
        EXPECT_DOUBLE_EQ(r.decision.applied.exposure_s, s.exposure_s);
        EXPECT_DOUBLE_EQ(r.decision.applied.gain, s.gain);
        // The first fresh frame that had the setting, no later and no earlier: the `depth`
        // requests in flight at the start are stale; the fresh ones behind them carry the
        // setting, which shows `delay` frames later at the latest (sooner on a repeat).
        EXPECT_EQ(r.completions - 1, r.first_matching_seen);
        EXPECT_GE(r.completions, depth + 1);
        EXPECT_LE(r.completions, depth + delay + 1);
      }
    }
  }
}

}  // namespace
}  // namespace rouen::libcamera_internal
