#include "capture/sim/atmosphere.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

Eigen::Vector3d Dir(double az_deg, double el_deg) {
  const double az = az_deg * kPi / 180, el = el_deg * kPi / 180;
  return Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
}

const Atmosphere& Atm() {
  static const Atmosphere atm;
  return atm;
}

TEST(AtmosphereTest, RejectsBadParameters) {
  AtmosphereParams p;
  p.visibility_km = -1;
  EXPECT_THROW(Atmosphere{p}, Error);
  p = {};
  p.mie_g = 1.0;
  EXPECT_THROW(p.Validate(), Error);
  p = {};
  p.visibility_km = 1000;  // clearer than a pure Rayleigh atmosphere
  EXPECT_THROW(p.Validate(), Error);
}

TEST(AtmosphereTest, VerticalDepthMatchesPlaneParallelFormula) {
  // Straight up from sea level the column is beta0 * H (curvature is negligible there).
  const AtmosphereParams& p = Atm().params();
  const Eigen::Vector3d mie = p.MieExtinction();
  const Eigen::Vector3d tau = Atm().OpticalDepthExact(0, 1);
  for (int c = 0; c < 3; ++c) {
    const double expected = p.rayleigh_sea_level[c] * p.rayleigh_scale_m *
                                (1 - std::exp(-p.top_altitude_m / p.rayleigh_scale_m)) +
                            mie[c] * p.mie_scale_m;
    EXPECT_NEAR(tau[c], expected, 1e-3 * expected);
  }
  // Visibility 35 km: 3.912 / V total extinction at 550 nm.
  EXPECT_NEAR(mie[1] + p.rayleigh_sea_level[1], 3.912 / 35e3, 1e-9);
}

TEST(AtmosphereTest, TableAgreesWithDirectIntegration) {
  for (double h : {0.0, 60.0, 900.0, 5000.0, 30000.0}) {
    for (double mu : {1.0, 0.7, 0.3, 0.1, 0.03, 0.01}) {
      const Eigen::Vector3d a = Atm().OpticalDepth(h, mu), b = Atm().OpticalDepthExact(h, mu);
      EXPECT_NEAR(a[2], b[2], 0.01 * b[2] + 1e-4) << h << " " << mu;
    }
  }
  // Below the local horizon the path meets the ground.
  EXPECT_FALSE(std::isfinite(Atm().OpticalDepth(60, -0.1)[0]));
  EXPECT_EQ(Atm().Transmittance(60, -0.1)[1], 0.0);
}

TEST(AtmosphereTest, SunReddensAsItSinks) {
  double prev_ratio = 0, prev_green = 2;
  for (double el : {80.0, 60.0, 40.0, 20.0, 10.0, 5.0, 2.0}) {
    const Eigen::Vector3d t = Atm().Transmittance(60, std::sin(el * kPi / 180));
    EXPECT_GT(t[0] / t[2], prev_ratio) << el;  // R/B grows
    EXPECT_LT(t[1], prev_green);               // and less light gets through
    prev_ratio = t[0] / t[2];
    prev_green = t[1];
  }
}

TEST(AtmosphereTest, SkyIsBluerThanSunAndBrightensTowardsTheSun) {
  const Eigen::Vector3d sun = Dir(180, 50);
  const Eigen::Vector3d toa = Atm().params().solar_toa;
  const SkyTable sky(Atm(), 60, sun, toa);
  const Eigen::Vector3d t = Atm().Transmittance(60, sun.z());
  const Eigen::Vector3d zenith = sky.Radiance(Eigen::Vector3d::UnitZ());
  EXPECT_GT(zenith[2] / zenith[0], (toa[2] * t[2]) / (toa[0] * t[0]));
  // Aureole: 5 deg from the sun is much brighter than 90 deg away at the same elevation.
  const Eigen::Vector3d near = sky.Radiance(Dir(185, 50)), far = sky.Radiance(Dir(90, 50));
  EXPECT_GT(near[1], 3 * far[1]);
  // Symmetric about the solar vertical.
  const Eigen::Vector3d left = sky.Radiance(Dir(120, 30)), right = sky.Radiance(Dir(240, 30));
  EXPECT_NEAR(left[1], right[1], 1e-4 * left[1]);
  // Below the horizon: the horizon value.
  const Eigen::Vector3d below = sky.Radiance(Dir(30, -10)), at = sky.Radiance(Dir(30, 0));
  EXPECT_NEAR(below[0], at[0], 1e-9);
  // The horizon is whiter than the zenith (blue/red smaller), away from the sun.
  const Eigen::Vector3d horizon = sky.Radiance(Dir(0, 1));
  EXPECT_LT(horizon[2] / horizon[0], zenith[2] / zenith[0]);
}

// Looked up by a direction's float angles, the sky differs from the lookup by the direction
// only by that rounding: at most 2^-24 pi rad of azimuth (a 1e-5 fraction of the table's 1 deg
// cells) and a 2^-24 fraction of the elevation (a smaller one of its cells), so by at most
// 2e-5 of the difference between neighbouring table values, here bounded by the radiance.
TEST(AtmosphereTest, LookupByAnglesIsTheLookupByDirection) {
  const SkyTable sky(Atm(), 60, Dir(200, 8), Atm().params().solar_toa);
  for (double el = -5; el <= 90; el += 0.37) {
    for (double az = 0; az < 360; az += 0.53) {
      const Eigen::Vector3d d = Dir(az, el);
      const Eigen::Vector3d by_dir = sky.Radiance(d), by_angles = sky.Radiance(SkyAngles::Of(d));
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(by_angles[c], by_dir[c], 2e-5 * by_dir[c]) << "az " << az << " el " << el;
    }
  }
}

TEST(AtmosphereTest, PlaneIrradianceMatchesIndependentQuadrature) {
  const SkyTable sky(Atm(), 60, Dir(140, 35), Atm().params().solar_toa);
  // Cosine-weighted stratified quadrature for a tilted plane: directions below its horizon
  // and below the ground horizon do not count.
  for (const Eigen::Vector3d& n : {Eigen::Vector3d(0, 0, 1), Dir(140, 0), Dir(300, 30)}) {
    const Eigen::Vector3d a = n.unitOrthogonal(), b = n.cross(a);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    const int m = 400;
    for (int i = 0; i < m; ++i) {
      for (int j = 0; j < m; ++j) {
        const double u1 = (i + 0.5) / m, u2 = (j + 0.5) / m;
        const double r = std::sqrt(u1), phi = 2 * kPi * u2;
        const Eigen::Vector3d d =
            a * r * std::cos(phi) + b * r * std::sin(phi) + n * std::sqrt(1 - u1);
        if (d.z() > 0) sum += sky.Radiance(d);
      }
    }
    const Eigen::Vector3d expected = sum * (kPi / (m * m));
    const Eigen::Vector3d got = sky.PlaneIrradiance(n);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(got[c], expected[c], 5e-3 * expected[c]) << n.transpose();
  }
}

TEST(AtmosphereTest, EnergyIsConserved) {
  // Direct + diffuse on the ground cannot exceed what enters the top of the atmosphere.
  const Eigen::Vector3d toa = Atm().params().solar_toa;
  for (double el : {70.0, 30.0, 10.0}) {
    const Eigen::Vector3d sun = Dir(90, el);
    const SkyTable sky(Atm(), 60, sun, toa);
    const Eigen::Vector3d direct = toa.cwiseProduct(Atm().Transmittance(60, sun.z())) * sun.z();
    const Eigen::Vector3d total = direct + sky.HorizontalIrradiance();
    for (int c = 0; c < 3; ++c) {
      EXPECT_LT(total[c], toa[c] * sun.z()) << el;
      EXPECT_GT(sky.HorizontalIrradiance()[c], 0.02 * toa[c] * sun.z());
    }
  }
}

}  // namespace
}  // namespace rouen

namespace rouen {
namespace {

TEST(AtmosphereTest, RowMarchMatchesPerDirectionMarch) {
  const double sun_el = 25 * kPi / 180;
  const Eigen::Vector3d toa = Atm().params().solar_toa;
  for (double el_deg : {0.0, 3.0, 30.0, 89.0}) {
    const double el = el_deg * kPi / 180;
    std::vector<Atmosphere::Scatter> row(19);
    Atm().SingleScatterRow(60, el, sun_el, toa, 19, row.data());
    for (int j = 0; j < 19; ++j) {
      const double phi = kPi * j / 18;
      const Eigen::Vector3d v(std::cos(el) * std::sin(phi), std::cos(el) * std::cos(phi),
                              std::sin(el));
      const Eigen::Vector3d sun(0, std::cos(sun_el), std::sin(sun_el));
      const Atmosphere::Scatter one = Atm().SingleScatter(60, v, sun, toa);
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(row[j].radiance[c], one.radiance[c], 2e-3 * one.radiance[c])
            << el_deg << " " << j;
        EXPECT_NEAR(row[j].scatter_depth[c], one.scatter_depth[c], 1e-6 * one.scatter_depth[c]);
      }
    }
  }
}

}  // namespace
}  // namespace rouen
