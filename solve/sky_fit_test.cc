#include "solve/sky_fit.h"

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <vector>

#include "core/angles.h"
#include "core/error.h"
#include "solve/internal/sky_cost.h"
#include "solve/sky_cie.h"
#include "solve/sky_model.h"
#include "solve/sky_test_util.h"

namespace rouen {
namespace {

Eigen::Vector3d AzEl(double az_deg, double el_deg) {
  const double az = az_deg * kDeg, el = el_deg * kDeg;
  return {std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el)};
}

// Directions uniform in solid angle above `min_el_deg`, at least `min_sun_deg` from the sun.
std::vector<Eigen::Vector3d> SkyDirections(int n, const Eigen::Vector3d& sun, double min_el_deg,
                                           double min_sun_deg, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  const double z0 = std::sin(min_el_deg * kDeg);
  std::vector<Eigen::Vector3d> out;
  while (static_cast<int>(out.size()) < n) {
    const double z = z0 + (1 - z0) * u(rng), phi = 2 * kPi * u(rng);
    const double r = std::sqrt(1 - z * z);
    const Eigen::Vector3d d(r * std::cos(phi), r * std::sin(phi), z);
    if (std::acos(std::clamp(d.dot(sun), -1.0, 1.0)) < min_sun_deg * kDeg) continue;
    out.push_back(d);
  }
  return out;
}

SkyModel ClearSkyTruth(const Eigen::Vector3d& sun) {
  SkyModel m;
  m.sun_dir = sun;
  // Red, green, blue: bluer and with a weaker aureole towards blue; h != 1 on purpose.
  m.channel[0] = {0.8, -1.0, -0.40, 12.0, -3.2, 0.50, 0.9};
  m.channel[1] = {1.1, -1.0, -0.35, 9.0, -2.8, 0.45, 0.9};
  m.channel[2] = {1.9, -0.9, -0.30, 7.0, -2.5, 0.40, 0.85};
  return m;
}

TEST(SkyModel, RadianceIsEquationNineAndClampsBelowHorizon) {
  const Eigen::Vector3d sun = AzEl(120, 30);
  const SkyModel m = ClearSkyTruth(sun);
  const Eigen::Vector3d d = AzEl(200, 50);
  const double xi = std::acos(d.z()), gamma = std::acos(d.dot(sun));
  const SkyParams& p = m.channel[1];
  const double expected =
      p.Lz * (1 + p.a * std::exp(p.b / std::cos(xi))) *
      (1 + p.c * std::exp(p.d * std::pow(gamma, p.h)) + p.e * std::cos(gamma) * std::cos(gamma));
  EXPECT_NEAR(m.Radiance(d)[1], expected, 1e-12 * expected);
  // Below the horizon: the horizon value of the same azimuth.
  const Eigen::Vector3d below = AzEl(200, -20), horizon = AzEl(200, 0);
  EXPECT_EQ(m.Radiance(below), m.Radiance(horizon));
  EXPECT_TRUE(m.Radiance(Eigen::Vector3d(0, 0, -1)).allFinite());
  // At the sun itself gamma = 0 stays finite.
  EXPECT_TRUE(m.Radiance(sun).allFinite());
}

// The fit's cost evaluates eq. 9 with its analytic gradient; its values are the model's, at
// every direction of the sky (the one formula of solve/sky_model.h).
TEST(SkyModel, FitCostEvaluatesTheSameFormula) {
  const Eigen::Vector3d sun = AzEl(120, 30);
  const SkyModel m = ClearSkyTruth(sun);
  for (int c = 0; c < 3; ++c) {
    const SkyParams& p = m.channel[c];
    const double params[internal::kNumSkyParams] = {p.Lz, p.a, p.b, p.c, p.d, p.e, p.h};
    for (double az = 0; az < 360; az += 37)
      for (double el = 1; el < 90; el += 11) {
        const Eigen::Vector3d d = AzEl(az, el);
        const double model = m.Radiance(d)[c];
        const double cost =
            internal::SkyModelAt(params, internal::MakeSkyPoint(d, sun, 2), nullptr);
        EXPECT_NEAR(cost, model, 1e-9 * model) << c << " " << az << " " << el;
      }
  }
}

TEST(SkyModel, JsonRoundTripAndErrors) {
  const SkyModel m = ClearSkyTruth(AzEl(10, 20));
  const nlohmann::json j = m;
  const SkyModel back = j.get<SkyModel>();
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(back.channel[c].Lz, m.channel[c].Lz);
    EXPECT_EQ(back.channel[c].h, m.channel[c].h);
    EXPECT_EQ(back.channel[c].d, m.channel[c].d);
  }
  EXPECT_NEAR((back.sun_dir - m.sun_dir).norm(), 0, 1e-15);
  nlohmann::json bad = j;
  bad["channels"][1].erase("h");
  EXPECT_THROW(bad.get<SkyModel>(), Error);
  bad = j;
  bad["channels"][2]["a"] = "x";
  EXPECT_THROW(bad.get<SkyModel>(), Error);
  bad = j;
  bad["sun_dir"] = {0, 0};
  EXPECT_THROW(bad.get<SkyModel>(), Error);
  bad = j;
  bad["channels"].erase(0);
  EXPECT_THROW(bad.get<SkyModel>(), Error);
  // A sun direction written by hand (not unit) is normalized when read; written and read again
  // it stays the same to the last bit (found by the scene reader's fuzzer: a direction an ulp
  // off unit changed on every re-reading).
  for (const Eigen::Vector3d& given :
       {Eigen::Vector3d(0.9718991510515896, 0.05636377664865846, 0.2285494949807769),
        Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(1e-3, 0, 1e-3)}) {
    nlohmann::json hand = j;
    hand["sun_dir"] = {given.x(), given.y(), given.z()};
    const SkyModel once = hand.get<SkyModel>();
    EXPECT_NEAR(once.sun_dir.norm(), 1, 1e-15);
    EXPECT_EQ(nlohmann::json(nlohmann::json(once).get<SkyModel>()), nlohmann::json(once));
  }
}

TEST(FitSky, RecoversEquationNineSkyFromNoisySamples) {
  const Eigen::Vector3d sun = AzEl(140, 35);
  const SkyModel truth = ClearSkyTruth(sun);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0, 0.01);  // 1 % multiplicative noise
  std::vector<SkySample> samples;
  for (const Eigen::Vector3d& d : SkyDirections(4000, sun, 3, 3, 1)) {
    Eigen::Vector3d y = truth.Radiance(d);
    for (int c = 0; c < 3; ++c) y[c] *= 1 + noise(rng);
    samples.push_back({d, y});
  }
  SkyModel fit;
  const SkyFitSummary s = FitSky(samples, sun, SkyFitOptions{}, &fit);
  EXPECT_EQ(s.samples, 4000);
  for (int c = 0; c < 3; ++c) {
    // The residual statistics reflect the 1 % noise: median |N(0, 1%)| = 0.67 %.
    EXPECT_NEAR(s.channel[c].rel_error_median, 0.0067, 0.0015) << "channel " << c;
    EXPECT_GT(s.channel[c].iterations, 0);
    EXPECT_LE(s.channel[c].final_cost, s.channel[c].initial_cost);
  }
  // The fitted radiance matches the noise-free truth everywhere in the sky, including the
  // excluded band near the sun (3-5 deg) and the horizon, to 1.5 %; with 4000 samples of 1 %
  // noise and 7 parameters the statistical error is ~0.1 %.
  for (const Eigen::Vector3d& d : SkyDirections(2000, sun, 3, 5, 9)) {
    const Eigen::Vector3d t = truth.Radiance(d), f = fit.Radiance(d);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[c] / t[c], 1.0, 0.015) << "channel " << c;
  }
  EXPECT_NEAR((fit.sun_dir - sun).norm(), 0, 1e-12);
}

// A single-scattering sky unlike eq. 9: Rayleigh phase (1 + cos^2) with optical depth per
// channel, a Henyey-Greenstein aerosol aureole, and path-length horizon brightening.
Eigen::Vector3d ScatteringSky(const Eigen::Vector3d& d, const Eigen::Vector3d& sun) {
  const double tau_r[3] = {0.05, 0.10, 0.24};
  const double tau_m = 0.08, g = 0.72;
  const double mu = std::clamp(d.dot(sun), -1.0, 1.0);
  const double m_view = 1 / std::max(d.z(), 0.02), m_sun = 1 / std::max(sun.z(), 0.02);
  const double hg = (1 - g * g) / std::pow(1 + g * g - 2 * g * mu, 1.5);
  Eigen::Vector3d out;
  for (int c = 0; c < 3; ++c) {
    const double tau = tau_r[c] + tau_m;
    const double phase = (tau_r[c] * 0.75 * (1 + mu * mu) + tau_m * hg) / tau;
    // Single scattering along the view path, attenuated on the way in and out.
    const double dm = m_view - m_sun;
    const double path = std::abs(dm) < 1e-6
                            ? tau * std::exp(-tau * m_view) * m_view
                            : (std::exp(-tau * m_sun) - std::exp(-tau * m_view)) / dm * m_view;
    out[c] = std::abs(phase * path) + 0.02 * tau_r[c];  // plus a faint multiple-scatter floor
  }
  return out;
}

TEST(FitSky, FitsAScatteringSkyWithSmallRelativeError) {
  const Eigen::Vector3d sun = AzEl(200, 40);
  std::vector<SkySample> samples;
  for (const Eigen::Vector3d& d : SkyDirections(5000, sun, 3, 3, 2)) {
    samples.push_back({d, ScatteringSky(d, sun)});
  }
  SkyModel fit;
  const SkyFitSummary s = FitSky(samples, sun, SkyFitOptions{}, &fit);
  for (int c = 0; c < 3; ++c) {
    // The paper: "the fitting error at most places is within 5 %" (p90 < 5 %). This sky is
    // not separable in (xi, gamma) as eq. 9 is, so the median stays above the ~1 % that
    // NOTES.md reports for physically based skies; 3 % is the bound for "small".
    EXPECT_LT(s.channel[c].rel_error_median, 0.03) << "channel " << c;
    EXPECT_LT(s.channel[c].rel_error_p90, 0.05) << "channel " << c;
    RecordProperty("median_" + std::to_string(c), std::to_string(s.channel[c].rel_error_median));
    RecordProperty("p90_" + std::to_string(c), std::to_string(s.channel[c].rel_error_p90));
  }
}

const double kJacobianProbes[][7] = {{3, -1, -0.32, 10, -3, 0.45, 1},
                                     {5, 0.7, -0.9, 2, -1.5, 0.15, 1.7},
                                     {1, -0.5, -2.0, 30, -6, -0.3, 0.5}};

std::vector<internal::SkyPoint> JacobianPoints() {
  const Eigen::Vector3d sun = AzEl(80, 25);
  std::vector<internal::SkyPoint> points;
  for (const Eigen::Vector3d& d : SkyDirections(50, sun, 1, 0.5, 4)) {
    points.push_back(internal::MakeSkyPoint(d, sun, 2 + 10 * d.z()));
  }
  return points;
}

TEST(FitSky, AnalyticJacobianMatchesCentralDifferences) {
  const std::vector<internal::SkyPoint> points = JacobianPoints();
  const internal::SkyCost cost(points);
  const int n = static_cast<int>(points.size());
  // Step ~ cbrt(eps) x scale: truncation and rounding errors both ~1e-10 relative.
  for (const auto& p0 : kJacobianProbes) {
    testing::ExpectJacobianMatchesCentralDifferences(cost, n, p0, 1e-5, 1e-6, "");
  }
}

// Ceres's own checker. Under AddressSanitizer Eigen switches its aligned allocator, so the
// matrices that the (uninstrumented) Ceres library allocates cannot be freed here.
TEST(FitSky, CeresGradientChecker) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "Eigen's allocator differs between this ASan build and the Ceres library";
#else
  const std::vector<internal::SkyPoint> points = JacobianPoints();
  internal::SkyCost cost(points);
  ceres::NumericDiffOptions nd;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(&cost, no_manifolds, nd);
  for (const auto& p0 : kJacobianProbes) {
    double p[7];
    std::copy(p0, p0 + 7, p);
    const double* params[1] = {p};
    ceres::GradientChecker::ProbeResults results;
    // Ceres's differences agree to ~2e-7 relative here; a wrong term is off by O(1).
    EXPECT_TRUE(checker.Probe(params, 1e-6, &results)) << results.error_log;
  }
#endif
}

TEST(FitSky, RejectsBadInput) {
  const Eigen::Vector3d sun = AzEl(0, 45);
  std::vector<SkySample> good;
  for (const Eigen::Vector3d& d : SkyDirections(100, sun, 3, 3, 5)) {
    good.push_back({d, Eigen::Vector3d(1, 2, 3) * (1 + d.z())});
  }
  SkyModel m;
  EXPECT_NO_THROW(FitSky(good, sun, SkyFitOptions{}, &m));
  std::vector<SkySample> few(good.begin(), good.begin() + 10);
  EXPECT_THROW(FitSky(few, sun, SkyFitOptions{}, &m), Error);
  std::vector<SkySample> bad = good;
  bad[7].radiance[1] = 0;
  EXPECT_THROW(FitSky(bad, sun, SkyFitOptions{}, &m), Error);
  bad[7].radiance[1] = -1;
  EXPECT_THROW(FitSky(bad, sun, SkyFitOptions{}, &m), Error);
  bad[7].radiance[1] = std::nan("");
  EXPECT_THROW(FitSky(bad, sun, SkyFitOptions{}, &m), Error);
  bad = good;
  bad[3].dir *= 2;
  EXPECT_THROW(FitSky(bad, sun, SkyFitOptions{}, &m), Error);
  bad = good;
  bad[3].dir = AzEl(10, -10);
  EXPECT_THROW(FitSky(bad, sun, SkyFitOptions{}, &m), Error);
  EXPECT_THROW(FitSky(good, Eigen::Vector3d::Zero(), SkyFitOptions{}, &m), Error);
  SkyFitOptions o;
  o.min_directions = 3;
  EXPECT_THROW(FitSky(good, sun, o, &m), Error);
  o = SkyFitOptions{};
  o.max_iterations = 0;
  EXPECT_THROW(o.Validate(), Error);
}

// A radiance image of the scattering sky from a level fisheye looking up.
Image RenderSky(const Intrinsics& k, const Pose& pose, const Eigen::Vector3d& sun) {
  Image img(k.width, k.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      const Eigen::Vector3d l = d.z() > 0 ? ScatteringSky(d, sun) : Eigen::Vector3d(0.1, 0.1, 0.1);
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(l[c]);
    }
  }
  return img;
}

TEST(ExtractSkySamples, SelectsValidSkySpreadOverSolidAngle) {
  const Intrinsics k = Intrinsics::FisheyeFov(240, 240, 180);
  const Pose pose = Pose::LookAt(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, 1));
  const Eigen::Vector3d sun = AzEl(100, 50);
  Image img = RenderSky(k, pose, sun);
  std::vector<uint8_t> mask(static_cast<size_t>(k.width) * k.height, 1);
  // Mask out the upper-left quarter of the image; poison it so a leak would show.
  for (int y = 0; y < k.height / 2; ++y) {
    for (int x = 0; x < k.width / 2; ++x) {
      mask[static_cast<size_t>(y) * k.width + x] = 0;
      img.at(x, y, 0) = -1;
    }
  }
  SkySampleOptions opt;
  opt.max_samples = 3000;
  const std::vector<SkySample> s = ExtractSkySamples(img, &mask, k, pose, sun, opt);
  ASSERT_EQ(s.size(), 3000u);
  int upper = 0;
  for (const SkySample& q : s) {
    EXPECT_NEAR(q.dir.norm(), 1, 1e-9);
    EXPECT_GE(q.dir.z(), std::sin(3 * kDeg) - 1e-12);
    EXPECT_GE(std::acos(std::clamp(q.dir.dot(sun), -1.0, 1.0)), 3 * kDeg - 1e-12);
    EXPECT_GT(q.radiance.minCoeff(), 0);
    const Eigen::Vector3d t = ScatteringSky(q.dir, sun);
    // The pixel centre's own value (float precision).
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(q.radiance[c] / t[c], 1, 1e-5);
    if (q.dir.z() > 0.5) ++upper;
  }
  // Evenly over solid angle: z > 0.5 is (1 - 0.5) / (1 - sin 3 deg) = 52.7 % of the sky.
  EXPECT_NEAR(upper / 3000.0, 0.527, 0.04);
  // Malformed inputs.
  std::vector<uint8_t> short_mask(10, 1);
  EXPECT_THROW(ExtractSkySamples(img, &short_mask, k, pose, sun, opt), Error);
  Image digital = img;
  digital.units = PixelUnits::kDigital;
  EXPECT_THROW(ExtractSkySamples(digital, nullptr, k, pose, sun, opt), Error);
  Intrinsics other = k;
  other.width = 100;
  EXPECT_THROW(ExtractSkySamples(img, nullptr, other, pose, sun, opt), Error);
  opt.max_samples = 0;
  EXPECT_THROW(ExtractSkySamples(img, nullptr, k, pose, sun, opt), Error);
}

TEST(FitSky, EndToEndFromImageAndTiming) {
  const Intrinsics k = Intrinsics::FisheyeFov(400, 400, 180);
  const Pose pose = Pose::LookAt(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, 1));
  const Eigen::Vector3d sun = AzEl(250, 30);
  const Image img = RenderSky(k, pose, sun);
  const std::vector<SkySample> s =
      ExtractSkySamples(img, nullptr, k, pose, sun, SkySampleOptions{});
  EXPECT_EQ(s.size(), 20000u);
  SkyModel fit;
  const SkyFitSummary summary = FitSky(s, sun, SkyFitOptions{}, &fit);
  for (int c = 0; c < 3; ++c) {
    EXPECT_LT(summary.channel[c].rel_error_median, 0.03);
    EXPECT_LT(summary.channel[c].rel_error_p90, 0.05);
  }
  // The model also predicts the pixels it was not fitted to (every pixel above 3 deg).
  std::vector<double> rel;
  for (int y = 0; y < k.height; y += 3) {
    for (int x = 0; x < k.width; x += 3) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      if (d.z() < std::sin(3 * kDeg) || std::acos(d.dot(sun)) < 3 * kDeg) continue;
      rel.push_back(std::abs(fit.Radiance(d)[1] / img.at(x, y, 1) - 1));
    }
  }
  std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
  EXPECT_LT(rel[rel.size() / 2], 0.03);
  RecordProperty("fit_seconds_20k_x3", std::to_string(summary.seconds));
}

TEST(FitSky, Perez5FixesHAtOne) {
  const Eigen::Vector3d sun = AzEl(60, 45);
  SkyModel truth = ClearSkyTruth(sun);
  for (SkyParams& p : truth.channel) p.h = 1;  // a Perez-form sky
  std::vector<SkySample> samples;
  for (const Eigen::Vector3d& d : SkyDirections(3000, sun, 3, 3, 5)) {
    samples.push_back({d, truth.Radiance(d)});
  }
  SkyFitOptions o;
  o.model = SkyModelKind::kPerez5;
  SkyModel fit;
  const SkyFitSummary s = FitSky(samples, sun, o, &fit);
  EXPECT_EQ(s.model, SkyModelKind::kPerez5);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(fit.channel[c].h, 1.0);
    // Noise-free samples of a model in the family: the fit is exact up to LM tolerances.
    EXPECT_LT(s.channel[c].rel_error_p90, 2e-3) << "channel " << c;
  }
}

TEST(FitSky, CiePicksTheGeneratingTypeAndScalesLzPerChannel) {
  const Eigen::Vector3d sun = AzEl(150, 30);
  const double zs = std::acos(sun.z());
  const double lz[3] = {2.0, 3.0, 5.0};
  for (int type : {1, 7, 12}) {
    SkyModel truth;
    truth.sun_dir = sun;
    for (int c = 0; c < 3; ++c) truth.channel[c] = CieAsSkyParams(CieStandardSky(type), zs, lz[c]);
    std::vector<SkySample> samples;
    for (const Eigen::Vector3d& d : SkyDirections(2000, sun, 3, 3, 6)) {
      samples.push_back({d, truth.Radiance(d)});
    }
    SkyFitOptions o;
    o.model = SkyModelKind::kCie;
    SkyModel fit;
    const SkyFitSummary s = FitSky(samples, sun, o, &fit);
    EXPECT_EQ(s.model, SkyModelKind::kCie);
    EXPECT_EQ(s.cie_type, type);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(fit.Radiance(Eigen::Vector3d::UnitZ())[c], lz[c], 1e-9 * lz[c]);
      EXPECT_LT(s.channel[c].rel_error_max, 1e-9);
    }
  }
}

TEST(FitSky, RelativeWeightingAndResiduals) {
  const Eigen::Vector3d sun = AzEl(140, 35);
  const SkyModel truth = ClearSkyTruth(sun);
  std::mt19937_64 rng(8);
  std::normal_distribution<double> noise(0, 0.01);
  std::vector<SkySample> samples;
  for (const Eigen::Vector3d& d : SkyDirections(3000, sun, 3, 3, 2)) {
    Eigen::Vector3d y = truth.Radiance(d);
    for (int c = 0; c < 3; ++c) y[c] *= 1 + noise(rng);
    samples.push_back({d, y});
  }
  SkyFitOptions o;
  o.weighting = SkyWeighting::kRelative;
  SkyModel fit;
  const SkyFitSummary s = FitSky(samples, sun, o, &fit);
  const std::vector<Eigen::Vector3d> res = SkyRelativeResiduals(fit, samples);
  ASSERT_EQ(res.size(), samples.size());
  const SkyResidualStats st = SummarizeSkyResiduals(res);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(s.channel[c].rel_error_median, 0.0067, 0.0015) << "channel " << c;
    // The per-sample residuals reproduce the summary's statistics.
    EXPECT_NEAR(st.median[c], s.channel[c].rel_error_median, 1e-9);
    EXPECT_NEAR(st.p90[c], s.channel[c].rel_error_p90, 1e-9);
    EXPECT_NEAR(st.mean[c], s.channel[c].rel_error_mean, 1e-9);
  }
  // A residual is (model - y) / y.
  EXPECT_NEAR(res[5][1], fit.Radiance(samples[5].dir)[1] / samples[5].radiance[1] - 1, 1e-12);
}

TEST(FitSky, ModelKindNames) {
  for (SkyModelKind k : {SkyModelKind::kSevenParam, SkyModelKind::kPerez5, SkyModelKind::kCie}) {
    EXPECT_EQ(ParseSkyModelKind(SkyModelKindName(k)), k);
  }
  EXPECT_THROW(ParseSkyModelKind("perez"), Error);
}

}  // namespace
}  // namespace rouen
