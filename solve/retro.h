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
#include <array>
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

// Where a point's sky and environment light comes from, as much as its rough reflection needs:
// with weights L(l) (n.l) / E over the directions l it arrives from (E the irradiance), the
// means of l, of s_l = (1 - n.l)^5, of s_l l and of s_l l l^T. D is a polynomial in l (F - 1 is
// linear in l.v), so these give its mean exactly whatever the light's distribution: a low sun's
// aureole seen through a street at a grazing angle reflects towards a camera near the sun's
// side far more than the same irradiance spread over the whole sky.
struct LightMoments {
  Eigen::Vector3f l = Eigen::Vector3f::Zero();
  float s = 0;
  Eigen::Vector3f sl = Eigen::Vector3f::Zero();
  std::array<float, 6> sll{};  // xx, xy, xz, yy, yz, zz

  // The mixture of two lights: `a` weighted wa and `b` weighted wb (their irradiances); `a`
  // when neither weighs anything.
  static LightMoments Mix(const LightMoments& a, double wa, const LightMoments& b, double wb);
};

// Sums light arriving at a point of unit normal n, direction by direction.
class LightMomentsSum {
 public:
  explicit LightMomentsSum(const Eigen::Vector3d& n) : n_(n) {}
  void Add(const Eigen::Vector3d& dir, double w);  // unit dir, weight w > 0 (L n.l)
  double weight() const { return w_; }
  // The means; `fallback` when nothing was added.
  LightMoments Moments(const LightMoments& fallback) const;

 private:
  Eigen::Vector3d n_;
  double w_ = 0, s_ = 0;
  Eigen::Vector3d l_ = Eigen::Vector3d::Zero(), sl_ = Eigen::Vector3d::Zero();
  std::array<double, 6> sll_{};
};

// The moments of light of one radiance from the whole hemisphere above n (the closed forms:
// E[l] = 2/3 n, E[s_l] = 1/21, E[s_l l] = n / 84, E[s_l l l^T] = 1/252 along n, 11/504 across).
LightMoments UniformLight(const Eigen::Vector3d& n);

// The same surface under light arriving as `light` describes: the mean of D over it. A rough
// surface brightens towards oblique views under sky light as well as sunlight, which the sky
// and environment irradiance E_se (one number per point) cannot show by itself; the albedo
// solve and the renderer scale E_se by this. 1 for retro == 0.
double AmbientRetroFactor(double retro, const Eigen::Vector3d& n, const Eigen::Vector3d& v,
                          const LightMoments& light);
// Under light of one radiance from the whole hemisphere (UniformLight): about 1.04 head-on for
// retro 1.
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
