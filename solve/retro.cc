#include "solve/retro.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace rouen {

double RetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& l,
                   const Eigen::Vector3d& v) {
  if (retro == 0) return 1;
  const double cl = std::clamp(n.dot(l), 0.0, 1.0), cv = std::clamp(n.dot(v), 0.0, 1.0);
  const Eigen::Vector3d h = l + v;
  const double hn = h.norm();
  // l == -v cannot happen with both above the surface; guard anyway.
  const double cd = hn > 0 ? l.dot(h) / hn : 0;
  const double f1 = retro * (2 * cd * cd - 0.5);
  const double sl = std::pow(1 - cl, 5), sv = std::pow(1 - cv, 5);
  return std::max(0.0, (1 + f1 * sl) * (1 + f1 * sv));
}

}  // namespace rouen
