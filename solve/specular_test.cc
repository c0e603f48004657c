#include "solve/specular.h"

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <random>

#include "core/error.h"

namespace rouen {
namespace {

Eigen::Vector3d Unit(double az, double el) {
  return Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
}

TEST(SpecularLobe, PeaksAtTheMirrorDirectionAndVanishesBelowTheSurface) {
  SpecularLobe lobe;
  lobe.rho_s = Eigen::Vector3d(0.2, 0.3, 0.4);
  lobe.kappa = 1;
  lobe.n = 30;
  const Eigen::Vector3d n(0, 0, 1), u = Unit(0.3, 0.6);
  const Eigen::Vector3d mirror = 2 * u.dot(n) * n - u;
  EXPECT_NEAR(lobe.Shape(n, u, mirror), 1.0, 1e-12);
  EXPECT_TRUE(lobe.Eval(n, u, mirror).isApprox(lobe.rho_s, 1e-12));
  // Away from the mirror direction: the cosine to it raised to n.
  const Eigen::Vector3d off = Unit(0.3 + M_PI + 0.2, 0.6);
  EXPECT_NEAR(lobe.Shape(n, u, off), std::pow(off.dot(mirror), 30), 1e-12);
  EXPECT_LT(lobe.Shape(n, u, off), 1.0);
  EXPECT_EQ(lobe.Shape(n, u, Unit(1, -0.1)), 0.0);  // viewer below the surface
  EXPECT_EQ(lobe.Shape(n, Unit(1, -0.1), mirror), 0.0);
  // kappa above 1 leans the lobe towards grazing: at a grazing mirror pair it exceeds 1.
  lobe.kappa = 1.4;
  const Eigen::Vector3d g = Unit(0.3, 0.1), gm = 2 * g.dot(n) * n - g;
  EXPECT_GT(lobe.Shape(n, g, gm), 1.0);
}

// The microfacet lobe from its definition, term by term through the half vector: GGX's D,
// Smith's G1 for GGX and Schlick's Fresnel with F0 0.04, over its value at normal incidence
// F0 / (4 pi alpha^2).
double MicrofacetReference(const Eigen::Vector3d& n, const Eigen::Vector3d& u,
                           const Eigen::Vector3d& v, double exponent) {
  const double a2 = 2 / (exponent + 2);
  const Eigen::Vector3d h = (u + v).normalized();
  const double nh = n.dot(h);
  const double d = a2 / (M_PI * std::pow(nh * nh * (a2 - 1) + 1, 2));
  auto g1 = [&](const Eigen::Vector3d& x) {
    const double c = n.dot(x);
    return 2 * c / (c + std::sqrt(a2 + (1 - a2) * c * c));
  };
  const double f = 0.04 + 0.96 * std::pow(1 - v.dot(h), 5);
  const double brdf = d * g1(u) * g1(v) * f / (4 * n.dot(u) * n.dot(v));
  return brdf / (0.04 / (4 * M_PI * a2));
}

// The integral over the hemisphere of g(u) cos(u), by the midpoint rule in (theta, phi) about
// the normal z, fine enough for lobes a few degrees wide.
template <typename F>
double HemisphereIntegral(const F& g) {
  constexpr int kTheta = 3000, kPhi = 360;
  double sum = 0;
  for (int i = 0; i < kTheta; ++i) {
    const double t = (i + 0.5) * (M_PI / 2) / kTheta;
    for (int j = 0; j < kPhi; ++j) {
      const double p = (j + 0.5) * 2 * M_PI / kPhi;
      const Eigen::Vector3d u(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
      sum += g(u) * std::cos(t) * std::sin(t);
    }
  }
  return sum * (M_PI / 2 / kTheta) * (2 * M_PI / kPhi);
}

TEST(SpecularLobe, MicrofacetLobeIsGgxSmithAndSchlick) {
  SpecularLobe lobe;
  lobe.model = LobeModel::kMicrofacet;
  lobe.n = 120;  // alpha 0.128
  lobe.rho_s = Eigen::Vector3d(0.2, 0.25, 0.3);
  EXPECT_NO_THROW(lobe.Validate("roof"));
  const Eigen::Vector3d n(0, 0, 1);
  EXPECT_NEAR(lobe.Shape(n, n, n), 1.0, 1e-12);  // rho_s is the value at normal incidence
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> uni(0, 1);
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector3d u = Unit(2 * M_PI * uni(rng), 0.02 + 1.5 * uni(rng));
    const Eigen::Vector3d v = Unit(2 * M_PI * uni(rng), 0.02 + 1.5 * uni(rng));
    EXPECT_NEAR(lobe.Shape(n, u, v), MicrofacetReference(n, u, v, lobe.n),
                1e-9 * (1 + MicrofacetReference(n, u, v, lobe.n)));
  }
  // The glint a Lafortune lobe cannot make: at a grazing mirror pair (sun and viewer 77 degrees
  // from the normal) Fresnel and 1 / (u.n)(v.n) lift the peak tens of times over normal
  // incidence's.
  const Eigen::Vector3d g = Unit(0.3, 13 * M_PI / 180), gm = 2 * g.dot(n) * n - g;
  EXPECT_GT(lobe.Shape(n, g, gm), 20);
  EXPECT_EQ(lobe.Shape(n, Unit(1, -0.1), gm), 0.0);
  // The energy bound: at MaxLobeRho the lobe reflects at most what it receives at normal
  // incidence (Smith's shadowing takes a few percent).
  const double rho_max = MaxLobeRho(lobe.n, LobeModel::kMicrofacet);
  const double reflected =
      HemisphereIntegral([&](const Eigen::Vector3d& u) { return rho_max * lobe.Shape(n, u, n); });
  EXPECT_LE(reflected, 1.0);
  EXPECT_GT(reflected, 0.95);
  // kappa means nothing to it: anything but 1 is refused, as is rho_s over the bound.
  lobe.kappa = 1.1;
  EXPECT_THROW(lobe.Validate("roof"), Error);
  lobe.kappa = 1;
  lobe.rho_s[0] = rho_max * 1.01;
  EXPECT_THROW(lobe.Validate("roof"), Error);
  EXPECT_EQ(ParseLobeModel(LobeModelName(LobeModel::kMicrofacet), "m"), LobeModel::kMicrofacet);
  EXPECT_THROW(ParseLobeModel("phong", "roof.model"), Error);
}

// Directions about the normal and the mirror weighed by MixtureWeight integrate a narrow lobe
// against a sky without bias: the mean over many independent draws equals the quadrature.
TEST(SpecularLobe, MixtureDirectionsIntegrateANarrowLobe) {
  const Eigen::Vector3d n(0, 0, 1), v = Unit(0.4, 0.5);
  const Eigen::Vector3d m = 2 * v.dot(n) * n - v;
  auto sky = [](const Eigen::Vector3d& u) { return 1 + 3 * std::pow(1 - u.z(), 2) + u.x(); };
  for (const LobeModel model : {LobeModel::kLafortune, LobeModel::kMicrofacet}) {
    SpecularLobe lobe;
    lobe.model = model;
    lobe.n = 300;
    lobe.rho_s = Eigen::Vector3d::Ones();
    const double want =
        HemisphereIntegral([&](const Eigen::Vector3d& u) { return lobe.Shape(n, u, v) * sky(u); });
    const double e = lobe.MirrorExponent();
    constexpr int kCosine = 8, kMirror = 8, kRuns = 4000;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> uni(0, 1);
    // The mean and standard deviation of one estimate from `cosine` and `mirror` draws.
    auto estimate = [&](int cosine, int mirror) {
      double sum = 0, sum2 = 0;
      for (int r = 0; r < kRuns; ++r) {
        double est = 0;
        for (int k = 0; k < cosine + mirror; ++k) {
          const Eigen::Vector3d u =
              DrawAboutAxis(k < cosine ? n : m, k < cosine ? 1 : e, uni(rng), uni(rng));
          est += lobe.Shape(n, u, v) * sky(u) * MixtureWeight(n, m, u, e, cosine, mirror);
        }
        sum += est;
        sum2 += est * est;
      }
      const double mean = sum / kRuns;
      return std::pair{mean, std::sqrt(std::max(0.0, sum2 / kRuns - mean * mean))};
    };
    const auto [mean, sd] = estimate(kCosine, kMirror);
    EXPECT_NEAR(mean, want, 4 * sd / std::sqrt(kRuns)) << LobeModelName(model);
    // The mirror's directions do the work: as many cosine directions alone spread at least
    // three times wider (and are unbiased too).
    const auto [cosine_mean, cosine_sd] = estimate(kCosine + kMirror, 0);
    EXPECT_NEAR(cosine_mean, want, 4 * cosine_sd / std::sqrt(kRuns)) << LobeModelName(model);
    std::printf("%s: spread of one estimate %.3f (mixture) vs %.3f (cosine) of %.3f\n",
                LobeModelName(model), sd, cosine_sd, want);
    EXPECT_LT(3 * sd, cosine_sd) << LobeModelName(model);
  }
}

// The directional albedo the renderer scales its sky lobe's mean radiance by: the lobe's
// integral against the cosine, here by a fine quadrature over the hemisphere, for both models,
// a broad and a narrow lobe, from near grazing to near normal views. A 96 x 96 midpoint rule of
// the mixture's smooth weights: within 1%.
TEST(SpecularLobe, DirectionalAlbedoIsTheLobesIntegralAgainstTheCosine) {
  const Eigen::Vector3d n(0, 0, 1);
  for (const LobeModel model : {LobeModel::kLafortune, LobeModel::kMicrofacet}) {
    for (const double exponent : {20.0, 120.0}) {
      SpecularLobe lobe;
      lobe.model = model;
      lobe.n = exponent;
      lobe.kappa = model == LobeModel::kLafortune ? 1.2 : 1.0;
      lobe.rho_s = Eigen::Vector3d::Ones();
      for (const double cos_view : {0.15, 0.5, 0.95}) {
        const Eigen::Vector3d v(std::sqrt(1 - cos_view * cos_view), 0, cos_view);
        const double want =
            HemisphereIntegral([&](const Eigen::Vector3d& u) { return lobe.Shape(n, u, v); });
        EXPECT_NEAR(LobeDirectionalAlbedo(lobe, cos_view), want, 0.01 * want)
            << LobeModelName(model) << " n " << exponent << " cos " << cos_view;
      }
      EXPECT_EQ(LobeDirectionalAlbedo(lobe, 0), 0);
      EXPECT_EQ(LobeDirectionalAlbedo(lobe, -0.3), 0);
    }
  }
}

TEST(SpecularLobe, PaperRhoIsEq15) {
  for (double z : {-7.0, -1.0, 0.0, 0.3, 2.0, 40.0}) {
    const double e = std::exp(-std::abs(z) / 2);
    EXPECT_NEAR(PaperRho(z), (1 - e) / (1 + e), 1e-14) << z;
  }
}

TEST(SpecularLobe, ValidateNamesTheBadValue) {
  SpecularLobe lobe;
  EXPECT_NO_THROW(lobe.Validate("roof"));
  lobe.n = 0.5;
  EXPECT_THROW(lobe.Validate("roof"), Error);
  lobe.n = 10;
  lobe.kappa = 3;
  EXPECT_THROW(lobe.Validate("roof"), Error);
  lobe.kappa = 1.05;
  lobe.n = 40;  // 1.05^40 = 7: brighter at grazing than kLobeMaxGrazingGain allows
  EXPECT_THROW(lobe.Validate("roof"), Error);
  lobe.kappa = 1;
  lobe.rho_s = Eigen::Vector3d::Constant(MaxLobeRho(40) * 1.01);  // more light than received
  EXPECT_THROW(lobe.Validate("roof"), Error);
  lobe.rho_s = Eigen::Vector3d::Constant(MaxLobeRho(40));
  EXPECT_NO_THROW(lobe.Validate("roof"));
  lobe.rho_s[1] = NAN;
  try {
    lobe.Validate("roof");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("roof"), std::string::npos);
  }
}

// Observations of a block's faces (four walls and a sloped roof) under suns and viewers spread
// over the sky, their residual after the diffuse fit being `truth`'s lobe plus noise of
// `noise` (relative to the diffuse radiance) and a fraction of gross outliers.
std::vector<LobeSample> Samples(const SpecularLobe& truth, double noise, double outliers, int count,
                                uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0, 1);
  std::normal_distribution<double> gauss(0, 1);
  const std::vector<Eigen::Vector3d> normals = {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(-1, 0, 0),
                                                Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, -1, 0),
                                                Eigen::Vector3d(0.5, 0, 0.866)};
  std::vector<LobeSample> out;
  while (static_cast<int>(out.size()) < count) {
    LobeSample s;
    s.normal = normals[out.size() % normals.size()];
    s.to_light = Unit(2 * M_PI * uni(rng), 0.15 + 1.1 * uni(rng));
    // Half the viewers near the mirror direction (a photo placed for the highlight), half
    // anywhere in front of the face.
    const Eigen::Vector3d mirror = 2 * s.to_light.dot(s.normal) * s.normal - s.to_light;
    Eigen::Vector3d v = Unit(2 * M_PI * uni(rng), -0.2 + 1.2 * uni(rng));
    if (uni(rng) < 0.5) v = (mirror + 0.25 * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)));
    s.to_viewer = v.normalized();
    if (s.to_light.dot(s.normal) < 0.05 || s.to_viewer.dot(s.normal) < 0.05) continue;
    s.irradiance = Eigen::Vector3d(800, 700, 600) * s.to_light.dot(s.normal);
    const Eigen::Vector3d diffuse = 0.3 / M_PI * s.irradiance;
    s.sigma = noise * diffuse;
    s.residual = truth.Eval(s.normal, s.to_light, s.to_viewer).cwiseProduct(s.irradiance);
    for (int c = 0; c < 3; ++c) s.residual[c] += s.sigma[c] * gauss(rng);
    if (uni(rng) < outliers) s.residual *= 0, s.residual += diffuse * (uni(rng) - 0.5);
    out.push_back(s);
  }
  return out;
}

TEST(SunLobe, RecoversAKnownLobeDespiteOutliers) {
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d(0.030, 0.025, 0.020);  // peak 1/10 of the diffuse 0.3/pi
  truth.kappa = 1.03;                                  // kappa^n 3.3: within kLobeMaxGrazingGain
  truth.n = 40;
  const std::vector<LobeSample> samples = Samples(truth, 0.02, 0.1, 3000, 7);
  const LobeFit fit = FitSunLobe(samples, SunLobeOptions{});
  ASSERT_TRUE(fit.kept);
  EXPECT_LT(fit.cost, fit.cost_zero);
  // The truth costs no less than the fit: the search found the minimum it was looking for.
  EXPECT_LE(fit.cost, SunLobeCost(samples, truth) + 1e-6);
  EXPECT_NEAR(fit.cost, SunLobeCost(samples, fit.lobe), 1e-6 * fit.cost);
  // 2% noise on ~1500 samples near the peak: parameters within a few percent.
  EXPECT_NEAR(fit.lobe.kappa, truth.kappa, 0.02);
  EXPECT_NEAR(std::log(fit.lobe.n), std::log(truth.n), 0.1);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(fit.lobe.rho_s[c], truth.rho_s[c], 0.1 * truth.rho_s[c]);
}

// Both models are fitted and the one of lower cost kept: eq. 13's lobe for eq. 13's data,
// the microfacet lobe, alpha and rho_s within a few percent, for a microfacet material.
TEST(SunLobe, TheModelOfLowerCostIsKept) {
  SunLobeOptions both;
  both.model = std::nullopt;  // "auto"
  SpecularLobe lafortune;
  lafortune.rho_s = Eigen::Vector3d(0.030, 0.025, 0.020);
  lafortune.n = 40;
  const LobeFit a = FitSunLobe(Samples(lafortune, 0.02, 0.1, 3000, 7), both);
  ASSERT_TRUE(a.kept);
  EXPECT_EQ(a.lobe.model, LobeModel::kLafortune);

  SpecularLobe microfacet;
  microfacet.model = LobeModel::kMicrofacet;
  microfacet.rho_s = Eigen::Vector3d(0.030, 0.025, 0.020);
  microfacet.n = 120;
  const std::vector<LobeSample> samples = Samples(microfacet, 0.02, 0.1, 3000, 8);
  const LobeFit b = FitSunLobe(samples, both);
  ASSERT_TRUE(b.kept);
  EXPECT_EQ(b.lobe.model, LobeModel::kMicrofacet);
  EXPECT_EQ(b.lobe.kappa, 1.0);
  EXPECT_LE(b.cost, SunLobeCost(samples, microfacet) + 1e-6);
  EXPECT_NEAR(std::sqrt(2 / (b.lobe.n + 2)), std::sqrt(2 / (microfacet.n + 2)),
              0.05 * std::sqrt(2 / (microfacet.n + 2)));
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(b.lobe.rho_s[c], microfacet.rho_s[c], 0.1 * microfacet.rho_s[c]);
  // Asked for eq. 13's lobe on the same data, the fit is worse.
  SunLobeOptions only;
  only.model = LobeModel::kLafortune;
  EXPECT_GT(FitSunLobe(samples, only).cost, b.cost);
}

TEST(SunLobe, MatteBlockGetsNoLobe) {
  const std::vector<LobeSample> samples = Samples(SpecularLobe{}, 0.02, 0.05, 3000, 11);
  const LobeFit fit = FitSunLobe(samples, SunLobeOptions{});
  EXPECT_FALSE(fit.kept);
  EXPECT_TRUE(fit.lobe.IsZero());
  // What noise alone lets the search gain stays below the threshold.
  EXPECT_LT(fit.cost_zero - fit.cost, SunLobeOptions{}.min_gain * fit.cost_zero);
}

// A few samples far from the lobe's peak could be fitted by a huge rho_s: the fit stays within
// the physical bounds whatever the data.
TEST(SunLobe, StaysWithinPhysicalBounds) {
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d::Constant(0.05);
  truth.n = 20;
  std::vector<LobeSample> samples = Samples(truth, 0.02, 0, 2000, 5);
  // Highlights a hundred times brighter than any lobe could reflect.
  for (size_t i = 0; i < samples.size(); i += 7) samples[i].residual *= 100;
  const LobeFit fit = FitSunLobe(samples, SunLobeOptions{});
  ASSERT_TRUE(fit.kept);
  EXPECT_NO_THROW(fit.lobe.Validate("fit"));
}

TEST(SunLobe, TooFewOrUnusableSamplesGiveNoLobe) {
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d::Constant(0.05);
  truth.n = 20;
  std::vector<LobeSample> samples = Samples(truth, 0.01, 0, 50, 3);
  EXPECT_FALSE(FitSunLobe(samples, SunLobeOptions{}).kept);
  samples = Samples(truth, 0.01, 0, 400, 3);
  for (size_t i = 0; i < samples.size(); i += 2) samples[i].residual[0] = NAN;
  for (size_t i = 1; i < samples.size(); i += 4) samples[i].sigma[2] = 0;
  const LobeFit fit = FitSunLobe(samples, SunLobeOptions{});
  EXPECT_EQ(fit.samples, 100);  // every other dropped, then every fourth of the rest
  EXPECT_TRUE(std::isfinite(fit.cost));
  EXPECT_TRUE(fit.lobe.rho_s.allFinite());
}

TEST(SunLobe, OptionsAreChecked) {
  SunLobeOptions o;
  o.min_samples = 0;
  EXPECT_THROW(FitSunLobe({}, o), Error);
  o = {};
  o.exponent_steps = 1;
  EXPECT_THROW(FitSunLobe({}, o), Error);
  o = {};
  o.min_gain = -1;
  EXPECT_THROW(FitSunLobe({}, o), Error);
  o.min_gain = 1.5;
  EXPECT_THROW(FitSunLobe({}, o), Error);
}

// A sky of `pieces` directions over the upper hemisphere (brighter towards the horizon and
// one side) seen by points of a box's walls and roof, and observations whose residual is
// `truth`'s reflection of it (eq. 14's inner sum) plus noise of `noise` x that reflection's
// typical size.
std::vector<SkyLobeSample> SkySamples(const SpecularLobe& truth, double noise, int count,
                                      uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0, 1);
  std::normal_distribution<double> gauss(0, 1);
  const std::vector<Eigen::Vector3d> normals = {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, -1, 0),
                                                Eigen::Vector3d(-0.6, 0, 0.8),
                                                Eigen::Vector3d(0, 0, 1)};
  std::vector<SkyLobeSample> out;
  while (static_cast<int>(out.size()) < count) {
    SkyLobeSample s;
    s.normal = normals[out.size() % normals.size()];
    s.to_viewer = Unit(2 * M_PI * uni(rng), -0.3 + 1.5 * uni(rng));
    if (s.to_viewer.dot(s.normal) < 0.1) continue;
    for (int k = 0; k < 64; ++k) {
      const Eigen::Vector3d u = Unit(2 * M_PI * (k + uni(rng)) / 64, std::asin(uni(rng)));
      LightPiece p;
      p.to_light = u.cast<float>();
      const double radiance = 1 + 2 * std::pow(1 - u.z(), 3) + 0.5 * u.x();
      p.irradiance = (Eigen::Vector3d(0.6, 0.8, 1.0) * radiance * std::max(0.0, u.dot(s.normal)) *
                      (2 * M_PI / 64))
                         .cast<float>();
      s.pieces.push_back(p);
    }
    Eigen::Vector3d refl = Eigen::Vector3d::Zero();
    for (const LightPiece& p : s.pieces)
      refl += truth.Eval(s.normal, p.to_light.cast<double>(), s.to_viewer)
                  .cwiseProduct(p.irradiance.cast<double>());
    s.sigma = Eigen::Vector3d(0.01, 0.01, 0.01);
    for (int c = 0; c < 3; ++c) s.residual[c] = refl[c] + noise * gauss(rng);
    out.push_back(s);
  }
  return out;
}

// The automatic derivatives of eq. 14's terms against central differences of the same terms.
TEST(SkyLobe, JacobiansMatchFiniteDifferences) {
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d(0.05, 0.04, 0.03);
  truth.n = 15;
  const std::vector<SkyLobeSample> samples = SkySamples(truth, 0.001, 5, 3);
  for (size_t i = 0; i < 2 * samples.size(); ++i) {
    const SkyLobeSample& s = samples[i % samples.size()];
    const LobeModel model = i < samples.size() ? LobeModel::kLafortune : LobeModel::kMicrofacet;
    std::unique_ptr<ceres::CostFunction> cost(SkyLobeCost(s, model));
    ASSERT_EQ(cost->num_residuals(), 3);
    double rho[3] = {0.03, 0.05, 0.02}, shape[2] = {0.9, std::log(12.0)};
    const double* params[2] = {rho, shape};
    double r[3], j_rho[9], j_shape[6];
    double* jac[2] = {j_rho, j_shape};
    ASSERT_TRUE(cost->Evaluate(params, r, jac));
    auto residual = [&](double* block, int k, double h) {
      const double keep = block[k];
      block[k] = keep + h;
      double plus[3], minus[3];
      cost->Evaluate(params, plus, nullptr);
      block[k] = keep - h;
      cost->Evaluate(params, minus, nullptr);
      block[k] = keep;
      return Eigen::Vector3d((plus[0] - minus[0]) / (2 * h), (plus[1] - minus[1]) / (2 * h),
                             (plus[2] - minus[2]) / (2 * h));
    };
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d fd = residual(rho, k, 1e-6);
      for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(j_rho[i * 3 + k], fd[i], 1e-6 * (1 + std::abs(fd[i])));
    }
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector3d fd = residual(shape, k, 1e-6);
      for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(j_shape[i * 2 + k], fd[i], 1e-5 * (1 + std::abs(fd[i])));
    }
  }
}

TEST(SkyLobe, RecoversAKnownLobeFromTheExtendedSky) {
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d(0.06, 0.05, 0.04);
  truth.kappa = 1;
  truth.n = 25;
  // Noise 0.3 sigma (sigma 0.01) against reflections of 0.02-0.07: the fitted cost is about
  // 0.09 per term, far below the lobe's own signal.
  const double noise = 0.003;
  const std::vector<SkyLobeSample> samples = SkySamples(truth, noise, 800, 9);
  SkyLobeOptions options;
  options.source = SkyLobeOptions::Source::kFit;
  options.max_samples = 800;  // all of them
  const LobeFit fit = FitSkyLobe(samples, options);
  EXPECT_EQ(fit.samples, 800);
  ASSERT_TRUE(fit.kept);
  EXPECT_LT(fit.cost, 1.5 * 3 * samples.size() * (noise / 0.01) * (noise / 0.01));
  EXPECT_LE(fit.cost, SkyLobeCost(samples, truth) * 1.001);
  // An extended source constrains the lobe's reflected light, rho_s 2 pi / (n + 2) at normal
  // incidence, better than rho_s and n apart (they trade off): that within 5%, n within 15%.
  EXPECT_NEAR(std::log(fit.lobe.n), std::log(truth.n), 0.15);
  EXPECT_NEAR(fit.lobe.kappa, 1.0, 0.05);
  for (int c = 0; c < 3; ++c) {
    const double got = fit.lobe.rho_s[c] / (fit.lobe.n + 2), want = truth.rho_s[c] / (truth.n + 2);
    EXPECT_NEAR(got, want, 0.05 * want) << c;
  }
}

TEST(SkyLobe, MatteOrTooFewSamplesGiveNoLobe) {
  SkyLobeOptions fitted;
  fitted.source = SkyLobeOptions::Source::kFit;
  const std::vector<SkyLobeSample> matte = SkySamples(SpecularLobe{}, 0.01, 400, 4);
  const LobeFit fit = FitSkyLobe(matte, fitted);
  EXPECT_FALSE(fit.kept);
  EXPECT_TRUE(fit.lobe.IsZero());
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d::Constant(0.05);
  truth.n = 10;
  EXPECT_FALSE(FitSkyLobe(SkySamples(truth, 0.01, 50, 4), fitted).kept);
  SkyLobeOptions bad;
  bad.max_iterations = 0;
  EXPECT_THROW(FitSkyLobe(matte, bad), Error);
}

// The default: the sky lobe is the block's sun lobe (one material), kept while the sky's
// reflection in the photographs agrees with it and dropped when it contradicts it.
TEST(SkyLobe, TheSunLobeIsKeptUnlessTheSkyContradictsIt) {
  SpecularLobe truth;
  truth.model = LobeModel::kMicrofacet;
  truth.rho_s = Eigen::Vector3d(0.2, 0.2, 0.2);
  truth.n = 60;
  const std::vector<SkyLobeSample> samples = SkySamples(truth, 0.003, 400, 6);
  const LobeFit same = FitSkyLobe(samples, SkyLobeOptions{}, truth);
  ASSERT_TRUE(same.kept);
  EXPECT_EQ(same.lobe.model, LobeModel::kMicrofacet);
  EXPECT_EQ(same.lobe.rho_s, truth.rho_s);
  EXPECT_EQ(same.lobe.n, truth.n);
  EXPECT_LT(same.cost, 0.01 * same.cost_zero);
  // A sharp, strong sun lobe fitted to a few bright pixels reflects a sky the photographs do
  // not show.
  SpecularLobe spike = truth;
  spike.n = 1900;
  spike.rho_s = Eigen::Vector3d::Constant(20);
  const LobeFit refuted = FitSkyLobe(samples, SkyLobeOptions{}, spike);
  EXPECT_FALSE(refuted.kept);
  EXPECT_TRUE(refuted.lobe.IsZero());
  EXPECT_GT(refuted.cost, refuted.cost_zero);
  // Too few samples to judge: the sun lobe stands.
  EXPECT_TRUE(FitSkyLobe(SkySamples(truth, 0.003, 20, 6), SkyLobeOptions{}, spike).kept);

  // Diffuse albedos solved without a sky lobe hold its mean reflection: the residual is the
  // reflection less a share of the diffuse light. Eq. 14's cost alone then counts that share
  // twice and stays far above the noise even for the true lobe; with the share fitted back
  // it falls to the noise.
  std::vector<SkyLobeSample> absorbed = samples;
  double reflected = 0, diffuse = 0;
  for (SkyLobeSample& s : absorbed) {
    Eigen::Vector3d sky = Eigen::Vector3d::Zero();
    for (const LightPiece& p : s.pieces) sky += p.irradiance.cast<double>();
    s.diffuse_se = 0.3 / M_PI * sky;
    reflected += s.residual.sum();
    diffuse += s.diffuse_se.sum();
  }
  for (SkyLobeSample& s : absorbed) s.residual -= (reflected / diffuse) * s.diffuse_se;
  EXPECT_GT(SkyLobeCost(absorbed, truth), 10 * SkyLobeCostRefittingDiffuse(absorbed, truth));
  EXPECT_LT(SkyLobeCostRefittingDiffuse(absorbed, truth),
            0.05 * SkyLobeCostRefittingDiffuse(absorbed, SpecularLobe{}));
  EXPECT_TRUE(FitSkyLobe(absorbed, SkyLobeOptions{}, truth).kept);
}

}  // namespace
}  // namespace rouen
