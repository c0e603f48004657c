// Specular lobes of the pseudo-BRDFs (Yu & Malik 1998, §4.2): eq. 13's lobe, one per block,
// isotropic (Cx = Cy), in the local frame of each surface (z its outward normal):
//   f_s(u, v) = rho_s [Cxy (u_x v_x + u_y v_y) + Cz u_z v_z]^n,
// u the unit direction to the light, v to the viewer. Cz = 1 fixes the bracket's scale (rho_s
// absorbs it), so a lobe is rho_s per channel, kappa = -Cxy and n: kappa 1 is a lobe around the
// mirror direction; above 1 it leans towards grazing (the off-specular peaks eq. 13 was chosen
// for). The radiance it adds under a light of irradiance E on the surface is f_s(u, v) E.
//
// Beside it, a microfacet lobe (LobeModel::kMicrofacet; not in the paper): Walter et al.'s GGX
// distribution with Smith's shadowing and Schlick's Fresnel for a dielectric (F0 = 0.04),
//   f_s(u, v) = rho_s 4 pi alpha^2 D(h) G(u) G(v) F(v.h) / (4 (u.n) (v.n) F0),
// scaled to rho_s at normal incidence, with alpha^2 = 2 / (n + 2) (the Phong exponent of the
// same width). A glossy roof seen near grazing reflects the sun tens of times more than at
// normal incidence (Fresnel and the 1 / (u.n)(v.n) of a microfacet lobe); eq. 13 cannot.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace ceres {
class CostFunction;
}

namespace rouen {

// The ranges the fit searches.
constexpr double kLobeKappaMin = 0.5, kLobeKappaMax = 1.5;
constexpr double kLobeExponentMin = 1, kLobeExponentMax = 2000;

// Physical bounds on a lobe: it reflects no more than the light it receives (rho_s at most
// MaxLobeRho), and eq. 13's lobe rises towards grazing at most this factor over its peak at
// normal incidence (kappa^n, when kappa > 1).
constexpr double kLobeMaxGrazingGain = 4;

enum class LobeModel { kLafortune, kMicrofacet };
// "lafortune" / "microfacet"; ParseLobeModel throws rouen::Error naming `what`.
const char* LobeModelName(LobeModel model);
LobeModel ParseLobeModel(const std::string& name, const std::string& what);

// The energy bound on rho_s for a lobe of exponent n: (n + 2) / 2 pi (eq. 13's bracket at
// kappa 1 is a normalised cosine lobe), (n + 2) / 8 pi for the microfacet lobe (its integral
// against the cosine is 4 pi alpha^2 at normal incidence).
double MaxLobeRho(double n, LobeModel model = LobeModel::kLafortune);

// The lobe's shape (f_s / rho_s) from u.n, v.n and u.v, for doubles and Ceres' Jets alike.
template <typename T>
T LobeShape(LobeModel model, const T& kappa, const T& n, double un, double vn, double uv) {
  using std::pow;
  using std::sqrt;
  if (!(un > 0) || !(vn > 0)) return T(0);
  if (model == LobeModel::kLafortune) {
    // Cxy (u_x v_x + u_y v_y) + Cz u_z v_z with Cxy = -kappa, Cz = 1 (eq. 13).
    const T bracket = -kappa * (uv - un * vn) + un * vn;
    return bracket > T(0) ? T(pow(bracket, n)) : T(0);
  }
  const double len = std::sqrt(std::max(2 + 2 * uv, 1e-12));
  const double nh = (un + vn) / len, vh = (1 + uv) / len;
  if (!(nh > 0)) return T(0);
  const T a2 = T(2) / (n + T(2));
  const T t = nh * nh * (a2 - T(1)) + T(1);
  auto g1 = [&](double c) { return T(2 * c) / (T(c) + sqrt(a2 + (T(1) - a2) * (c * c))); };
  constexpr double kF0 = 0.04;  // a dielectric's reflectance at normal incidence
  const double fresnel = 1 + (1 - kF0) / kF0 * std::pow(std::max(0.0, 1 - vh), 5);
  // rho_s 4 pi a2 D G G F / (4 un vn F0), D = a2 / (pi t^2): the a2 and pi cancel.
  return a2 * a2 / (t * t) * g1(un) * g1(vn) * (fresnel / (un * vn));
}

struct SpecularLobe {
  Eigen::Vector3d rho_s = Eigen::Vector3d::Zero();  // per channel (1/sr at the lobe's peak)
  double kappa = 1;                                 // -Cxy (1 for the microfacet lobe)
  double n = 1;                                     // exponent
  LobeModel model = LobeModel::kLafortune;

  bool IsZero() const { return !(rho_s.maxCoeff() > 0); }
  // f_s / rho_s: eq. 13's bracket raised to n, or the microfacet lobe's shape (0 when u or v
  // is below the surface).
  double Shape(const Eigen::Vector3d& normal, const Eigen::Vector3d& u,
               const Eigen::Vector3d& v) const;
  // The exponent e of a lobe cos^e about the mirror direction of about this lobe's width: the
  // density its extended light is sampled with (n for eq. 13; a microfacet lobe's mirror lobe
  // is twice as wide as its half-vector lobe, e = (n + 2) / 4 at its core, and GGX's tails
  // and its stretch towards grazing ask for wider: e = (n + 2) / 8, which spreads a 16-draw
  // estimate a third less than / 4 in specular_test).
  double MirrorExponent() const;
  // f_s(u, v) per channel.
  Eigen::Vector3d Eval(const Eigen::Vector3d& normal, const Eigen::Vector3d& u,
                       const Eigen::Vector3d& v) const {
    return rho_s * Shape(normal, u, v);
  }
  // Throws rouen::Error naming `what` when a value is out of its range or not finite.
  void Validate(const std::string& what) const;
  // "rho_s R/G/B, kappa K, n N", or "microfacet rho_s R/G/B, alpha A" (for logs and reports).
  std::string Text() const;
};

// lobes[block], or no lobe for a block without an entry or -1 (no block).
inline SpecularLobe BlockLobe(const std::vector<SpecularLobe>& lobes, int block) {
  return block >= 0 && block < static_cast<int>(lobes.size()) ? lobes[block] : SpecularLobe{};
}

// Eq. 15's robust rho(z) = (1 - e^{-|z|/2}) / (1 + e^{-|z|/2}), which is tanh(|z| / 4).
double PaperRho(double z);

// One observation of a block under the sun, for the fit of its sun lobe (§4.2.2).
struct LobeSample {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d to_light = Eigen::Vector3d::UnitZ();   // unit, to the sun
  Eigen::Vector3d to_viewer = Eigen::Vector3d::UnitZ();  // unit, to the camera
  Eigen::Vector3d irradiance = Eigen::Vector3d::Zero();  // the sun's on the surface, shadows in
  Eigen::Vector3d residual = Eigen::Vector3d::Zero();    // I minus the diffuse model's I
  Eigen::Vector3d sigma = Eigen::Vector3d::Ones();       // residual's uncertainty, > 0
};

struct SunLobeOptions {
  bool fit = true;  // false: no block gets a lobe (the paper's matte pseudo-BRDF)
  // Eq. 13's lobe, the microfacet lobe, or (none: "auto", the default) both fitted and the one
  // of lower cost kept per block (a copper roof's Phong-like lobe, a slate roof's Fresnel
  // glint). A block's sky lobe takes its sun lobe's model. On the nave world's slate roof the
  // microfacet lobe explains the glint photographed at 09:00 (18 -> 52 dB) and the evening
  // (south-east view 32.3 -> 32.8 dB); the worlds without a glossy block are unchanged.
  std::optional<LobeModel> model;
  // A block's lobe is fitted from at least this many sunlit observations; else none.
  int min_samples = 100;
  // At most this many samples per block enter the fit (an even subsample beyond).
  int max_samples = 4000;
  // The lobe is kept only when it lowers eq. 15's cost (summed over samples and channels,
  // each term at most 1) by at least this fraction: below it the lobe explains noise or
  // what the diffuse model leaves, not a highlight.
  double min_gain = 0.1;
  // The global search: a grid of kappa x log(n), then downhill simplex from its best point.
  int kappa_steps = 5;
  int exponent_steps = 16;
  int simplex_iterations = 100;
  void Validate() const;  // throws rouen::Error
};

struct LobeFit {
  SpecularLobe lobe;     // zero unless kept
  int samples = 0;       // used in the fit
  double cost_zero = 0;  // eq. 15 with no lobe
  double cost = 0;       // eq. 15 with the fitted lobe (before the min_gain test)
  bool kept = false;
};

// §4.2.2: the sun lobe of one block minimising eq. 15 with the paper's rho(z) over
// z = (residual - f_s E) / sigma, within the physical bounds above. Global search: for every
// (kappa, n) of a grid, each channel's rho_s >= 0 is the exact minimiser of its 1-D cost (rho(z) is
// concave in |z|, so the minimum lies at a sample's own zero or at 0); then downhill simplex over
// (kappa, log n).
// `admissible`, when given, bounds the search to lobes it accepts (e.g. ones whose reflection
// of the sky the photographs do not contradict); a candidate it refuses costs infinity.
LobeFit FitSunLobe(const std::vector<LobeSample>& samples, const SunLobeOptions& options,
                   const std::function<bool(const SpecularLobe&)>& admissible = {});

// Eq. 15's cost of `lobe` on `samples` (what FitSunLobe minimises).
double SunLobeCost(const std::vector<LobeSample>& samples, const SpecularLobe& lobe);

// §4.2.1: the sky and the environment are extended sources, split into pieces: each piece's
// direction and the irradiance it brings onto the surface (per channel).
struct LightPiece {
  Eigen::Vector3f to_light = Eigen::Vector3f::UnitZ();
  Eigen::Vector3f irradiance = Eigen::Vector3f::Zero();
};

// Directions for integrating a lobe against extended light (§4.2.1's sky and environment):
// DrawAboutAxis maps (u1, u2) in [0, 1)^2 to a direction with the density
// (e + 1) / 2 pi cos^e of its angle to `axis` (e = 1 about the normal: cosine-distributed).
// Of K_c directions cosine-distributed about the normal n and K_m drawn about the mirror
// direction m with exponent e (the lobe's MirrorExponent), the light L(u) arriving along each,
// weighed by MixtureWeight, sums to an estimate of the integral of L cos over the hemisphere
// without bias whatever multiplies L (Veach's balance heuristic): a broad lobe is served by
// the cosine directions, a narrow one by the mirror's.
Eigen::Vector3d DrawAboutAxis(const Eigen::Vector3d& axis, double exponent, double u1, double u2);
double MixtureWeight(const Eigen::Vector3d& n, const Eigen::Vector3d& m, const Eigen::Vector3d& u,
                     double exponent, int cosine_count, int mirror_count);

// The lobe's directional albedo towards a viewer at `cos_view` from the normal: the integral of
// Shape(n, u, v) cos over the hemisphere, what rho_s scales into the light it reflects of a
// uniform unit sky. A quadrature of that mixture (`strata` x `strata` midpoints about the
// mirror and as many cosine-distributed), no ray cast; 0 at or below grazing.
double LobeDirectionalAlbedo(const SpecularLobe& lobe, double cos_view, int strata = 96);

// One observation of a block for the fit of its sky/environment lobe.
struct SkyLobeSample {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d to_viewer = Eigen::Vector3d::UnitZ();
  std::vector<LightPiece> pieces;                      // the point's sky and environment
  Eigen::Vector3d residual = Eigen::Vector3d::Zero();  // I less the diffuse and sun-lobe model
  Eigen::Vector3d sigma = Eigen::Vector3d::Ones();     // > 0
  // The diffuse model's sky and environment radiance in I (rho_se E_se / pi): fitted without a
  // sky lobe, it holds the lobe's mean reflection (see SkyLobeCostRefittingDiffuse).
  Eigen::Vector3d diffuse_se = Eigen::Vector3d::Zero();
};

struct SkyLobeOptions {
  bool fit = true;  // false: no block gets a sky/environment lobe
  // The sky lobe is the block's sun lobe itself (kSun: one material reflects the sun and the
  // sky alike, as it does in the world and in an RGB renderer), or §4.2.1's own fit of eq. 14
  // (kFit: the paper's pseudo-BRDF, free to differ from the sun's).
  enum class Source { kSun, kFit };
  Source source = Source::kSun;
  int min_samples = 100;
  int max_samples = 400;  // an even subsample beyond (each carries all its pieces)
  // Directions drawn about each observation's mirror direction beside the hemisphere cache's
  // (see MixtureWeight): the pieces a narrow lobe reflects.
  int mirror_samples = 64;
  // Kept only when it lowers eq. 14's cost by at least this fraction.
  double min_gain = 0.1;
  int max_iterations = 50;  // Levenberg-Marquardt iterations per start
  void Validate() const;    // throws rouen::Error
};

// Eq. 14's terms for one sample, (sum_j e_j f_s(u_j, v) - I) / sigma per channel, as a Ceres
// cost of the parameters rho_s (3) and (kappa, log n) (2) of a lobe of `model`, with automatic
// derivatives. Owned by the caller (or a ceres::Problem).
ceres::CostFunction* SkyLobeCost(const SkyLobeSample& sample,
                                 LobeModel model = LobeModel::kLafortune);

// The samples reduced once (each piece's u.n, u.v and irradiance over sigma) for the costs
// of many lobes: Cost is eq. 14, CostRefittingDiffuse is SkyLobeCostRefittingDiffuse.
class SkyLobeCosts {
 public:
  explicit SkyLobeCosts(const std::vector<SkyLobeSample>& samples);
  ~SkyLobeCosts();
  double Cost(const SpecularLobe& lobe) const;
  double CostRefittingDiffuse(const SpecularLobe& lobe) const;

 private:
  struct Terms;
  std::unique_ptr<Terms> terms_;
};

// Eq. 14: sum over samples and channels of the squared terms.
double SkyLobeCost(const std::vector<SkyLobeSample>& samples, const SpecularLobe& lobe);
// Eq. 14 with each channel's diffuse sky and environment light rescaled by the factor that
// fits best (linear least squares): the cost the lobe leaves once the diffuse albedos give
// back the mean reflection they absorbed. SkyLobeOptions::Source::kSun judges a sun lobe by it.
double SkyLobeCostRefittingDiffuse(const std::vector<SkyLobeSample>& samples,
                                   const SpecularLobe& lobe);

// §4.2.1: a block's sky/environment lobe by Levenberg-Marquardt over eq. 14 from three starts
// (`start`'s kappa and n, e.g. the block's sun lobe; n 5 and n 80), kappa within
// [kLobeKappaMin, 1] (held at 1 for the microfacet lobe) and rho_s within the energy bound;
// the lobe has `start`'s model. With options.source kSun the lobe is `start` itself, kept
// unless it raises SkyLobeCostRefittingDiffuse on min_samples or more samples (the photographs
// contradict it).
LobeFit FitSkyLobe(const std::vector<SkyLobeSample>& samples, const SkyLobeOptions& options,
                   const SpecularLobe& start = {Eigen::Vector3d::Zero(), 1, 20});

}  // namespace rouen
