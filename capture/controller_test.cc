#include "capture/controller.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <tuple>

#include "core/error.h"
#include "core/fault_io.h"
#include "core/files.h"
#include "tests/sanitizers.h"

namespace rouen {
namespace {

// A linear camera looking at a horizontal radiance ramp spanning `range` (max/min), with the
// sun disc (radiance `sun`) in the middle of the sun target.
class RampCamera : public Camera {
 public:
  double min_radiance = 1.0, range = 4000.0, sun = 5e5;
  double nd = 0, exposure = 0.01;
  Target target = Target::kArchitecture;
  std::vector<std::pair<Target, double>> grabs;  // (target, exposure)

  std::string Id() const override { return "ramp"; }
  std::vector<ControlInfo> Controls() const override {
    return {{"exposure_s", 1e-4, 30, exposure}};
  }
  double SetExposure(double s) override { return exposure = std::clamp(s, 1e-4, 30.0); }
  double SetGain(double g) override { return g; }
  void SetNdFilter(double d) override { nd = d; }
  double NdFilter() const override { return nd; }
  int ViewCount(Target t) const override { return t == Target::kArchitecture ? 2 : 1; }
  void Aim(Target t, int) override { target = t; }
  CapturedFrame Grab() override {
    CapturedFrame f;
    f.image = Image(64, 16, 3, PixelUnits::kDigital);
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 64; ++x) {
        double L = min_radiance * std::pow(range, x / 63.0);
        if (target == Target::kSun) L = (std::abs(x - 32) < 3 && std::abs(y - 8) < 3) ? sun : 1.0;
        double dn = std::min(255.0, std::round(L * exposure * std::pow(10, -nd) * 100));
        for (int c = 0; c < 3; ++c) f.image.at(x, y, c) = static_cast<float>(dn);
      }
    f.exposure_s = exposure;
    f.nd_density = nd;
    f.utc = now;
    now = now.PlusSeconds(exposure + 0.1);
    grabs.push_back({target, exposure});
    return f;
  }
  UtcTime now = ParseIso8601("2026-08-25T20:00:00Z");
};

class JumpClock : public Clock {
 public:
  UtcTime t;
  UtcTime Now() override { return t; }
  bool JumpTo(UtcTime x) override {
    t = x;
    return true;
  }
};

std::filesystem::path TempDir(const std::string& name) {
  auto p = std::filesystem::temp_directory_path() /
           ("rouen_controller_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(p);
  return p;
}

CapturePlan OneSlotPlan() {
  CapturePlan plan;
  plan.slots = {ParseIso8601("2026-08-25T20:00:00Z")};
  plan.bracket.min_exposure_s = 1e-4;
  plan.sun_start_exposure_s = 1.0;
  plan.start_exposure_s = 0.01;
  return plan;
}

TEST(ControllerTest, BracketsCoverTheRangeAndJournalEveryFrame) {
  RampCamera cam;
  JumpClock clock;
  CapturePlan plan = OneSlotPlan();
  auto dir = TempDir("range");
  SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
  CaptureController ctl({&cam, nullptr, &clock}, plan, Site{});
  CaptureSummary s = ctl.Run(w, nullptr, nullptr);
  EXPECT_EQ(s.frames, static_cast<int>(cam.grabs.size()));
  EXPECT_EQ(w.frames().size(), cam.grabs.size());
  // For each architecture view: some frame has no saturated pixel of the ramp's top, and
  // some frame has the ramp's bottom above the noise floor.
  for (int v = 0; v < 2; ++v) {
    double shortest = 1e9, longest = 0;
    for (const FrameRecord& f : w.frames())
      if (f.group == BracketName(0, Target::kArchitecture, v)) {
        shortest = std::min(shortest, f.exposure_s);
        longest = std::max(longest, f.exposure_s);
      }
    const double top = cam.min_radiance * cam.range, bottom = cam.min_radiance;
    EXPECT_LT(top * shortest * 100, plan.bracket.saturation_dn) << "view " << v;
    EXPECT_GT(bottom * longest * 100, plan.bracket.noise_floor_dn) << "view " << v;
  }
  // The sun: through the ND filter, with an unsaturated frame; later groups without ND.
  bool sun_unsaturated = false;
  for (const FrameRecord& f : w.frames()) {
    if (f.target == Target::kSun) {
      EXPECT_DOUBLE_EQ(f.nd_density, plan.sun_nd_density);
      if (cam.sun * f.exposure_s * std::pow(10, -f.nd_density) * 100 < 250) sun_unsaturated = true;
    } else {
      EXPECT_DOUBLE_EQ(f.nd_density, 0.0);
    }
    EXPECT_TRUE(std::filesystem::exists(dir / f.file));
  }
  EXPECT_TRUE(sun_unsaturated);
  // Aureole frames are exactly the plan's shutter speeds.
  std::vector<double> aureole;
  for (const FrameRecord& f : w.frames())
    if (f.target == Target::kAureole) aureole.push_back(f.exposure_s);
  EXPECT_EQ(aureole, plan.aureole_exposures_s);
  // No GPS: frames carry no fix, sun positions come from the fallback site.
  EXPECT_FALSE(w.frames().front().gps.has_value());
  std::filesystem::remove_all(dir);
}

TEST(ControllerTest, StopFlagEndsCleanlyAndResumeCompletes) {
  RampCamera cam;
  JumpClock clock;
  CapturePlan plan = OneSlotPlan();
  auto dir = TempDir("resume");
  size_t full = 0;
  {
    RampCamera ref;
    auto d2 = TempDir("resume_ref");
    SessionWriter w = SessionWriter::Create(d2, SessionInfo{});
    CaptureController(CaptureDevices{&ref, nullptr, &clock}, plan, Site{}).Run(w, nullptr, nullptr);
    full = w.frames().size();
    std::filesystem::remove_all(d2);
  }
  std::atomic<bool> stop{false};
  {
    SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
    CaptureController ctl({&cam, nullptr, &clock}, plan, Site{});
    int seen = 0;
    CaptureSummary s = ctl.Run(
        w,
        [&](const CaptureProgress&) {
          if (++seen == 5) stop = true;
        },
        &stop);
    EXPECT_TRUE(s.stopped);
    EXPECT_LT(w.frames().size(), full);
  }
  Session partial = Session::Load(dir);
  EXPECT_GT(partial.frames().size(), 0u);
  {
    SessionWriter w = SessionWriter::Resume(dir);
    CaptureController ctl({&cam, nullptr, &clock}, plan, Site{});
    CaptureSummary s = ctl.Run(w, nullptr, nullptr);
    EXPECT_FALSE(s.stopped);
  }
  Session done = Session::Load(dir);
  // Every group of the plan is present after the resume.
  std::map<std::string, int> groups;
  for (const FrameRecord& f : done.frames()) groups[f.group]++;
  EXPECT_EQ(groups.size(), 1u + 1u + 1u + 1u + 2u);  // sun, aureole, sky, landscape, 2 views
  std::filesystem::remove_all(dir);
}

TEST(ControllerTest, RejectsBadPlans) {
  RampCamera cam;
  JumpClock clock;
  CapturePlan plan = OneSlotPlan();
  plan.slots.clear();
  EXPECT_THROW(CaptureController({&cam, nullptr, &clock}, plan, Site{}), Error);
  plan = OneSlotPlan();
  plan.bracket.step_stops = 0;
  EXPECT_THROW(CaptureController({&cam, nullptr, &clock}, plan, Site{}), Error);
  plan = OneSlotPlan();
  EXPECT_THROW(CaptureController({nullptr, nullptr, &clock}, plan, Site{}), Error);
}

// A RampCamera that fails like an unplugged device after `fail_after` grabs.
class UnpluggedCamera : public RampCamera {
 public:
  int fail_after = 1 << 30;
  CapturedFrame Grab() override {
    if (static_cast<int>(grabs.size()) >= fail_after)
      throw DeviceError("ramp: device vanished (ENODEV)");
    return RampCamera::Grab();
  }
};

// The journal stays loadable and consistent after a lost camera: every frame journalled
// before the loss is there, with its file.
void ExpectConsistent(const std::filesystem::path& dir, size_t frames) {
  Session s = Session::Load(dir);
  EXPECT_EQ(s.frames().size(), frames);
  for (const FrameRecord& f : s.frames())
    EXPECT_EQ(Sha256File(s.dir() / f.file), f.sha256) << f.file;
}

TEST(ControllerTest, LostCameraStopsWithAConsistentSession) {
  UnpluggedCamera cam;
  cam.fail_after = 5;
  JumpClock clock;
  auto dir = TempDir("lost_stop");
  CaptureSummary s;
  {
    SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
    CaptureController ctl({&cam, nullptr, &clock}, OneSlotPlan(), Site{});
    s = ctl.Run(w, nullptr, nullptr);
  }
  EXPECT_TRUE(s.stopped);
  EXPECT_TRUE(s.camera_lost);
  EXPECT_EQ(s.frames, 5);
  ASSERT_FALSE(s.warnings.empty());
  EXPECT_NE(s.warnings.back().find("camera lost"), std::string::npos) << s.warnings.back();
  ExpectConsistent(dir, 5);
  std::filesystem::remove_all(dir);
}

TEST(ControllerTest, LostCameraReconnectsAndRedoesTheBracket) {
  RampCamera reference;
  JumpClock clock;
  auto ref_dir = TempDir("lost_ref");
  SessionWriter ref = SessionWriter::Create(ref_dir, SessionInfo{});
  CaptureController(CaptureDevices{&reference, nullptr, &clock}, OneSlotPlan(), Site{})
      .Run(ref, nullptr, nullptr);
  std::set<std::string> ref_groups;
  for (const FrameRecord& f : ref.frames()) ref_groups.insert(f.group);

  UnpluggedCamera first;
  first.fail_after = 6;
  RampCamera second;  // the device after it was plugged in again
  int attempts = 0;
  CaptureDevices dev{&first, nullptr, &clock};
  dev.reopen_camera = [&]() -> Camera* {
    // Not back on the first attempt, then back.
    return ++attempts < 2 ? nullptr : &second;
  };
  DeviceLossOptions loss;
  loss.policy = DeviceLostPolicy::kReconnect;
  loss.retry_interval_s = 0.001;
  auto dir = TempDir("lost_reconnect");
  SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
  CaptureSummary s = CaptureController(dev, OneSlotPlan(), Site{}, loss).Run(w, nullptr, nullptr);
  EXPECT_FALSE(s.stopped);
  EXPECT_EQ(s.reconnects, 1);
  EXPECT_EQ(attempts, 2);
  std::set<std::string> groups;
  for (const FrameRecord& f : w.frames()) groups.insert(f.group);
  EXPECT_EQ(groups, ref_groups);
  // The interrupted bracket was redone in full on the new device: every frame the reference
  // took after the interrupted group's start was taken again by `second`.
  EXPECT_EQ(w.frames().size(), 6 + second.grabs.size());
  const std::string lost_group = w.frames()[5].group;
  size_t ref_in_group = 0, redone_in_group = 0;
  for (const FrameRecord& f : ref.frames()) ref_in_group += f.group == lost_group;
  for (size_t i = 6; i < w.frames().size(); ++i)
    redone_in_group += w.frames()[i].group == lost_group;
  EXPECT_EQ(redone_in_group, ref_in_group);
  std::filesystem::remove_all(dir);
  std::filesystem::remove_all(ref_dir);
}

TEST(ControllerTest, ReconnectGivesUpAfterTheTimeout) {
  UnpluggedCamera cam;
  cam.fail_after = 2;
  JumpClock clock;
  CaptureDevices dev{&cam, nullptr, &clock};
  int attempts = 0;
  dev.reopen_camera = [&]() -> Camera* {
    ++attempts;
    throw DeviceError("ramp: no such device");
  };
  DeviceLossOptions loss;
  loss.policy = DeviceLostPolicy::kReconnect;
  loss.reconnect_timeout_s = 0.05;
  loss.retry_interval_s = 0.01;
  auto dir = TempDir("lost_timeout");
  SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
  CaptureSummary s = CaptureController(dev, OneSlotPlan(), Site{}, loss).Run(w, nullptr, nullptr);
  EXPECT_TRUE(s.camera_lost);
  EXPECT_GE(attempts, 2);
  EXPECT_NE(s.warnings.back().find("did not come back"), std::string::npos) << s.warnings.back();
  std::filesystem::remove_all(dir);
}

// A GPS whose fixes are `lag_s` behind when they reach the laptop, whose clock is `skew_s`
// behind GPS time.
class LaggingGps : public Gps {
 public:
  double skew_s = 2.5;
  std::vector<double> lags_s = {0.4, 0.15, 0.3, 0.12, 0.5};
  int polls = 0;
  std::string Id() const override { return "lag"; }
  std::optional<GpsFix> Poll() override {
    GpsFix f;
    f.utc = ParseIso8601("2026-08-25T20:00:00Z").PlusSeconds(polls);
    f.lat_deg = 37.87;
    f.lon_deg = -122.26;
    f.mode = 3;
    f.satellites = 9;
    f.received_utc = f.utc.PlusSeconds(lags_s[polls % lags_s.size()] - skew_s);
    ++polls;
    return f;
  }
};

class LaptopClock : public JumpClock {
 public:
  bool JumpTo(UtcTime) override { return false; }
  bool IsLaptopClock() const override { return true; }
};

TEST(ControllerTest, LaptopClockOffsetComesFromGpsFixes) {
  RampCamera cam;
  LaggingGps gps;
  LaptopClock clock;
  auto dir = TempDir("offset");
  SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
  CaptureController(CaptureDevices{&cam, &gps, &clock}, OneSlotPlan(), Site{})
      .Run(w, nullptr, nullptr);
  ASSERT_GE(gps.polls, 5);
  // The estimate is the skew minus the smallest lag seen (0.12 s once 4 fixes came in).
  EXPECT_NEAR(w.info().clock_offset_s, gps.skew_s - 0.12, 1e-6);
  EXPECT_EQ(w.info().extra["clock_offset"]["source"], "gps");
  // Frame times are the camera's (laptop) times shifted by the offset known at the frame.
  const FrameRecord& last = w.frames().back();
  UtcTime grabbed = cam.now.PlusSeconds(-(cam.grabs.back().second + 0.1));
  EXPECT_NEAR((last.utc.ns - grabbed.ns) * 1e-9, gps.skew_s - 0.12, 1e-6);
  std::filesystem::remove_all(dir);
}

// A camera that reports its battery, card and clock: 93 s ahead of the laptop's clock, with
// the laptop itself LaggingGps::skew_s - 0.12 s behind GPS time.
class StatusCamera : public RampCamera {
 public:
  LaptopClock* laptop = nullptr;
  int status_calls = 0;
  CameraStatus Status() override {
    ++status_calls;
    CameraStatus s;
    s.battery_percent = 64;
    s.free_bytes = int64_t{31'900'000'000};
    s.clock = laptop->Now().PlusSeconds(93);
    return s;
  }
};

// Before each bracket the camera's battery and card reach the progress line, and its clock's
// offset from GPS time (the laptop's clock corrected by its own offset) the session's info.
TEST(ControllerTest, CameraBatteryCardAndClockAreReportedAndJournalled) {
  StatusCamera cam;
  LaggingGps gps;
  LaptopClock clock;
  clock.t = ParseIso8601("2026-08-25T20:00:00Z");
  cam.laptop = &clock;
  auto dir = TempDir("camera_status");
  SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
  std::vector<std::string> lines;
  CaptureController(CaptureDevices{&cam, &gps, &clock}, OneSlotPlan(), Site{})
      .Run(
          w, [&](const CaptureProgress& p) { lines.push_back(p.camera_status); }, nullptr);
  EXPECT_GE(cam.status_calls, 3);  // sun, sky, landscape, architecture brackets
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines.back(), "battery 64%, card 31.9 GB free");
  const nlohmann::json& cc = w.info().extra.at("camera_clock");
  EXPECT_EQ(cc.at("device"), "ramp");
  // camera - GPS = (laptop + 93) - (laptop + offset)
  EXPECT_NEAR(cc.at("offset_s").get<double>(), 93 - w.info().clock_offset_s, 1e-6);
  std::filesystem::remove_all(dir);
}

TEST(ClockOffsetTest, IgnoresFixesWithoutLaptopTimeAndGlitches) {
  ClockOffsetEstimator est;
  GpsFix f;
  f.mode = 3;
  f.utc = ParseIso8601("2026-08-25T20:00:00Z");
  est.Add(f);  // no received_utc
  EXPECT_FALSE(est.Offset());
  for (double lag : {0.3, 0.2, 0.25}) {
    f.received_utc = f.utc.PlusSeconds(lag - 1.0);
    est.Add(f);
  }
  GpsFix glitch = f;
  glitch.utc = f.utc.PlusSeconds(604800);  // a week off: a cold-start glitch
  est.Add(glitch);
  GpsFix nofix = f;
  nofix.mode = 0;
  nofix.utc = f.utc.PlusSeconds(50);
  est.Add(nofix);  // no fix: ignored
  ASSERT_TRUE(est.Offset());
  EXPECT_NEAR(*est.Offset(), 1.0 - 0.2, 1e-9);
  EXPECT_EQ(est.count(), 4);
}

std::set<std::string> GroupsOf(const std::vector<FrameRecord>& frames) {
  std::set<std::string> groups;
  for (const FrameRecord& f : frames) groups.insert(f.group);
  return groups;
}

// Every journalled frame is whole (sha256 and decode, through LoadFrame) and frames/ holds
// nothing else.
void ExpectWholeSession(const std::filesystem::path& dir) {
  Session s = Session::Load(dir);
  for (const FrameRecord& f : s.frames()) {
    Image im = s.LoadFrame(f);
    EXPECT_EQ(im.width, 64) << f.file;
  }
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir / "frames")) {
    (void)e;
    ++files;
  }
  EXPECT_EQ(files, s.frames().size());
}

// Resumes `dir` with a working disk and camera and checks the plan completes.
void ExpectResumeCompletes(const std::filesystem::path& dir, const std::set<std::string>& groups) {
  RampCamera cam;
  JumpClock clock;
  {
    SessionWriter w = SessionWriter::Resume(dir);
    CaptureSummary s =
        CaptureController({&cam, nullptr, &clock}, OneSlotPlan(), Site{}).Run(w, nullptr, nullptr);
    EXPECT_FALSE(s.stopped);
  }
  EXPECT_EQ(GroupsOf(Session::Load(dir).frames()), groups);
  ExpectWholeSession(dir);
}

TEST(ControllerTest, DiskFullOrReadOnlyAtEveryWriteLeavesAResumableSession) {
  JumpClock clock;
  auto ref_dir = TempDir("full_ref");
  FaultyFileIo counter;
  std::set<std::string> ref_groups;
  {
    RampCamera cam;
    ScopedFileIo use(counter);
    SessionWriter w = SessionWriter::Create(ref_dir, SessionInfo{});
    CaptureController({&cam, nullptr, &clock}, OneSlotPlan(), Site{}).Run(w, nullptr, nullptr);
    ref_groups = GroupsOf(w.frames());
  }
  std::filesystem::remove_all(ref_dir);
  const long calls = counter.calls();
  ASSERT_GT(calls, 50);
  // Hundreds of captures: on a memory file system when there is one (fsync is then cheap).
  const std::filesystem::path shm = "/dev/shm";
  auto dir = std::filesystem::is_directory(shm)
                 ? shm / ("rouen_controller_test_full_" + std::to_string(::getpid()))
                 : TempDir("full");
  // The disk fills at call k and stays full: every k of the whole capture. A disk that turns
  // read-only (EROFS) behaves the same; every 7th k of it. Under ASan/UBSan (./dev test
  // --sanitize, 10-20x slower) every 5th and 35th k: the same code paths, a sample of the
  // positions.
  const long sample = testing_build::kSanitized ? 5 : 1;
  for (const auto& [err, words, stride] :
       {std::tuple{ENOSPC, "the disk is full", sample}, std::tuple{EROFS, "read-only", 7 * sample}})
    for (long k = 0; k < calls; k += stride) {
      SCOPED_TRACE(std::string(words) + " from durable-write call " + std::to_string(k) + " of " +
                   std::to_string(calls));
      std::filesystem::remove_all(dir);
      RampCamera cam;
      FaultyFileIo full(k, err);
      try {
        ScopedFileIo use(full);
        SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
        CaptureController({&cam, nullptr, &clock}, OneSlotPlan(), Site{}).Run(w, nullptr, nullptr);
        ADD_FAILURE() << "the capture finished on a failing disk";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
      }
      if (!std::filesystem::exists(dir / "session.json")) {
        // Full before the session existed: a new capture may use the folder.
        RampCamera again;
        SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
        CaptureController({&again, nullptr, &clock}, OneSlotPlan(), Site{})
            .Run(w, nullptr, nullptr);
        EXPECT_EQ(GroupsOf(w.frames()), ref_groups);
        continue;
      }
      ExpectWholeSession(dir);
      ExpectResumeCompletes(dir, ref_groups);
    }
  std::filesystem::remove_all(dir);
}

// A RampCamera whose grab number `at` fails as `how` says.
class FaultyCamera : public RampCamera {
 public:
  enum class Fault { kTimeout, kPartialFrame, kBadExposure };
  int at = 0;
  Fault how = Fault::kTimeout;
  CapturedFrame Grab() override {
    const bool fail = static_cast<int>(grabs.size()) == at;
    CapturedFrame f = RampCamera::Grab();
    if (!fail) return f;
    switch (how) {
      case Fault::kTimeout:
        throw DeviceError("ramp: timed out waiting for a frame (ETIMEDOUT)");
      case Fault::kPartialFrame:
        f.image.data.resize(f.image.data.size() / 3);  // the transfer stopped a third of the way
        break;
      case Fault::kBadExposure:
        f.exposure_s = std::nan("");
        break;
    }
    return f;
  }
};

TEST(ControllerTest, CameraTimeoutOrPartialFrameStopsWithAConsistentResumableSession) {
  JumpClock clock;
  std::set<std::string> ref_groups;
  {
    RampCamera ref;
    auto ref_dir = TempDir("fault_ref");
    SessionWriter w = SessionWriter::Create(ref_dir, SessionInfo{});
    CaptureController({&ref, nullptr, &clock}, OneSlotPlan(), Site{}).Run(w, nullptr, nullptr);
    ref_groups = GroupsOf(w.frames());
    std::filesystem::remove_all(ref_dir);
  }
  const std::pair<FaultyCamera::Fault, const char*> faults[] = {
      {FaultyCamera::Fault::kTimeout, "timed out"},
      {FaultyCamera::Fault::kPartialFrame, "partial frame"},
      {FaultyCamera::Fault::kBadExposure, "impossible exposure"}};
  for (const auto& [fault, words] : faults) {
    for (int at : {0, 3, 9}) {  // the first frame, inside the sun bracket, a later bracket
      SCOPED_TRACE(std::string(words) + " at grab " + std::to_string(at));
      FaultyCamera cam;
      cam.how = fault;
      cam.at = at;
      auto dir = TempDir("fault");
      CaptureSummary s;
      {
        SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
        s = CaptureController({&cam, nullptr, &clock}, OneSlotPlan(), Site{})
                .Run(w, nullptr, nullptr);
      }
      EXPECT_TRUE(s.stopped);
      EXPECT_TRUE(s.camera_lost);
      ASSERT_FALSE(s.warnings.empty());
      EXPECT_NE(s.warnings.back().find(words), std::string::npos) << s.warnings.back();
      EXPECT_NE(s.warnings.back().find("ramp"), std::string::npos) << s.warnings.back();
      EXPECT_EQ(Session::Load(dir).frames().size(), static_cast<size_t>(at));
      ExpectWholeSession(dir);
      ExpectResumeCompletes(dir, ref_groups);
      std::filesystem::remove_all(dir);
    }
  }
}

// A receiver that answers a few polls, then fails like a GPS pulled out.
class VanishingGps : public Gps {
 public:
  int good_polls = 3, polls = 0;
  std::string Id() const override { return "gps0"; }
  std::optional<GpsFix> Poll() override {
    if (polls++ >= good_polls) throw DeviceError("gps0: /dev/ttyACM0: no such device");
    GpsFix f;
    f.utc = ParseIso8601("2026-08-25T20:00:00Z").PlusSeconds(polls);
    f.lat_deg = 37.8722;  // Berkeley, as the plan's time (13:00 PDT)
    f.lon_deg = -122.2578;
    f.height_m = 140;
    f.mode = 3;
    f.satellites = 8;
    return f;
  }
};

TEST(ControllerTest, GpsLostMidCaptureKeepsTheLastFixAndSaysSo) {
  RampCamera cam;
  VanishingGps gps;
  JumpClock clock;
  auto dir = TempDir("gps_lost");
  std::vector<std::string> statuses;
  CaptureSummary s;
  {
    SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
    s = CaptureController({&cam, &gps, &clock}, OneSlotPlan(), Site{})
            .Run(
                w, [&](const CaptureProgress& p) { statuses.push_back(p.gps_status); }, nullptr);
  }
  EXPECT_FALSE(s.stopped);  // the site does not move: the capture goes on
  Session done = Session::Load(dir);
  ASSERT_GT(done.frames().size(), static_cast<size_t>(gps.good_polls));
  for (const FrameRecord& f : done.frames()) {
    ASSERT_TRUE(f.gps.has_value()) << f.file;
    EXPECT_DOUBLE_EQ(f.gps->lat_deg, 37.8722);
  }
  ASSERT_FALSE(statuses.empty());
  EXPECT_NE(statuses.back().find("no such device"), std::string::npos) << statuses.back();
  ExpectWholeSession(dir);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace rouen
