// Rough diffuse reflection of the sun, beyond the paper's Lambertian diffuse term (§4.2, eq. 13
// keeps rho_d constant): rough stone, render and brick send more of a grazing sun back towards
// the viewer than Lambert's law. Burley's diffuse factor (SIGGRAPH 2012 course, "Physically
// Based Shading at Disney") describes that with one parameter; here it is parametrised so that
// 0 is Lambert exactly:
//   D = (1 + (F - 1)(1 - n.l)^5) (1 + (F - 1)(1 - n.v)^5),  F = 1 + retro (2 (l.h)^2 - 1/2),
// h the half vector of the light l and the view v. retro = 1 is Burley's roughness-1 surface;
// D = 1 at normal incidence and normal view, so rho_sun stays the albedo seen head-on.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

namespace rouen {

// The range a block's retro parameter is fitted in (D stays >= 1/4 inside it).
constexpr double kRetroMin = -0.5;
constexpr double kRetroMax = 1.5;

// D for unit normal n, unit direction to the light l and unit direction to the viewer v (all
// ENU). Exactly 1 for retro == 0; cosines below 0 count as 0 (a grazing light or view).
double RetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& l,
                   const Eigen::Vector3d& v);

// The same surface under light of one radiance from the whole hemisphere above it: the mean of
// D weighted by n.l / pi, in closed form (the moments of that weight). A rough surface
// brightens towards oblique views under sky light as well as sunlight, which the sky and
// environment irradiance E_se (one number per point, no direction) cannot show by itself;
// the albedo solve and the renderer scale E_se by this. 1 for retro == 0; about 1.04 head-on
// for retro 1.
double AmbientRetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& v);

// The sun's side of the reflection model for the albedo solve and the renderer: the sun
// direction per slot and the retro parameter per block (empty: Lambert everywhere).
struct SunShading {
  std::vector<Eigen::Vector3d> sun_dirs;  // unit ENU, per slot
  std::vector<double> retro;              // per block; blocks beyond its end are Lambertian
};

// One refinement of a grid search over the retro parameter with an even `step`: the vertex of
// the parabola through the costs at grid[best - 1], grid[best] and grid[best + 1], within one
// step of grid[best]; none at the grid's ends or where the costs do not curve upwards.
std::optional<double> ParabolaVertex(const std::vector<double>& grid,
                                     const std::vector<double>& cost, size_t best, double step);

// retro[block], or 0 (Lambert) for a block without an entry or -1 (no block).
inline double BlockRetro(const std::vector<double>& retro, int block) {
  return block >= 0 && block < static_cast<int>(retro.size()) ? retro[block] : 0.0;
}

}  // namespace rouen
