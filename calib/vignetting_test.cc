#include "calib/vignetting.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "calib/test_util.h"
#include "core/error.h"

namespace rouen {
namespace {

constexpr int kW = 240, kH = 160;

VignettingModel TrueModel(double cx = kW / 2.0, double cy = kH / 2.0) {
  VignettingModel m;
  m.width = kW;
  m.height = kH;
  m.cx = cx;
  m.cy = cy;
  m.a = {-0.35, 0.08, -0.03};  // about 30% fall-off in the corners
  return m;
}

// A flat field of `level` with a linear gradient (fraction per half-diagonal along x and y),
// vignetted by `m`, with multiplicative noise of relative sd `sigma`.
Image Flat(const VignettingModel& m, double level, double gx, double gy, double sigma,
           uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0, sigma);
  const double hd = 0.5 * std::hypot(double(kW), double(kH));
  Image im(kW, kH, 3, PixelUnits::kRadiance);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double g = 1 + gx * (x + 0.5 - kW / 2.0) / hd + gy * (y + 0.5 - kH / 2.0) / hd;
      for (int c = 0; c < 3; ++c)
        im.at(x, y, c) = static_cast<float>(level * g * m.Falloff(x + 0.5, y + 0.5) * (1 + n(rng)));
    }
  return im;
}

double MaxModelError(const VignettingModel& fit, const VignettingModel& truth) {
  double worst = 0;
  for (int y = 0; y <= kH; y += 4)
    for (int x = 0; x <= kW; x += 4)
      worst = std::max(worst, std::abs(fit.Falloff(x, y) - truth.Falloff(x, y)));
  return worst;
}

// 1% noise per pixel value; an 8 x 8 bin of 3 channels averages 192 values: 0.072% per bin.
// The fit pools hundreds of bins, so its error anywhere stays below a few bins' noise:
// tolerance 4 x 0.072% = 0.3%.
constexpr double kSigma = 0.01;
constexpr double kTol = 4 * kSigma / 13.86;

TEST(VignettingTest, RecoversFalloffFromSeveralUnevenFlats) {
  const VignettingModel truth = TrueModel();
  const Image f1 = Flat(truth, 100, 0.02, -0.01, kSigma, 1);
  const Image f2 = Flat(truth, 40, -0.015, 0.02, kSigma, 2);
  const Image f3 = Flat(truth, 180, 0.0, 0.03, kSigma, 3);
  VignettingSummary s;
  const VignettingModel fit = FitVignetting({&f1, &f2, &f3}, VignettingOptions{}, nullptr, &s);
  EXPECT_LT(MaxModelError(fit, truth), kTol);
  EXPECT_EQ(s.frames, 3);
  EXPECT_EQ(s.bins_used, 3 * 30 * 20);
  // Residual per bin ~ the bin noise (0.072%).
  EXPECT_LT(s.residual_rms, 2 * kSigma / 13.86);
  EXPECT_NEAR(s.corner_falloff, truth.FalloffAtRadius(1), kTol);
  // Without the gradient terms the same data fit worse (the 1.5-3% gradients stay in the
  // residual).
  VignettingOptions no_grad;
  no_grad.fit_gradient = false;
  VignettingSummary s2;
  FitVignetting({&f1, &f2, &f3}, no_grad, nullptr, &s2);
  EXPECT_GT(s2.residual_rms, 5 * s.residual_rms);
}

TEST(VignettingTest, FitsAnOffCentreLensOnAnEvenField) {
  const VignettingModel truth = TrueModel(kW / 2.0 + 9, kH / 2.0 - 6);
  const Image f1 = Flat(truth, 100, 0, 0, kSigma, 4);
  const Image f2 = Flat(truth, 60, 0, 0, kSigma, 5);
  VignettingOptions o;
  o.fit_gradient = false;
  o.fit_centre = true;
  const VignettingModel fit = FitVignetting({&f1, &f2}, o, nullptr);
  EXPECT_NEAR(fit.cx, truth.cx, 1.0);
  EXPECT_NEAR(fit.cy, truth.cy, 1.0);
  EXPECT_LT(MaxModelError(fit, truth), kTol);
}

TEST(VignettingTest, LinearisesDigitalFlatsThroughTheResponse) {
  const VignettingModel truth = TrueModel();
  const ResponseCurve curve = testing::TrueCurve();
  std::mt19937_64 rng(6);
  const Image r1 = Flat(truth, 1.0, 0.01, 0, 0, 0);
  const Image r2 = Flat(truth, 0.5, 0, -0.01, 0, 0);
  const Image d1 = testing::Expose(r1, 1.0, 0.7, &rng);
  const Image d2 = testing::Expose(r2, 1.0, 0.7, &rng);
  const VignettingModel fit = FitVignetting({&d1, &d2}, VignettingOptions{}, &curve);
  // 0.7 DN at about 0.02 ln/DN is 1.4% per value: twice the radiance case's noise.
  EXPECT_LT(MaxModelError(fit, truth), 2 * kTol);
  EXPECT_THROW(FitVignetting({&d1}, VignettingOptions{}, nullptr), Error);
}

TEST(VignettingTest, BadInputsAreErrors) {
  const VignettingModel truth = TrueModel();
  const Image f = Flat(truth, 1, 0, 0, 0.01, 1);
  Image g(kW + 2, kH, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(FitVignetting({&f, &g}, VignettingOptions{}, nullptr), Error);
  EXPECT_THROW(FitVignetting({}, VignettingOptions{}, nullptr), Error);
  Image tiny(16, 16, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(FitVignetting({&tiny}, VignettingOptions{}, nullptr), Error);
  Image black(kW, kH, 3, PixelUnits::kRadiance, 0.f);
  EXPECT_THROW(FitVignetting({&black}, VignettingOptions{}, nullptr), Error);
  VignettingOptions both;
  both.fit_centre = true;
  EXPECT_THROW(both.Validate(), Error);
}

}  // namespace
}  // namespace rouen
