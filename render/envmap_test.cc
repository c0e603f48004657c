#include "render/envmap.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/angles.h"
#include "core/error.h"
#include "core/hash_random.h"
#include "solve/sky_time.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

Eigen::Vector3d Compass(double azimuth_deg, double elevation_deg) {
  const double a = azimuth_deg * kDeg, e = elevation_deg * kDeg;
  return Eigen::Vector3d(std::sin(a) * std::cos(e), std::cos(a) * std::cos(e), std::sin(e));
}

// A clear sky with the sun at azimuth 130 deg, elevation 35 deg, and an environment whose
// regions hold that sky's means above the horizon and ground below, each scaled by its own
// factor in 0.5..1.5 (so that a map turned or mirrored lights the planes differently).
Lighting TestLighting() {
  Lighting l;
  l.sun_dir = Compass(130, 35);
  l.sun_radiance = Eigen::Vector3d(1.2e5, 1.0e5, 0.8e5);
  l.sky = testing::ClearSky(l.sun_dir);
  l.env = EnvironmentMap::FromSky(EnvOptions{}, l.sky, Eigen::Vector3d(0.3, 0.25, 0.2));
  for (size_t r = 0; r < l.env.radiance.size(); ++r)
    l.env.radiance[r] *= 0.5 + HashUniform53(MixHash(r + 17));
  l.use_env = true;
  return l;
}

TEST(EnvmapTest, BlendersOrientation) {
  // Blender's equirectangular convention (render/envmap.h): east at the centre, north at a
  // quarter, south at three quarters, west at the edges; the zenith on row 0.
  const int w = 360, h = 180;
  auto near = [](const Eigen::Vector2d& a, double x, double y) {
    EXPECT_NEAR(a.x(), x, 1e-9);
    EXPECT_NEAR(a.y(), y, 1e-9);
  };
  near(LatLongPixel(w, h, Eigen::Vector3d::UnitX()), 180, 90);
  near(LatLongPixel(w, h, Eigen::Vector3d::UnitY()), 90, 90);
  near(LatLongPixel(w, h, -Eigen::Vector3d::UnitY()), 270, 90);
  EXPECT_NEAR(LatLongPixel(w, h, Eigen::Vector3d::UnitZ()).y(), 0, 1e-9);
  EXPECT_NEAR(LatLongPixel(w, h, Compass(0, 30)).y(), 60, 1e-9);
  // Round trip through every part of the sphere.
  for (double az = 0; az < 360; az += 37)
    for (double el = -80; el <= 80; el += 20) {
      const Eigen::Vector3d d = Compass(az, el);
      const Eigen::Vector2d p = LatLongPixel(w, h, d);
      EXPECT_NEAR(p.x(), std::fmod(90 + az, 360.0), 1e-9) << az << " " << el;
      EXPECT_LT((LatLongDirection(w, h, p.x(), p.y()) - d).norm(), 1e-12);
    }
  // Solid angles sum to the sphere.
  double total = 0;
  for (int row = 0; row < h; ++row) total += w * LatLongPixelSolidAngle(w, h, row);
  EXPECT_NEAR(total, 4 * kPi, 1e-12);
}

TEST(EnvmapTest, TheSunsEnergyIsConservedAndWhereTheSunIs) {
  Lighting l = TestLighting();
  LatLongOptions o;
  o.width = 512;
  const Image with = BakeLatLong(l, o);
  Lighting dark = l;
  dark.sun_radiance.setZero();
  const Image without = BakeLatLong(dark, o);
  Eigen::Vector3d flux = Eigen::Vector3d::Zero(), centroid = Eigen::Vector3d::Zero();
  int pixels = 0;
  for (int row = 0; row < with.height; ++row)
    for (int col = 0; col < with.width; ++col) {
      const double sr = LatLongPixelSolidAngle(with.width, with.height, row);
      Eigen::Vector3d d;
      for (int c = 0; c < 3; ++c) d[c] = with.at(col, row, c) - without.at(col, row, c);
      if (d.maxCoeff() <= 0) continue;
      ++pixels;
      flux += sr * d;
      centroid += sr * d[0] * LatLongDirection(with.width, with.height, col + 0.5, row + 0.5);
    }
  // L_sun Omega_sun exactly, up to the float pixels (relative 1e-7 each, and the sky's value
  // subtracted back: 1e-5).
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(flux[c], l.sun_radiance[c] * l.sun_solid_angle_sr, 1e-5 * flux[c]) << c;
  // A 0.53-degree disc on 0.70-degree pixels: a handful of them, centred on the sun to within
  // half a pixel.
  EXPECT_GE(pixels, 1);
  EXPECT_LE(pixels, 9);
  const double off = std::acos(std::min(1.0, centroid.normalized().dot(l.sun_dir)));
  EXPECT_LT(off, 0.5 * kPi / with.height);
}

// Re-integrating the map's irradiance on planes gives rouen's irradiance (sun + environment
// regions by vector flux) within the discretisation's bound.
TEST(EnvmapTest, ReintegratedIrradianceMatchesRouens) {
  const Lighting l = TestLighting();
  LatLongOptions o;
  o.width = 512;
  const Image map = BakeLatLong(l, o);
  const int w = map.width, h = map.height;
  // Each pixel holds the exact mean of the regions over it (and the sun's share), so the only
  // error of sum_p L_p int_p cos is the covariance of radiance and cosine inside pixels:
  // |int_p (L - mean L)(cos - mean cos)| <= int_p |L - mean L| diam_p <= Omega_p (Lmax -
  // Lmin)_p / 2 diam_p (a mean absolute deviation is at most half the range), with diam_p
  // (<= sqrt 2 pi / h) bounding the cosine's range over the pixel. Lmax - Lmin is found from
  // 5 x 5 points per pixel (regions are far larger than pixels, so those see every region a
  // pixel touches). The sun's pixels lie within r + sqrt 2 pi / h of its centre: their cosine
  // is off by at most that, of L_sun Omega_sun. Rouen's vector flux follows the regions'
  // parallels with 64 great arcs per region (its sagitta moves an edge by < 1e-5 rad).
  const double diam = std::sqrt(2.0) * kPi / h;
  std::vector<double> spread_sr(static_cast<size_t>(w) * h);
  for (int row = 0; row < h; ++row)
    for (int col = 0; col < w; ++col) {
      Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
      for (int a = 0; a <= 4; ++a)
        for (int b = 0; b <= 4; ++b) {
          const Eigen::Vector3d d = LatLongDirection(w, h, col + b / 4.0, row + a / 4.0);
          const Eigen::Vector3d r = l.env.Radiance(d, 0.0);
          lo = lo.cwiseMin(r);
          hi = hi.cwiseMax(r);
        }
      spread_sr[static_cast<size_t>(row) * w + col] =
          (hi - lo).maxCoeff() / 2 * LatLongPixelSolidAngle(w, h, row);
    }
  const double sun_bound =
      l.sun_radiance.maxCoeff() * l.sun_solid_angle_sr * (l.SunAngularRadius() + diam);
  for (const Eigen::Vector3d& n :
       {Compass(0, 90), Compass(90, 0), Compass(0, 0), Compass(270, 0), Compass(180, 0), l.sun_dir,
        Compass(310, -20), Compass(200, 45)}) {
    const Eigen::Vector3d from_map = LatLongIrradiance(map, n);
    const Eigen::Vector3d rouen = UnoccludedIrradiance(l, n, 0.0);
    double bound = sun_bound;
    for (int row = 0; row < h; ++row)
      for (int col = 0; col < w; ++col)
        if (n.dot(LatLongDirection(w, h, col + 0.5, row + 0.5)) > -diam)
          bound += spread_sr[static_cast<size_t>(row) * w + col] * diam;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(from_map[c], rouen[c], bound) << "normal " << n.transpose() << " channel " << c;
    }
    std::printf("normal (%+.2f %+.2f %+.2f): map %.5g, rouen %.5g (rel %.2e, bound %.2e)\n", n.x(),
                n.y(), n.z(), from_map[1], rouen[1], std::abs(from_map[1] / rouen[1] - 1),
                bound / rouen[1]);
  }
}

// The map turned by a quarter or mirrored east-west lights the walls differently: the
// comparison above can tell a wrong orientation.
TEST(EnvmapTest, AWrongOrientationWouldBeSeen) {
  const Lighting l = TestLighting();
  LatLongOptions o;
  o.width = 256;
  const Image map = BakeLatLong(l, o);
  const double east = LatLongIrradiance(map, Compass(90, 0))[1];
  const double west = LatLongIrradiance(map, Compass(270, 0))[1];
  const double south = LatLongIrradiance(map, Compass(180, 0))[1];
  // The sun at azimuth 130 deg: the east and south walls are sunlit, the west wall is not.
  EXPECT_NEAR(east, UnoccludedIrradiance(l, Compass(90, 0), 0)[1], 0.02 * east);
  EXPECT_GT(east, 2 * west);
  EXPECT_GT(south, 2 * west);
}

TEST(EnvmapTest, TheSkyModelAboveTheHorizon) {
  Lighting l = TestLighting();
  l.sun_radiance.setZero();
  LatLongOptions o;
  o.width = 256;
  o.sky_model = true;
  const Image map = BakeLatLong(l, o);
  // Away from the circumsolar peak a pixel is the sky model's value at its centre to second
  // order in the pixel (0.7 deg): within 0.5%.
  for (const Eigen::Vector3d& d : {Compass(300, 40), Compass(10, 70), Compass(200, 5)}) {
    const Eigen::Vector2d p = LatLongPixel(map.width, map.height, d);
    const int col = static_cast<int>(p.x()), row = static_cast<int>(p.y());
    const Eigen::Vector3d centre =
        l.sky.Radiance(LatLongDirection(map.width, map.height, col + 0.5, row + 0.5));
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(map.at(col, row, c), centre[c], 5e-3 * centre[c]);
  }
  // Its horizontal irradiance is the sky model's (solve/sky_time.h, midpoint rule on 48 x 96
  // cells, ~1e-3).
  const Eigen::Vector3d e = LatLongIrradiance(map, Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d expected = HorizontalIrradiance(l.sky);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], expected[c], 3e-3 * expected[c]) << c;
}

TEST(EnvmapTest, BadInputIsRefused) {
  const Lighting l = TestLighting();
  LatLongOptions o;
  o.width = 513;
  EXPECT_THROW(BakeLatLong(l, o), Error);
  o.width = 4;
  EXPECT_THROW(BakeLatLong(l, o), Error);
  o.width = 64;
  Lighting bad = l;
  bad.sun_radiance[0] = NAN;
  EXPECT_THROW(BakeLatLong(bad, o), Error);
  EXPECT_THROW(LatLongIrradiance(Image(10, 10, 3), Eigen::Vector3d::UnitZ()), Error);
}

}  // namespace
}  // namespace rouen
