#include "core/solar.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

TEST(SolarTest, ReproducesSpaWorkedExample) {
  // Reda & Andreas (2008), NREL SPA, Table A5.1 / A5.2.
  const UtcTime t = ParseIso8601("2003-10-17T12:30:30-07:00");
  const Site site{39.742476, -105.1786, 1830.14};
  const Weather weather{820.0, 11.0};
  const SunPosition s = ComputeSunPosition(t, site, weather);
  EXPECT_NEAR(90.0 - s.elevation_deg, 50.111622, 3e-4);
  EXPECT_NEAR(s.azimuth_deg, 194.340241, 3e-4);
  // The refraction applied is exactly SPA's formula at the true elevation.
  const double e0 = s.elevation_true_deg;
  const double expected = (820.0 / 1010.0) * (283.0 / (273.0 + 11.0)) * 1.02 /
                          (60.0 * std::tan((e0 + 10.3 / (e0 + 5.11)) * kPi / 180.0));
  EXPECT_NEAR(s.elevation_deg - s.elevation_true_deg, expected, 1e-12);
  EXPECT_GT(expected, 0.0);
}

TEST(SolarTest, NoRefractionWithoutAirOrBelowTheHorizon) {
  const Site site{39.742476, -105.1786, 1830.14};
  const UtcTime noon = ParseIso8601("2003-10-17T12:30:30-07:00");
  const SunPosition airless = ComputeSunPosition(noon, site, Weather{0.0, 11.0});
  EXPECT_DOUBLE_EQ(airless.elevation_deg, airless.elevation_true_deg);
  const SunPosition night = ComputeSunPosition(ParseIso8601("2003-10-17T00:30:30-07:00"), site);
  EXPECT_LT(night.elevation_true_deg, -(0.26667 + 0.5667));
  EXPECT_DOUBLE_EQ(night.elevation_deg, night.elevation_true_deg);
}

TEST(SolarTest, EarthSunDistanceAndDiscSize) {
  const Site site;
  // Perihelion is in early January, aphelion in early July.
  const SunPosition jan = ComputeSunPosition(ParseIso8601("2024-01-03T00:00:00Z"), site);
  const SunPosition jul = ComputeSunPosition(ParseIso8601("2024-07-05T00:00:00Z"), site);
  EXPECT_NEAR(jan.distance_au, 0.9833, 1e-3);
  EXPECT_NEAR(jul.distance_au, 1.0167, 1e-3);
  for (const SunPosition& s : {jan, jul}) {
    EXPECT_NEAR(s.angular_radius_deg, 0.2666 / s.distance_au, 5e-4);
    const double r = s.angular_radius_deg * kPi / 180.0;
    // Spherical cap 2 pi (1 - cos r) = pi r^2 (1 - r^2 / 12 + O(r^4)); r^4 ~ 5e-10.
    EXPECT_NEAR(s.SolidAngleSr(), kPi * r * r * (1 - r * r / 12), 1e-9 * kPi * r * r);
  }
  EXPECT_GT(jan.angular_radius_deg, jul.angular_radius_deg);
}

TEST(SolarTest, EquinoxNoonAtTheEquatorIsNearZenith) {
  const Site equator{0.0, 0.0, 0.0};
  double best = -90;
  UtcTime t = ParseIso8601("2024-03-20T11:30:00Z");
  for (int i = 0; i <= 60; ++i, t = t.PlusSeconds(60)) {
    best = std::max(best, ComputeSunPosition(t, equator).elevation_true_deg);
  }
  // Declination is about +0.1 deg at noon on 2024-03-20, so the sun culminates within a
  // few tenths of a degree of the zenith (1-minute steps add at most 0.13 deg).
  EXPECT_GT(best, 89.5);
  EXPECT_LE(best, 90.0);
  // Morning sun is in the east, afternoon sun in the west, each 45 deg up 3 h from noon
  // (solar noon is ~7.5 min after 12:00 UTC at longitude 0 on this date: 1.9 deg).
  const SunPosition morning = ComputeSunPosition(ParseIso8601("2024-03-20T09:00:00Z"), equator);
  const SunPosition evening = ComputeSunPosition(ParseIso8601("2024-03-20T15:00:00Z"), equator);
  EXPECT_NEAR(morning.azimuth_deg, 90.0, 1.0);
  EXPECT_NEAR(evening.azimuth_deg, 270.0, 1.0);
  EXPECT_NEAR(morning.elevation_true_deg, 45.0 - 1.9, 0.5);
  EXPECT_NEAR(evening.elevation_true_deg, 45.0 + 1.9, 0.5);
}

TEST(SolarTest, AzElEnuRoundTrip) {
  EXPECT_TRUE(EnuFromAzEl(0, 0).isApprox(Eigen::Vector3d(0, 1, 0)));
  EXPECT_TRUE(EnuFromAzEl(90, 0).isApprox(Eigen::Vector3d(1, 0, 0)));
  EXPECT_TRUE(EnuFromAzEl(123, 90).isApprox(Eigen::Vector3d(0, 0, 1), 1e-12));
  for (double az = 0; az < 360; az += 17.5) {
    for (double el = -85; el <= 85; el += 10) {
      const Eigen::Vector3d d = EnuFromAzEl(az, el);
      EXPECT_NEAR(d.norm(), 1.0, 1e-14);
      double a2, e2;
      AzElFromEnu(3.0 * d, &a2, &e2);
      EXPECT_NEAR(a2, az, 1e-10);
      EXPECT_NEAR(e2, el, 1e-10);
    }
  }
  double a, e;
  AzElFromEnu(Eigen::Vector3d(-1, 1e-18, 0), &a, &e);
  EXPECT_GE(a, 0.0);
  EXPECT_LT(a, 360.0);
  const SunPosition s = ComputeSunPosition(ParseIso8601("2024-06-21T20:00:00Z"), Site());
  AzElFromEnu(s.DirectionEnu(), &a, &e);
  EXPECT_NEAR(a, s.azimuth_deg, 1e-9);
  EXPECT_NEAR(e, s.elevation_deg, 1e-9);
}

TEST(SolarTest, RefusesBadSite) {
  EXPECT_THROW(ComputeSunPosition(UtcTime{}, Site{95.0, 0.0, 0.0}), Error);
  EXPECT_THROW(ComputeSunPosition(UtcTime{}, Site{NAN, 0.0, 0.0}), Error);
  EXPECT_THROW(ComputeSunPosition(ParseIso8601("2026-08-25T20:30:00Z"), Site{37.0, -122.0, 1e15}),
               Error);  // ERFA gives NaN there
  EXPECT_THROW(ComputeSunPosition(UtcTime{}, Site{}, Weather{-5.0, 10.0}), Error);
}

}  // namespace
}  // namespace rouen
