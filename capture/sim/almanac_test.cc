#include "capture/sim/almanac.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "core/angles.h"
#include "core/solar.h"
#include "core/time.h"

namespace rouen {
namespace {

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / kPi;
}

Eigen::Vector3d Enu(double az_deg, double el_deg) {
  const double az = az_deg * kPi / 180, el = el_deg * kPi / 180;
  return Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
}

// The almanac's stated accuracy is ~0.01 deg (1950-2050); ERFA is far better, so the two
// must agree within 0.02 deg on airless directions, and the distances within 2e-4 AU.
TEST(AlmanacTest, AgreesWithErfaOnSeveralDatesAndSites) {
  const Site sites[] = {
      {37.8722, -122.2578, 60.0}, {-33.86, 151.21, 20.0}, {64.15, -21.94, 0.0}, {0.0, 0.0, 0.0}};
  const char* times[] = {"2001-03-20T18:00:00Z", "2010-06-21T12:34:56Z", "2019-12-21T23:10:00Z",
                         "2026-08-25T14:45:00Z", "2026-08-25T20:30:00Z", "2026-08-26T01:15:00Z",
                         "2035-09-23T09:00:00Z", "2044-02-02T16:20:00Z"};
  int compared = 0;
  for (const Site& site : sites) {
    for (const char* ts : times) {
      const UtcTime t = ParseIso8601(ts);
      const AlmanacSun a = AlmanacSunPosition(t, site);
      const SunPosition e = ComputeSunPosition(t, site);
      if (e.elevation_true_deg < -5) continue;
      ++compared;
      EXPECT_LT(AngleDeg(a.TrueDirectionEnu(), Enu(e.azimuth_deg, e.elevation_true_deg)), 0.02)
          << ts << " lat " << site.lat_deg;
      EXPECT_NEAR(a.distance_au, e.distance_au, 2e-4) << ts;
      EXPECT_NEAR(a.angular_radius_deg, e.angular_radius_deg, 0.002) << ts;
      if (e.elevation_true_deg > 10) {
        // Bennett vs SPA refraction differ by < 0.002 deg above 10 deg.
        EXPECT_LT(AngleDeg(a.DirectionEnu(), e.DirectionEnu()), 0.02) << ts;
      }
    }
  }
  EXPECT_GE(compared, 12);
}

TEST(AlmanacTest, NoonSunIsSouthAtBerkeleyInAugust) {
  const AlmanacSun a = AlmanacSunPosition(ParseIso8601("2026-08-25T20:08:00Z"), Site{});
  EXPECT_NEAR(a.azimuth_deg, 180.0, 3.0);
  // Declination ~ +10.5 deg late August: noon elevation ~ 90 - 37.87 + 10.5.
  EXPECT_NEAR(a.elevation_true_deg, 62.6, 0.5);
  EXPECT_NEAR(a.distance_au, 1.0108, 0.001);
}

TEST(AlmanacTest, BennettRefraction) {
  // About 34 arcmin at the horizon, ~1 arcmin at 45 deg, decreasing with elevation.
  EXPECT_NEAR(BennettRefractionDeg(-0.5, 1010, 10), 0.57, 0.06);
  EXPECT_NEAR(BennettRefractionDeg(45, 1010, 10), 1.0 / 60, 0.1 / 60);
  double prev = 1e9;
  for (double e = -1.5; e <= 90; e += 0.5) {
    const double r = BennettRefractionDeg(e, 1010, 10);
    EXPECT_LE(r, prev);
    EXPECT_GE(r, 0);
    prev = r;
  }
  EXPECT_EQ(BennettRefractionDeg(-3, 1010, 10), 0.0);
  // Thinner air refracts less.
  EXPECT_LT(BennettRefractionDeg(5, 800, 10), BennettRefractionDeg(5, 1010, 10));
}

}  // namespace
}  // namespace rouen
