#include "calib/hdr.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "calib/test_util.h"
#include "core/error.h"

namespace rouen {
namespace {

using testing::MakeBracket;
using testing::RadianceField;
using testing::TrueCurve;
using testing::TrueSlope;

std::vector<const Image*> Pointers(const Bracket& b) {
  std::vector<const Image*> p;
  for (const Image& f : b.frames) p.push_back(&f);
  return p;
}

TEST(MergeHdr, ReproducesTrueRadianceWithinNoise) {
  const Image radiance = RadianceField(200, 150, -5.0, 4.0, 21);
  const std::vector<double> exposures = {1.0 / 64, 1.0 / 16, 1.0 / 4, 1.0, 4.0, 16.0};
  const double noise_dn = 0.7;
  const Bracket b = MakeBracket(radiance, exposures, noise_dn, 5);
  MergeSummary summary;
  std::vector<uint8_t> mask;
  const Image hdr = MergeHdr(Pointers(b), exposures, TrueCurve(), MergeOptions{}, &summary, &mask);
  ASSERT_EQ(hdr.units, PixelUnits::kRadiance);
  ASSERT_EQ(hdr.width, 200);
  EXPECT_EQ(summary.pixels, 200 * 150);
  EXPECT_EQ(summary.saturated_pixels, 0);
  EXPECT_EQ(summary.dark_pixels, 0);
  double sum_sq = 0;
  int n = 0;
  for (int y = 0; y < hdr.height; ++y) {
    for (int x = 0; x < hdr.width; ++x) {
      EXPECT_EQ(mask[static_cast<size_t>(y) * hdr.width + x], 1);
      for (int c = 0; c < 3; ++c) {
        const double err = std::log(hdr.at(x, y, c) / radiance.at(x, y, c));
        ASSERT_TRUE(std::isfinite(err));
        // Worst case: a single usable frame near the toe, where the slope is 0.2 ln/DN:
        // noise of 3 sigma plus half a DN of quantisation there.
        EXPECT_LT(std::abs(err), (3 * noise_dn + 0.5) * 0.2);
        sum_sq += err * err;
        ++n;
      }
    }
  }
  // Typical: 2-3 frames well exposed at ~0.02-0.05 ln/DN, 0.76 DN per reading -> ~2%.
  const double rms = std::sqrt(sum_sq / n);
  EXPECT_LT(rms, 0.03);
}

TEST(MergeHdr, SaturatedAndDarkEverywhereArePinnedAndCounted) {
  const std::vector<double> exposures = {0.5, 1.0, 2.0};
  Bracket b;
  b.exposures = exposures;
  for (size_t j = 0; j < exposures.size(); ++j) {
    Image f(4, 1, 3, PixelUnits::kDigital, 128.f);
    for (int c = 0; c < 3; ++c) {
      f.at(0, 0, c) = 255;  // saturated in every frame
      f.at(1, 0, c) = 0;    // dark in every frame
    }
    f.at(2, 0, 1) = 255;  // one channel saturated only
    b.frames.push_back(f);
  }
  const ResponseCurve curve = TrueCurve();
  MergeSummary summary;
  std::vector<uint8_t> mask;
  const Image hdr = MergeHdr(Pointers(b), exposures, curve, MergeOptions{}, &summary, &mask);
  EXPECT_EQ(summary.saturated_pixels, 2);
  EXPECT_EQ(summary.dark_pixels, 1);
  EXPECT_EQ(mask, (std::vector<uint8_t>{0, 0, 0, 1}));
  for (int c = 0; c < 3; ++c) {
    // Lower bound from the shortest exposure at z = 255.
    EXPECT_NEAR(std::log(hdr.at(0, 0, c)), curve.g[c][255] - std::log(0.5), 1e-5);
    // Longest exposure's reading of z = 0.
    EXPECT_NEAR(std::log(hdr.at(1, 0, c)), curve.g[c][0] - std::log(2.0), 1e-5);
    // Ordinary pixel: 128 in every frame averages g(128) - ln X over the three exposures.
    EXPECT_NEAR(std::log(hdr.at(3, 0, c)), curve.g[c][128], 1e-5);
    for (int x = 0; x < 4; ++x) EXPECT_TRUE(std::isfinite(hdr.at(x, 0, c)));
  }
}

TEST(MergeHdr, FractionalDigitalNumbersInterpolateTheCurve) {
  // 16-bit sources arrive as fractional digital numbers.
  Image f(1, 1, 3, PixelUnits::kDigital, 100.25f);
  const ResponseCurve curve = TrueCurve();
  const Image hdr = MergeHdr({&f}, {1.0}, curve, MergeOptions{}, nullptr);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(std::log(hdr.at(0, 0, c)), 0.75 * curve.g[c][100] + 0.25 * curve.g[c][101], 1e-5);
  }
}

TEST(MergeHdr, RejectsBadInput) {
  const ResponseCurve curve = TrueCurve();
  Image a(8, 6, 3, PixelUnits::kDigital, 100.f), b(8, 6, 3, PixelUnits::kDigital, 120.f);
  EXPECT_NO_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, curve, MergeOptions{}, nullptr));
  Image wrong_size(8, 7, 3, PixelUnits::kDigital, 100.f);
  EXPECT_THROW(MergeHdr({&a, &wrong_size}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  Image wrong_channels(8, 6, 1, PixelUnits::kDigital, 100.f);
  EXPECT_THROW(MergeHdr({&a, &wrong_channels}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({}, {}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 0.0}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, std::nan("")}, curve, MergeOptions{}, nullptr), Error);
  Image radiance = a;
  radiance.units = PixelUnits::kRadiance;
  EXPECT_THROW(MergeHdr({&a, &radiance}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  Image nan_pixel = a;
  nan_pixel.at(2, 2, 1) = std::nan("");
  EXPECT_THROW(MergeHdr({&a, &nan_pixel}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  ResponseCurve broken = curve;
  broken.g[1][50] = std::nan("");
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, broken, MergeOptions{}, nullptr), Error);
  broken = curve;
  broken.g[2].resize(10);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, broken, MergeOptions{}, nullptr), Error);
  MergeOptions bad;
  bad.dark_level = 200;
  bad.saturation_level = 100;
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, curve, bad, nullptr), Error);
  // Absurd exposures push the radiance out of float range: an error, not inf.
  EXPECT_THROW(MergeHdr({&a, &b}, {1e-60, 2e-60}, curve, MergeOptions{}, nullptr), Error);
}

}  // namespace
}  // namespace rouen
