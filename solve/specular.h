// Specular lobes of the pseudo-BRDFs (Yu & Malik 1998, §4.2): eq. 13's lobe, one per block,
// isotropic (Cx = Cy), in the local frame of each surface (z its outward normal):
//   f_s(u, v) = rho_s [Cxy (u_x v_x + u_y v_y) + Cz u_z v_z]^n,
// u the unit direction to the light, v to the viewer. Cz = 1 fixes the bracket's scale (rho_s
// absorbs it), so a lobe is rho_s per channel, kappa = -Cxy and n: kappa 1 is a lobe around the
// mirror direction; above 1 it leans towards grazing (the off-specular peaks eq. 13 was chosen
// for). The radiance it adds under a light of irradiance E on the surface is f_s(u, v) E.
#pragma once

#include <Eigen/Core>
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
// (n + 2) / 2 pi, the peak of a normalised cosine lobe), and towards grazing it rises at most
// this factor over its peak at normal incidence (kappa^n, when kappa > 1).
constexpr double kLobeMaxGrazingGain = 4;
double MaxLobeRho(double n);

struct SpecularLobe {
  Eigen::Vector3d rho_s = Eigen::Vector3d::Zero();  // per channel (1/sr at the lobe's peak)
  double kappa = 1;                                 // -Cxy
  double n = 1;                                     // exponent

  bool IsZero() const { return !(rho_s.maxCoeff() > 0); }
  // The bracket of eq. 13 raised to n (0 when it is <= 0 or u or v is below the surface).
  double Shape(const Eigen::Vector3d& normal, const Eigen::Vector3d& u,
               const Eigen::Vector3d& v) const;
  // f_s(u, v) per channel.
  Eigen::Vector3d Eval(const Eigen::Vector3d& normal, const Eigen::Vector3d& u,
                       const Eigen::Vector3d& v) const {
    return rho_s * Shape(normal, u, v);
  }
  // Throws rouen::Error naming `what` when a value is out of its range or not finite.
  void Validate(const std::string& what) const;
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
LobeFit FitSunLobe(const std::vector<LobeSample>& samples, const SunLobeOptions& options);

// Eq. 15's cost of `lobe` on `samples` (what FitSunLobe minimises).
double SunLobeCost(const std::vector<LobeSample>& samples, const SpecularLobe& lobe);

// §4.2.1: the sky and the environment are extended sources, split into pieces: each piece's
// direction and the irradiance it brings onto the surface (per channel).
struct LightPiece {
  Eigen::Vector3f to_light = Eigen::Vector3f::UnitZ();
  Eigen::Vector3f irradiance = Eigen::Vector3f::Zero();
};

// One observation of a block for the fit of its sky/environment lobe.
struct SkyLobeSample {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d to_viewer = Eigen::Vector3d::UnitZ();
  std::vector<LightPiece> pieces;                      // the point's sky and environment
  Eigen::Vector3d residual = Eigen::Vector3d::Zero();  // I less the diffuse and sun-lobe model
  Eigen::Vector3d sigma = Eigen::Vector3d::Ones();     // > 0
};

struct SkyLobeOptions {
  bool fit = true;  // false: no block gets a sky/environment lobe
  int min_samples = 100;
  int max_samples = 400;  // an even subsample beyond (each carries all its pieces)
  // Kept only when it lowers eq. 14's cost by at least this fraction.
  double min_gain = 0.1;
  int max_iterations = 50;  // Levenberg-Marquardt iterations per start
  void Validate() const;    // throws rouen::Error
};

// Eq. 14's terms for one sample, (sum_j e_j f_s(u_j, v) - I) / sigma per channel, as a Ceres
// cost of the parameters rho_s (3) and (kappa, log n) (2), with automatic derivatives.
// Owned by the caller (or a ceres::Problem).
ceres::CostFunction* SkyLobeCost(const SkyLobeSample& sample);

// Eq. 14: sum over samples and channels of the squared terms.
double SkyLobeCost(const std::vector<SkyLobeSample>& samples, const SpecularLobe& lobe);

// §4.2.1: a block's sky/environment lobe by Levenberg-Marquardt over eq. 14 from three starts
// (`start`'s kappa and n, e.g. the block's sun lobe; n 5 and n 80), kappa within
// [kLobeKappaMin, 1] and rho_s within the energy bound.
LobeFit FitSkyLobe(const std::vector<SkyLobeSample>& samples, const SkyLobeOptions& options,
                   const SpecularLobe& start = {Eigen::Vector3d::Zero(), 1, 20});

}  // namespace rouen
