// The paper's revised seven-parameter sky model, one parameter set per colour channel
// (Yu & Malik 1998, eq. 9):
//   Ls(xi, gamma) = Lz [1 + a exp(b / cos xi)] [1 + c exp(d gamma^h) + e cos^2 gamma]
// xi: zenith angle of the sky element, gamma: its angle to the sun, both radians.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <nlohmann/json_fwd.hpp>

namespace rouen {

struct SkyParams {
  double Lz = 1, a = 0, b = 0, c = 0, d = 0, e = 0, h = 1;
};

// Eq. 9's geometry as its two factors take it: cos(xi) is clamped to >= 0.01 so the horizon
// stays finite, gamma to >= 1e-6 so that gamma^h is defined.
inline double SkyInvCosXi(double xi) { return 1.0 / std::max(std::cos(xi), 0.01); }
inline double SkyLogGamma(double gamma) { return std::log(std::max(gamma, 1e-6)); }

// Eq. 9's two factors, the one formula of the model: every evaluation, and every residual the
// fits differentiate (T a Ceres Jet), goes through these.
//   gradation   Bg = 1 + a exp(b / cos xi)
//   scattering  Sa = 1 + c exp(d gamma^h) + e cos^2 gamma
template <typename T>
T SkyGradationFactor(const T& a, const T& b, double inv_cos_xi) {
  using std::exp;
  return T(1) + a * exp(b * inv_cos_xi);
}
template <typename T>
T SkyScatteringFactor(const T& c, const T& d, const T& e, const T& h, double log_gamma,
                      double cos2_gamma) {
  using std::exp;
  return T(1) + c * exp(d * exp(h * log_gamma)) + e * cos2_gamma;
}

// The factors for one channel's parameters, so that
// SkyRadiance(p, xi, gamma) == p.Lz * SkyBackground(p, xi) * SkyScattering(p, gamma).
double SkyBackground(const SkyParams& p, double xi);
double SkyScattering(const SkyParams& p, double gamma);
// Eq. 9 for one channel.
double SkyRadiance(const SkyParams& p, double xi, double gamma);

struct SkyModel {
  std::array<SkyParams, 3> channel;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();  // unit, ENU

  // Radiance towards a unit ENU direction (upper hemisphere; below it, the horizon value).
  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir) const;
};

void to_json(nlohmann::json& j, const SkyModel& m);
void from_json(const nlohmann::json& j, SkyModel& m);

}  // namespace rouen
