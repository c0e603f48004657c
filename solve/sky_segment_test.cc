#include "solve/sky_segment.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/angles.h"
#include "core/error.h"
#include "core/solar.h"
#include "solve/sky_model.h"

namespace rouen {
namespace {

// A 360x180 equirect scene: a clear sky (eq. 9, bluish) above the horizon; a building from
// azimuth 60 to 120 deg up to 30 deg elevation (left half a smooth grey wall, right half
// textured bright stone) with a sky-blue smooth "window" inside it; grey ground below.
struct Scene {
  Image img;
  Intrinsics k = Intrinsics::Equirect(360, 180);
  Pose pose = Pose::Level(Eigen::Vector3d::Zero(), 0, 0);
  Eigen::Vector3d sun = EnuFromAzEl(200, 40);
  std::vector<uint8_t> truth;  // 1 = sky
};

Scene MakeScene() {
  Scene s;
  SkyModel m;
  m.sun_dir = s.sun;
  m.channel[0] = {0.8, -1.0, -0.40, 12.0, -3.2, 0.50, 0.9};
  m.channel[1] = {1.1, -1.0, -0.35, 9.0, -2.8, 0.45, 0.9};
  m.channel[2] = {1.9, -0.9, -0.30, 7.0, -2.5, 0.40, 0.85};
  s.img = Image(360, 180, 3, PixelUnits::kRadiance);
  s.truth.assign(360 * 180, 0);
  for (int y = 0; y < 180; ++y) {
    for (int x = 0; x < 360; ++x) {
      const Eigen::Vector3d d =
          (s.pose.rotation * Unproject(s.k, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
      const double el = std::asin(d.z()) / kDeg;
      double az = std::atan2(d.x(), d.y()) / kDeg;
      if (az < 0) az += 360;
      Eigen::Vector3d v;
      if (el < 0) {
        v = Eigen::Vector3d(0.3, 0.3, 0.25);
      } else if (az > 60 && az < 120 && el < 30) {
        if (az > 80 && az < 90 && el > 10 && el < 20) {
          v = m.Radiance(EnuFromAzEl(az, 60));  // window reflecting the sky
        } else if (az < 90) {
          v = Eigen::Vector3d(0.6, 0.55, 0.5);
        } else {
          const double t = 1.5 + ((x / 2 + y / 2) % 2 ? 0.6 : -0.6);
          v = Eigen::Vector3d(t, 0.95 * t, 0.8 * t);
        }
      } else {
        v = m.Radiance(d);
        s.truth[static_cast<size_t>(y) * 360 + x] = 1;
      }
      for (int c = 0; c < 3; ++c) s.img.at(x, y, c) = static_cast<float>(v[c]);
    }
  }
  return s;
}

TEST(SegmentSky, FindsTheSkyAndExcludesBuildingWindowGroundAndSun) {
  const Scene s = MakeScene();
  SkySegmentSummary sum;
  const std::vector<uint8_t> mask =
      SegmentSky(s.img, s.k, s.pose, s.sun, SkySegmentOptions{}, &sum);
  ASSERT_EQ(mask.size(), s.truth.size());
  int sky = 0, found = 0, false_sky = 0;
  for (size_t p = 0; p < mask.size(); ++p) {
    sky += s.truth[p];
    if (s.truth[p] && mask[p]) ++found;
    if (!s.truth[p] && mask[p]) ++false_sky;
  }
  // Lost sky: the one-pixel rim along the building's outline (its smoothness test sees the
  // edge), the sun's 3-degree disc and the steepest aureole: a few percent at most.
  EXPECT_GT(found, 0.95 * sky);
  EXPECT_EQ(false_sky, 0);  // nothing of the building, its window or the ground
  EXPECT_EQ(sum.sky_pixels, found);
  EXPECT_GT(sum.seeds, 0);
  // The sun itself is excluded.
  const Eigen::Vector2d sun_px = *Project(s.k, s.pose.WorldToCamera(s.sun));
  EXPECT_EQ(mask[static_cast<size_t>(sun_px.y()) * 360 + static_cast<size_t>(sun_px.x())], 0);
}

TEST(SegmentSky, RejectsBadInput) {
  Scene s = MakeScene();
  SkySegmentOptions bad;
  bad.max_log_gradient_per_deg = 0;
  EXPECT_THROW(SegmentSky(s.img, s.k, s.pose, s.sun, bad), Error);
  Image digital = s.img;
  digital.units = PixelUnits::kDigital;
  EXPECT_THROW(SegmentSky(digital, s.k, s.pose, s.sun, {}), Error);
  EXPECT_THROW(SegmentSky(s.img, Intrinsics::Equirect(100, 50), s.pose, s.sun, {}), Error);
  Image dark(360, 180, 3, PixelUnits::kRadiance, 0.f);  // nothing positive: no sky
  EXPECT_THROW(SegmentSky(dark, s.k, s.pose, s.sun, {}), Error);
}

}  // namespace
}  // namespace rouen
