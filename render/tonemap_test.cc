#include "render/tonemap.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"

namespace rouen {
namespace {

// g(z) = ln((z + 1) / 256): exposure (z + 1) / 256, i.e. z = 256 x exposure - 1.
ResponseCurve LinearResponse() {
  ResponseCurve r;
  for (auto& ch : r.g) {
    ch.resize(256);
    for (int z = 0; z < 256; ++z) ch[z] = std::log((z + 1) / 256.0);
  }
  return r;
}

TEST(TonemapTest, MapsThroughTheResponse) {
  const ResponseCurve r = LinearResponse();
  Image rad(3, 1, 3, PixelUnits::kRadiance);
  rad.at(0, 0, 0) = 0.5f;   // 256 * 0.5 * 1 - 1 = 127
  rad.at(1, 0, 1) = 0.25f;  // x 2 below: 127
  rad.at(2, 0, 2) = 100.f;  // saturates
  const Image dn = ToDigital(rad, r, 1.0);
  EXPECT_EQ(dn.units, PixelUnits::kDigital);
  EXPECT_EQ(dn.at(0, 0, 0), 127);
  EXPECT_EQ(dn.at(1, 0, 1), 63);
  EXPECT_EQ(dn.at(2, 0, 2), 255);
  EXPECT_EQ(dn.at(0, 0, 1), 0);  // zero radiance
  EXPECT_EQ(ToDigital(rad, r, 2.0).at(1, 0, 1), 127);
  // Auto exposure puts the 99th percentile at the target.
  Image flat(10, 10, 3, PixelUnits::kRadiance, 3.f);
  const double f = AutoExposure(flat, r, 0.99, 200);
  EXPECT_NEAR(ToDigital(flat, r, f).at(5, 5, 1), 200, 1);
}

TEST(TonemapTest, BadInputThrows) {
  Image rad(3, 1, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(ToDigital(rad, ResponseCurve(), 1.0), Error);
  EXPECT_THROW(ToDigital(rad, LinearResponse(), 0.0), Error);
  Image dn = rad;
  dn.units = PixelUnits::kDigital;
  EXPECT_THROW(ToDigital(dn, LinearResponse(), 1.0), Error);
  rad.at(1, 0, 1) = NAN;
  EXPECT_THROW(ToDigital(rad, LinearResponse(), 1.0), Error);
}

}  // namespace
}  // namespace rouen
