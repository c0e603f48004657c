#include "solve/vector_flux.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/angles.h"
#include "core/error.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

// Counter-clockwise seen from above: the upper hemisphere's boundary.
SphericalPolygon UpperHemisphere() {
  return {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitX(),
          -Eigen::Vector3d::UnitY()};
}

TEST(VectorFluxTest, UpperHemisphereGivesPiOnHorizontalPlane) {
  const Eigen::Vector3d phi = VectorFlux(UpperHemisphere());
  EXPECT_NEAR((phi - kPi * Eigen::Vector3d::UnitZ()).norm(), 0, 1e-14);
  // Reversed order: the lower hemisphere, whose flux is the opposite.
  SphericalPolygon lower = UpperHemisphere();
  std::reverse(lower.begin(), lower.end());
  EXPECT_NEAR((VectorFlux(lower) + kPi * Eigen::Vector3d::UnitZ()).norm(), 0, 1e-14);
}

TEST(VectorFluxTest, OctantMatchesClosedForm) {
  // Integral of w over the octant x, y, z > 0: pi/4 per component (a quarter of the x > 0
  // hemisphere's pi by symmetry); solid angle 4 pi / 8.
  const SphericalPolygon oct = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                Eigen::Vector3d::UnitZ()};
  EXPECT_NEAR((VectorFlux(oct) - Eigen::Vector3d::Constant(kPi / 4)).norm(), 0, 1e-14);
  EXPECT_NEAR(SolidAngle(oct), kPi / 2, 1e-14);
}

TEST(VectorFluxTest, SmallPolygonIsSolidAngleTimesCosine) {
  // A square of half-width h (tangent-plane units) about a direction 60 deg from the normal.
  const double theta = kPi / 3, h = 1e-3;
  const Eigen::Vector3d c(std::sin(theta), 0, std::cos(theta));
  const Eigen::Vector3d t(0, 1, 0), b = c.cross(t);
  SphericalPolygon sq;
  for (const auto& [u, v] : {std::pair{-h, -h}, {h, -h}, {h, h}, {-h, h}}) {
    sq.push_back((c + u * b + v * t).normalized());
  }
  if (VectorFlux(sq).dot(c) < 0) std::reverse(sq.begin(), sq.end());
  const double omega = SolidAngle(sq);
  EXPECT_NEAR(omega, 4 * h * h, 4 * h * h * 3 * h * h);  // gnomonic area distortion O(h^2)
  // n.Phi = Omega cos(theta) up to the cosine's variation over the patch, O(h^2).
  EXPECT_NEAR(VectorFlux(sq).z() / (omega * std::cos(theta)), 1, 1e-5);
}

TEST(VectorFluxTest, TiltedPlaneUnderUniformUpperHemisphere) {
  const Mesh empty;
  for (double tilt_deg : {0.0, 30.0, 90.0, 135.0}) {
    const double tilt = tilt_deg * kPi / 180;
    const Eigen::Vector3d n(std::sin(tilt), 0, std::cos(tilt));
    // Clipping the upper hemisphere's four octants by the tangent plane.
    const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
    const SphericalPolygon h = UpperHemisphere();
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    for (int q = 0; q < 4; ++q) phi += VectorFlux(ClipToHalfSpace({h[q], h[(q + 1) % 4], z}, n));
    const double expected = kPi * (1 + std::cos(tilt)) / 2;
    EXPECT_NEAR(n.dot(phi), expected, 1e-12) << tilt_deg;
    // Through the sky path with a uniform sky model (radiance 2).
    const PointVisibility pv(empty, Eigen::Vector3d::Zero(), n);
    const Eigen::Vector3d e =
        SkyIrradianceVectorFlux(pv, testing::UniformSkyModel(2), VectorFluxOptions());
    EXPECT_NEAR(e.x(), 2 * expected, 1e-12) << tilt_deg;
  }
}

TEST(VectorFluxTest, ClippingIsAdditive) {
  const SphericalPolygon oct = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                Eigen::Vector3d::UnitZ()};
  const Eigen::Vector3d m = Eigen::Vector3d(0.3, -0.7, 0.2).normalized();
  const SphericalPolygon a = ClipToHalfSpace(oct, m), b = ClipToHalfSpace(oct, -m);
  ASSERT_FALSE(a.empty());
  ASSERT_FALSE(b.empty());
  for (const auto& v : a) EXPECT_NEAR(v.norm(), 1, 1e-15);
  EXPECT_NEAR((VectorFlux(a) + VectorFlux(b) - VectorFlux(oct)).norm(), 0, 1e-14);
  EXPECT_NEAR(SolidAngle(a) + SolidAngle(b), kPi / 2, 1e-14);
  EXPECT_TRUE(ClipToHalfSpace(oct, -Eigen::Vector3d::Ones()).empty());
}

TEST(VectorFluxTest, SubtractConvexPartitions) {
  const SphericalPolygon oct = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                Eigen::Vector3d::UnitZ()};
  ConvexSpherical q;
  const Eigen::Vector3d c = Eigen::Vector3d::Ones().normalized();
  const Eigen::Vector3d t = Eigen::Vector3d(1, -1, 0).normalized(), b = c.cross(t);
  SphericalPolygon sq;
  for (const auto& [u, v] : {std::pair{-0.2, -0.2}, {0.2, -0.2}, {0.2, 0.2}, {-0.2, 0.2}}) {
    sq.push_back((c + u * t + v * b).normalized());
  }
  if (VectorFlux(sq).dot(c) < 0) std::reverse(sq.begin(), sq.end());
  ASSERT_TRUE(q.Set(sq));
  std::vector<SphericalPolygon> out, in;
  SubtractConvex(oct, q, &out, &in);
  ASSERT_EQ(in.size(), 1u);
  EXPECT_NEAR((VectorFlux(in[0]) - VectorFlux(sq)).norm(), 0, 1e-14);
  Eigen::Vector3d sum = VectorFlux(in[0]);
  for (const auto& p : out) sum += VectorFlux(p);
  EXPECT_NEAR((sum - VectorFlux(oct)).norm(), 0, 1e-14);
  // Disjoint: returned whole.
  out.clear();
  in.clear();
  const SphericalPolygon far = {-Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY(),
                                -Eigen::Vector3d::UnitZ()};
  SubtractConvex(far, q, &out, &in);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(in.empty());
  EXPECT_EQ(out[0], far);
  // Degenerate polygons are refused.
  EXPECT_FALSE(q.Set({c, c, c}));
}

// SubtractConvex computes each vertex's distance to an edge's plane once for both sides and
// skips cuts that leave every vertex on one side: the pieces are bitwise those of cutting by
// -m and m with ClipToHalfSpace for every edge normal m (the same arithmetic), including
// polygons sharing corners and edges with q (vertices on the planes) and lying inside it.
TEST(VectorFluxTest, SubtractConvexEqualsClippingEdgeByEdge) {
  auto convex = [](const Eigen::Vector3d& centre, double radius, int n, double turn) {
    const Eigen::Vector3d c = centre.normalized();
    const Eigen::Vector3d t = c.unitOrthogonal(), b = c.cross(t);
    SphericalPolygon p;
    for (int k = 0; k < n; ++k) {
      const double a = turn + 2 * kPi * k / n;
      p.push_back((c + radius * (std::cos(a) * t + std::sin(a) * b)).normalized());
    }
    return p;  // counter-clockwise seen from outside
  };
  ConvexSpherical q;
  const SphericalPolygon qv = convex({0.2, 0.1, 1}, 0.3, 5, 0.1);
  ASSERT_TRUE(q.Set(qv));
  std::vector<SphericalPolygon> cases = {
      qv,                                  // q itself: every vertex on its planes
      convex({0.2, 0.1, 1}, 0.1, 7, 0.0),  // inside q
      convex({0.2, 0.1, 1}, 0.6, 4, 0.3),  // holding q
      {qv[0], qv[1], (qv[0] + qv[1]).normalized() + 0.2 * Eigen::Vector3d(0.2, 0.1, 1),
       qv[3]},  // two corners and an edge of q
  };
  cases.back()[2].normalize();
  for (int k = 0; k < 24; ++k) {  // overlapping q's interior from every side
    const double a = 2 * kPi * k / 24;
    cases.push_back(
        convex(Eigen::Vector3d(0.2, 0.1, 1).normalized() * 3 +
                   Eigen::Vector3d(std::cos(a), std::sin(a), 0) * (0.3 + 0.05 * (k % 5)),
               0.2 + 0.02 * (k % 7), 3 + k % 6, 0.37 * k));
  }
  int cut = 0;
  for (size_t c = 0; c < cases.size(); ++c) {
    const SphericalPolygon& p = cases[c];
    std::vector<SphericalPolygon> out, in;
    SubtractConvex(p, q, &out, &in);
    std::vector<SphericalPolygon> ref_out, ref_in;
    SphericalPolygon rest = p;
    for (const auto& m : q.edge_normal) {
      SphericalPolygon o = ClipToHalfSpace(rest, -m);
      if (!o.empty()) ref_out.push_back(std::move(o));
      rest = ClipToHalfSpace(rest, m);
      if (rest.empty()) break;
    }
    if (!rest.empty()) ref_in.push_back(rest);
    EXPECT_EQ(out, ref_out) << "case " << c;
    EXPECT_EQ(in, ref_in) << "case " << c;
    cut += !out.empty() && !in.empty();
  }
  EXPECT_GT(cut, 10);
}

TEST(VectorFluxTest, CeilingRectangleMatchesFormFactor) {
  // A ceiling [0, a] x [0, b] at height h above the point, corner overhead: the classic
  // parallel-rectangle form factor F; unoccluded uniform sky L gives pi L (1 - F).
  const double a = 3, b = 2, h = 1.5;
  Mesh m;
  const int blk = m.AddBlock("ceiling");
  testing::AddHorizontalRect(&m, 0, a, 0, b, h, false, blk);
  const double A = a / h, B = b / h;
  const double F = (A / std::sqrt(1 + A * A) * std::atan(B / std::sqrt(1 + A * A)) +
                    B / std::sqrt(1 + B * B) * std::atan(A / std::sqrt(1 + B * B))) /
                   (2 * kPi);
  const PointVisibility pv(m, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  EXPECT_EQ(pv.num_occluders(), 2);
  FluxStats st;
  const Eigen::Vector3d e =
      SkyIrradianceVectorFlux(pv, testing::UniformSkyModel(1), VectorFluxOptions(), &st);
  EXPECT_NEAR(e.y(), kPi * (1 - F), 1e-12);
  EXPECT_EQ(st.occluders, 2);
  // Seen from its back (the ceiling faces down here, so from above it is a back face): still
  // occludes -- the same area from below the other way round.
  Mesh up;
  testing::AddHorizontalRect(&up, 0, a, 0, b, h, true, up.AddBlock("c"));
  const PointVisibility pv2(up, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  EXPECT_NEAR(SkyIrradianceVectorFlux(pv2, testing::UniformSkyModel(1), VectorFluxOptions()).z(),
              kPi * (1 - F), 1e-12);
}

TEST(VectorFluxTest, EnvironmentRegionsTileTheSphere) {
  const EnvironmentMap env =
      EnvironmentMap::Constant(EnvOptions(), Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(0, 0, 0));
  VectorFluxOptions o;
  const EnvironmentRegions regions(env, o);
  ASSERT_EQ(regions.size(), env.num_regions());
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  double omega = 0, worst = 0;
  for (int r = 0; r < env.num_regions(); ++r) {
    total += VectorFlux(regions.polygon(r));
    omega += SolidAngle(regions.polygon(r));
    double el0, el1, az0, az1;
    env.RegionBounds(r, &el0, &el1, &az0, &az1);
    // Exact lat-long region: Phi_z = dAz (sin^2 el1 - sin^2 el0) / 2.
    const double exact =
        (az1 - az0) * (std::sin(el1) * std::sin(el1) - std::sin(el0) * std::sin(el0)) / 2;
    const double exact_omega = (az1 - az0) * (std::sin(el1) - std::sin(el0));
    worst = std::max(worst, std::abs(SolidAngle(regions.polygon(r)) - exact_omega) / exact_omega);
    EXPECT_NEAR(VectorFlux(regions.polygon(r)).z(), exact, 0.01 * std::abs(exact) + 1e-12) << r;
  }
  // The shared edges are the same polylines on both sides: an exact tiling.
  EXPECT_NEAR(total.norm(), 0, 1e-12);
  EXPECT_NEAR(omega, 4 * kPi, 1e-11);
  // Parallels followed by 3.75-degree great arcs: the bulge is <= dAz^2/8 sin cos el of a
  // 10-degree band, below 0.4% of a region's solid angle.
  EXPECT_LT(worst, 4e-3);
}

TEST(VectorFluxTest, EnvironmentUniformHorizontalPlaneIsPiL) {
  const EnvironmentMap env =
      EnvironmentMap::Constant(EnvOptions(), Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(5, 5, 5));
  const EnvironmentRegions regions(env, VectorFluxOptions());
  const Mesh empty;
  const PointVisibility pv(empty, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d e =
      EnvironmentIrradianceVectorFlux(pv, env, 0, regions, nullptr, Eigen::Vector3d::Ones());
  EXPECT_NEAR((e - kPi * Eigen::Vector3d(1, 2, 3)).norm(), 0, 1e-12);
  // Vertical wall: half the sky, half the ground, each pi L / 2.
  const PointVisibility wall(empty, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX());
  const Eigen::Vector3d ew =
      EnvironmentIrradianceVectorFlux(wall, env, 0, regions, nullptr, Eigen::Vector3d::Ones());
  EXPECT_NEAR((ew - kPi / 2 * Eigen::Vector3d(6, 7, 8)).norm(), 0, 1e-12);
  // Regions of another layout are refused.
  EnvOptions coarse;
  coarse.sectors = 12;
  const EnvironmentRegions other(
      EnvironmentMap::Constant(coarse, Eigen::Vector3d::Ones(), Eigen::Vector3d::Ones()),
      VectorFluxOptions());
  EXPECT_THROW(EnvironmentIrradianceVectorFlux(pv, env, 0, other, nullptr, Eigen::Vector3d::Ones()),
               Error);
}

TEST(VectorFluxTest, AdaptiveSkyMatchesFineQuadrature) {
  const Eigen::Vector3d sun = Eigen::Vector3d(0.3, 0.5, 0.6).normalized();
  const SkyModel sky = testing::ClearSky(sun);
  const Mesh empty;
  for (const Eigen::Vector3d& n :
       {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.6, 0.8, 0), Eigen::Vector3d(-0.6, 0, 0.8)}) {
    // Midpoint quadrature in (el, az) on a 600 x 1200 grid over the upper hemisphere.
    Eigen::Vector3d ref = Eigen::Vector3d::Zero();
    const int ne = 600, na = 1200;
    for (int i = 0; i < ne; ++i) {
      const double el = (i + 0.5) / ne * kPi / 2;
      for (int j = 0; j < na; ++j) {
        const double az = (j + 0.5) / na * 2 * kPi;
        const Eigen::Vector3d d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az),
                                std::sin(el));
        const double c = n.dot(d);
        if (c > 0) ref += sky.Radiance(d) * c * std::cos(el);
      }
    }
    ref *= (kPi / 2 / ne) * (2 * kPi / na);
    const PointVisibility pv(empty, Eigen::Vector3d::Zero(), n);
    FluxStats st;
    const Eigen::Vector3d e = SkyIrradianceVectorFlux(pv, sky, VectorFluxOptions(), &st);
    for (int ch = 0; ch < 3; ++ch) {
      // Midpoint rule over patches whose radiance varies by <= 10%: second order, ~1e-3 at
      // worst; the quadrature itself is good to ~1e-4 (half-cells at the tangent plane).
      EXPECT_NEAR(e[ch] / ref[ch], 1, 1.5e-3) << n.transpose() << " ch " << ch;
    }
    EXPECT_GT(st.patches, 16);
    EXPECT_LT(st.patches, 10000);
  }
}

TEST(VectorFluxTest, ProjectPolygonRejectsBehindAndEdgeOn) {
  ConvexSpherical cs;
  const Eigen::Vector3d o = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::UnitZ();
  // Entirely below the tangent plane.
  EXPECT_FALSE(ProjectPolygon({{0, 0, -1}, {1, 0, -1}, {0, 1, -1}}, o, n, &cs));
  // In a plane through the origin.
  EXPECT_FALSE(ProjectPolygon({{1, 0, 1}, {2, 0, 1}, {1, 0, 2}}, o, n, &cs));
  // Straddling the plane: the part in front, on the sphere, counter-clockwise.
  ASSERT_TRUE(ProjectPolygon({{1, -1, -1}, {1, 1, -1}, {1, 0, 1}}, o, n, &cs));
  for (const auto& v : cs.vertices) {
    EXPECT_NEAR(v.norm(), 1, 1e-15);
    EXPECT_GE(v.z(), -1e-15);
  }
  EXPECT_GT(SolidAngle(cs.vertices), 0);
}

TEST(VectorFluxTest, OptionsValidate) {
  VectorFluxOptions o;
  EXPECT_NO_THROW(o.Validate());
  o.sky_tolerance = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = VectorFluxOptions();
  o.env_parallel_segments = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = VectorFluxOptions();
  o.sky_initial_split = 9;
  EXPECT_THROW(o.Validate(), Error);
  o = VectorFluxOptions();
  o.sky_tree_levels = 10;
  EXPECT_THROW(o.Validate(), Error);
  o = VectorFluxOptions();
  o.select.resolution = 0;
  EXPECT_THROW(o.Validate(), Error);
}

}  // namespace
}  // namespace rouen
