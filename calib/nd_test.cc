#include "calib/nd.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <random>

#include "calib/test_util.h"
#include "core/error.h"

namespace rouen {
namespace {

const std::array<double, 3> kTrueT = {0.10, 0.125, 0.08};  // a slightly coloured filter

Image ScaleChannels(const Image& in, const std::array<double, 3>& t) {
  Image out = in;
  for (size_t i = 0; i < out.data.size(); ++i) out.data[i] *= static_cast<float>(t[i % 3]);
  return out;
}

// Multiplicative Gaussian noise of relative standard deviation `sigma`.
Image Noisy(const Image& in, double sigma, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0, sigma);
  Image out = in;
  for (float& v : out.data) v = static_cast<float>(v * (1 + n(rng)));
  return out;
}

TEST(NdTest, RecoversPerChannelTransmissionFromRadianceImages) {
  const Image scene = testing::RadianceField(100, 80, -1, 2, 7);
  // 2% noise per pixel: the log10 ratio of two such pixels has sd 0.0087 x sqrt(2) = 0.0123;
  // the median over n = 8000 pixels has sd 1.25 x 0.0123 / sqrt(8000) = 1.7e-4.
  const Image without = Noisy(scene, 0.02, 1);
  const Image with = Noisy(ScaleChannels(scene, kTrueT), 0.02, 2);
  const NdCalibration cal = EstimateNdTransmission(with, nullptr, without, nullptr, NdOptions{});
  for (int c = 0; c < 3; ++c) {
    const double true_d = -std::log10(kTrueT[c]);
    EXPECT_NEAR(cal.channel[c].density, true_d, 1e-3) << "channel " << c;
    EXPECT_NEAR(cal.channel[c].transmission, kTrueT[c], kTrueT[c] * 2.3e-3) << c;
    // The 95% interval is about 2 sd of the median wide and covers the truth (with slack).
    EXPECT_GT(cal.channel[c].density_ci95, 1e-4);
    EXPECT_LT(cal.channel[c].density_ci95, 1e-3);
    EXPECT_LE(std::abs(cal.channel[c].density - true_d), 3 * cal.channel[c].density_ci95);
    // Per-pixel spread estimated near 0.0123.
    EXPECT_NEAR(cal.channel[c].density_spread, 0.0123, 0.003);
    EXPECT_EQ(cal.channel[c].pixels, 8000);
  }
}

TEST(NdTest, RobustToMovingContentAndHonoursMasks) {
  const Image scene = testing::RadianceField(100, 80, -1, 2, 8);
  const Image without = Noisy(scene, 0.02, 3);
  Image with = Noisy(ScaleChannels(scene, kTrueT), 0.02, 4);
  // A "moving" object covering 15% of the frame, 3x brighter, present only with the filter.
  for (int y = 0; y < 80; ++y)
    for (int x = 0; x < 15; ++x)
      for (int c = 0; c < 3; ++c) with.at(x, y, c) *= 3;
  const NdCalibration robust = EstimateNdTransmission(with, nullptr, without, nullptr, NdOptions{});
  for (int c = 0; c < 3; ++c) {
    // 15% one-sided outliers move the median to the clean 0.5 / 0.85 = 0.59 quantile:
    // 0.22 sd of the per-pixel spread (0.0123) = 0.0027 at most.
    EXPECT_NEAR(robust.channel[c].density, -std::log10(kTrueT[c]), 4e-3) << c;
  }
  // Masking the object out restores the unbiased estimate.
  std::vector<uint8_t> mask(100 * 80, 1);
  for (int y = 0; y < 80; ++y)
    for (int x = 0; x < 15; ++x) mask[y * 100 + x] = 0;
  const NdCalibration masked = EstimateNdTransmission(with, &mask, without, nullptr, NdOptions{});
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(masked.channel[c].density, -std::log10(kTrueT[c]), 1e-3) << c;
    EXPECT_EQ(masked.channel[c].pixels, 85 * 80);
  }
}

TEST(NdTest, RecoversTransmissionFromLdrBrackets) {
  const Image scene = testing::RadianceField(120, 90, -2, 1, 9);
  const ResponseCurve curve = testing::TrueCurve();
  const Bracket without = testing::MakeBracket(scene, {0.25, 1, 4}, 0.7, 11);
  // Through the filter, 10x longer exposures (exposures listed without the filter).
  const Bracket with = testing::MakeBracket(ScaleChannels(scene, kTrueT), {2.5, 10, 40}, 0.7, 12);
  const NdCalibration cal = EstimateNdTransmission(with, without, curve, NdOptions{});
  for (int c = 0; c < 3; ++c) {
    // 0.7 DN noise at <= 0.03 ln/DN gives <= 0.013 log10 per pixel pair before merging; the
    // median over ~10^4 pixels is good to ~3e-4; 2e-3 leaves room for the tabulated curve's
    // linear interpolation.
    EXPECT_NEAR(cal.channel[c].density, -std::log10(kTrueT[c]), 2e-3) << c;
    EXPECT_GT(cal.channel[c].pixels, 5000);
  }
  // A single frame each is a valid "pair".
  Bracket w1, o1;
  w1.frames = {with.frames[1]};
  w1.exposures = {10};
  o1.frames = {without.frames[1]};
  o1.exposures = {1};
  const NdCalibration pair = EstimateNdTransmission(w1, o1, curve, NdOptions{});
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(pair.channel[c].density, -std::log10(kTrueT[c]), 4e-3) << c;
}

TEST(NdTest, BadInputsAreErrors) {
  const Image a = testing::RadianceField(40, 30, -1, 1, 1);
  const Image b = testing::RadianceField(41, 30, -1, 1, 1);
  EXPECT_THROW(EstimateNdTransmission(a, nullptr, b, nullptr, NdOptions{}), Error);
  Image digital = a;
  digital.units = PixelUnits::kDigital;
  EXPECT_THROW(EstimateNdTransmission(digital, nullptr, a, nullptr, NdOptions{}), Error);
  std::vector<uint8_t> short_mask(10, 1);
  EXPECT_THROW(EstimateNdTransmission(a, &short_mask, a, nullptr, NdOptions{}), Error);
  std::vector<uint8_t> empty_mask(40 * 30, 0);
  try {
    EstimateNdTransmission(a, &empty_mask, a, nullptr, NdOptions{});
    ADD_FAILURE() << "no usable pixels must be an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("well exposed"), std::string::npos) << e.what();
  }
  NdOptions bad;
  bad.min_relative_level = -1;
  EXPECT_THROW(bad.Validate(), Error);
  Bracket none;
  EXPECT_THROW(EstimateNdTransmission(none, none, testing::TrueCurve(), NdOptions{}), Error);
}

TEST(NdTest, JsonRoundTrip) {
  NdCalibration cal;
  for (int c = 0; c < 3; ++c) {
    cal.channel[c].density = 1 + 0.1 * c;
    cal.channel[c].transmission = std::pow(10.0, -cal.channel[c].density);
  }
  const NdCalibration back = nlohmann::json(cal).get<NdCalibration>();
  for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(back.channel[c].density, cal.channel[c].density);
  EXPECT_THROW(nlohmann::json({{"density_rgb", {1, 2}}}).get<NdCalibration>(), Error);
}

}  // namespace
}  // namespace rouen
