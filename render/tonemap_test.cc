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

// Without a response curve: IEC 61966-2-1's encoding (linear below 0.0031308, 1/2.4 power
// above), white at radiance x exposure = 1, and the auto exposure puts the 99th percentile at
// 0.9 of white.
TEST(TonemapTest, SrgbWithoutAResponse) {
  Image r(4, 1, 3, PixelUnits::kRadiance, 0.f);
  const float l[4] = {0.f, 0.002f, 0.5f, 3.f};
  for (int x = 0; x < 4; ++x)
    for (int c = 0; c < 3; ++c) r.at(x, 0, c) = l[x];
  const Image d = ToSrgbDigital(r, 1.0);
  EXPECT_EQ(d.at(0, 0, 1), 0);
  EXPECT_EQ(d.at(1, 0, 1), std::round(255 * 12.92 * 0.002));
  EXPECT_EQ(d.at(2, 0, 1), std::round(255 * (1.055 * std::pow(0.5, 1 / 2.4) - 0.055)));
  EXPECT_EQ(d.at(3, 0, 1), 255);  // clipped
  Image ramp(100, 1, 3, PixelUnits::kRadiance, 0.f);
  for (int x = 0; x < 100; ++x)
    for (int c = 0; c < 3; ++c) ramp.at(x, 0, c) = static_cast<float>(x + 1);
  // 300 values; the lower nearest rank of p = 0.99 is 296 -> the value 99.
  EXPECT_NEAR(AutoExposureSrgb(ramp), 0.9 / 99, 1e-12);
  EXPECT_THROW(ToSrgbDigital(r, 0), Error);
  EXPECT_THROW(AutoExposureSrgb(r, 0), Error);
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
