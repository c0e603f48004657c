#include "capture/sim/sim_devices.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "capture/sim/sim_test_world.h"
#include "core/angles.h"

namespace rouen {
namespace {

// A non-owning shared_ptr to the process-wide test world.
std::shared_ptr<SimWorld> World() {
  return std::shared_ptr<SimWorld>(&SimTestWorld(), [](SimWorld*) {});
}

TEST(SimClockTest, AdvancesByGrabsAndJumpsToSlots) {
  SimClock clock(SimTestNoon());
  EXPECT_EQ(clock.Now(), SimTestNoon());
  clock.Advance(1.5);
  EXPECT_EQ(clock.Now(), SimTestNoon().PlusSeconds(1.5));
  EXPECT_EQ(clock.SlotTime(), SimTestNoon());
  EXPECT_TRUE(clock.JumpTo(SimTestEvening()));
  EXPECT_EQ(clock.Now(), SimTestEvening());
  EXPECT_EQ(clock.SlotTime(), SimTestEvening());
  EXPECT_THROW(clock.Advance(-1), Error);
}

TEST(SimCameraTest, ControlsAreClampedAndQuantised) {
  SimClock clock(SimTestNoon());
  SimCamera cam(World(), &clock, true, 1);
  // 1/3-stop steps: 2^(n/3) seconds.
  const double e = cam.SetExposure(0.0042);
  EXPECT_NEAR(std::log2(e) * 3, std::round(std::log2(e) * 3), 1e-9);
  EXPECT_NEAR(e, 0.0042, 0.0042 * 0.13);
  EXPECT_DOUBLE_EQ(cam.SetExposure(1e-6), 1.0 / 8000);
  EXPECT_DOUBLE_EQ(cam.SetExposure(100), 30.0);
  EXPECT_DOUBLE_EQ(cam.SetGain(0.5), 1.0);
  EXPECT_DOUBLE_EQ(cam.SetGain(40), 16.0);
  EXPECT_THROW(cam.SetExposure(-1), DeviceError);
  EXPECT_THROW(cam.SetNdFilter(-0.5), DeviceError);
  cam.SetNdFilter(4.5);
  EXPECT_DOUBLE_EQ(cam.NdFilter(), 4.5);
  bool found = false;
  for (const ControlInfo& c : cam.Controls()) {
    if (c.name == "exposure_s") {
      found = true;
      EXPECT_DOUBLE_EQ(c.value, 30.0);
      EXPECT_DOUBLE_EQ(c.min, 1.0 / 8000);
    }
  }
  EXPECT_TRUE(found);
  EXPECT_EQ(cam.ViewCount(Target::kArchitecture), 4);
  EXPECT_EQ(cam.ViewCount(Target::kSun), 1);
  EXPECT_EQ(cam.ViewCount(Target::kLandscape), 2);
  EXPECT_THROW(cam.Aim(Target::kArchitecture, 4), DeviceError);
  EXPECT_THROW(cam.Aim(Target::kLandscape, 2), DeviceError);
  EXPECT_THROW(cam.Aim(Target::kSky, 1), DeviceError);
}

TEST(SimCameraTest, GrabsFramesOfEachTargetAtTheSlotTime) {
  SimClock clock(SimTestNoon());
  const int computed = SimTestWorld().stats().times_computed;
  SimCamera cam(World(), &clock, true, 7);
  struct Case {
    Target target;
    int w, h;
  };
  const Case cases[] = {{Target::kSun, 256, 256},
                        {Target::kAureole, 320, 320},
                        {Target::kSky, 320, 320},
                        {Target::kLandscape, 512, 256},
                        {Target::kArchitecture, 320, 240}};
  for (const Case& c : cases) {
    cam.Aim(c.target, 0);
    const UtcTime before = clock.Now();
    const double exposure = cam.SetExposure(1.0 / 500);
    const CapturedFrame f = cam.Grab();
    EXPECT_EQ(f.image.width, c.w);
    EXPECT_EQ(f.image.height, c.h);
    EXPECT_EQ(f.image.units, PixelUnits::kDigital);
    EXPECT_FALSE(f.hdr);
    ASSERT_TRUE(f.intrinsics && f.pose);
    EXPECT_EQ(f.intrinsics->width, c.w);
    EXPECT_DOUBLE_EQ(f.exposure_s, exposure);
    EXPECT_EQ(f.utc, before.PlusSeconds(0.5 * exposure));
    EXPECT_EQ(clock.Now(), before.PlusSeconds(exposure + 0.2));
    for (float v : f.image.data) {
      EXPECT_GE(v, 0.0f);
      EXPECT_LE(v, 255.0f);
      EXPECT_EQ(v, std::round(v));
    }
  }
  // The second landscape view is taken from the mast at the top of the tower.
  cam.Aim(Target::kLandscape, 1);
  const CapturedFrame high = cam.Grab();
  ASSERT_TRUE(high.pose);
  EXPECT_GT(high.pose->position.z(), 66.0);
  EXPECT_EQ(high.image.width, 512);
  // The lighting stayed at the slot: no new time was computed for the later frame times.
  EXPECT_EQ(SimTestWorld().stats().times_computed, computed);
}

TEST(SimCameraTest, RadianceOfAViewIsWhatItsFramesExpose) {
  SimClock clock(SimTestNoon());
  SimCamera cam(World(), &clock, true, 1);
  clock.JumpTo(SimTestEvening());
  // Asked for another slot's view: the world's render of that view at that slot's instant.
  const Image& noon = cam.Radiance(Target::kArchitecture, 1, SimTestNoon());
  const SimView v = SimTestWorld().ArchitectureViews(true)[1];
  EXPECT_EQ(noon.data, SimTestWorld().RenderRadiance(v.intrinsics, v.pose).data);
  EXPECT_EQ(SimTestWorld().Time(), SimTestNoon());
  // The target's other views, rendered meanwhile on other threads, are the world's renders too.
  for (int other : {0, 2, 3}) {
    const SimView ov = SimTestWorld().ArchitectureViews(true)[other];
    EXPECT_EQ(cam.Radiance(Target::kArchitecture, other, SimTestNoon()).data,
              SimTestWorld().RenderRadiance(ov.intrinsics, ov.pose).data);
  }
  // The camera's own frames of that view and slot expose the same image.
  clock.JumpTo(SimTestNoon());
  cam.Aim(Target::kArchitecture, 1);
  EXPECT_EQ(&cam.CurrentRadiance(), &noon);
  EXPECT_THROW(cam.Radiance(Target::kArchitecture, 4, SimTestNoon()), DeviceError);
}

TEST(SimCameraTest, SunFramesThroughNdAreUnsaturatedAndArchitectureIsMidRange) {
  SimClock clock(SimTestNoon());
  SimCamera cam(World(), &clock, true, 3);
  cam.Aim(Target::kSun, 0);
  cam.SetNdFilter(4.5);
  cam.SetExposure(1.0 / 1000);
  const CapturedFrame sun = cam.Grab();
  const float peak = *std::max_element(sun.image.data.begin(), sun.image.data.end());
  EXPECT_GT(peak, 60.0f);
  EXPECT_LT(peak, 255.0f);
  // Without the filter the disc saturates even at 1/8000 s.
  cam.SetNdFilter(0);
  cam.SetExposure(1.0 / 8000);
  const CapturedFrame bare = cam.Grab();
  EXPECT_EQ(*std::max_element(bare.image.data.begin(), bare.image.data.end()), 255.0f);

  cam.Aim(Target::kArchitecture, 0);
  cam.SetExposure(1.0 / 500);
  const CapturedFrame arch = cam.Grab();
  std::vector<float> v(arch.image.data);
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  EXPECT_GT(v[v.size() / 2], 25.0f);
  EXPECT_LT(v[v.size() / 2], 230.0f);
}

TEST(SimCameraTest, DeterministicForASeed) {
  SimClock c1(SimTestNoon()), c2(SimTestNoon()), c3(SimTestNoon());
  SimCamera a(World(), &c1, true, 5), b(World(), &c2, true, 5), c(World(), &c3, true, 6);
  for (SimCamera* cam : {&a, &b, &c}) {
    cam->Aim(Target::kArchitecture, 2);
    cam->SetExposure(1.0 / 250);
  }
  const CapturedFrame fa = a.Grab(), fb = b.Grab(), fc = c.Grab();
  EXPECT_EQ(fa.image.data, fb.image.data);
  EXPECT_NE(fa.image.data, fc.image.data);
  // Two frames from one camera differ only by noise.
  const CapturedFrame fa2 = a.Grab();
  EXPECT_NE(fa.image.data, fa2.image.data);
}

TEST(SimGpsTest, FixesScatterAroundTheSiteWithTheStatedNoise) {
  SimClock clock(SimTestNoon());
  SimGps gps(World(), &clock, 9, 1.8);
  const Site& site = SimTestWorld().site();
  const double m_per_deg_lat = 111000.0;
  const double m_per_deg_lon = 111000.0 * std::cos(site.lat_deg * kPi / 180);
  double sum_e = 0, sum_n = 0, sum2 = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    const std::optional<GpsFix> f = gps.Poll();
    ASSERT_TRUE(f);
    EXPECT_EQ(f->mode, 3);
    EXPECT_EQ(f->utc, clock.Now());
    const double e = (f->lon_deg - site.lon_deg) * m_per_deg_lon;
    const double nn = (f->lat_deg - site.lat_deg) * m_per_deg_lat;
    sum_e += e;
    sum_n += nn;
    sum2 += e * e + nn * nn;
  }
  // Horizontal RMS = sigma sqrt(2) ~ 2.5 m; 1 deg is 111 km to 0.5%, so 3% covers it.
  EXPECT_NEAR(std::sqrt(sum2 / n), 1.8 * std::sqrt(2.0), 0.03 * 2.55 + 0.05);
  EXPECT_NEAR(sum_e / n, 0, 5 * 1.8 / std::sqrt(n));
  EXPECT_NEAR(sum_n / n, 0, 5 * 1.8 / std::sqrt(n));
}

}  // namespace
}  // namespace rouen
