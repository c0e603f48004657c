#include "solve/ground_apron.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

struct Added {
  Mesh mesh;
  GroundApronSummary summary;
  int block = -1;
};

Added WithApron(Mesh m, const GroundApronOptions& o) {
  Added a;
  const RayCaster rc(m);
  a.summary = AddGroundApron(rc, o, &m);
  a.mesh = std::move(m);
  for (size_t b = 0; b < a.mesh.block_names.size(); ++b)
    if (a.mesh.block_names[b] == o.block) a.block = static_cast<int>(b);
  return a;
}

// Whether a face of the added block covers (x, y) in plan.
bool Covered(const Added& a, double x, double y) {
  for (size_t t = 0; t < a.mesh.triangles.size(); ++t) {
    if (a.mesh.triangle_block[t] != a.block) continue;
    const Eigen::Vector3i& f = a.mesh.triangles[t];
    double sign[3];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& p = a.mesh.vertices[f[k]];
      const Eigen::Vector3d& q = a.mesh.vertices[f[(k + 1) % 3]];
      sign[k] = (q.x() - p.x()) * (y - p.y()) - (q.y() - p.y()) * (x - p.x());
    }
    if (sign[0] >= 0 && sign[1] >= 0 && sign[2] >= 0) return true;
  }
  return false;
}

// Points of a lattice over [x0, x1] x [y0, y1] (inside by 1 cm) that the block covers.
int CoveredInside(const Added& a, double x0, double x1, double y0, double y1) {
  int n = 0;
  for (int i = 0; i <= 20; ++i)
    for (int j = 0; j <= 20; ++j)
      n += Covered(a, x0 + 0.01 + (x1 - x0 - 0.02) * i / 20, y0 + 0.01 + (y1 - y0 - 0.02) * j / 20);
  return n;
}

TEST(GroundApronTest, SurroundsABuildingAndLeavesItsFootprintOut) {
  Mesh m;
  testing::AddBox(&m, {-3, -3, 0}, {3, 3, 10}, m.AddBlock("tower"));
  GroundApronOptions o;
  o.radius_m = 4;
  o.cell_m = 0.5;
  o.max_face_m = 4;
  const Added a = WithApron(m, o);
  ASSERT_GE(a.block, 0);
  EXPECT_EQ(a.mesh.block_names[a.block], "ground");
  // (6 + 2 x 4)^2 less the 6 x 6 footprint, which is whole cells of 0.5 m.
  EXPECT_NEAR(a.summary.area_m2, 14.0 * 14.0 - 36.0, 1e-9);
  EXPECT_EQ(a.summary.cells_under_model, 144);
  EXPECT_EQ(a.summary.cells_kept, 28 * 28 - 144);
  EXPECT_EQ(CoveredInside(a, -3, 3, -3, 3), 0);
  EXPECT_EQ(CoveredInside(a, -7, -3, -7, 7), 21 * 21);  // the ground west of it, to the edge
  double area = 0;
  for (size_t t = 0; t < a.mesh.triangles.size(); ++t) {
    if (a.mesh.triangle_block[t] != a.block) continue;
    EXPECT_NEAR(a.mesh.Normal(t).z(), 1, 1e-12);  // facing up, at the lowest vertex
    for (int k = 0; k < 3; ++k) EXPECT_EQ(a.mesh.vertices[a.mesh.triangles[t][k]].z(), 0);
    // No side longer than max_face_m (the diagonal of a square of it at most).
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e = a.mesh.vertices[a.mesh.triangles[t][(k + 1) % 3]] -
                                a.mesh.vertices[a.mesh.triangles[t][k]];
      EXPECT_LE(std::max(std::abs(e.x()), std::abs(e.y())), o.max_face_m + 1e-9);
    }
    area += a.mesh.Area(t);
  }
  EXPECT_NEAR(area, a.summary.area_m2, 1e-9);
  EXPECT_EQ(a.summary.faces * 2, static_cast<int>(a.mesh.triangles.size()) - 10);
}

TEST(GroundApronTest, KeepsTheModelsOwnGroundAndTheGroundUnderAnOverhang) {
  Mesh m;
  const int plaza = m.AddBlock("plaza");
  testing::AddHorizontalRect(&m, -5, 5, -5, 5, 0, true, plaza);
  testing::AddBox(&m, {-1, -1, 0}, {1, 1, 8}, m.AddBlock("tower"));
  // A canopy 3 m up on the east, closed below: the ground under it is outside and lit.
  testing::AddBox(&m, {8, -1, 3}, {10, 1, 3.5}, m.AddBlock("canopy"), /*bottom=*/true);
  GroundApronOptions o;
  o.radius_m = 2;
  o.cell_m = 0.25;
  const Added a = WithApron(m, o);
  // The bounding box in plan is [-5, 10] x [-5, 5]; grown by 2: 19 x 14 m, less the plaza.
  EXPECT_NEAR(a.summary.area_m2, 19.0 * 14.0 - 100.0, 1e-9);
  EXPECT_EQ(CoveredInside(a, -5, 5, -5, 5), 0);
  EXPECT_EQ(CoveredInside(a, 8, 10, -1, 1), 21 * 21);
}

TEST(GroundApronTest, NothingForRadiusZeroAndClearErrors) {
  Mesh m;
  testing::AddBox(&m, {0, 0, 0}, {1, 1, 1}, m.AddBlock("ground"));
  const RayCaster rc(m);
  Mesh copy = m;
  const GroundApronSummary none = AddGroundApron(rc, GroundApronOptions{}, &copy);
  EXPECT_EQ(none.faces, 0);
  EXPECT_EQ(copy.triangles.size(), m.triangles.size());
  GroundApronOptions o;
  o.radius_m = 5;
  try {
    AddGroundApron(rc, o, &copy);
    FAIL() << "a second 'ground' block was added";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("already has a block named 'ground'"), std::string::npos);
  }
  o.radius_m = -1;
  EXPECT_THROW(o.Validate(), Error);
  o.radius_m = 5;
  o.max_face_m = 0.1;  // below cell_m
  try {
    o.Validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("ground.max_face_m"), std::string::npos);
  }
  // The scene's record of it round-trips, and a bad one is refused.
  o.max_face_m = 6;
  o.block = "yard";
  const GroundApronOptions back = nlohmann::json(o).get<GroundApronOptions>();
  EXPECT_EQ(back.radius_m, 5);
  EXPECT_EQ(back.max_face_m, 6);
  EXPECT_EQ(back.block, "yard");
  EXPECT_THROW(nlohmann::json({{"radius_m", -2}}).get<GroundApronOptions>(), Error);
}

// A wall sees the ground in front of it with that ground's own albedo: of a box on ground bright
// to the north and dark to the south, lit alike, the north wall gets five times the south
// wall's light from the ground, and each the form factor of its strip of ground.
TEST(GroundApronTest, EachWallSeesItsOwnGroundThroughTheInterreflection) {
  Mesh m;
  testing::AddBox(&m, {-3, -3, 0}, {3, 3, 10}, m.AddBlock("tower"));
  GroundApronOptions o;
  o.radius_m = 40;
  const Added a = WithApron(m, o);
  GridOptions go;
  go.spacing_m = 1.0;
  go.block_spacing_m["ground"] = 2.0;
  const SurfaceGrid g = BuildSurfaceGrid(a.mesh, go);
  const RayCaster rc(a.mesh);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  SlotIrradiance irr;
  irr.sun.assign(g.size(), Eigen::Vector3d::Zero());
  irr.direct_se.assign(g.size(), Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> rho_sun(g.size(), Eigen::Vector3d::Zero()), rho_se = rho_sun;
  for (int i = 0; i < g.size(); ++i) {
    if (g.points[i].block != a.block) continue;
    irr.direct_se[i].setOnes();  // every ground point lit alike: B = rho
    rho_se[i].setConstant(g.points[i].position.y() > 3 ? 0.5 : 0.1);
  }
  AddInterreflection(g, cache, rho_sun, rho_se, &irr, 1);
  // Expected: B F, F = (1 - h / sqrt(h^2 + D^2)) / 2 the form factor from a vertical element at
  // height h to the ground strip of depth D = 40 m in front of it (infinitely wide; the apron's
  // 86 m width misses directions nearly along the wall, of negligible weight).
  const double D = 40;
  double sum[2] = {0, 0}, expect[2] = {0, 0};
  int n[2] = {0, 0};
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    if (p.block == a.block || std::abs(p.normal.y()) < 0.99) continue;
    const int side = p.normal.y() > 0 ? 0 : 1;  // north, south
    const double h = p.position.z();
    const double F = 0.5 * (1 - h / std::hypot(h, D));
    sum[side] += irr.se[i].x();
    expect[side] += (side == 0 ? 0.5 : 0.1) * F;
    ++n[side];
  }
  ASSERT_GT(n[0], 50);
  ASSERT_EQ(n[0], n[1]);
  // Mean over n points of K cosine-weighted directions: binomial error <= 0.5 / sqrt(n K) of B.
  const double tol = 4 * 0.5 / std::sqrt(static_cast<double>(n[0]) * cache.directions);
  EXPECT_NEAR(sum[0] / n[0], expect[0] / n[0], 0.5 * tol + 0.01 * expect[0] / n[0]);
  EXPECT_NEAR(sum[1] / n[1], expect[1] / n[1], 0.1 * tol + 0.01 * expect[1] / n[1]);
  EXPECT_NEAR(sum[0] / sum[1], 5, 0.15);
}

}  // namespace
}  // namespace rouen
