#include "core/geodesy.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

constexpr double kA = 6378137.0;            // WGS84 semi-major axis, m
constexpr double kF = 1.0 / 298.257223563;  // WGS84 flattening
constexpr double kE2 = kF * (2 - kF);       // first eccentricity squared

TEST(GeodesyTest, RoundTrip) {
  const LocalFrame frame(Site{37.8722, -122.2578, 60.0});
  EXPECT_LT(frame.ToEnu(frame.origin()).norm(), 1e-9);
  for (double e = -2000; e <= 2000; e += 500) {
    for (double n = -2000; n <= 2000; n += 500) {
      for (double u : {-50.0, 0.0, 300.0}) {
        const Eigen::Vector3d enu(e, n, u);
        EXPECT_LT((frame.ToEnu(frame.ToGeodetic(enu)) - enu).norm(), 1e-6);
      }
    }
  }
}

TEST(GeodesyTest, KnownOffsetsFromTheEllipsoid) {
  const double lat = 37.87, h = 0.0;
  const LocalFrame frame(Site{lat, -122.0, h});
  const double s = std::sin(lat * kPi / 180);
  const double w = 1 - kE2 * s * s;
  const double meridian = kA * (1 - kE2) / std::pow(w, 1.5);  // M
  const double normal = kA / std::sqrt(w);                    // N
  const double dphi = 0.001 * kPi / 180;
  const Eigen::Vector3d north = frame.ToEnu(Site{lat + 0.001, -122.0, h});
  EXPECT_NEAR(north.y(), meridian * dphi, 0.05);
  EXPECT_NEAR(north.x(), 0.0, 1e-6);
  EXPECT_LT(north.z(), 0.0);  // the ellipsoid curves away below the tangent plane
  const Eigen::Vector3d east = frame.ToEnu(Site{lat, -122.0 + 0.001, h});
  EXPECT_NEAR(east.x(), normal * std::cos(lat * kPi / 180) * dphi, 0.05);
  EXPECT_NEAR(east.y(), 0.0, 0.01);
  const Eigen::Vector3d up = frame.ToEnu(Site{lat, -122.0, h + 12.5});
  EXPECT_LT((up - Eigen::Vector3d(0, 0, 12.5)).norm(), 1e-6);
}

TEST(GeodesyTest, RefusesBadOrigin) {
  EXPECT_THROW(LocalFrame(Site{91.0, 0.0, 0.0}), Error);
  EXPECT_THROW(LocalFrame(Site{0.0, INFINITY, 0.0}), Error);
}

}  // namespace
}  // namespace rouen
