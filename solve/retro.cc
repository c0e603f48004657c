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

double AmbientRetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& v) {
  if (retro == 0) return 1;
  const double c = std::clamp(n.dot(v), 0.0, 1.0), sv = Pow5(1 - c);
  // D = 1 + a s_l + a s_v + a^2 s_l s_v with a = F - 1 = retro (l.v + 1/2), s_l = (1 - n.l)^5,
  // averaged over l with density n.l / pi. The moments of that density (mu = n.l, c = n.v):
  // E[l] = 2/3 n, E[(l.v)^2] = 1/4 + c^2 / 4, E[s_l] = 1/21, E[s_l l] = n / 84,
  // E[s_l l l^T] = 1/252 along n and 11/504 across it.
  const double e_a = retro * (2 * c / 3 + 0.5);
  const double e_a_sl = retro * (c / 84 + 1.0 / 42);
  const double e_a2_sl = retro * retro * (11 * (1 - c * c) / 504 + c * c / 252 + c / 84 + 1.0 / 84);
  return std::max(0.0, 1 + e_a_sl + sv * (e_a + e_a2_sl));
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
