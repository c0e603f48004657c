// The simulated world through the Aravis driver gives the same session as the plain
// simulated camera.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>

#include "capture/aravis/aravis_camera.h"
#include "capture/controller.h"
#include "capture/sim/sim_devices.h"
#include "capture/sim/sim_test_world.h"
#include "core/session.h"

namespace rouen {
namespace {

std::shared_ptr<SimWorld> World() {
  return std::shared_ptr<SimWorld>(&SimTestWorld(), [](SimWorld*) {});
}

std::filesystem::path TempDir(const std::string& name) {
  auto p = std::filesystem::temp_directory_path() /
           ("rouen_aravis_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(p);
  return p;
}

// Same grabs, frame by frame: pixels identical (RGB8 carries the sensor's 8-bit values),
// timestamps identical, exposure within the Fake camera's 1-us register quantisation.
TEST(SimAravisCameraTest, FramesMatchThePlainSimCamera) {
  SimClock clock_a(SimTestNoon()), clock_b(SimTestNoon());
  SimCamera plain(World(), &clock_a, true, 7);
  std::unique_ptr<Camera> arv = OpenSimAravisCamera(World(), &clock_b, true, 7);
  EXPECT_EQ(arv->ViewCount(Target::kArchitecture), plain.ViewCount(Target::kArchitecture));
  plain.Aim(Target::kArchitecture, 1);
  arv->Aim(Target::kArchitecture, 1);
  for (double e : {1.0 / 8000, 1.0 / 700, 1.0 / 60, 0.3}) {
    const double ea = plain.SetExposure(e), eb = arv->SetExposure(e);
    EXPECT_LE(std::abs(ea - eb), 0.5e-6) << e;
    CapturedFrame a = plain.Grab(), b = arv->Grab();
    EXPECT_EQ(b.exposure_s, eb);
    EXPECT_EQ(a.utc, b.utc);
    EXPECT_EQ(a.gain, b.gain);
    ASSERT_EQ(a.image.width, b.image.width);
    ASSERT_EQ(a.image.height, b.image.height);
    EXPECT_EQ(b.image.units, PixelUnits::kDigital);
    EXPECT_TRUE(a.image.data == b.image.data) << "pixels differ at exposure " << e;
    ASSERT_TRUE(b.pose.has_value());
    EXPECT_TRUE(a.pose->rotation.isApprox(b.pose->rotation));
  }
  // Gain: GainRaw steps of 1 dB; the rendered gain is the read-back one.
  const double g = arv->SetGain(2.0);
  EXPECT_NEAR(g, std::pow(10.0, 6.0 / 20), 1e-12);  // 6.02 dB -> 6 steps
  plain.SetGain(g);
  CapturedFrame a = plain.Grab(), b = arv->Grab();
  EXPECT_EQ(b.gain, g);
  EXPECT_TRUE(a.image.data == b.image.data);
  const AravisStats st = *AravisStatsOf(*arv);
  EXPECT_EQ(st.stale, 0u) << "a frame filled before the hand-over was delivered";
  EXPECT_EQ(st.dropped, 0u);
  EXPECT_EQ(st.delivered, 5u);
  EXPECT_FALSE(AravisStatsOf(plain).has_value());
}

struct RunResult {
  std::vector<FrameRecord> frames;
  std::vector<Image> images;
  CaptureSummary summary;
  std::optional<AravisStats> stats;
};

RunResult RunCapture(bool through_aravis, const std::string& name) {
  SimClock clock(SimTestNoon());
  std::unique_ptr<Camera> cam;
  if (through_aravis) {
    cam = OpenSimAravisCamera(World(), &clock, true, 11);
  } else {
    cam = std::make_unique<SimCamera>(World(), &clock, true, 11);
  }
  SimGps gps(World(), &clock, 5);
  CapturePlan plan;
  plan.slots = {SimTestNoon()};
  plan.targets = {Target::kSun, Target::kAureole, Target::kArchitecture};
  const auto dir = TempDir(name);
  RunResult r;
  {
    SessionWriter w = SessionWriter::Create(dir, SessionInfo{});
    CaptureController ctl({cam.get(), &gps, &clock}, plan, SimTestWorld().site());
    r.summary = ctl.Run(w, nullptr, nullptr);
  }
  Session s = Session::Load(dir);
  r.frames = s.frames();
  for (const FrameRecord& f : r.frames) r.images.push_back(s.LoadFrame(f));
  r.stats = AravisStatsOf(*cam);
  std::filesystem::remove_all(dir);
  return r;
}

// The capture controller (sun through ND, aureole, four architecture views, adaptive
// brackets) journals the same session through both cameras: same groups in the same order,
// same frame count, same timestamps, GPS fixes, ND densities and gains, identical pixels
// (so identical file hashes), and exposures equal to within 0.5 us (the Fake camera's
// ExposureTimeAbs register holds whole microseconds; the plain camera reports 2^(n/3) s).
TEST(SimAravisCameraTest, CaptureSessionIsTheSameThroughAravis) {
  const RunResult plain = RunCapture(false, "plain");
  const RunResult arv = RunCapture(true, "aravis");
  for (const std::string& w : arv.summary.warnings) ADD_FAILURE() << "aravis run: " << w;
  ASSERT_GT(plain.frames.size(), 8u);
  ASSERT_EQ(plain.frames.size(), arv.frames.size());
  EXPECT_EQ(plain.summary.frames, arv.summary.frames);
  std::map<std::string, int> groups;
  for (size_t i = 0; i < plain.frames.size(); ++i) {
    const FrameRecord &p = plain.frames[i], &a = arv.frames[i];
    SCOPED_TRACE("frame " + std::to_string(i) + " " + p.group);
    groups[p.group]++;
    EXPECT_EQ(p.group, a.group);
    EXPECT_EQ(p.target, a.target);
    EXPECT_EQ(p.slot, a.slot);
    EXPECT_EQ(p.utc, a.utc);
    EXPECT_LE(std::abs(p.exposure_s - a.exposure_s), 0.5e-6);
    EXPECT_NEAR(a.exposure_s * 1e6, std::round(a.exposure_s * 1e6), 1e-6);
    EXPECT_EQ(p.gain, a.gain);
    EXPECT_EQ(p.nd_density, a.nd_density);
    ASSERT_EQ(p.gps.has_value(), a.gps.has_value());
    if (p.gps) {
      EXPECT_EQ(p.gps->lat_deg, a.gps->lat_deg);
    }
    EXPECT_EQ(p.sun_elevation_deg, a.sun_elevation_deg);
    EXPECT_EQ(p.sha256, a.sha256);
    EXPECT_TRUE(plain.images[i].data == arv.images[i].data);
    EXPECT_EQ(a.device, "aravis:Fake_1");
  }
  EXPECT_EQ(groups.size(), 2u + 4u);  // sun, aureole, 4 architecture views
  ASSERT_TRUE(arv.stats.has_value());
  EXPECT_EQ(arv.stats->stale, 0u);
  EXPECT_EQ(arv.stats->dropped, 0u);
  EXPECT_EQ(arv.stats->incomplete, 0u);
  EXPECT_EQ(arv.stats->delivered, arv.frames.size());
}

}  // namespace
}  // namespace rouen
