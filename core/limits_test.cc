#include "core/limits.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/error.h"

namespace rouen {
namespace {

TEST(LimitsTest, HeightsFromTheDeadSeaToAboveEverest) {
  EXPECT_EQ(HeightProblem(-430), "");
  EXPECT_EQ(HeightProblem(8849), "");
  EXPECT_EQ(HeightProblem(kMinHeightM), "");
  EXPECT_EQ(HeightProblem(kMaxHeightM), "");
  EXPECT_EQ(HeightProblem(1e15),
            "height 1e+15 m is outside -500..9000 m above the WGS84 ellipsoid");
  EXPECT_NE(HeightProblem(-501), "");
  EXPECT_NE(HeightProblem(std::nan("")), "");
  EXPECT_NE(HeightProblem(std::numeric_limits<double>::infinity()), "");
}

TEST(LimitsTest, LatitudeLongitudeExposureAndNd) {
  EXPECT_EQ(LatitudeProblem(-90), "");
  EXPECT_EQ(LatitudeProblem(91), "latitude 91 deg is outside -90..90 deg");
  EXPECT_EQ(LongitudeProblem(180), "");
  EXPECT_NE(LongitudeProblem(-180.5), "");
  EXPECT_NE(LongitudeProblem(std::nan("")), "");
  EXPECT_EQ(ExposureProblem(1.0 / 8000), "");
  EXPECT_EQ(ExposureProblem(1e308), "exposure 1e+308 s is outside 1e-09..86400 s");
  EXPECT_EQ(ExposureProblem(-1), "exposure -1 s is not positive (the range is 1e-09..86400 s)");
  EXPECT_NE(ExposureProblem(0), "");
  EXPECT_NE(ExposureProblem(1e-10), "");
  EXPECT_EQ(NdDensityProblem(4.5), "");
  EXPECT_EQ(NdDensityProblem(-1), "ND density -1 is outside 0..10");
}

TEST(LimitsTest, CheckSiteNamesWhereTheSiteCameFrom) {
  EXPECT_NO_THROW(CheckSite(Site{37.87, -122.26, 60}, "--site"));
  try {
    CheckSite(Site{37.87, -122.26, 1e15}, "rig.toml:8");
    FAIL() << "accepted a height of 1e15 m";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(),
                 "rig.toml:8: height 1e+15 m is outside -500..9000 m above the WGS84 ellipsoid");
  }
}

}  // namespace
}  // namespace rouen
