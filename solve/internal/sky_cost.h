// Internal to solve/: the eq. 10 cost of the seven-parameter sky model with analytic
// derivatives (used by sky_fit.cc; exposed here for the gradient-check test only).
#pragma once

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace rouen::internal {

// Parameter block order.
enum SkyParamIndex { kLz = 0, kA, kB, kC, kD, kE, kH, kNumSkyParams };

// One sample, with the geometry precomputed.
struct SkyPoint {
  double inv_cos_xi;  // 1 / max(cos xi, 0.01)
  double log_gamma;   // ln max(gamma, 1e-6), gamma in radians
  double cos2_gamma;  // cos^2 gamma
  double y;           // normalised radiance (>= 2)
  double s;           // 1 / sigma = log(y) / y (eq. 10), or 1 / y (relative weighting)
  double w;           // the sample's weight in the objective (its solid angle, normalised)
};

// `relative`: sigma = y (plain relative residuals) instead of eq. 10's y / log y; `weight`
// multiplies the sample's term of the objective.
inline SkyPoint MakeSkyPoint(const Eigen::Vector3d& dir, const Eigen::Vector3d& sun, double y,
                             bool relative = false, double weight = 1) {
  const double cos_xi = std::max(dir.z(), 0.01);
  const double cos_g = std::clamp(dir.dot(sun), -1.0, 1.0);
  const double gamma = std::max(std::acos(cos_g), 1e-6);
  return {1.0 / cos_xi, std::log(gamma), cos_g * cos_g, y, relative ? 1.0 / y : std::log(y) / y,
          weight};
}

// Eq. 9 at a precomputed point with its analytic gradient (the fit's speed); the same values as
// solve/sky_model.h's factors, which sky_fit_test checks.
inline double SkyModelAt(const double* p, const SkyPoint& q, double* grad) {
  const double e1 = std::exp(p[kB] * q.inv_cos_xi);
  const double g = 1 + p[kA] * e1;
  const double gh = std::exp(p[kH] * q.log_gamma);  // gamma^h
  const double e2 = std::exp(p[kD] * gh);
  const double f = 1 + p[kC] * e2 + p[kE] * q.cos2_gamma;
  if (grad) {
    grad[kLz] = g * f;
    grad[kA] = p[kLz] * e1 * f;
    grad[kB] = p[kLz] * p[kA] * e1 * q.inv_cos_xi * f;
    grad[kC] = p[kLz] * g * e2;
    grad[kD] = p[kLz] * g * p[kC] * e2 * gh;
    grad[kE] = p[kLz] * g * q.cos2_gamma;
    grad[kH] = p[kLz] * g * p[kC] * e2 * p[kD] * gh * q.log_gamma;
  }
  return p[kLz] * g * f;
}

// The p-norm of SkyFitOptions::norm_p as a transform of one residual: t(r) = sign(r) sqrt(rho(r)),
// rho(r) = (r^2 + eps^2)^(p/2) - eps^p (a smoothed |r|^p, eps = `norm_eps`), so that half the sum
// of t^2 is half sum rho(r_i); p = 2 is the identity (eq. 10's least squares).
class SkyNormTransform {
 public:
  explicit SkyNormTransform(double norm_p = 2, double norm_eps = 1e-3)
      : half_p_(0.5 * norm_p),
        eps_(norm_eps),
        eps2_(norm_eps * norm_eps),
        eps_p_(std::pow(norm_eps, norm_p)) {}

  bool identity() const { return half_p_ == 1; }

  // t(r) and dt/dr.
  void Transform(double r, double* t, double* dt) const {
    if (half_p_ == 1) {
      *t = r;
      *dt = 1;
      return;
    }
    if (half_p_ == 0.5) {
      // p = 1 (the default) without pow: with root = sqrt(r^2 + eps^2), rho = root - eps =
      // r^2 / (root + eps), so t = r / sqrt(root + eps) and dt/dr = sqrt(root + eps) / (2 root).
      const double root = std::sqrt(r * r + eps2_);
      const double s = std::sqrt(root + eps_);
      *t = r / s;
      *dt = s / (2 * root);
      return;
    }
    const double u = r * r / eps2_;
    // rho = eps^p ((1 + u)^(p/2) - 1), written to keep precision at small u.
    const double rho = eps_p_ * std::expm1(half_p_ * std::log1p(u));
    const double root = std::sqrt(rho);
    *t = r < 0 ? -root : root;
    // d rho / dr = p r (r^2 + eps^2)^(p/2 - 1); dt/dr = |d rho / dr| / (2 sqrt(rho)), with its
    // limit sqrt(p/2) eps^(p/2 - 1) at r = 0.
    const double a = std::pow(r * r + eps2_, half_p_ - 1);
    *dt = root > 0 ? half_p_ * std::abs(r) * a / root
                   : std::sqrt(half_p_) * std::pow(eps2_, 0.5 * (half_p_ - 1));
  }

 private:
  double half_p_, eps_, eps2_, eps_p_;
};

// Residual i = sqrt(w_i) (y_i - Ls_i) / sigma_i with sigma_i = y_i / log y_i (eq. 10) and w_i
// the sample's weight; one block of seven parameters {Lz, a, b, c, d, e, h}. With `fixed_h` (Perez
// et al. 1993's five-parameter form) the block has six parameters {Lz, a, b, c, d, e} and h = 1.
// With `norm_p` != 2 the residual is sqrt(w_i) times SkyNormTransform's t(r_i), so that half the
// sum of squares is half sum w_i rho(r_i). FitSky's Levenberg-Marquardt (sky_fit.cc) evaluates it;
// a ceres::CostFunction so that Ceres's gradient checker can test it.
class SkyCost : public ceres::CostFunction {
 public:
  explicit SkyCost(std::vector<SkyPoint> points, bool fixed_h = false, double norm_p = 2,
                   double norm_eps = 1e-3)
      : points_(std::move(points)),
        n_(fixed_h ? kNumSkyParams - 1 : kNumSkyParams),
        norm_(norm_p, norm_eps) {
    set_num_residuals(static_cast<int>(points_.size()));
    mutable_parameter_block_sizes()->push_back(n_);
  }

  void Transform(double r, double* t, double* dt) const { norm_.Transform(r, t, dt); }
  const std::vector<SkyPoint>& points() const { return points_; }
  int num_params() const { return n_; }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    double p[kNumSkyParams] = {0, 0, 0, 0, 0, 0, 1};
    std::copy(parameters[0], parameters[0] + n_, p);
    double* jac = jacobians ? jacobians[0] : nullptr;
    double grad[kNumSkyParams];
    for (size_t i = 0; i < points_.size(); ++i) {
      const SkyPoint& q = points_[i];
      const double l = SkyModelAt(p, q, jac ? grad : nullptr);
      double dr = 1;  // d residual / d r
      norm_.Transform(q.s * (q.y - l), &residuals[i], &dr);
      const double sw = std::sqrt(q.w);
      residuals[i] *= sw;
      if (!std::isfinite(residuals[i])) return false;
      if (jac) {
        for (int k = 0; k < n_; ++k) jac[i * n_ + k] = -sw * dr * q.s * grad[k];
      }
    }
    return true;
  }

  // The normal equations of Levenberg-Marquardt in one pass, without storing the Jacobian J
  // (rows j_i = d t_i / d params, t_i the residual before its weight): returns half the
  // weighted sum of squared residuals, half sum w_i t_i^2 (+inf where one is not finite), and
  // writes the Gauss-Newton matrix `h` = sum w_i a_i j_i j_i^T (num_params() squared,
  // row-major) and the gradient `g` = sum w_i t_i j_i (num_params()), a_i = 1. With `irls`
  // (this cost's own norm_p being 2), the residuals r_i are first transformed by it, t_i =
  // t(r_i), and a_i = t_i dt_i / r_i: the weights of iteratively reweighted least squares, so
  // that h is that of the weighted squares a_i r_i^2 / 2 which majorise half rho(r_i) for p < 2.
  double NormalEquations(const double* params, const SkyNormTransform* irls, double* h,
                         double* g) const {
    double p[kNumSkyParams] = {0, 0, 0, 0, 0, 0, 1};
    std::copy(params, params + n_, p);
    // Lower triangle of h and g over all seven parameters; h's column of a fixed h is dropped.
    double hl[kNumSkyParams * (kNumSkyParams + 1) / 2] = {};
    double gg[kNumSkyParams] = {};
    double sum = 0;
    for (const SkyPoint& q : points_) {
      double grad[kNumSkyParams];
      const double l = SkyModelAt(p, q, grad);
      const double r = q.s * (q.y - l);
      double t = 0, dt = 1, a = 1;
      if (irls) {
        irls->Transform(r, &t, &dt);
        a = r != 0 ? t * dt / r : dt * dt;
        dt = 1;  // the rows stay those of r
      } else {
        norm_.Transform(r, &t, &dt);
      }
      sum += q.w * t * t;
      double j[kNumSkyParams];
      for (int k = 0; k < kNumSkyParams; ++k) j[k] = -dt * q.s * grad[k];
      const double b = q.w * (irls ? a * r : t);  // g += b j
      for (int k = 0, m = 0; k < kNumSkyParams; ++k) {
        gg[k] += b * j[k];
        const double ajk = q.w * a * j[k];
        for (int c = 0; c <= k; ++c) hl[m++] += ajk * j[c];
      }
    }
    for (int k = 0, m = 0; k < kNumSkyParams; ++k) {
      for (int c = 0; c <= k; ++c, ++m) {
        if (k < n_) h[k * n_ + c] = h[c * n_ + k] = hl[m];
      }
      if (k < n_) g[k] = gg[k];
    }
    return std::isfinite(sum) ? 0.5 * sum : std::numeric_limits<double>::infinity();
  }

 private:
  std::vector<SkyPoint> points_;
  int n_;
  SkyNormTransform norm_;
};

}  // namespace rouen::internal
