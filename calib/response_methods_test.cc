// The response-recovery methods side by side (Debevec-Malik, Robertson, Mitsunaga-Nayar) on
// synthetic brackets with known curves, and their agreement on Memorial.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "calib/response.h"
#include "calib/test_util.h"
#include "core/error.h"

namespace rouen {
namespace {

using testing::CurveShape;
using testing::MakeBracket;
using testing::RadianceField;
using testing::TrueLogExposure;
using testing::TrueSlope;

const std::vector<double>& kExposures = testing::kTwoStopExposures;
using testing::StrictlyIncreasing;

struct Case {
  ResponseMethod method;
  CurveShape shape;
  double noise_dn;
  int z_lo, z_hi;        // levels judged
  double fit_allowance;  // ln; the method's own approximation error (see Tolerance)
  double mn_fit_high;    // Mitsunaga-Nayar fit range top
};

std::string CaseName(const ::testing::TestParamInfo<Case>& info) {
  std::string n = ResponseMethodName(info.param.method);
  n.erase(std::remove(n.begin(), n.end(), '-'), n.end());
  n += info.param.shape == CurveShape::kFilm ? "Film" : "Srgb";
  n += info.param.noise_dn > 0 ? "Noisy" : "NoiseFree";
  return n;
}

// Allowed |g - g_true| at level z (ln units).
//  - Noise-free, a reading z stands for every exposure rounding to it: +-0.5 DN, i.e. half a
//    DN of the local slope; plus 0.01 ln for the smoothness term and the level averaging.
//  - With Gaussian noise sigma the readings at a level come from a band sigma_eff =
//    sqrt(sigma^2 + 1/12) DN wide; the averaged level is biased by the curve's curvature
//    over that band, bounded by one sigma_eff of slope (hundreds of readings per level make
//    the random part small), plus 0.02 ln.
//  - fit_allowance adds a method's own approximation error: a degree <= 10 polynomial
//    following the film curve's pole 15 DN beyond its fit range (Chebyshev bound
//    rho^-10 with rho ~ 1.6 times the curve's 9x range: ~0.03 ln), or sRGB's 2.4 power near
//    the top (0.02 ln).
double Tolerance(const Case& k, int c, int z) {
  const double slope = TrueSlope(c, z, k.shape);
  if (k.noise_dn <= 0) return 0.01 + 0.5 * slope + k.fit_allowance;
  const double sigma = std::sqrt(k.noise_dn * k.noise_dn + 1.0 / 12);
  return 0.02 + sigma * slope + k.fit_allowance;
}

class MethodCurveTest : public ::testing::TestWithParam<Case> {};

TEST_P(MethodCurveTest, RecoversKnownCurve) {
  const Case& k = GetParam();
  const Image radiance = RadianceField(240, 160, -5.0, 4.0, 7);
  const std::vector<Bracket> brackets = {
      MakeBracket(radiance, kExposures, k.noise_dn, 11, k.shape)};
  ResponseOptions opt;
  opt.method = k.method;
  opt.mn_fit_high = k.mn_fit_high;
  ResponseSummary s;
  const ResponseCurve curve = RecoverResponse(brackets, opt, &s);
  EXPECT_EQ(s.method, k.method);
  EXPECT_GT(s.residual_rms, 0);
  EXPECT_GT(s.method_residual, 0);
  EXPECT_TRUE(std::isfinite(s.method_residual));
  if (k.method == ResponseMethod::kRobertson) {
    EXPECT_TRUE(s.converged);
    EXPECT_GT(s.iterations, 1);
    EXPECT_GE(s.samples_used, 2000);
  }
  if (k.method == ResponseMethod::kMitsunagaNayar) {
    EXPECT_GE(s.polynomial_order, 2);  // neither curve is linear
    EXPECT_LE(s.polynomial_order, opt.max_polynomial_order);
  }
  EXPECT_TRUE(curve.valid());
  double worst = 0;
  for (int c = 0; c < 3; ++c) {
    ASSERT_EQ(curve.g[c].size(), 256u);
    for (double v : curve.g[c]) ASSERT_TRUE(std::isfinite(v));
    EXPECT_TRUE(StrictlyIncreasing(curve.g[c])) << "channel " << c;
    EXPECT_DOUBLE_EQ(curve.g[c][128], 0.0);
    const double offset = TrueLogExposure(c, 128, k.shape);
    for (int z = k.z_lo; z <= k.z_hi; ++z) {
      const double err = curve.g[c][z] - (TrueLogExposure(c, z, k.shape) - offset);
      const double tol = Tolerance(k, c, z);
      worst = std::max(worst, std::abs(err) / tol);
      EXPECT_NEAR(err, 0.0, tol) << "channel " << c << " z " << z;
    }
  }
  RecordProperty("worst_error_over_tolerance", std::to_string(worst));
  RecordProperty("residual_rms", std::to_string(s.residual_rms));
  RecordProperty("method_residual", std::to_string(s.method_residual));
  std::printf(
      "%s: worst |error| / tolerance %.2f, residual %.4f ln, method residual %.4g, "
      "iterations %d, order %d, %.3f s\n",
      CaseName({k, 0}).c_str(), worst, s.residual_rms, s.method_residual, s.iterations,
      s.polynomial_order, s.seconds);
}

constexpr auto kDM = ResponseMethod::kDebevecMalik;
constexpr auto kRob = ResponseMethod::kRobertson;
constexpr auto kMN = ResponseMethod::kMitsunagaNayar;
constexpr auto kFilm = CurveShape::kFilm;
constexpr auto kSrgb = CurveShape::kSrgb;

INSTANTIATE_TEST_SUITE_P(
    Synthetic, MethodCurveTest,
    ::testing::Values(
        // Noise-free: every method over z = 5..250; Mitsunaga-Nayar from its fit range's
        // bottom (20) and, on the film curve, whose pole at 255 no polynomial follows,
        // fitted to 240 and judged to 235.
        Case{kDM, kFilm, 0.0, 5, 250, 0.0, 252}, Case{kDM, kSrgb, 0.0, 5, 250, 0.0, 252},
        Case{kRob, kFilm, 0.0, 5, 250, 0.0, 252}, Case{kRob, kSrgb, 0.0, 5, 250, 0.0, 252},
        Case{kMN, kSrgb, 0.0, 20, 250, 0.02, 252}, Case{kMN, kFilm, 0.0, 20, 235, 0.03, 240},
        // 0.7 DN noise: z = 20..235 (the bench's stability range); Mitsunaga-Nayar on sRGB
        // over 20..250. (On the film curve with noise it is 0.15 ln off in the toe: not
        // claimed.)
        Case{kDM, kFilm, 0.7, 20, 235, 0.0, 252}, Case{kDM, kSrgb, 0.7, 20, 235, 0.0, 252},
        Case{kRob, kFilm, 0.7, 20, 235, 0.0, 252}, Case{kRob, kSrgb, 0.7, 20, 235, 0.0, 252},
        Case{kMN, kSrgb, 0.7, 20, 250, 0.02, 252}),
    CaseName);

class MethodTest : public ::testing::TestWithParam<ResponseMethod> {};

std::string MethodName(const ::testing::TestParamInfo<ResponseMethod>& info) {
  std::string n = ResponseMethodName(info.param);
  n.erase(std::remove(n.begin(), n.end(), '-'), n.end());
  return n;
}

TEST_P(MethodTest, MonotoneAndFiniteWhereLevelsNeverOccur) {
  // Radiance over a narrow range, three exposures: most levels never occur.
  const Image radiance = RadianceField(80, 60, -1.5, -0.5, 9);
  const std::vector<Bracket> brackets = {MakeBracket(radiance, {1.0, 2.0, 4.0}, 0.3, 1)};
  ResponseOptions opt;
  opt.method = GetParam();
  ResponseSummary s;
  const ResponseCurve curve = RecoverResponse(brackets, opt, &s);
  EXPECT_TRUE(curve.valid());
  for (int c = 0; c < 3; ++c) {
    for (double v : curve.g[c]) ASSERT_TRUE(std::isfinite(v));
    EXPECT_TRUE(StrictlyIncreasing(curve.g[c])) << "channel " << c;
    EXPECT_DOUBLE_EQ(curve.g[c][128], 0.0);
  }
  EXPECT_TRUE(std::isfinite(s.residual_rms));
  EXPECT_TRUE(std::isfinite(s.method_residual));
}

INSTANTIATE_TEST_SUITE_P(AllMethods, MethodTest, ::testing::Values(kDM, kRob, kMN), MethodName);

TEST(RecoverResponse, GridScanOfLargeBracketsKeepsTheCurve) {
  // 240 x 160 = 38400 pixels with scan_pixels = 10000: stride 2.
  const Image radiance = RadianceField(240, 160, -5.0, 4.0, 7);
  const std::vector<Bracket> brackets = {MakeBracket(radiance, kExposures, 0.7, 11)};
  ResponseOptions opt;
  opt.scan_pixels = 10000;
  ResponseSummary s;
  const ResponseCurve curve = RecoverResponse(brackets, opt, &s);
  EXPECT_EQ(s.scan_stride, 2);
  EXPECT_GT(s.samples_used, 150);
  const Case k{kDM, kFilm, 0.7, 20, 235, 0.0, 252};
  for (int c = 0; c < 3; ++c) {
    EXPECT_TRUE(StrictlyIncreasing(curve.g[c]));
    const double offset = TrueLogExposure(c, 128);
    for (int z = 20; z <= 235; ++z) {
      EXPECT_NEAR(curve.g[c][z], TrueLogExposure(c, z) - offset, Tolerance(k, c, z))
          << "channel " << c << " z " << z;
    }
  }
}

TEST(RecoverResponse, MitsunagaNayarRatioEstimationRecoversWrongExposures) {
  // The camera's real exposures are kExposures; the list claims the 4th frame got 1.3x
  // its true value. With fixed ratios the curve must absorb the error; re-estimated ratios
  // recover the true ones (within 3%) and the curve over the middle.
  const Image radiance = RadianceField(240, 160, -5.0, 4.0, 7);
  Bracket b = MakeBracket(radiance, kExposures, 0.0, 11, kSrgb);
  b.exposures[3] *= 1.3;
  ResponseOptions opt;
  opt.method = kMN;
  opt.mn_estimate_ratios = true;
  ResponseSummary s;
  const ResponseCurve curve = RecoverResponse({b}, opt, &s);
  ASSERT_FALSE(s.exposure_ratios.empty());
  int close = 0;
  for (double r : s.exposure_ratios) close += std::abs(r - 0.25) < 0.25 * 0.03;
  EXPECT_EQ(close, static_cast<int>(s.exposure_ratios.size()));
  for (int c = 0; c < 3; ++c) {
    const double offset = TrueLogExposure(c, 128, kSrgb);
    for (int z = 20; z <= 235; ++z) {
      EXPECT_NEAR(curve.g[c][z], TrueLogExposure(c, z, kSrgb) - offset, 0.05)
          << "channel " << c << " z " << z;
    }
  }
}

TEST(RecoverResponse, MethodOptionsAreValidated) {
  const Image radiance = RadianceField(40, 30, -1.0, 1.0, 3);
  const Bracket good = MakeBracket(radiance, {1.0, 2.0}, 0.0, 1);
  auto bad = [&](auto edit) {
    ResponseOptions o;
    edit(o);
    EXPECT_THROW(o.Validate(), Error);
    EXPECT_THROW(RecoverResponse({good}, o, nullptr), Error);
  };
  bad([](ResponseOptions& o) { o.method = static_cast<ResponseMethod>(7); });
  bad([](ResponseOptions& o) { o.max_iterations = 0; });
  bad([](ResponseOptions& o) { o.convergence_tolerance = 0; });
  bad([](ResponseOptions& o) { o.max_polynomial_order = 0; });
  bad([](ResponseOptions& o) { o.max_polynomial_order = 16; });
  bad([](ResponseOptions& o) { o.mn_fit_low = 200; });
  bad([](ResponseOptions& o) { o.mn_fit_high = 255; });
  bad([](ResponseOptions& o) { o.scan_pixels = 10; });
  bad([](ResponseOptions& o) { o.robertson_min_samples_per_bracket = -1; });
  EXPECT_STREQ(ResponseMethodName(kRob), "Robertson");
}

// ---- Memorial: the three methods side by side (agreement reported, not asserted). ----

TEST(RecoverResponse, MemorialMethodsAreMonotoneAndAgreementIsReported) {
  if (!std::filesystem::exists(testing::MemorialDir() / "exposures.txt")) {
    GTEST_SKIP() << "Memorial data absent at " << testing::MemorialDir();
  }
  const Bracket memorial = testing::LoadMemorial();
  ASSERT_EQ(memorial.frames.size(), 16u);
  ResponseCurve curves[3];
  ResponseSummary sums[3];
  const ResponseMethod methods[3] = {kDM, kRob, kMN};
  for (int m = 0; m < 3; ++m) {
    ResponseOptions opt;
    opt.method = methods[m];
    curves[m] = RecoverResponse({memorial}, opt, &sums[m]);
    for (int c = 0; c < 3; ++c) {
      for (double v : curves[m].g[c]) ASSERT_TRUE(std::isfinite(v));
      EXPECT_TRUE(StrictlyIncreasing(curves[m].g[c])) << ResponseMethodName(methods[m]);
      EXPECT_DOUBLE_EQ(curves[m].g[c][128], 0.0);
    }
  }
  // Reported over z = 20..235 (the bench's range) and 40..235: Memorial's toe below ~40 is
  // steep (Debevec-Malik: g(20) - g(40) ~ -3 ln) and sparsely read, and that is where the
  // methods part.
  for (int m = 1; m < 3; ++m) {
    double diff20 = 0, diff40 = 0;
    for (int c = 0; c < 3; ++c) {
      for (int z = 20; z <= 235; ++z) {
        const double d = std::abs(curves[m].g[c][z] - curves[0].g[c][z]);
        diff20 = std::max(diff20, d);
        if (z >= 40) diff40 = std::max(diff40, d);
      }
    }
    const std::string name = ResponseMethodName(methods[m]);
    RecordProperty("max_abs_delta_vs_debevec_malik_20_235_" + name, std::to_string(diff20));
    RecordProperty("max_abs_delta_vs_debevec_malik_40_235_" + name, std::to_string(diff40));
    std::printf(
        "Memorial: %s vs Debevec-Malik, max |delta g| over z 20..235 = %.3f ln, over "
        "40..235 = %.3f ln; residual %.4f vs %.4f ln; %.3f s\n",
        name.c_str(), diff20, diff40, sums[m].residual_rms, sums[0].residual_rms, sums[m].seconds);
  }
}

}  // namespace
}  // namespace rouen
