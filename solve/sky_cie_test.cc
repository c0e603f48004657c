#include "solve/sky_cie.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

TEST(CieSky, FifteenTypesFromTheGroups) {
  // Type 12 (CIE clear, V.4): gradation V (-1, -0.32), indicatrix 4 (10, -3, 0.45).
  const CieSkyType& t12 = CieStandardSky(12);
  EXPECT_STREQ(t12.name, "V.4");
  EXPECT_EQ(t12.a, -1.0);
  EXPECT_EQ(t12.b, -0.32);
  EXPECT_EQ(t12.c, 10.0);
  EXPECT_EQ(t12.d, -3.0);
  EXPECT_EQ(t12.e, 0.45);
  // Type 1 (overcast, I.1): gradation I (4, -0.7), no indicatrix.
  const CieSkyType& t1 = CieStandardSky(1);
  EXPECT_EQ(t1.a, 4.0);
  EXPECT_EQ(t1.c, 0.0);
  EXPECT_EQ(CieStandardSky(15).c, 24.0);
  for (int t = 1; t <= kNumCieSkyTypes; ++t) EXPECT_EQ(CieStandardSky(t).type, t);
  EXPECT_THROW(CieStandardSky(0), Error);
  EXPECT_THROW(CieStandardSky(16), Error);
}

TEST(CieSky, NormalisedToZenithAndOvercastRatio) {
  for (int t = 1; t <= kNumCieSkyTypes; ++t) {
    const double zs = 40 * kDeg;
    // At the zenith gamma equals the sun's zenith angle: L / Lz = 1.
    EXPECT_NEAR(CieRelativeLuminance(CieStandardSky(t), 0, zs, zs), 1.0, 1e-12) << t;
  }
  // Type 1: horizon / zenith = phi(90) / phi(0) = 1 / (1 + 4 e^-0.7), the classic ~1:3.
  const double ratio = CieRelativeLuminance(CieStandardSky(1), 0.5 * kPi, 1.0, 0.3);
  EXPECT_NEAR(ratio, 1 / (1 + 4 * std::exp(-0.7)), 1e-12);
}

TEST(CieSky, AsSkyParamsReproducesTheLuminance) {
  for (int t = 1; t <= kNumCieSkyTypes; ++t) {
    const CieSkyType& type = CieStandardSky(t);
    const double zs = 55 * kDeg, lz = 3.7;
    const SkyParams p = CieAsSkyParams(type, zs, lz);
    EXPECT_EQ(p.h, 1.0);
    for (double xi : {0.0, 0.3, 0.9, 1.4}) {
      for (double gamma : {0.05, 0.5, 1.2, 2.5}) {
        const double expected = lz * CieRelativeLuminance(type, xi, gamma, zs);
        EXPECT_NEAR(SkyRadiance(p, xi, gamma), expected, 1e-9 * expected)
            << "type " << t << " xi " << xi << " gamma " << gamma;
      }
    }
  }
}

}  // namespace
}  // namespace rouen
