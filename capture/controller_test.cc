#include "capture/controller.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>

#include <gtest/gtest.h>

#include "core/error.h"

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
  std::vector<ControlInfo> Controls() const override { return {{"exposure_s", 1e-4, 30, exposure}}; }
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
  auto p = std::filesystem::temp_directory_path() / ("rouen_controller_test_" + name + "_" +
                                                     std::to_string(::getpid()));
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
      if (f.group == GroupName(0, Target::kArchitecture, v)) {
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
        w, [&](const CaptureProgress&) { if (++seen == 5) stop = true; }, &stop);
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

}  // namespace
}  // namespace rouen
