#include "solve/retro.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace rouen {

namespace {

// Schlick's fifth power, by multiplication (std::pow was most of the retro fit's time).
double Pow5(double x) {
  const double x2 = x * x;
  return x2 * x2 * x;
}

}  // namespace

double RetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& l,
                   const Eigen::Vector3d& v) {
  if (retro == 0) return 1;
  const double cl = std::clamp(n.dot(l), 0.0, 1.0), cv = std::clamp(n.dot(v), 0.0, 1.0);
  const Eigen::Vector3d h = l + v;
  const double hn = h.norm();
  // l == -v cannot happen with both above the surface; guard anyway.
  const double cd = hn > 0 ? l.dot(h) / hn : 0;
  const double f1 = retro * (2 * cd * cd - 0.5);
  const double sl = Pow5(1 - cl), sv = Pow5(1 - cv);
  return std::max(0.0, (1 + f1 * sl) * (1 + f1 * sv));
}

void LightMomentsSum::Add(const Eigen::Vector3d& dir, double w) {
  const double sd = Pow5(1 - std::clamp(n_.dot(dir), 0.0, 1.0));
  w_ += w;
  l_ += w * dir;
  s_ += w * sd;
  sl_ += (w * sd) * dir;
  const double ws = w * sd;
  sll_[0] += ws * dir.x() * dir.x();
  sll_[1] += ws * dir.x() * dir.y();
  sll_[2] += ws * dir.x() * dir.z();
  sll_[3] += ws * dir.y() * dir.y();
  sll_[4] += ws * dir.y() * dir.z();
  sll_[5] += ws * dir.z() * dir.z();
}

LightMoments LightMomentsSum::Moments(const LightMoments& fallback) const {
  if (!(w_ > 0)) return fallback;
  LightMoments m;
  m.l = (l_ / w_).cast<float>();
  m.s = static_cast<float>(s_ / w_);
  m.sl = (sl_ / w_).cast<float>();
  for (int k = 0; k < 6; ++k) m.sll[k] = static_cast<float>(sll_[k] / w_);
  return m;
}

LightMoments LightMoments::Mix(const LightMoments& a, double wa, const LightMoments& b, double wb) {
  if (!(wa + wb > 0)) return a;
  const float ta = static_cast<float>(wa / (wa + wb)), tb = 1 - ta;
  LightMoments m;
  m.l = ta * a.l + tb * b.l;
  m.s = ta * a.s + tb * b.s;
  m.sl = ta * a.sl + tb * b.sl;
  for (int k = 0; k < 6; ++k) m.sll[k] = ta * a.sll[k] + tb * b.sll[k];
  return m;
}

LightMoments UniformLight(const Eigen::Vector3d& n) {
  LightMoments m;
  m.l = (2.0 / 3 * n).cast<float>();
  m.s = static_cast<float>(1.0 / 21);
  m.sl = (n / 84).cast<float>();
  // 11/504 I + (1/252 - 11/504) n n^T
  const double across = 11.0 / 504, along = 1.0 / 252 - across;
  m.sll = {static_cast<float>(across + along * n.x() * n.x()),
           static_cast<float>(along * n.x() * n.y()),
           static_cast<float>(along * n.x() * n.z()),
           static_cast<float>(across + along * n.y() * n.y()),
           static_cast<float>(along * n.y() * n.z()),
           static_cast<float>(across + along * n.z() * n.z())};
  return m;
}

double AmbientRetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& v,
                          const LightMoments& light) {
  if (retro == 0) return 1;
  const double sv = Pow5(1 - std::clamp(n.dot(v), 0.0, 1.0));
  // D = 1 + a s_l + a s_v + a^2 s_l s_v with a = F - 1 = alpha (l.v) + beta (alpha = retro,
  // beta = retro / 2), averaged over the light: E[a] = alpha v.E[l] + beta, E[a s_l] =
  // alpha v.E[s_l l] + beta E[s_l], E[a^2 s_l] = alpha^2 v^T E[s_l l l^T] v + 2 alpha beta
  // v.E[s_l l] + beta^2 E[s_l].
  const double alpha = retro, beta = retro / 2;
  const auto& m = light.sll;
  const double vsv = m[0] * v.x() * v.x() + m[3] * v.y() * v.y() + m[5] * v.z() * v.z() +
                     2 * (m[1] * v.x() * v.y() + m[2] * v.x() * v.z() + m[4] * v.y() * v.z());
  const double v_sl = v.dot(light.sl.cast<double>());
  const double e_a = alpha * v.dot(light.l.cast<double>()) + beta;
  const double e_a_sl = alpha * v_sl + beta * light.s;
  const double e_a2_sl = alpha * alpha * vsv + 2 * alpha * beta * v_sl + beta * beta * light.s;
  return std::max(0.0, 1 + e_a_sl + sv * (e_a + e_a2_sl));
}

double AmbientRetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& v) {
  if (retro == 0) return 1;
  return AmbientRetroFactor(retro, n, v, UniformLight(n));
}

std::optional<double> ParabolaVertex(const std::vector<double>& grid,
                                     const std::vector<double>& cost, size_t best, double step) {
  if (best == 0 || best + 1 >= grid.size() || cost.size() != grid.size()) return std::nullopt;
  const double curvature = cost[best - 1] - 2 * cost[best] + cost[best + 1];
  if (!(curvature > 0)) return std::nullopt;
  return grid[best] +
         std::clamp(0.5 * step * (cost[best - 1] - cost[best + 1]) / curvature, -step, step);
}

}  // namespace rouen
