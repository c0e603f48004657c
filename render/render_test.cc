#include "render/render.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/angles.h"
#include "core/error.h"
#include "solve/retro.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

struct Fixture {
  Mesh mesh;
  SurfaceGrid grid;
  std::unique_ptr<RayCaster> rc;
  HemisphereCache cache;
  Lighting lighting;
  SlotIrradiance irr;
  AlbedoResult albedo;
};

// A plaza under a uniform unit sky with the sun at the zenith and a small slab floating 8 m
// above the origin: its shadow is the square |x|, |y| < 0.5 on the plaza.
Fixture Make() {
  Fixture f;
  const int plaza = f.mesh.AddBlock("plaza");
  const int slab = f.mesh.AddBlock("slab");
  testing::AddHorizontalRect(&f.mesh, -40, 40, -40, 40, 0, true, plaza);
  testing::AddBox(&f.mesh, {-0.5, -0.5, 8}, {0.5, 0.5, 8.5}, slab, true);
  GridOptions go;
  go.block_spacing_m["plaza"] = 2.0;
  f.grid = BuildSurfaceGrid(f.mesh, go);
  f.rc = std::make_unique<RayCaster>(f.mesh);
  HemisphereOptions ho;
  ho.directions = 64;
  f.cache = BuildHemisphereCache(f.grid, *f.rc, ho);
  f.lighting.sun_dir = Eigen::Vector3d::UnitZ();
  f.lighting.sun_radiance = Eigen::Vector3d(1e4, 1e4, 1e4);
  f.lighting.sun_solid_angle_sr = 6.8e-5;
  f.lighting.sky = SkyModel();  // Lz = 1, flat
  f.lighting.env = EnvironmentMap::Constant(EnvOptions(), {1, 1, 1}, {0, 0, 0});
  f.irr = ComputeIrradiance(f.grid, f.cache, *f.rc, f.lighting);
  f.albedo.rho_sun.assign(f.grid.size(), Eigen::Vector3d(0.5, 0.5, 0.5));
  f.albedo.rho_se.assign(f.grid.size(), Eigen::Vector3d(0.3, 0.2, 0.1));
  return f;
}

TEST(RenderTest, LitShadowedSkyAndSun) {
  const Fixture f = Make();
  const Intrinsics k = Intrinsics::PinholeFov(160, 120, 60);
  const Pose pose = Pose::LookAt({0, -15, 10}, {0, 0, 0});
  RenderStats stats;
  const Image img = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose,
                               RenderOptions(), &stats);
  EXPECT_EQ(img.units, PixelUnits::kRadiance);
  EXPECT_GT(stats.rays, 0);
  const Image ids = RenderBlockIds(f.mesh, *f.rc, k, pose);
  const double e_sun = 1e4 * 6.8e-5;
  int lit = 0, shadow = 0;
  for (int y = 0; y < 120; ++y) {
    for (int x = 0; x < 160; ++x) {
      const Eigen::Vector3d d = (pose.rotation * Unproject(k, {x + 0.5, y + 0.5})).normalized();
      const RayHit h = f.rc->Intersect(pose.position, d);
      ASSERT_TRUE(h.hit);  // the camera looks down at the plaza only
      EXPECT_EQ(static_cast<int>(ids.at(x, y)), f.mesh.triangle_block[h.triangle]);
      if (f.mesh.triangle_block[h.triangle] != 0) continue;
      const Eigen::Vector3d p = pose.position + h.t * d;
      // Unoccluded plaza: E_se = pi (less the slab's < 0.5% of the sky, which 64 directions
      // see as 0 or 1/64).
      if (std::abs(p.x()) > 3 || std::abs(p.y()) > 3) {
        for (int c = 0; c < 3; ++c) {
          const double expect = (0.5 * e_sun + f.albedo.rho_se[0][c] * kPi) / kPi;
          EXPECT_NEAR(img.at(x, y, c), expect, 0.02 * expect);
        }
        ++lit;
      } else if (std::abs(p.x()) < 0.4 && std::abs(p.y()) < 0.4) {
        for (int c = 0; c < 3; ++c) {
          const double expect = f.albedo.rho_se[0][c];  // no sun, E_se ~ pi (slab: -1.6%)
          EXPECT_NEAR(img.at(x, y, c), expect, 0.03 * expect);
        }
        ++shadow;
      }
    }
  }
  EXPECT_GT(lit, 1000);
  EXPECT_GT(shadow, 5);
  // Supersampling keeps flat regions unchanged.
  RenderOptions ss;
  ss.supersample = 2;
  ss.interpolate = false;
  const Image img2 = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, ss);
  EXPECT_NEAR(img2.at(5, 110, 1), img.at(5, 110, 1), 0.01 * img.at(5, 110, 1));
  // Looking straight up: the sun disc in the centre, the unit sky around it.
  const Intrinsics up_k = Intrinsics::PinholeFov(101, 101, 20);
  const Pose up = Pose::LookAt({5, 5, 1}, {5, 5, 100});
  const Image sky = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, up_k, up);
  EXPECT_NEAR(sky.at(50, 50, 0), 1e4, 1e-6);
  EXPECT_NEAR(sky.at(5, 5, 0), 1.0, 1e-9);
  const Image up_ids = RenderBlockIds(f.mesh, *f.rc, up_k, up);
  EXPECT_EQ(up_ids.at(5, 5), -1);
  const std::vector<uint8_t> mask = BlockMask(ids, {0});
  EXPECT_EQ(mask[(119) * 160 + 80], 1);
}

TEST(RenderTest, AdaptiveSupersamplingAgreesWithFullAndCastsFewerRays) {
  Fixture f = Make();
  // An albedo that varies across the plaza (bilinear between grid points).
  for (int i = 0; i < f.grid.size(); ++i) {
    const double x = f.grid.points[i].position.x();
    f.albedo.rho_se[i] = Eigen::Vector3d(0.3, 0.2, 0.1) * (1 + 0.02 * x);
  }
  const Intrinsics k = Intrinsics::PinholeFov(160, 120, 60);
  const Pose pose = Pose::LookAt({0, -15, 10}, {0, 0, 0});
  RenderOptions full;
  full.adaptive = false;
  RenderStats s_full, s_adaptive;
  const Image a =
      RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, full, &s_full);
  const Image b = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose,
                             RenderOptions{}, &s_adaptive);
  // The shadow's edge and the slab's silhouette are supersampled in both; elsewhere the pixel
  // mean of a field linear within a grid cell is its centre value, so they differ only where a
  // pixel straddles a cell boundary (slope change 4%/m over a pixel of at most 0.25 m: < 1%).
  double worst = 0, mean = 0;
  for (size_t i = 0; i < a.data.size(); ++i) {
    const double r = std::abs(b.data[i] / a.data[i] - 1);
    worst = std::max(worst, r);
    mean += r / a.data.size();
  }
  EXPECT_LT(worst, 0.01);
  EXPECT_LT(mean, 1e-3);
  EXPECT_LT(s_adaptive.rays, s_full.rays / 4);
}

// The grid points a view shades: every point a supersampled render reads (the stencil of each
// of its 4 x 4 rays per pixel) is flagged, but for the corner of a sub-triangle poking between
// the rays cast, whose weight is small: under 1% of one ray's value, so that the Monte Carlo
// estimate such a point keeps (2.9% noise) moves no pixel by more than 2e-5. The slab's
// underside, which the camera above it cannot see, and the plaza behind the camera are not.
TEST(RenderTest, GridPointsInViewAreThePointsTheRenderReads) {
  const Fixture f = Make();
  const Intrinsics k = Intrinsics::PinholeFov(160, 120, 60);
  const Pose pose = Pose::LookAt({0, -15, 10}, {0, 0, 0});
  const std::vector<uint8_t> seen = GridPointsInView(f.grid, *f.rc, k, pose);
  ASSERT_EQ(static_cast<int>(seen.size()), f.grid.size());
  int read = 0;
  double worst_missed = 0;  // the largest weight a ray puts on an unflagged point
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      for (int a = 0; a < 4; ++a) {
        for (int b = 0; b < 4; ++b) {
          const Eigen::Vector3d d =
              (pose.rotation * Unproject(k, Eigen::Vector2d(x + (b + 0.5) / 4, y + (a + 0.5) / 4)))
                  .normalized();
          const RayHit hit = f.rc->Intersect(pose.position, d, 0.0);
          if (!hit.hit) continue;
          const GridStencil st = f.grid.Stencil(hit.triangle, hit.u, hit.v);
          for (int m = 0; m < st.count; ++m) {
            ++read;
            if (!seen[st.index[m]]) worst_missed = std::max(worst_missed, st.weight[m]);
          }
        }
      }
    }
  }
  EXPECT_GT(read, 0);
  EXPECT_LT(worst_missed, 0.01);
  int underside = 0, behind = 0, flagged = 0;
  for (int i = 0; i < f.grid.size(); ++i) {
    const GridPoint& p = f.grid.points[i];
    flagged += seen[i];
    if (p.normal.z() < -0.5 && p.position.z() > 7) underside += seen[i];
    if (p.position.z() < 0.1 && p.position.y() < -17) behind += seen[i];
  }
  EXPECT_EQ(underside, 0);
  EXPECT_EQ(behind, 0);
  EXPECT_LT(flagged, f.grid.size());
}

// The sun as a disc: with a sun 6 deg across (its disc at the slab's height 8 m up a circle of
// r = 8 tan 3 deg = 0.42 m round the plaza point), the shadow of the 1 m slab is a penumbra whose
// visible part of the disc is the circle's area outside the slab's square: 0 under its middle,
// 1/2 under its edge, 1 - (r^2 acos(d/r) - d sqrt(r^2 - d^2)) / (pi r^2) at d = 0.25 m outside
// it (0.855), 1 beyond r. A point sun's shadow is crisp: 1 and 0 there.
TEST(RenderTest, TheSunsDiscCastsAPenumbra) {
  Fixture f = Make();
  const double radius = 3 * kDeg;
  f.lighting.sun_solid_angle_sr = 2 * kPi * (1 - std::cos(radius));
  for (Eigen::Vector3d& rho : f.albedo.rho_se) rho.setZero();  // the sun term alone
  const Intrinsics k = Intrinsics::PinholeFov(160, 120, 60);
  const Pose pose = Pose::LookAt({0, -15, 10}, {0, 0, 0});
  const double r = 8 * std::tan(radius), d = 0.25;
  const double outside =
      1 - (r * r * std::acos(d / r) - d * std::sqrt(r * r - d * d)) / (kPi * r * r);
  const double full = 0.5 * 1e4 * f.lighting.sun_solid_angle_sr / kPi;  // rho_sun E_sun / pi
  auto visible_at = [&](const Image& img, double x) {
    const auto px = Project(k, pose.WorldToCamera(Eigen::Vector3d(x, 0, 0)));
    EXPECT_TRUE(px.has_value());
    return img.at(static_cast<int>(px->x()), static_cast<int>(px->y()), 1) / full;
  };
  const Image soft =
      RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, RenderOptions{});
  // 16 points of the disc per pixel: the fraction to about 1/16.
  EXPECT_NEAR(visible_at(soft, 0.0), 0.0, 0.07);
  EXPECT_NEAR(visible_at(soft, 0.5), 0.5, 0.07);
  EXPECT_NEAR(visible_at(soft, 0.5 + d), outside, 0.07);
  EXPECT_NEAR(visible_at(soft, 0.5 + r + 0.1), 1.0, 1e-6);  // float pixels
  RenderOptions point;
  point.soft_shadows = false;
  const Image crisp =
      RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, point);
  EXPECT_NEAR(visible_at(crisp, 0.2), 0.0, 1e-6);
  EXPECT_NEAR(visible_at(crisp, 0.5 + d), 1.0, 1e-6);
}

// Pixel (80, 100) of a grazing view of the plaza (block 0), green, rendered Lambertian and with
// the plaza's retro 1 (the slab has no entry: Lambertian), and the ray to it.
struct RetroPixel {
  double lambert = 0, rough = 0;
  Eigen::Vector3d dir;
  int point = -1;  // the grid point the pixel reads (no interpolation)
};
RetroPixel RenderPlazaPixel(Fixture* f) {
  const Intrinsics k = Intrinsics::PinholeFov(160, 120, 60);
  const Pose pose = Pose::LookAt({0, -15, 3}, {0, 0, 0});
  RenderOptions o;
  o.interpolate = false;
  o.supersample = 1;
  RetroPixel out;
  f->albedo.retro.clear();
  out.lambert = RenderView(f->mesh, f->grid, *f->rc, f->albedo, f->lighting, f->irr, k, pose, o)
                    .at(80, 100, 1);
  f->albedo.retro = {1.0};
  out.rough = RenderView(f->mesh, f->grid, *f->rc, f->albedo, f->lighting, f->irr, k, pose, o)
                  .at(80, 100, 1);
  out.dir = (pose.rotation * Unproject(k, Eigen::Vector2d(80.5, 100.5))).normalized();
  const RayHit h = f->rc->Intersect(pose.position, out.dir);
  EXPECT_TRUE(h.hit && f->mesh.triangle_block[h.triangle] == 0);
  out.point = f->grid.NearestPoint(h.triangle, h.u, h.v);
  return out;
}

TEST(RenderTest, TheSunTermFollowsTheBlocksRetro) {
  Fixture f = Make();
  f.albedo.rho_se.assign(f.grid.size(), Eigen::Vector3d::Zero());  // the sun's term alone
  const RetroPixel px = RenderPlazaPixel(&f);
  const double want =
      RetroFactor(1.0, Eigen::Vector3d::UnitZ(), f.lighting.sun_dir, -px.dir) * px.lambert;
  EXPECT_NEAR(px.rough, want, 1e-5 * want);
  EXPECT_GT(px.rough, 1.02 * px.lambert);  // grazing: brighter (1.04)
}

TEST(RenderTest, TheSkyTermFollowsTheBlocksAmbientRetro) {
  Fixture f = Make();
  f.albedo.rho_sun.assign(f.grid.size(), Eigen::Vector3d::Zero());  // the sky's term alone
  const RetroPixel px = RenderPlazaPixel(&f);
  ASSERT_GT(px.lambert, 0);
  // The factor of the light as it arrives at the pixel's grid point (the slab hides part of
  // the sky from it): where it comes from matters, not only how much.
  ASSERT_GE(px.point, 0);
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  const double want =
      AmbientRetroFactor(1.0, up, -px.dir, LightAt(f.irr.se_light, px.point, up)) * px.lambert;
  EXPECT_NEAR(px.rough, want, 1e-5 * want);
  // An oblique view of a rough plaza is brighter under sky light too (1.067 at this pixel
  // under a whole uniform sky).
  EXPECT_GT(px.rough, 1.05 * px.lambert);
}

TEST(RenderTest, TheSunLobeAddsItsHighlight) {
  Fixture f = Make();
  const Intrinsics k = Intrinsics::PinholeFov(160, 120, 60);
  const Pose pose = Pose::LookAt({0, -15, 3}, {0, 0, 0});
  RenderOptions o;
  o.interpolate = false;
  o.supersample = 1;
  const Image matte = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, o);
  SpecularLobe lobe;
  lobe.rho_s = Eigen::Vector3d(0.05, 0.06, 0.07);
  lobe.kappa = 1;
  lobe.n = 3;
  f.albedo.sun_lobes = {lobe};  // the plaza (block 0); the slab: none
  const Image glossy = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, o);
  const Eigen::Vector2d px(80.5, 100.5);
  const Eigen::Vector3d d = (pose.rotation * Unproject(k, px)).normalized();
  const RayHit h = f.rc->Intersect(pose.position, d);
  ASSERT_TRUE(h.hit);
  ASSERT_EQ(f.mesh.triangle_block[h.triangle], 0);
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ(), s = f.lighting.sun_dir.normalized();
  // Eq. 13's lobe under the sun's irradiance on the surface, added to the diffuse radiance.
  const Eigen::Vector3d e = f.lighting.sun_radiance * f.lighting.sun_solid_angle_sr * n.dot(s);
  const Eigen::Vector3d add = lobe.Eval(n, s, -d).cwiseProduct(e);
  ASSERT_GT(add[1], 0.01 * matte.at(80, 100, 1));
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(glossy.at(80, 100, c), matte.at(80, 100, c) + add[c], 1e-5 * glossy.at(80, 100, c));
  // The slab has no lobe: its pixels are unchanged (a view that looks at it).
  const Pose up = Pose::LookAt({0, -12, 4}, {0, 0, 8});
  f.albedo.sun_lobes.clear();
  const Image matte_up = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, up, o);
  f.albedo.sun_lobes = {lobe};
  const Image glossy_up = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, up, o);
  int slab = 0;
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d dd =
          (up.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
      const RayHit hh = f.rc->Intersect(up.position, dd);
      if (!hh.hit || f.mesh.triangle_block[hh.triangle] == 0) continue;
      ++slab;
      EXPECT_EQ(glossy_up.at(x, y, 1), matte_up.at(x, y, 1));
    }
  }
  EXPECT_GT(slab, 0);
}

// §4.2.1: under the fixture's uniform unit sky, a lobe seen along the normal reflects
// rho_s times the integral of cos^n(angle to the normal) cos(theta) over the hemisphere,
// rho_s 2 pi / (n + 2) exactly; the renderer scales the lobe's directional albedo by the mean
// radiance its draws meet (here the sky's 1).
TEST(RenderTest, TheSkyLobeReflectsTheSky) {
  Fixture f = Make();
  const Intrinsics k = Intrinsics::PinholeFov(9, 9, 2);
  const Pose pose = Pose::LookAt({20, 19.99, 25}, {20, 20, 0});  // straight down, off the slab
  RenderOptions o;
  o.supersample = 1;
  const Image matte = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, o);
  SpecularLobe lobe;
  lobe.rho_s = Eigen::Vector3d(0.1, 0.2, 0.3);
  lobe.n = 10;
  f.albedo.sky_lobes = {lobe};
  const Image glossy = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, o);
  for (int c = 0; c < 3; ++c) {
    const double want = lobe.rho_s[c] * 2 * kPi / (lobe.n + 2);
    // The lobe's directional albedo (a quadrature within 1%, specular_test) times the uniform
    // sky's radiance, whatever the draws.
    EXPECT_NEAR(glossy.at(4, 4, c) - matte.at(4, 4, c), want, 0.01 * want) << c;
  }
  // The microfacet lobe under the same uniform sky: rho_s times its integral against the
  // cosine, by a fine quadrature over the hemisphere (within the directional albedo's 1%).
  lobe.model = LobeModel::kMicrofacet;
  lobe.n = 48;  // alpha 0.2
  f.albedo.sky_lobes = {lobe};
  const Image micro = RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, o);
  const Eigen::Vector3d up(0, 0, 1);
  double integral = 0;
  constexpr int kTheta = 2000, kPhi = 90;
  for (int i = 0; i < kTheta; ++i) {
    const double t = (i + 0.5) * (kPi / 2) / kTheta;
    for (int j = 0; j < kPhi; ++j) {
      const double p = (j + 0.5) * 2 * kPi / kPhi;
      const Eigen::Vector3d u(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
      integral += lobe.Shape(up, u, up) * std::cos(t) * std::sin(t);
    }
  }
  integral *= (kPi / 2 / kTheta) * (2 * kPi / kPhi);
  for (int c = 0; c < 3; ++c) {
    const double want = lobe.rho_s[c] * integral;
    EXPECT_NEAR(micro.at(4, 4, c) - matte.at(4, 4, c), want, 0.01 * want) << c;
  }
  RenderOptions bad;
  bad.sky_lobe_samples = 0;
  EXPECT_THROW(bad.Validate(), Error);
}

// §4.2.1 with the model in the lobe: a glossy plaza before a wall reflects the wall where the
// lobe looks at it, the wall's diffuse radiance (rho_sun E_sun + rho_se E_se) / pi through the
// lobe, as the albedo solve's lobe light has it; not the black of a blocked sky.
TEST(RenderTest, TheSkyLobeReflectsTheWallsItLooksAt) {
  Mesh mesh;
  const int plaza = mesh.AddBlock("plaza"), wall = mesh.AddBlock("wall");
  testing::AddHorizontalRect(&mesh, -40, 40, -40, 40, 0, true, plaza);
  testing::AddBox(&mesh, {-30, 3, 0}, {30, 4, 30}, wall);
  GridOptions go;
  go.spacing_m = 1;
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, go);
  const RayCaster rc(mesh);
  Lighting lighting;
  lighting.sun_dir = Eigen::Vector3d::UnitZ();
  lighting.sun_radiance.setZero();
  lighting.sky = SkyModel();
  lighting.env = EnvironmentMap::Constant(EnvOptions(), {1, 1, 1}, {0, 0, 0});
  // The wall's south face sends (3, 2, 1) (rho_se E_se / pi); nothing else matters here.
  SlotIrradiance irr;
  irr.sun.assign(grid.size(), Eigen::Vector3d::Zero());
  irr.direct_se.assign(grid.size(), Eigen::Vector3d::Constant(1));
  irr.se = irr.direct_se;
  irr.sun_visibility.assign(grid.size(), 0.f);
  AlbedoResult albedo;
  albedo.rho_sun.assign(grid.size(), Eigen::Vector3d::Constant(0.5));
  albedo.rho_se.assign(grid.size(), Eigen::Vector3d(0.3, 0.2, 0.1));
  for (int i = 0; i < grid.size(); ++i)
    if (grid.points[i].block == wall) irr.se[i] = Eigen::Vector3d::Constant(10 * kPi);
  // The plaza point at the origin seen from 45 deg above the south: its mirror direction
  // meets the wall 3 m up, a 100-exponent lobe (about 8 deg wide) all on the wall.
  const Intrinsics k = Intrinsics::PinholeFov(9, 9, 2);
  const Pose pose = Pose::LookAt({0, -6, 6}, {0, 0, 0});
  RenderOptions o;
  o.supersample = 1;
  const Image matte = RenderView(mesh, grid, rc, albedo, lighting, irr, k, pose, o);
  SpecularLobe lobe;
  lobe.rho_s = Eigen::Vector3d(0.1, 0.2, 0.3);
  lobe.n = 100;
  albedo.sky_lobes = {lobe, SpecularLobe()};
  const Image glossy = RenderView(mesh, grid, rc, albedo, lighting, irr, k, pose, o);
  // rho_s (3, 2, 1) times the lobe's integral against the cosine, by quadrature.
  const Eigen::Vector3d up(0, 0, 1), v = Eigen::Vector3d(0, -1, 1).normalized();
  double integral = 0;
  constexpr int kTheta = 900, kPhi = 1440;
  for (int i = 0; i < kTheta; ++i) {
    const double t = (i + 0.5) * (kPi / 2) / kTheta;
    for (int j = 0; j < kPhi; ++j) {
      const double p = (j + 0.5) * 2 * kPi / kPhi;
      const Eigen::Vector3d u(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
      integral += lobe.Shape(up, u, v) * std::cos(t) * std::sin(t);
    }
  }
  integral *= (kPi / 2 / kTheta) * (2 * kPi / kPhi);
  const Eigen::Vector3d wall_radiance(3, 2, 1);
  for (int c = 0; c < 3; ++c) {
    const double want = lobe.rho_s[c] * wall_radiance[c] * integral;
    // The lobe's directional albedo (within 1%, specular_test) times the mean radiance its
    // draws meet, all on the wall: the render's 16 draws (the default) suffice.
    EXPECT_NEAR(glossy.at(4, 4, c) - matte.at(4, 4, c), want, 0.01 * want) << c;
  }
}

TEST(RenderTest, BadInputThrows) {
  Fixture f = Make();
  const Intrinsics k = Intrinsics::PinholeFov(16, 12, 60);
  const Pose pose = Pose::LookAt({0, -15, 10}, {0, 0, 0});
  AlbedoResult a = f.albedo;
  a.rho_se.pop_back();
  EXPECT_THROW(RenderView(f.mesh, f.grid, *f.rc, a, f.lighting, f.irr, k, pose), Error);
  RenderOptions o;
  o.supersample = 0;
  EXPECT_THROW(RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, k, pose, o), Error);
  Intrinsics bad = k;
  bad.width = 0;
  EXPECT_THROW(RenderView(f.mesh, f.grid, *f.rc, f.albedo, f.lighting, f.irr, bad, pose), Error);
}

}  // namespace
}  // namespace rouen
