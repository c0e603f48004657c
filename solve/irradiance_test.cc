#include "solve/irradiance.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "core/angles.h"
#include "core/error.h"
#include "solve/specular.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

Lighting UniformSky(const Eigen::Vector3d& sky, const Eigen::Vector3d& ground) {
  Lighting l;
  l.env = EnvironmentMap::Constant(EnvOptions(), sky, ground);
  l.sun_radiance.setZero();
  return l;
}

TEST(HemisphereTest, DirectionsAreStratifiedCosineDistributed) {
  SurfaceGrid g;
  GridPoint p;
  p.position.setZero();
  p.normal = Eigen::Vector3d(0.3, -0.4, 0.866).normalized();
  g.points.push_back(p);
  HemisphereCache c;
  c.strata = 16;
  c.directions = 256;
  // Moments of the cosine-weighted distribution: E[cos] = 2/3, E[cos^2] = 1/2.
  double m1 = 0, m2 = 0;
  for (int k = 0; k < 256; ++k) {
    const Eigen::Vector3d d = c.Direction(p, 0, k);
    EXPECT_NEAR(d.norm(), 1, 1e-12);
    const double ct = d.dot(p.normal);
    EXPECT_GT(ct, 0);
    m1 += ct;
    m2 += ct * ct;
  }
  // Stratified: each u1 stratum holds 16 samples, so the cos^2 = 1 - u1 moment is exact up
  // to the shift inside a stratum: |error| <= 1/(2 * 16).
  EXPECT_NEAR(m2 / 256, 0.5, 1.0 / 32);
  EXPECT_NEAR(m1 / 256, 2.0 / 3.0, 1.0 / 32);
  // Different points get different patterns.
  EXPECT_GT((c.Direction(p, 0, 5) - c.Direction(p, 1, 5)).norm(), 1e-6);
  // All of a point's directions at once are the same, to the bit.
  std::vector<Eigen::Vector3d> all;
  c.Directions(p, 3, &all);
  ASSERT_EQ(all.size(), 256u);
  for (int k = 0; k < 256; ++k) EXPECT_EQ(all[k], c.Direction(p, 3, k)) << k;
}

TEST(IrradianceTest, HorizontalPlaneUnderUniformSkyIsPiL) {
  Mesh m;
  const int b = m.AddBlock("plane");
  testing::AddHorizontalRect(&m, -5, 5, -5, 5, 0, true, b);
  const SurfaceGrid g = BuildSurfaceGrid(m, GridOptions());
  const RayCaster rc(m);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  EXPECT_EQ(cache.directions, 256);
  const Eigen::Vector3d L(1, 2, 3);
  const SlotIrradiance irr = ComputeIrradiance(g, cache, rc, UniformSky(L, {9, 9, 9}));
  for (int i = 0; i < g.size(); ++i) {
    // Every cosine-weighted sample escapes upwards: the estimate is exact.
    EXPECT_NEAR((irr.direct_se[i] - kPi * L).norm(), 0, 1e-9);
    EXPECT_EQ(irr.se[i], irr.direct_se[i]);
    EXPECT_FLOAT_EQ(cache.escaped_fraction[i], 1.f);
  }
}

TEST(IrradianceTest, VerticalPlaneSeesHalfTheSky) {
  Mesh m;
  const int b = m.AddBlock("wall");
  m.AddPolygon({{0, 0, 0}, {4, 0, 0}, {4, 0, 3}, {0, 0, 3}}, b);  // normal -y
  const SurfaceGrid g = BuildSurfaceGrid(m, GridOptions());
  const RayCaster rc(m);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  const Eigen::Vector3d L(2, 2, 2);
  const SlotIrradiance irr = ComputeIrradiance(g, cache, rc, UniformSky(L, {0, 0, 0}));
  for (int i = 0; i < g.size(); ++i) {
    // The horizon splits the projected disc through its centre: with 16 equally spaced
    // azimuth strata per ring, exactly half the samples of each ring lie above (up to a
    // sample falling exactly on the boundary: 1/16 of a ring).
    EXPECT_NEAR(irr.direct_se[i].x(), kPi * L.x() / 2, kPi * L.x() / 16) << i;
  }
  double mean = 0;
  for (int i = 0; i < g.size(); ++i) mean += irr.direct_se[i].x() / g.size();
  EXPECT_NEAR(mean, kPi * L.x() / 2, 1e-3 * kPi * L.x());
  // Where that light comes from (se_light): the upper half of the projected disc, whose mean
  // height is 4 / (3 pi), and 2/3 along the normal as for the whole hemisphere.
  ASSERT_EQ(irr.se_light.size(), static_cast<size_t>(g.size()));
  Eigen::Vector3d l = Eigen::Vector3d::Zero();
  for (const LightMoments& m : irr.se_light) l += m.l.cast<double>() / g.size();
  EXPECT_NEAR(l.y(), -2.0 / 3, 0.01);
  EXPECT_NEAR(l.z(), 4 / (3 * kPi), 0.01);
  EXPECT_NEAR(l.x(), 0, 0.01);
  // Not asked for (no rough block to reflect it): none, and the same irradiance.
  IrradianceOptions plain;
  plain.light_directions = false;
  const SlotIrradiance without = ComputeIrradiance(g, cache, rc, UniformSky(L, {0, 0, 0}), plain);
  EXPECT_TRUE(without.se_light.empty() && without.direct_se_light.empty());
  for (int i = 0; i < g.size(); ++i) EXPECT_EQ(without.direct_se[i], irr.direct_se[i]);
}

TEST(IrradianceTest, SunOnPlaneAndBoxShadow) {
  Mesh m;
  const int ground = m.AddBlock("plaza");
  const int box = m.AddBlock("box");
  testing::AddHorizontalRect(&m, -10, 10, -10, 10, 0, true, ground);
  testing::AddBox(&m, {-1, -1, 0}, {1, 1, 2}, box);
  GridOptions go;
  go.spacing_m = 0.4;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const RayCaster rc(m);
  HemisphereOptions ho;
  ho.directions = 16;
  const HemisphereCache cache = BuildHemisphereCache(g, rc, ho);
  Lighting l = UniformSky({0, 0, 0}, {0, 0, 0});
  // Sun in the south at 45 deg elevation: the box's shadow covers x in [-1, 1], y in [1, 3].
  l.sun_dir = Eigen::Vector3d(0, -1, 1).normalized();
  l.sun_radiance = Eigen::Vector3d(1e4, 2e4, 3e4);
  l.sun_solid_angle_sr = 6.8e-5;
  const SlotIrradiance irr = ComputeIrradiance(g, cache, rc, l);
  const Eigen::Vector3d full = l.sun_radiance * l.sun_solid_angle_sr * std::sqrt(0.5);
  int in_shadow = 0, lit = 0;
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    if (p.block != ground) {
      // Box faces: the north face never sees the sun; the south face is at 45 deg.
      if (p.normal.y() > 0.9) {
        EXPECT_EQ(irr.sun[i].norm(), 0);
      }
      if (p.normal.y() < -0.9) {
        EXPECT_NEAR((irr.sun[i] - full).norm(), 0, 1e-9);
      }
      continue;
    }
    const double x = p.position.x(), y = p.position.y();
    const bool inside = std::abs(x) < 0.8 && y > 1.2 && y < 2.8;
    const bool outside = std::abs(x) > 1.2 || y < 0.8 || y > 3.2;
    if (inside) {
      EXPECT_EQ(irr.sun[i].norm(), 0) << x << " " << y;
      ++in_shadow;
    } else if (outside && !(std::abs(x) < 1 && std::abs(y) < 1)) {
      EXPECT_NEAR((irr.sun[i] - full).norm(), 0, 1e-9) << x << " " << y;
      ++lit;
    }
  }
  EXPECT_GT(in_shadow, 10);
  EXPECT_GT(lit, 1000);
}

// Form factor from a differential area to a parallel rectangle [0, a] x [0, b] at distance c
// with the normal through one corner (Howell's catalogue, C-11).
double CornerFormFactor(double a, double b, double c) {
  const double X = a / c, Y = b / c;
  const double sx = std::sqrt(1 + X * X), sy = std::sqrt(1 + Y * Y);
  return (X / sx * std::atan(Y / sx) + Y / sy * std::atan(X / sy)) / (2 * kPi);
}

TEST(IrradianceTest, BounceBetweenFacingPlanesMatchesFormFactor) {
  Mesh m;
  const int lower = m.AddBlock("lower");
  const int upper = m.AddBlock("upper");
  const double half = 2, c = 2;
  testing::AddHorizontalRect(&m, -half, half, -half, half, 0, true, lower);
  testing::AddHorizontalRect(&m, -half, half, -half, half, c, false, upper);
  GridOptions go;
  go.spacing_m = 0.5;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const RayCaster rc(m);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  const int K = cache.directions;
  // The upper plane emits B = 1 (rho_se = 1, E_direct_se = 1); nothing else is lit.
  SlotIrradiance irr;
  irr.sun.assign(g.size(), Eigen::Vector3d::Zero());
  irr.direct_se.assign(g.size(), Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> rho_sun(g.size(), Eigen::Vector3d::Zero()), rho_se = rho_sun;
  for (int i = 0; i < g.size(); ++i) {
    irr.direct_se_light.push_back(UniformLight(g.points[i].normal));  // where light comes from
    if (g.points[i].block == upper) {
      irr.direct_se[i].setOnes();
      rho_se[i].setOnes();
    }
  }
  AddInterreflection(g, cache, rho_sun, rho_se, &irr, 1);
  EXPECT_TRUE(irr.has_bounce);
  double err_sum = 0;
  int n = 0;
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    if (p.block != lower) continue;
    const double x = p.position.x(), y = p.position.y();
    double F = 0;
    for (double a : {half - x, half + x}) {
      for (double b : {half - y, half + y}) F += CornerFormFactor(a, b, c);
    }
    // Binomial sampling error of K cosine-weighted directions (stratification only helps).
    const double sigma = std::sqrt(F * (1 - F) / K);
    EXPECT_NEAR(irr.se[i].x(), F, 5 * sigma) << x << " " << y;
    err_sum += irr.se[i].x() - F;
    ++n;
  }
  ASSERT_GT(n, 50);
  // The mean error over n independent points shrinks as 1/sqrt(n) (sigma <= 0.5/sqrt(K)).
  EXPECT_LT(std::abs(err_sum / n), 4 * 0.5 / std::sqrt(K * static_cast<double>(n)));
  // The lower plane's light comes from the upper one (se_light): its cosine-weighted mean
  // height is that of the upper square seen from the point (a midpoint sum over the square;
  // 0.84 at the middle, where the sky's whole hemisphere would give 2/3).
  ASSERT_EQ(irr.se_light.size(), static_cast<size_t>(g.size()));
  int middle = 0;
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    if (p.block != lower || std::abs(p.position.x()) > 0.3 || std::abs(p.position.y()) > 0.3)
      continue;
    double cos2 = 0, cos1 = 0;
    const int cells = 200;
    for (int a = 0; a < cells; ++a) {
      for (int bb = 0; bb < cells; ++bb) {
        const double x = -half + (a + 0.5) * 2 * half / cells - p.position.x();
        const double y = -half + (bb + 0.5) * 2 * half / cells - p.position.y();
        const double r2 = x * x + y * y + c * c, cz = c / std::sqrt(r2);
        cos1 += cz * cz / r2;  // cos x d(omega) / dA, d(omega) = cos dA / r^2
        cos2 += cz * cz * cz / r2;
      }
    }
    EXPECT_NEAR(irr.se_light[i].l.z(), cos2 / cos1, 0.03) << i;
    EXPECT_NEAR(irr.se_light[i].l.head<2>().norm(), 0, 0.05) << i;
    ++middle;
  }
  EXPECT_GT(middle, 0);
  // Two bounces add the lower plane's reflection back to the upper one.
  std::vector<Eigen::Vector3d> rho_all(g.size(), Eigen::Vector3d::Constant(0.5));
  SlotIrradiance irr2 = irr;
  AddInterreflection(g, cache, rho_sun, rho_all, &irr2, 1);
  SlotIrradiance irr3 = irr;
  AddInterreflection(g, cache, rho_sun, rho_all, &irr3, 2);
  for (int i = 0; i < g.size(); ++i) {
    if (g.points[i].block == upper) {
      EXPECT_GE(irr3.se[i].x(), irr2.se[i].x());
    }
  }
}

// A 1 x 1 m plate facing down `height` above a square ground of half-size `half` (its grid
// `ground_spacing`, the plate's 0.25 m), 1,024 gathering directions per point, and the ground
// under a sun of irradiance 1 (E_sun = 1 on every ground point, nothing else).
struct PlateOverGround {
  PlateOverGround(double half, double height, double ground_spacing)
      : m(Make(half, height)), g(Grid(m, ground_spacing)), rc(m), cache(Cache(g, rc)) {
    irr.sun.assign(g.size(), Eigen::Vector3d::Zero());
    irr.direct_se.assign(g.size(), Eigen::Vector3d::Zero());
    for (int i = 0; i < g.size(); ++i)
      if (g.points[i].block == ground) irr.sun[i].setOnes();
  }
  static Mesh Make(double half, double height) {
    Mesh m;
    testing::AddHorizontalRect(&m, -half, half, -half, half, 0, true, m.AddBlock("ground"));
    testing::AddHorizontalRect(&m, -0.5, 0.5, -0.5, 0.5, height, false, m.AddBlock("plate"));
    return m;
  }
  static SurfaceGrid Grid(const Mesh& m, double ground_spacing) {
    GridOptions go;
    go.spacing_m = 0.25;
    go.block_spacing_m["ground"] = ground_spacing;
    return BuildSurfaceGrid(m, go);
  }
  static HemisphereCache Cache(const SurfaceGrid& g, const RayCaster& rc) {
    HemisphereOptions ho;
    ho.directions = 1024;
    return BuildHemisphereCache(g, rc, ho);
  }
  static constexpr int ground = 0, plate = 1;  // the blocks, in Make's order
  const Mesh m;
  const SurfaceGrid g;
  const RayCaster rc;
  const HemisphereCache cache;
  SlotIrradiance irr;
};

// A tall tower's own shadow on the unmodelled ground darkens what its shaded side sees.
// A rough surface sends its light towards each receiver as the photos would see it there
// (RetroFactor): ground lit from the zenith, seen from a plate 1 m above it, is brighter at
// oblique views, D(theta) = 1 + retro (1/2 + cos theta) (1 - cos theta)^5, so the plate gets
// the integral of D over its cosine-weighted view of the ground instead of the form factor.
TEST(IrradianceTest, RoughSurfacesReflectTowardsEachReceiverAsTheyLook) {
  const double half = 20, c = 1;
  const PlateOverGround w(half, c, 0.5);
  const SurfaceGrid& g = w.g;
  const HemisphereCache& cache = w.cache;
  const int ground = w.ground, plate = w.plate;
  const SlotIrradiance& irr = w.irr;  // the sun at the zenith: B = rho_sun E_sun = 1 (Lambert)
  std::vector<Eigen::Vector3d> rho_sun(g.size(), Eigen::Vector3d::Zero()), rho_se = rho_sun;
  for (int i = 0; i < g.size(); ++i)
    if (g.points[i].block == ground) rho_sun[i].setOnes();
  const Eigen::Vector3d zenith = Eigen::Vector3d::UnitZ();
  SlotIrradiance lambert = irr, lambert_zero = irr, rough = irr;
  AddInterreflection(g, cache, rho_sun, rho_se, &lambert, 1);
  AddInterreflection(g, cache, rho_sun, rho_se, &lambert_zero, 1, {0.0, 0.0}, zenith);
  AddInterreflection(g, cache, rho_sun, rho_se, &rough, 1, {1.0, 0.0}, zenith);
  // The plate's view of the ground by the midpoint rule in theta (a disc of the square's half
  // size: the corners lie beyond 87 degrees, where cos theta sin theta is small).
  const double theta_max = std::atan(half / c);
  double form = 0, with_d = 0;
  const int steps = 20000;
  for (int k = 0; k < steps; ++k) {
    const double t = (k + 0.5) * theta_max / steps, ct = std::cos(t);
    const double w = 2 * ct * std::sin(t) * theta_max / steps;
    form += w;
    with_d += w * (1 + (0.5 + ct) * std::pow(1 - ct, 5));
  }
  double sum_l = 0, sum_r = 0;
  int n = 0;
  for (int i = 0; i < g.size(); ++i) {
    EXPECT_EQ(lambert_zero.se[i], lambert.se[i]) << i;  // retro 0 is Lambert, to the bit
    if (g.points[i].block != plate) continue;
    EXPECT_GE(rough.se[i].x(), lambert.se[i].x()) << i;  // D >= 1 for light from the normal
    sum_l += lambert.se[i].x();
    sum_r += rough.se[i].x();
    ++n;
  }
  ASSERT_GT(n, 10);
  // Stratified directions over n points: a fraction of a percent; 1% each.
  EXPECT_NEAR(sum_l / n, form, 0.01 * form);
  EXPECT_NEAR(sum_r / n, with_d, 0.01 * with_d);
  EXPECT_GT(with_d / form, 1.02);  // the test tells the two apart
}

// A glossy ground sends the sun's glint on (AddInterreflection's sun_lobes): under a sun of
// irradiance 1 on the ground, a plate 2 m above it facing down sees the radiance f_s(l, v) of
// eq. 13's lobe (kappa 1: (r.v)^n, r the sun's mirror direction) in every direction, so it gets
// E = rho_s \int (r.v)^n cos(theta) dw over its view of the ground, computed here by the
// midpoint rule (the square's corners, beyond 79 degrees, left out: the lobe is 0 there). The
// cache's estimate per plate point scatters; the mean over the points is checked within 4
// standard errors of that mean. Without the lobe the diffuse-black ground sends nothing.
TEST(IrradianceTest, AGlossySurfaceSendsTheSunsGlintOn) {
  const double half = 10, c = 2;
  const PlateOverGround w(half, c, 0.25);
  const SurfaceGrid& g = w.g;
  const HemisphereCache& cache = w.cache;
  const int ground = w.ground, plate = w.plate;
  const SlotIrradiance& irr = w.irr;
  const std::vector<Eigen::Vector3d> black(g.size(), Eigen::Vector3d::Zero());
  // The lobe about 24 degrees wide, the ground's points 3.6 degrees apart as the plate sees them
  // below it (the interreflection takes a hit point's direction as its grid point's).
  const double tilt = 30 * kPi / 180, exponent = 8, rho_s = 0.5;
  const Eigen::Vector3d sun(0, std::sin(tilt), std::cos(tilt)), mirror(0, -sun.y(), sun.z());
  std::vector<SpecularLobe> lobes(2);
  lobes[ground].rho_s.setConstant(rho_s);
  lobes[ground].n = exponent;
  SlotIrradiance plain = irr, glossy = irr;
  AddInterreflection(g, cache, black, black, &plain, 1, {}, sun);
  AddInterreflection(g, cache, black, black, &glossy, 2, {}, sun, nullptr, nullptr, nullptr, lobes);
  const double theta_max = std::atan(half / c);
  const int steps = 2000;
  double want = 0;
  for (int a = 0; a < steps; ++a) {
    const double t = (a + 0.5) * theta_max / steps;
    for (int b = 0; b < steps; ++b) {
      const double phi = (b + 0.5) * 2 * kPi / steps;
      const Eigen::Vector3d v(std::sin(t) * std::cos(phi), std::sin(t) * std::sin(phi),
                              std::cos(t));
      want += std::pow(std::max(0.0, mirror.dot(v)), exponent) * std::cos(t) * std::sin(t);
    }
  }
  want *= rho_s * (theta_max / steps) * (2 * kPi / steps);
  std::vector<double> got;
  for (int i = 0; i < g.size(); ++i) {
    EXPECT_EQ(plain.se[i], Eigen::Vector3d::Zero()) << i;
    if (g.points[i].block == plate) got.push_back(glossy.se[i].x());
  }
  ASSERT_GT(got.size(), 10u);
  double mean = 0, var = 0;
  for (double x : got) mean += x / got.size();
  for (double x : got) var += (x - mean) * (x - mean) / (got.size() - 1);
  const double standard_error = std::sqrt(var / got.size());
  EXPECT_GT(want, 0.05);  // the test sees the lobe: rho_s 2 pi / (n + 2) for a sun overhead
  EXPECT_NEAR(mean, want, 4 * standard_error + 1e-3 * want);
  EXPECT_LT(standard_error, 0.02 * want);  // and tells a wrong lobe from noise
}

TEST(IrradianceTest, GroundShadowDarkensTheEnvironmentBehindTheTower) {
  Mesh m;
  const int ground = m.AddBlock("plaza");
  const int tower = m.AddBlock("tower");
  testing::AddHorizontalRect(&m, -5, 5, -5, 5, 0, true, ground);
  testing::AddBox(&m, {-1, -1, 0}, {1, 1, 40}, tower);
  GridOptions go;
  go.spacing_m = 2.0;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const RayCaster rc(m);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  Lighting l = UniformSky({1, 1, 1}, {1, 1, 1});
  l.sun_dir = Eigen::Vector3d(0, -std::cos(0.5), std::sin(0.5));  // south, 28.6 deg up
  l.sun_radiance = Eigen::Vector3d::Constant(1e5);
  IrradianceOptions on, off;
  off.ground_shadow = false;
  const SlotIrradiance a = ComputeIrradiance(g, cache, rc, l, on);
  const SlotIrradiance b = ComputeIrradiance(g, cache, rc, l, off);
  // Shadowed/sunlit ground ratio: E_sky / (E_sky + E_sun), with E_sky = pi.
  const double e_sun = 1e5 * l.sun_solid_angle_sr * std::sin(0.5);
  const double ratio = kPi / (kPi + e_sun);
  int darker = 0;
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    if (p.block != tower || std::abs(p.normal.z()) > 0.5) continue;
    if (p.normal.y() < -0.9) {
      // The south face looks away from the shadow: unchanged.
      EXPECT_NEAR(a.direct_se[i].x(), b.direct_se[i].x(), 1e-12);
    } else if (p.normal.y() > 0.9 && p.position.z() > 10) {
      // The north face: some downward rays meet the shadow; at most the whole ground part
      // (pi/2 of the irradiance, from below the horizon) is scaled by the ratio.
      EXPECT_LE(a.direct_se[i].x(), b.direct_se[i].x() + 1e-12);
      EXPECT_GE(a.direct_se[i].x(), b.direct_se[i].x() - (1 - ratio) * kPi / 2 - 1e-9);
      darker += a.direct_se[i].x() < b.direct_se[i].x() - 1e-9;
    }
  }
  EXPECT_GT(darker, 5);
  // A rough ground (EnvironmentMap::ground_retro) seen from the north face has the sun behind
  // its viewer: sunlit it is brighter than Lambert's, so its shadow is darker beside it
  // (GroundShadowRatio) and the north face sees less light; the south face still none of it.
  Lighting rough = l;
  rough.env.ground_retro = 1;
  const SlotIrradiance c = ComputeIrradiance(g, cache, rc, rough, on);
  int darker_rough = 0;
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    if (p.block != tower || std::abs(p.normal.z()) > 0.5) continue;
    if (p.normal.y() < -0.9) {
      EXPECT_NEAR(c.direct_se[i].x(), b.direct_se[i].x(), 1e-12);
    }
    if (p.normal.y() > 0.9 && p.position.z() > 10) {
      EXPECT_LE(c.direct_se[i].x(), a.direct_se[i].x() + 1e-12);
      EXPECT_GE(c.direct_se[i].x(), b.direct_se[i].x() - kPi / 2 - 1e-9);
      darker_rough += c.direct_se[i].x() < a.direct_se[i].x() - 1e-9;
    }
  }
  EXPECT_GT(darker_rough, 5);
}

// A requested cancellation stops each long computation with Cancelled instead of a result; an
// unrequested token changes nothing.
TEST(IrradianceTest, ACancellationStopsTheWork) {
  Mesh m;
  const int b = m.AddBlock("plane");
  testing::AddHorizontalRect(&m, -5, 5, -5, 5, 0, true, b);
  const SurfaceGrid g = BuildSurfaceGrid(m, GridOptions());
  const RayCaster rc(m);
  Cancellation cancel;
  HemisphereOptions ho;
  ho.cancel = &cancel;
  const HemisphereCache cache = BuildHemisphereCache(g, rc, ho);
  IrradianceOptions io;
  io.cancel = &cancel;
  const Lighting sky = UniformSky({1, 2, 3}, {9, 9, 9});
  SlotIrradiance irr = ComputeIrradiance(g, cache, rc, sky, io);
  EXPECT_EQ(irr.se, ComputeIrradiance(g, cache, rc, sky).se);
  const std::vector<Eigen::Vector3d> rho(g.size(), Eigen::Vector3d::Constant(0.5));
  cancel.Request();
  EXPECT_THROW(BuildHemisphereCache(g, rc, ho), Cancelled);
  EXPECT_THROW(ComputeIrradiance(g, cache, rc, sky, io), Cancelled);
  const std::vector<Eigen::Vector3d> before = irr.se;
  EXPECT_THROW(
      AddInterreflection(g, cache, rho, rho, &irr, 2, {}, Eigen::Vector3d::UnitZ(), &cancel),
      Cancelled);
  EXPECT_EQ(irr.se, before);  // left as it was
  EXPECT_FALSE(irr.has_bounce);
}

TEST(IrradianceTest, BadInputThrows) {
  Mesh m;
  const int b = m.AddBlock("plane");
  testing::AddHorizontalRect(&m, -1, 1, -1, 1, 0, true, b);
  const SurfaceGrid g = BuildSurfaceGrid(m, GridOptions());
  const RayCaster rc(m);
  HemisphereOptions ho;
  ho.directions = 0;
  EXPECT_THROW(BuildHemisphereCache(g, rc, ho), Error);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  Lighting l = UniformSky({1, 1, 1}, {1, 1, 1});
  l.sun_dir = Eigen::Vector3d(0, 0, 2);
  EXPECT_THROW(ComputeIrradiance(g, cache, rc, l), Error);
  l.sun_dir = Eigen::Vector3d::UnitZ();
  l.sun_radiance = Eigen::Vector3d(NAN, 0, 0);
  EXPECT_THROW(ComputeIrradiance(g, cache, rc, l), Error);
  l.sun_radiance.setZero();
  HemisphereCache wrong = cache;
  wrong.hit.pop_back();
  EXPECT_THROW(ComputeIrradiance(g, wrong, rc, l), Error);
  SlotIrradiance irr = ComputeIrradiance(g, cache, rc, l);
  std::vector<Eigen::Vector3d> short_rho(g.size() - 1, Eigen::Vector3d::Ones());
  std::vector<Eigen::Vector3d> rho(g.size(), Eigen::Vector3d::Ones());
  EXPECT_THROW(AddInterreflection(g, cache, short_rho, rho, &irr), Error);
}

// A 10 m cube on a 60 m plaza: points on the plaza and the walls see the cube, the plaza and
// (beyond it) the environment's ground.
struct BoxScene {
  Mesh mesh;
  SurfaceGrid grid;
  std::unique_ptr<RayCaster> rc;
  BoxScene() {
    testing::AddHorizontalRect(&mesh, -30, 30, -30, 30, 0, true, mesh.AddBlock("plaza"));
    testing::AddBox(&mesh, {-5, -5, 0}, {5, 5, 10}, mesh.AddBlock("box"));
    GridOptions go;
    go.spacing_m = 8;
    grid = BuildSurfaceGrid(mesh, go);
    rc = std::make_unique<RayCaster>(mesh);
  }
};

Lighting VaryingEnvironment(bool sun) {
  Lighting l;
  SkyModel sky;
  sky.channel[0] = SkyParams{1.0, -1.0, -0.32, 10, -3, 0.45, 1};
  sky.channel[1] = SkyParams{1.2, -1.0, -0.4, 12, -3.2, 0.5, 1};
  sky.channel[2] = SkyParams{1.5, -1.0, -0.5, 8, -2.5, 0.3, 1};
  sky.sun_dir = Eigen::Vector3d(0.5, -0.4, 0.6).normalized();
  l.sky = sky;
  l.sun_dir = sky.sun_dir;
  l.env = EnvironmentMap::FromSky(EnvOptions(), sky, Eigen::Vector3d(0.3, 0.25, 0.2));
  // Below the horizon: a different radiance per region.
  for (int r = 0; r < l.env.bands_below * l.env.sectors; ++r) {
    l.env.radiance[r] = Eigen::Vector3d(0.2 + 0.1 * std::sin(r), 0.25, 0.3 + 0.05 * (r % 5));
  }
  l.sun_radiance = sun ? Eigen::Vector3d(2e4, 2e4, 2e4) : Eigen::Vector3d::Zero();
  return l;
}

TEST(IrradianceVectorFluxTest, MatchesConvergedMonteCarloOnABox) {
  const BoxScene s;
  HemisphereOptions ho;
  ho.directions = 4096;
  const HemisphereCache fine = BuildHemisphereCache(s.grid, *s.rc, ho);
  for (const auto& [use_env, ground_shadow] : {std::pair{true, true}, std::pair{false, false}}) {
    {
      Lighting l = VaryingEnvironment(true);
      l.use_env = use_env;
      IrradianceOptions mc;
      mc.ground_shadow = ground_shadow;
      IrradianceOptions vf = mc;
      vf.method = IrradianceMethod::kVectorFlux;
      vf.mesh = &s.mesh;
      const SlotIrradiance a = ComputeIrradiance(s.grid, fine, *s.rc, l, mc);
      const SlotIrradiance b = ComputeIrradiance(s.grid, fine, *s.rc, l, vf);
      double worst = 0, mean = 0, bias = 0;
      int count = 0;
      for (int i = 0; i < s.grid.size(); ++i) {
        EXPECT_EQ(a.sun[i], b.sun[i]);
        EXPECT_TRUE(b.direct_se[i].allFinite());
        if (fine.escaped_fraction[i] == 0) {  // under the box: nothing to see
          EXPECT_LT(b.direct_se[i].norm(), 1e-9);
          continue;
        }
        const double rel = (b.direct_se[i] - a.direct_se[i]).norm() / a.direct_se[i].norm();
        worst = std::max(worst, rel);
        mean += rel;
        bias += (b.direct_se[i].sum() - a.direct_se[i].sum()) / a.direct_se[i].sum();
        ++count;
      }
      mean /= std::max(count, 1);
      bias /= std::max(count, 1);
      // 4096 stratified cosine samples against piecewise constant regions with sharp edges
      // and occluder silhouettes converge like K^-1/2 (bench/irradiance_bench): ~0.4-0.6%
      // noise on average, a few % at the worst point; the noise averages out of the signed
      // mean, which would show a systematic error (orientation, clipping, ground shadow).
      EXPECT_GT(count, 50);
      EXPECT_LT(worst, 0.05) << "use_env " << use_env << " mean " << mean;
      EXPECT_LT(mean, 0.007) << "use_env " << use_env << " worst " << worst;
      EXPECT_LT(std::abs(bias), 0.0015) << "use_env " << use_env;
    }
  }
}

// The sky's shape inside each region (EnvOptions::sky_detail) brings a map of region means
// towards the sky it was averaged from: on the box and the ground around it, the direct sky
// irradiance from the model's map with 4 x 4 cells per region is several times nearer the model
// integrated exactly (the sky tree) than the uniform regions are, by both methods.
TEST(IrradianceVectorFluxTest, SkyShapeBringsRegionMeansTowardsTheSky) {
  const BoxScene s;
  HemisphereOptions ho;
  ho.directions = 4096;
  const HemisphereCache fine = BuildHemisphereCache(s.grid, *s.rc, ho);
  Lighting exact = VaryingEnvironment(false);
  exact.use_env = false;  // the sky model above the horizon, nothing below
  IrradianceOptions vf;
  vf.method = IrradianceMethod::kVectorFlux;
  vf.mesh = &s.mesh;
  vf.ground_shadow = false;
  const SlotIrradiance truth = ComputeIrradiance(s.grid, fine, *s.rc, exact, vf);
  double error[2][2] = {};  // [method][detail 1, 4]
  for (int method = 0; method < 2; ++method) {
    IrradianceOptions o = vf;
    if (method == 1) o.method = IrradianceMethod::kMonteCarlo;
    for (int d = 0; d < 2; ++d) {
      EnvOptions eo;
      eo.sky_detail = d == 0 ? 1 : 4;
      Lighting l = exact;
      l.use_env = true;
      l.env = EnvironmentMap::FromSky(eo, l.sky, Eigen::Vector3d::Zero());
      const SlotIrradiance irr = ComputeIrradiance(s.grid, fine, *s.rc, l, o);
      int count = 0;
      for (int i = 0; i < s.grid.size(); ++i) {
        if (truth.direct_se[i].norm() < 1e-9) continue;
        error[method][d] +=
            (irr.direct_se[i] - truth.direct_se[i]).norm() / truth.direct_se[i].norm();
        ++count;
      }
      error[method][d] /= count;
    }
  }
  // Vector flux: the same integral of a finer piecewise-constant sky; Monte Carlo adds its
  // 4096-direction noise (~0.5%) to both.
  EXPECT_LT(error[0][1], error[0][0] / 3) << error[0][0] << " " << error[0][1];
  EXPECT_LT(error[0][1], 0.002);
  EXPECT_LT(error[1][1], error[1][0]) << error[1][0] << " " << error[1][1];
}

TEST(IrradianceVectorFluxTest, InterreflectionStillWorks) {
  const BoxScene s;
  const HemisphereCache cache = BuildHemisphereCache(s.grid, *s.rc);
  IrradianceOptions vf;
  vf.method = IrradianceMethod::kVectorFlux;
  vf.mesh = &s.mesh;
  SlotIrradiance irr = ComputeIrradiance(s.grid, cache, *s.rc, VaryingEnvironment(true), vf);
  const std::vector<Eigen::Vector3d> rho(s.grid.size(), Eigen::Vector3d::Constant(0.5));
  AddInterreflection(s.grid, cache, rho, rho, &irr, 1);
  int brighter = 0;
  for (int i = 0; i < s.grid.size(); ++i) {
    EXPECT_GE(irr.se[i].minCoeff(), irr.direct_se[i].minCoeff() - 1e-12);
    brighter += (irr.se[i] - irr.direct_se[i]).norm() > 1e-6;
  }
  EXPECT_GT(brighter, 0);
}

// One call for several lightings shares the per-point geometry; each lighting's irradiance is
// what a call of its own gives (environment maps of two layouts, a sky model, sun or none).
TEST(IrradianceVectorFluxTest, SeveralLightingsAtOnceEqualEachAlone) {
  const BoxScene s;
  const HemisphereCache cache = BuildHemisphereCache(s.grid, *s.rc);
  std::vector<Lighting> ls = {VaryingEnvironment(true), VaryingEnvironment(false),
                              VaryingEnvironment(true), VaryingEnvironment(true)};
  ls[1].sun_dir = Eigen::Vector3d(-0.6, 0.2, 0.3).normalized();
  ls[1].sun_radiance = Eigen::Vector3d(1e4, 9e3, 8e3);
  ls[2].use_env = false;
  EnvOptions coarse;
  coarse.sectors = 12;
  ls[3].env = EnvironmentMap::FromSky(coarse, ls[3].sky, Eigen::Vector3d(0.3, 0.25, 0.2));
  for (const IrradianceMethod method :
       {IrradianceMethod::kVectorFlux, IrradianceMethod::kMonteCarlo}) {
    IrradianceOptions o;
    o.method = method;
    o.mesh = &s.mesh;
    const std::vector<SlotIrradiance> all = ComputeIrradiance(s.grid, cache, *s.rc, ls, o);
    ASSERT_EQ(all.size(), ls.size());
    for (size_t k = 0; k < ls.size(); ++k) {
      const SlotIrradiance one = ComputeIrradiance(s.grid, cache, *s.rc, ls[k], o);
      for (int i = 0; i < s.grid.size(); ++i) {
        EXPECT_EQ(all[k].sun[i], one.sun[i]);
        EXPECT_EQ(all[k].direct_se[i], one.direct_se[i]) << "lighting " << k << " point " << i;
      }
    }
  }
}

// A convex block standing on the ground casts the hull of its corners' shadows, a closed
// non-convex block (two boxes) the shadows of its sun-facing faces; the same triangles each a
// block of its own (open: every face casts its shadow) cast the same shadow as a union.
TEST(IrradianceVectorFluxTest, BlockShadowsEqualTheirFacesShadows) {
  const Eigen::Vector3d sun = Eigen::Vector3d(0.4, -0.7, 0.5).normalized();
  for (const bool two_boxes : {false, true}) {
    Mesh m;
    testing::AddHorizontalRect(&m, -30, 30, -30, 30, 0, true, m.AddBlock("plaza"));
    const int block = m.AddBlock("building");
    // Tall enough for its shadow to reach beyond the plaza (the ground rays escape to).
    testing::AddBox(&m, {-5, -5, 0}, {5, 5, 40}, block);
    if (two_boxes) testing::AddBox(&m, {5, -5, 0}, {12, 0, 4}, block);
    Mesh apart = m;
    for (size_t t = 0; t < apart.triangles.size(); ++t) {
      apart.triangle_block[t] = apart.AddBlock("face" + std::to_string(t));
    }
    // One hull; the sun-facing faces (roofs, south and east sides, as quads); every triangle.
    EXPECT_EQ(GroundShadowOnPlane(m, OccluderFaces(m), sun, 0).size(), two_boxes ? 6u : 1u);
    EXPECT_EQ(GroundShadowOnPlane(apart, OccluderFaces(apart), sun, 0).size(),
              two_boxes ? 20u : 10u);
    GridOptions go;
    go.spacing_m = 8;
    const SurfaceGrid grid = BuildSurfaceGrid(m, go);
    const RayCaster rc(m);
    const HemisphereCache cache = BuildHemisphereCache(grid, rc);
    Lighting l = VaryingEnvironment(true);
    l.sun_dir = sun;
    l.sky.sun_dir = sun;
    IrradianceOptions o;
    o.method = IrradianceMethod::kVectorFlux;
    o.mesh = &m;
    const SlotIrradiance whole = ComputeIrradiance(grid, cache, rc, l, o);
    o.mesh = &apart;
    const SlotIrradiance tris = ComputeIrradiance(grid, cache, rc, l, o);
    o.ground_shadow = false;
    const SlotIrradiance none = ComputeIrradiance(grid, cache, rc, l, o);
    int shaded = 0;
    for (int i = 0; i < grid.size(); ++i) {
      // Exact clippings of the same set: equal to rounding.
      EXPECT_NEAR((whole.direct_se[i] - tris.direct_se[i]).norm(), 0,
                  1e-9 * tris.direct_se[i].norm() + 1e-12)
          << i;
      shaded += (none.direct_se[i] - tris.direct_se[i]).norm() > 1e-6 * none.direct_se[i].norm();
    }
    EXPECT_GT(shaded, 3);
  }
}

// Every grid point of `m` (spacing in metres) sees the same change of the environment's
// ground through the shadow polygons `a` as through `b`, to rounding; returns how many points
// see any change.
int ExpectSameShadowChange(const Mesh& m, const OccluderFaces& faces,
                           const std::vector<std::vector<Eigen::Vector3d>>& a,
                           const std::vector<std::vector<Eigen::Vector3d>>& b, double spacing_m) {
  Lighting l = VaryingEnvironment(true);
  const EnvironmentRegions regions(l.env, VectorFluxOptions());
  GridOptions go;
  go.spacing_m = spacing_m;
  const SurfaceGrid grid = BuildSurfaceGrid(m, go);
  const Eigen::Vector3d ratio(0.3, 0.4, 0.5);
  int changed = 0;
  EnvironmentView view;
  for (const GridPoint& p : grid.points) {
    const Eigen::Vector3d origin = p.position + 1e-4 * p.normal;
    if (!(origin.z() > 0)) continue;
    SeeEnvironment(PointVisibility(faces, origin, p.normal, p.triangle), regions, true, &view);
    const Eigen::Vector3d ea = GroundShadowChange(view, regions, l.env, origin.z(),
                                                  GroundShadowPolygons(a, origin), ratio);
    const Eigen::Vector3d eb = GroundShadowChange(view, regions, l.env, origin.z(),
                                                  GroundShadowPolygons(b, origin), ratio);
    EXPECT_NEAR((ea - eb).norm(), 0, 1e-9 * (1 + ea.norm())) << p.position.transpose();
    changed += ea.norm() > 1e-6;
  }
  return changed;
}

// The ground under a plaza is never seen from above it: the shadow falling there is cut away,
// and what is left changes each point's irradiance exactly as the whole shadow does.
TEST(IrradianceVectorFluxTest, ShadowOnThePlazaIsCutAway) {
  Mesh m;
  testing::AddHorizontalRect(&m, -30, 30, -30, 30, 0, true, m.AddBlock("plaza"));
  testing::AddBox(&m, {-5, -5, 0}, {5, 5, 40}, m.AddBlock("tower"));
  const OccluderFaces faces(m);
  auto area = [](const std::vector<std::vector<Eigen::Vector3d>>& polys) {
    double a = 0;
    for (const auto& p : polys) {
      for (size_t i = 0; i < p.size(); ++i) {
        const Eigen::Vector3d& u = p[i];
        const Eigen::Vector3d& v = p[(i + 1) % p.size()];
        a += 0.5 * (u.x() * v.y() - v.x() * u.y());
      }
    }
    return std::abs(a);
  };
  // A high sun: the whole shadow falls on the plaza.
  const Eigen::Vector3d high = Eigen::Vector3d(0.1, -0.15, 1).normalized();
  EXPECT_TRUE(ShadowBeyondGroundFaces(GroundShadowOnPlane(m, faces, high, 0), faces, 0).empty());
  // A low sun from the south-east: the shadow reaches 64 m north-west, past the plaza's edge.
  const Eigen::Vector3d sun = Eigen::Vector3d(0.4, -0.7, 0.5).normalized();
  const auto whole = GroundShadowOnPlane(m, faces, sun, 0);
  const auto cut = ShadowBeyondGroundFaces(whole, faces, 0);
  ASSERT_FALSE(cut.empty());
  EXPECT_LT(area(cut), area(whole));
  for (const auto& p : cut) {
    double outside = 0;  // how far the piece reaches beyond the plaza
    for (const auto& v : p) outside = std::max(outside, v.cwiseAbs().head<2>().maxCoeff() - 30);
    EXPECT_GT(outside, 0);
  }
  EXPECT_GT(ExpectSameShadowChange(m, faces, whole, cut, 6), 3);
}

// A modelled ground of tiles (as [ground] radius_m makes one) beside a shadow: the shadow
// meets no tile but crosses the lines through their edges, and is not cut along them. (It
// was, at every tile: a 45 m ground took a tower's solve from 8 s to 6 minutes, a 60 m one
// past 24 GB of memory.)
TEST(IrradianceVectorFluxTest, ShadowMissingEveryTileIsNotCut) {
  Mesh m;
  const int ground = m.AddBlock("ground");
  for (int i = 0; i < 12; ++i) {  // 7.5 m tiles 0.5 m apart: faces of their own
    testing::AddHorizontalRect(&m, 8 * i, 8 * i + 7.5, 0, 8, 0, true, ground);
  }
  const OccluderFaces faces(m);
  const std::vector<std::vector<Eigen::Vector3d>> shadow = {
      {{4, 20, 0}, {100, 20, 0}, {100, 30, 0}, {4, 30, 0}}};
  EXPECT_EQ(ShadowBeyondGroundFaces(shadow, faces, 0), shadow);
  // Over the tiles' corner: cut only by the tiles it meets (beyond them, and beside them).
  const std::vector<std::vector<Eigen::Vector3d>> corner = {
      {{-10, -10, 0}, {4, -10, 0}, {4, 4, 0}, {-10, 4, 0}}};
  EXPECT_LE(ShadowBeyondGroundFaces(corner, faces, 0).size(), 2u);
}

// A wall's shadow over a ground of many small faces with gaps between them would be taken into
// as many pieces as there are gaps: past a bound the cut keeps it whole, which changes no point's
// irradiance (what the faces hide, the points do not see).
TEST(IrradianceVectorFluxTest, ShadowOverManySmallFacesIsKeptWhole) {
  Mesh m;
  const int ground = m.AddBlock("ground");
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) {
      testing::AddHorizontalRect(&m, 20 + 2 * i, 21 + 2 * i, -20 + 2 * j, -19 + 2 * j, 0, true,
                                 ground);
    }
  }
  testing::AddBox(&m, {-4, -21, 0}, {4, 21, 40}, m.AddBlock("wall"));
  const OccluderFaces faces(m);
  const Eigen::Vector3d sun = Eigen::Vector3d(-1, 0, 0.5).normalized();  // low in the west
  const auto whole = MergeGroundShadow(GroundShadowOnPlane(m, faces, sun, 0));
  ASSERT_EQ(whole.size(), 1u);
  EXPECT_EQ(ShadowBeyondGroundFaces(whole, faces, 0), whole);
  EXPECT_GT(ExpectSameShadowChange(m, faces, whole, ShadowBeyondGroundFaces(whole, faces, 0), 8),
            3);
}

// MergeGroundShadow keeps the union: fewer polygons, the same shadowed ground seen from every
// point, the sunlit ground inside an open tube's shadow left out.
TEST(IrradianceVectorFluxTest, MergedGroundShadowIsTheSameUnion) {
  const Eigen::Vector3d sun = Eigen::Vector3d(0.4, -0.7, 0.5).normalized();
  auto area = [](const std::vector<std::vector<Eigen::Vector3d>>& polys) {
    double a = 0;
    for (const auto& p : polys) {
      for (size_t i = 0; i < p.size(); ++i) {
        a += 0.5 * (p[i].x() * p[(i + 1) % p.size()].y() - p[(i + 1) % p.size()].x() * p[i].y());
      }
    }
    return a;
  };
  auto apart = [](Mesh m) {  // every triangle a block of its own: every face casts a shadow
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      m.triangle_block[t] = m.AddBlock("face" + std::to_string(t));
    }
    return m;
  };
  // A closed box's ten triangles cast shadows whose union is the box's: one polygon.
  Mesh box;
  testing::AddBox(&box, {-5, -5, 0}, {5, 5, 40}, box.AddBlock("tower"));
  const auto hull = GroundShadowOnPlane(box, OccluderFaces(box), sun, 0);
  ASSERT_EQ(hull.size(), 1u);
  const Mesh box_apart = apart(box);
  const auto box_faces = GroundShadowOnPlane(box_apart, OccluderFaces(box_apart), sun, 0);
  const auto box_merged = MergeGroundShadow(box_faces);
  EXPECT_EQ(box_faces.size(), 10u);
  ASSERT_EQ(box_merged.size(), 1u);
  EXPECT_NEAR(area(box_merged), area(hull), 1e-9 * area(hull));

  // An open tube (walls, no roof, 20 m wide, 4 m tall: the sun reaches the ground inside it)
  // and a mast.
  Mesh m;
  const int tube = m.AddBlock("tube");
  const double w = 10, h = 4;
  m.AddPolygon({{-w, -w, 0}, {w, -w, 0}, {w, -w, h}, {-w, -w, h}}, tube);
  m.AddPolygon({{w, -w, 0}, {w, w, 0}, {w, w, h}, {w, -w, h}}, tube);
  m.AddPolygon({{w, w, 0}, {-w, w, 0}, {-w, w, h}, {w, w, h}}, tube);
  m.AddPolygon({{-w, w, 0}, {-w, -w, 0}, {-w, -w, h}, {-w, w, h}}, tube);
  testing::AddBox(&m, {-14, 12, 0}, {-12, 14, 30}, m.AddBlock("mast"));
  const Mesh ma = apart(m);
  const OccluderFaces faces(ma);
  const auto whole = GroundShadowOnPlane(ma, faces, sun, 0);
  const auto merged = MergeGroundShadow(whole);
  EXPECT_LT(merged.size(), whole.size());
  // The tube's centre is sunlit (its ray to the sun leaves through the open top): in no
  // polygon of either set.
  auto inside_any = [](const std::vector<std::vector<Eigen::Vector3d>>& polys, double x, double y) {
    for (const auto& p : polys) {
      double sign = 0;
      bool in = true;
      for (size_t i = 0; i < p.size() && in; ++i) {
        const Eigen::Vector3d& a = p[i];
        const Eigen::Vector3d& b = p[(i + 1) % p.size()];
        const double c = (b.x() - a.x()) * (y - a.y()) - (b.y() - a.y()) * (x - a.x());
        if (sign == 0) sign = c;
        in = c * sign > 0;
      }
      if (in) return true;
    }
    return false;
  };
  EXPECT_FALSE(inside_any(whole, 0, 0));
  EXPECT_FALSE(inside_any(merged, 0, 0));
  EXPECT_TRUE(inside_any(merged, 0, -9));  // inside the south wall, in its shadow
  // Every point sees the same shadowed ground through either set: exact clippings of one union,
  // equal to rounding.
  EXPECT_GT(ExpectSameShadowChange(m, faces, whole, merged, 3), 3);
}

TEST(IrradianceVectorFluxTest, RejectsMissingOrMismatchedMesh) {
  const BoxScene s;
  const HemisphereCache cache = BuildHemisphereCache(s.grid, *s.rc);
  IrradianceOptions vf;
  vf.method = IrradianceMethod::kVectorFlux;
  EXPECT_THROW(ComputeIrradiance(s.grid, cache, *s.rc, VaryingEnvironment(false), vf), Error);
  Mesh other;
  testing::AddHorizontalRect(&other, 0, 1, 0, 1, 0, true, other.AddBlock("x"));
  vf.mesh = &other;
  EXPECT_THROW(ComputeIrradiance(s.grid, cache, *s.rc, VaryingEnvironment(false), vf), Error);
  vf.mesh = &s.mesh;
  vf.vector_flux.sky_tolerance = -1;
  EXPECT_THROW(ComputeIrradiance(s.grid, cache, *s.rc, VaryingEnvironment(false), vf), Error);
}

}  // namespace
}  // namespace rouen
