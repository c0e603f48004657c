#include "solve/retro.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "core/angles.h"

namespace rouen {
namespace {

Eigen::Vector3d InXZ(double angle_from_z_deg) {
  const double a = angle_from_z_deg * kDeg;
  return {std::sin(a), 0, std::cos(a)};
}

TEST(RetroTest, ZeroIsLambertAndHeadOnIsOne) {
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  for (double tl : {0.0, 30.0, 80.0, 89.0}) {
    for (double tv : {0.0, 45.0, -70.0}) {
      EXPECT_EQ(RetroFactor(0, n, InXZ(tl), InXZ(tv)), 1.0) << tl << " " << tv;
    }
  }
  // Light and view along the normal: (1 - n.l)^5 = 0, whatever retro is.
  for (double r : {kRetroMin, 0.5, kRetroMax}) EXPECT_DOUBLE_EQ(RetroFactor(r, n, n, n), 1.0);
}

TEST(RetroTest, BurleyRoughnessOneAtAGrazingSun) {
  // retro 1 is Burley's diffuse at roughness 1: F_D90 = 0.5 + 2 cos^2(theta_d). Sun 80 degrees
  // from the normal, view along it: theta_d = 40 degrees (half the angle between l and v).
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  const double fd90 = 0.5 + 2 * std::pow(std::cos(40 * kDeg), 2);
  const double expected = 1 + (fd90 - 1) * std::pow(1 - std::cos(80 * kDeg), 5);
  EXPECT_NEAR(RetroFactor(1.0, n, InXZ(80), n), expected, 1e-12);
  EXPECT_GT(expected, 1.25);  // the brightening that a Lambertian model misses
  // Reciprocity: light and view swap.
  const Eigen::Vector3d l = InXZ(65), v = Eigen::Vector3d(-0.3, 0.5, 0.6).normalized();
  EXPECT_NEAR(RetroFactor(0.7, n, l, v), RetroFactor(0.7, n, v, l), 1e-12);
  // Over the whole range the factor stays positive and finite, even below the horizon.
  for (double r = kRetroMin; r <= kRetroMax; r += 0.25) {
    for (double tl = 0; tl <= 100; tl += 5) {
      const double d = RetroFactor(r, n, InXZ(tl), InXZ(-tl / 2));
      EXPECT_TRUE(std::isfinite(d) && d >= 0.25) << r << " " << tl << " " << d;
    }
  }
}

TEST(RetroTest, AmbientFactorIsTheMeanOverAUniformHemisphere) {
  // The closed form against RetroFactor integrated over light directions with density n.l / pi:
  // midpoint rule in mu = n.l (0..1) and azimuth. mu^2 = 1 - sin^2 makes d(omega) cos / pi =
  // mu dmu dphi / pi; 2000 x 720 cells, the integrand smooth: error well below 1e-6.
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  const int nm = 2000, np = 720;
  for (double retro : {kRetroMin, 0.5, 1.0, kRetroMax}) {
    for (double tv : {0.0, 30.0, 60.0, 75.0, 89.0}) {
      const Eigen::Vector3d v = InXZ(tv);
      double sum = 0;
      for (int i = 0; i < nm; ++i) {
        const double mu = (i + 0.5) / nm, st = std::sqrt(1 - mu * mu);
        for (int j = 0; j < np; ++j) {
          const double phi = (j + 0.5) * 2 * kPi / np;
          const Eigen::Vector3d l(st * std::cos(phi), st * std::sin(phi), mu);
          sum += RetroFactor(retro, n, l, v) * mu;
        }
      }
      const double mean = sum * (1.0 / nm) * (2 * kPi / np) / kPi;
      EXPECT_NEAR(AmbientRetroFactor(retro, n, v), mean, 1e-6) << retro << " " << tv;
    }
  }
  // Lambert is exactly 1; Burley's roughness 1 is about 4% brighter head-on and 40% at 85 deg.
  EXPECT_EQ(AmbientRetroFactor(0, n, InXZ(70)), 1.0);
  // (Through the moments, which are floats: to float precision.)
  EXPECT_NEAR(AmbientRetroFactor(1, n, n), 1 + 1.0 / 84 + 1.0 / 42, 1e-6);
  EXPECT_GT(AmbientRetroFactor(1, n, InXZ(85)), 1.35);
}

TEST(RetroTest, BlockRetroDefaultsToLambert) {
  const std::vector<double> retro = {0.5, 1.25};
  EXPECT_EQ(BlockRetro(retro, 1), 1.25);
  EXPECT_EQ(BlockRetro(retro, 2), 0.0);
  EXPECT_EQ(BlockRetro(retro, -1), 0.0);
  EXPECT_EQ(BlockRetro({}, 0), 0.0);
}

TEST(RetroTest, LightFromAFewDirectionsIsReflectedAsTheirMean) {
  // D is a polynomial of degree 3 in l, so the moments give the mean of D over any light
  // exactly (to float precision): three lamps of different weights, one grazing.
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, 0.9, 0.1).normalized();
  const std::vector<std::pair<Eigen::Vector3d, double>> lamps = {
      {Eigen::Vector3d(-0.9, 0.35, 0.25).normalized(), 3.0},
      {Eigen::Vector3d(0.1, 0.8, 0.6).normalized(), 1.0},
      {Eigen::Vector3d(0.5, 0.2, 0.8).normalized(), 0.5}};
  LightMomentsSum sum(n);
  for (const auto& [l, w] : lamps) sum.Add(l, w * n.dot(l));
  const LightMoments m = sum.Moments(UniformLight(n));
  for (double retro : {kRetroMin, 0.5, 1.0, kRetroMax}) {
    for (const Eigen::Vector3d& v : {Eigen::Vector3d(-0.95, 0.3, 0.05).normalized(), n,
                                     Eigen::Vector3d(0.6, 0.5, -0.1).normalized()}) {
      double mean = 0, weight = 0;
      for (const auto& [l, w] : lamps) {
        mean += w * n.dot(l) * RetroFactor(retro, n, l, v);
        weight += w * n.dot(l);
      }
      EXPECT_NEAR(AmbientRetroFactor(retro, n, v, m), mean / weight, 2e-6) << retro;
    }
  }
  // A camera on the lamps' side sees much more than under the same light from everywhere.
  const Eigen::Vector3d towards_lamp = Eigen::Vector3d(-0.95, 0.3, 0.05).normalized();
  EXPECT_GT(AmbientRetroFactor(1, n, towards_lamp, m),
            1.15 * AmbientRetroFactor(1, n, towards_lamp));
  // Nothing added: the fallback.
  EXPECT_EQ(LightMomentsSum(n).Moments(UniformLight(n)).s, UniformLight(n).s);
}

TEST(RetroTest, UniformLightSummedIsTheClosedFormAndMixesLinearly) {
  // A fine cosine-weighted sum over the hemisphere reproduces UniformLight's moments.
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.2, 0.93).normalized();
  Eigen::Vector3d t = n.unitOrthogonal(), b = n.cross(t);
  LightMomentsSum sum(n), upper(n), lower(n);
  const int nm = 800, np = 360;
  for (int i = 0; i < nm; ++i) {
    const double mu = (i + 0.5) / nm, st = std::sqrt(1 - mu * mu);
    for (int j = 0; j < np; ++j) {
      const double phi = (j + 0.5) * 2 * kPi / np;
      const Eigen::Vector3d l = st * std::cos(phi) * t + st * std::sin(phi) * b + mu * n;
      sum.Add(l, mu);
      (j < np / 2 ? upper : lower).Add(l, mu);
    }
  }
  const LightMoments m = sum.Moments({}), u = UniformLight(n);
  EXPECT_NEAR((m.l - u.l).norm(), 0, 1e-5);
  EXPECT_NEAR(m.s, u.s, 1e-5);
  EXPECT_NEAR((m.sl - u.sl).norm(), 0, 1e-5);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(m.sll[k], u.sll[k], 1e-5) << k;
  for (const Eigen::Vector3d& v : {n, InXZ(70), InXZ(-85)})
    EXPECT_NEAR(AmbientRetroFactor(1, n, v, m), AmbientRetroFactor(1, n, v), 1e-5);
  // Two halves of the sky, mixed by their weights, are the whole.
  const LightMoments mixed =
      LightMoments::Mix(upper.Moments({}), upper.weight(), lower.Moments({}), lower.weight());
  EXPECT_NEAR((mixed.l - m.l).norm(), 0, 1e-6);
  EXPECT_NEAR(mixed.sll[4], m.sll[4], 1e-6);
}

}  // namespace
}  // namespace rouen
