#include "solve/vector_flux_cache.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "core/angles.h"
#include "core/error.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

// Two buildings on a plaza: a tall box, a low box behind it, a small box hidden inside the
// tall one's shadow region seen from the test points, and the ground.
Mesh Street() {
  Mesh m;
  const int b = m.AddBlock("b");
  testing::AddBox(&m, {0, 0, 0}, {6, 4, 12}, b);
  testing::AddBox(&m, {-10, 8, 0}, {-2, 14, 5}, b);
  testing::AddBox(&m, {2, 5, 0}, {3, 6, 1}, b);
  testing::AddHorizontalRect(&m, -30, 30, -30, 30, 0, true, m.AddBlock("ground"));
  return m;
}

TEST(VectorFluxCacheTest, TreeTilesTheHemisphere) {
  const SkyPatchTree tree(3);
  EXPECT_EQ(tree.num_nodes(), 4 + 16 + 64 + 256);
  for (int l = 0; l <= tree.levels(); ++l) {
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    for (int k = tree.level_offset(l); k < tree.level_offset(l + 1); ++k) phi += tree.flux(k);
    // Integral of w over the upper hemisphere: pi z.
    EXPECT_NEAR((phi - kPi * Eigen::Vector3d::UnitZ()).norm(), 0, 1e-12) << l;
  }
  EXPECT_EQ(tree.FirstChild(0, 0), 4);
  EXPECT_EQ(tree.FirstChild(tree.level_offset(3), 3), -1);
  EXPECT_THROW(SkyPatchTree(-1), Error);
  EXPECT_THROW(SkyPatchTree(SkyPatchTree::kMaxLevels + 1), Error);
}

TEST(VectorFluxCacheTest, UniformSkyIsExactWithOccluders) {
  // Uniform radiance: whole nodes and partly visible nodes are both exact, so the cached sum
  // equals the analytic form factor result (float weights: ~1e-7 relative).
  const double a = 3, b = 2, h = 1.5;
  Mesh m;
  testing::AddHorizontalRect(&m, 0, a, 0, b, h, false, m.AddBlock("ceiling"));
  const double A = a / h, B = b / h;
  const double F = (A / std::sqrt(1 + A * A) * std::atan(B / std::sqrt(1 + A * A)) +
                    B / std::sqrt(1 + B * B) * std::atan(A / std::sqrt(1 + B * B))) /
                   (2 * kPi);
  const PointVisibility pv(m, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  const SkyPatchTree tree(5);
  const SkyTreeRadiance sky(tree, testing::UniformSkyModel(2), VectorFluxOptions());
  PointFluxCache c;
  CacheSky(pv, tree, &c);
  EXPECT_GT(c.partial_nodes, 0);
  const Eigen::Vector3d e = EvaluateSky(c, sky);
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(e[ch], 2 * kPi * (1 - F), 2 * kPi * 1e-6);
  // Tilted planes, no occluder: pi L (1 + cos tilt) / 2.
  const Mesh empty;
  for (double tilt_deg : {30.0, 90.0, 150.0}) {
    const double t = tilt_deg * kPi / 180;
    const Eigen::Vector3d n(std::sin(t), 0.3 * std::sin(t), std::cos(t));
    const PointVisibility tv(empty, Eigen::Vector3d::Zero(), n.normalized());
    CacheSky(tv, tree, &c);
    const double cos_tilt = n.normalized().z();
    EXPECT_NEAR(EvaluateSky(c, sky).x(), 2 * kPi * (1 + cos_tilt) / 2, 2 * kPi * 1e-6) << tilt_deg;
  }
}

TEST(VectorFluxCacheTest, CachedSkyMatchesAdaptiveUncached) {
  const Mesh m = Street();
  const SkyModel sky = testing::ClearSky(Eigen::Vector3d(0.4, -0.5, 0.5));
  VectorFluxOptions fine;
  fine.sky_tolerance = 0.02;
  const SkyPatchTree tree(6);
  const SkyTreeRadiance st(tree, sky, VectorFluxOptions());
  struct Probe {
    Eigen::Vector3d o, n;
  };
  const std::vector<Probe> probes = {{{3, -3, 0.01}, {0, 0, 1}},
                                     {{3, -0.01, 6}, {0, -1, 0}},
                                     {{-6, 7.99, 2}, {0, -1, 0}},
                                     {{8, 2, 0.01}, {0, 0, 1}}};
  PointFluxCache c;
  for (const auto& p : probes) {
    const PointVisibility vis(m, p.o, p.n);
    const Eigen::Vector3d ref = SkyIrradianceVectorFlux(vis, sky, fine);
    CacheSky(vis, tree, &c);
    const Eigen::Vector3d e = EvaluateSky(c, st);
    for (int ch = 0; ch < 3; ++ch) {
      // Whole nodes: exact up to G's quadrature (midpoint on pieces within 10% radiance
      // spread: ~1e-3 at worst); partly visible 1.4-degree nodes: their mean radiance.
      EXPECT_NEAR(e[ch] / ref[ch], 1, 2e-3) << p.o.transpose() << " ch " << ch;
    }
  }
}

// SeeEnvironment clips each region only against the occluders EnvironmentRegions::Near
// finds for it; every region clipped against every occluder must give the same irradiance.
TEST(VectorFluxCacheTest, EnvironmentViewEqualsClippingByEveryOccluder) {
  const Mesh m = Street();
  EnvironmentMap env =
      EnvironmentMap::Constant(EnvOptions(), Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(0, 0, 0));
  for (int r = 0; r < env.num_regions(); ++r) {
    env.radiance[r] = Eigen::Vector3d(0.5 + 0.3 * std::sin(r), 1 + 0.2 * std::cos(r), 0.7);
  }
  const EnvironmentRegions regions(env, VectorFluxOptions());
  EnvironmentView view;
  int occluded = 0;
  for (const auto& [o, n] : {std::pair{Eigen::Vector3d(3, -3, 0.01), Eigen::Vector3d(0, 0, 1)},
                             {Eigen::Vector3d(3, -0.01, 6), Eigen::Vector3d(0, -1, 0)},
                             {Eigen::Vector3d(-6, 7.99, 2), Eigen::Vector3d(0, -1, 0)},
                             {Eigen::Vector3d(1, 4.01, 0.5), Eigen::Vector3d(0, 1, 0)},
                             {Eigen::Vector3d(-2.01, 10, 4.9), Eigen::Vector3d(1, 0, 0)}}) {
    const PointVisibility vis(m, o, n);
    occluded += vis.num_occluders() > 0;
    Eigen::Vector3d ref = Eigen::Vector3d::Zero();
    for (int r = 0; r < regions.size(); ++r) {
      std::vector<SphericalPolygon> pieces;
      vis.Clip(regions.polygon(r), &pieces);
      for (const auto& p : pieces) ref += env.radiance[r] * n.dot(VectorFlux(p));
    }
    SeeEnvironment(vis, regions, false, &view);
    EXPECT_NEAR((EnvironmentIrradiance(view, env, 0) - ref).norm(), 0, 1e-12 * ref.norm())
        << o.transpose();
  }
  EXPECT_GE(occluded, 4);
  // A view of a larger map is refused by a smaller one.
  view.region.push_back(env.num_regions());
  view.flux.push_back(view.normal);
  EXPECT_THROW(EnvironmentIrradiance(view, env, 0), Error);
}

// EnvironmentRegions::Near bounds a convex polygon by its elevations and azimuths: every
// region the polygon meets (a clipped piece of more than rounding, |Phi| > 1e-12 sr) is listed,
// for polygons anywhere: round a pole, across north (azimuth 0) and south (+-180 deg), on the
// horizon, small and up to about 80 degrees across.
TEST(VectorFluxCacheTest, EnvironmentRegionsNearListsEveryRegionAPolygonMeets) {
  const EnvironmentMap env =
      EnvironmentMap::Constant(EnvOptions(), Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, 1, 1));
  const EnvironmentRegions regions(env, VectorFluxOptions());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> centres = {Eigen::Vector3d::UnitZ(), -Eigen::Vector3d::UnitZ(),
                                          Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitY(),
                                          Eigen::Vector3d(1, 0, 0.01).normalized()};
  for (int k = 0; k < 60; ++k) {
    const double z = 2 * u(rng) - 1, phi = 2 * kPi * u(rng);
    const double r = std::sqrt(1 - z * z);
    centres.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
  }
  int tested = 0;
  for (size_t k = 0; k < centres.size(); ++k) {
    const Eigen::Vector3d c = centres[k];
    Eigen::Vector3d t =
        c.cross(std::abs(c.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX());
    t.normalize();
    const Eigen::Vector3d b = c.cross(t);
    const double radius = (k % 3 == 0 ? 0.02 : 0.7) * (0.2 + u(rng));
    const int corners = 3 + static_cast<int>(k % 4);
    SphericalPolygon poly;
    for (int i = 0; i < corners; ++i) {
      const double a = 2 * kPi * (i + 0.3 * u(rng)) / corners;
      poly.push_back((c + std::tan(radius) * (std::cos(a) * t + std::sin(a) * b)).normalized());
    }
    ConvexSpherical q;
    ASSERT_TRUE(q.Set(poly)) << k;
    std::vector<int> near;
    regions.Near(q, &near);
    std::sort(near.begin(), near.end());
    for (int r = 0; r < regions.size(); ++r) {
      std::vector<SphericalPolygon> outside, inside;
      SubtractConvex(regions.polygon(r), q, &outside, &inside);
      Eigen::Vector3d phi = Eigen::Vector3d::Zero();
      for (const auto& p : inside) phi += VectorFlux(p);
      if (phi.norm() <= 1e-12) continue;
      ++tested;
      EXPECT_TRUE(std::binary_search(near.begin(), near.end(), r))
          << "polygon " << k << " about " << c.transpose() << " meets region " << r;
    }
  }
  EXPECT_GT(tested, 500);
}

TEST(VectorFluxCacheTest, OccluderSelectionAgreesWithAllFaces) {
  const Mesh m = Street();
  const RayCaster rc(m);
  const FaceAdjacency adj(m);
  const SkyModel sky = testing::UniformSkyModel(1);
  const SkyPatchTree tree(5);
  const SkyTreeRadiance st(tree, sky, VectorFluxOptions());
  OccluderSelectOptions so;
  so.resolution = 32;
  // A face the id buffer misses shares no corner with a face it sees and holds less than
  // about a pixel of unoccluded view: pi / 32^2 sr of projected solid angle each; allow 4.
  const double bound = 4 * kPi / (so.resolution * so.resolution);
  int selected_total = 0, all_total = 0;
  for (const auto& [o, n] : {std::pair{Eigen::Vector3d(3, -3, 0.01), Eigen::Vector3d(0, 0, 1)},
                             {Eigen::Vector3d(2.5, 4.01, 0.5), Eigen::Vector3d(0, 1, 0)},
                             {Eigen::Vector3d(-6, 7.99, 2), Eigen::Vector3d(0, -1, 0)},
                             {Eigen::Vector3d(6.01, 2, 3), Eigen::Vector3d(1, 0, 0)},
                             {Eigen::Vector3d(-4, 3, 0.01), Eigen::Vector3d(0, 0, 1)}}) {
    int rays = 0;
    const std::vector<int> cand = SelectOccluders(m, rc, adj, o, n, -1, so, &rays);
    EXPECT_EQ(rays, so.resolution * so.resolution);
    EXPECT_TRUE(std::is_sorted(cand.begin(), cand.end()));
    const PointVisibility sel(m, o, n, -1, cand), all(m, o, n);
    selected_total += sel.num_occluders() + sel.num_culled();
    all_total += all.num_occluders() + all.num_culled();
    PointFluxCache a, b;
    CacheSky(sel, tree, &a);
    CacheSky(all, tree, &b);
    const double ea = EvaluateSky(a, st).x(), eb = EvaluateSky(b, st).x();
    EXPECT_NEAR(ea, eb, bound) << o.transpose();
    // Missing an occluder can only add light.
    EXPECT_GE(ea, eb - 1e-6) << o.transpose();
  }
  // Faces hidden behind nearer ones are culled, by the id buffer and (exactly, inside a
  // single face's projection) by PointVisibility itself.
  EXPECT_LT(selected_total, all_total);
  const PointVisibility plaza(m, {3, -3, 0.01}, {0, 0, 1});
  EXPECT_GE(plaza.num_culled(), 4);  // at least the small box's faces towards the point
  // The small box (faces 20..29) is in front of the plaza point south of the tall box but
  // hidden from it by the tall box.
  const std::vector<int> hidden = SelectOccluders(m, rc, adj, {3, -3, 0.01}, {0, 0, 1}, -1, so);
  for (int t : hidden) EXPECT_TRUE(t < 20 || t >= 30) << t;
}

// The street on a 3 m grid with a 16-direction hemisphere cache.
struct StreetGrid {
  Mesh m = Street();
  RayCaster rc{m};
  SurfaceGrid grid;
  HemisphereCache cache;
  StreetGrid() {
    GridOptions go;
    go.spacing_m = 3.0;
    grid = BuildSurfaceGrid(m, go);
    HemisphereOptions ho;
    ho.directions = 16;
    cache = BuildHemisphereCache(grid, rc, ho);
  }
};

// A clear sky with its sun, the environment its region means over a grey ground.
Lighting StreetLighting() {
  Lighting l;
  l.sky = testing::ClearSky(Eigen::Vector3d(0.4, -0.5, 0.5));
  l.sun_dir = l.sky.sun_dir;
  l.sun_radiance = Eigen::Vector3d(1e4, 1e4, 1e4);
  l.env = EnvironmentMap::FromSky(EnvOptions(), l.sky, Eigen::Vector3d(0.3, 0.3, 0.3));
  return l;
}

TEST(VectorFluxCacheTest, ComputeIrradianceWithIdBufferAgreesWithAllFaces) {
  const StreetGrid s;
  const auto& [m, rc, grid, cache] = s;
  for (bool use_env : {false, true}) {
    Lighting l = StreetLighting();
    l.use_env = use_env;
    IrradianceOptions all;
    all.method = IrradianceMethod::kVectorFlux;
    all.mesh = &m;
    IrradianceOptions sel = all;
    sel.vector_flux.select_occluders = true;
    const SlotIrradiance a = ComputeIrradiance(grid, cache, rc, l, all);
    const SlotIrradiance b = ComputeIrradiance(grid, cache, rc, l, sel);
    // Per point: at most a few pixels' worth ((pi / 32)^2 / 2 sr of projected solid angle
    // each) of the brightest radiance.
    const double pixel = 0.5 * std::pow(kPi / 32, 2);
    const double lmax = l.sky.Radiance(l.sky.sun_dir).maxCoeff();
    double mean = 0;
    for (int i = 0; i < grid.size(); ++i) {
      EXPECT_NEAR((a.direct_se[i] - b.direct_se[i]).norm(), 0, 4 * pixel * lmax) << i;
      if (a.direct_se[i].norm() > 0) {
        mean += (a.direct_se[i] - b.direct_se[i]).norm() / a.direct_se[i].norm();
      }
    }
    EXPECT_LT(mean / grid.size(), 1e-3) << use_env;
  }
}

// exact_points: the listed points get the vector flux's value and the others Monte Carlo's, each
// to the bit as that method alone gives it; a mask of the wrong size is refused.
TEST(VectorFluxCacheTest, ExactPointsMixTheTwoMethodsPointByPoint) {
  const StreetGrid s;
  const auto& [m, rc, grid, cache] = s;
  const Lighting l = StreetLighting();
  IrradianceOptions vf;
  vf.method = IrradianceMethod::kVectorFlux;
  vf.mesh = &m;
  IrradianceOptions mc = vf;
  mc.method = IrradianceMethod::kMonteCarlo;
  std::vector<uint8_t> every_third(grid.size(), 0);
  for (int i = 0; i < grid.size(); i += 3) every_third[i] = 1;
  IrradianceOptions mixed = vf;
  mixed.exact_points = &every_third;
  const SlotIrradiance a = ComputeIrradiance(grid, cache, rc, l, vf);
  const SlotIrradiance b = ComputeIrradiance(grid, cache, rc, l, mc);
  const SlotIrradiance c = ComputeIrradiance(grid, cache, rc, l, mixed);
  int differ = 0;
  for (int i = 0; i < grid.size(); ++i) {
    EXPECT_EQ(c.direct_se[i], every_third[i] ? a.direct_se[i] : b.direct_se[i]) << i;
    EXPECT_EQ(c.sun[i], a.sun[i]) << i;
    differ += a.direct_se[i] != b.direct_se[i];
  }
  EXPECT_GT(differ, grid.size() / 2);  // the two methods do differ: the test can fail
  std::vector<uint8_t> short_mask(grid.size() - 1, 1);
  mixed.exact_points = &short_mask;
  EXPECT_THROW(ComputeIrradiance(grid, cache, rc, l, mixed), Error);
}

TEST(VectorFluxCacheTest, OccluderSelectionRejectsBadInput) {
  const Mesh m = Street();
  const RayCaster rc(m);
  const FaceAdjacency wrong(Mesh{});
  EXPECT_THROW(SelectOccluders(m, rc, wrong, {0, 0, 1}, {0, 0, 1}, -1, OccluderSelectOptions()),
               Error);
  OccluderSelectOptions so;
  so.resolution = 0;
  EXPECT_THROW(so.Validate(), Error);
  so = OccluderSelectOptions();
  so.grow_rings = -1;
  EXPECT_THROW(so.Validate(), Error);
}

TEST(VectorFluxCacheTest, FaceAdjacencyWeldsCorners) {
  Mesh m;
  const int b = m.AddBlock("b");
  // Two polygons sharing an edge by position only (separate vertex indices).
  m.AddPolygon({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, b);
  m.AddPolygon({{1, 0, 0}, {2, 0, 0}, {2, 1, 0}, {1, 1, 0}}, b);
  m.AddPolygon({{5, 5, 5}, {6, 5, 5}, {6, 6, 5}}, b);
  const FaceAdjacency adj(m);
  ASSERT_EQ(adj.num_faces(), 5);
  auto has = [&](int t, int u) { return std::find(adj.begin(t), adj.end(t), u) != adj.end(t); };
  EXPECT_TRUE(has(0, 1));  // same polygon
  // Across the shared edge, by position: (1, 0, 0) in faces 0 and 2, (1, 1, 0) in 0, 1, 3.
  EXPECT_TRUE(has(0, 2));
  EXPECT_TRUE(has(2, 0));
  EXPECT_TRUE(has(1, 3));
  EXPECT_FALSE(has(1, 2));
  EXPECT_EQ(adj.end(4) - adj.begin(4), 0);  // isolated
}

}  // namespace
}  // namespace rouen
