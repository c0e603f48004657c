#include "solve/grid.h"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

Mesh OneTriangle(double size) {
  Mesh m;
  const int b = m.AddBlock("wall");
  m.vertices = {{0, 0, 0}, {size, 0, 0}, {0, size, 0}};
  m.AddTriangle(0, 1, 2, b);
  return m;
}

// Barycentric (u, v) of p in triangle t (p = (1-u-v) a + u b + v c).
Eigen::Vector2d Bary(const Mesh& m, int t, const Eigen::Vector3d& p) {
  const auto& f = m.triangles[t];
  const Eigen::Vector3d a = m.vertices[f[0]], e1 = m.vertices[f[1]] - a, e2 = m.vertices[f[2]] - a;
  Eigen::Matrix<double, 3, 2> A;
  A << e1, e2;
  return A.colPivHouseholderQr().solve(p - a);
}

TEST(GridTest, SubdivisionCountsAreasAndCentroids) {
  const Mesh m = OneTriangle(3.0);  // longest edge 3 sqrt 2 = 4.24 m
  GridOptions o;
  o.spacing_m = 1.0;
  o.subdivision = GridSubdivision::kLongestEdge;
  const SurfaceGrid g = BuildSurfaceGrid(m, o);
  const int n = static_cast<int>(std::ceil(3 * std::sqrt(2.0)));  // 5
  ASSERT_EQ(g.triangle_n[0], n);
  ASSERT_EQ(g.size(), n * n);
  double area = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : g.points) {
    area += p.area;
    mean += p.area * p.position;
    EXPECT_NEAR(p.normal.z(), 1.0, 1e-12);
    const Eigen::Vector2d uv = Bary(m, 0, p.position);
    EXPECT_GT(uv.x(), 0);
    EXPECT_GT(uv.y(), 0);
    EXPECT_LT(uv.sum(), 1);
  }
  EXPECT_NEAR(area, m.Area(0), 1e-12);
  // Area-weighted mean of the cell centroids is the triangle's centroid.
  EXPECT_NEAR((mean / area - Eigen::Vector3d(1, 1, 0)).norm(), 0, 1e-12);
}

TEST(GridTest, NearestPointFindsEachPointsOwnCell) {
  Mesh m;
  const int b = m.AddBlock("box");
  testing::AddBox(&m, {0, 0, 0}, {2, 3, 4}, b, true);
  GridOptions o;
  o.spacing_m = 0.7;
  const SurfaceGrid g = BuildSurfaceGrid(m, o);
  ASSERT_GT(g.size(), 100);
  for (int i = 0; i < g.size(); ++i) {
    const auto& p = g.points[i];
    const Eigen::Vector2d uv = Bary(m, p.triangle, p.position);
    EXPECT_EQ(g.NearestPoint(p.triangle, uv.x(), uv.y()), i);
  }
  // Vertices and edges map to a point of the same triangle.
  for (int t = 0; t < static_cast<int>(m.triangles.size()); ++t) {
    for (auto uv : {Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 0), Eigen::Vector2d(0, 1),
                    Eigen::Vector2d(0.5, 0.5), Eigen::Vector2d(1.2, -0.1)}) {
      const int j = g.NearestPoint(t, uv.x(), uv.y());
      ASSERT_GE(j, 0);
      EXPECT_EQ(g.points[j].triangle, t);
    }
  }
}

TEST(GridTest, StencilIsAPartitionOfUnityAndLinearInside) {
  const Mesh m = OneTriangle(6.0);
  GridOptions o;
  o.spacing_m = 0.5;
  const SurfaceGrid g = BuildSurfaceGrid(m, o);
  const int n = g.triangle_n[0];
  std::vector<Eigen::Vector3d> f(g.size());
  auto lin = [](const Eigen::Vector3d& p) {
    return Eigen::Vector3d(2 * p.x() - p.y() + 1, 3, p.y());
  };
  for (int i = 0; i < g.size(); ++i) f[i] = lin(g.points[i].position);
  for (double u = 0.0; u <= 1.0; u += 0.037) {
    for (double v = 0.0; u + v <= 1.0; v += 0.041) {
      const GridStencil st = g.Stencil(0, u, v);
      double wsum = 0;
      for (int k = 0; k < st.count; ++k) {
        EXPECT_GE(st.weight[k], 0);
        EXPECT_EQ(g.points[st.index[k]].triangle, 0);
        wsum += st.weight[k];
      }
      EXPECT_NEAR(wsum, 1, 1e-12);
      // Away from the triangle's edges (interior lattice vertices are the means of
      // symmetric cell rings) a linear field is reproduced exactly.
      const double margin = 1.5 / n;
      if (u > margin && v > margin && 1 - u - v > margin) {
        const Eigen::Vector3d p(6 * u, 6 * v, 0);
        EXPECT_NEAR((g.Interpolate(f, 0, u, v) - lin(p)).norm(), 0, 1e-9) << u << " " << v;
      }
    }
  }
}

TEST(GridTest, DeterministicWithBlockOverride) {
  Mesh m;
  const int wall = m.AddBlock("shaft");
  const int plaza = m.AddBlock("plaza");
  testing::AddHorizontalRect(&m, -10, 10, -10, 10, 0, true, plaza);
  testing::AddBox(&m, {-1, -1, 0}, {1, 1, 5}, wall);
  GridOptions o;
  o.spacing_m = 0.5;
  o.subdivision = GridSubdivision::kLongestEdge;
  o.block_spacing_m["plaza"] = 2.0;
  const SurfaceGrid a = BuildSurfaceGrid(m, o);
  const SurfaceGrid b = BuildSurfaceGrid(m, o);
  ASSERT_EQ(a.size(), b.size());
  for (int i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a.points[i].position, b.points[i].position);
    EXPECT_EQ(a.points[i].triangle, b.points[i].triangle);
  }
  // Plaza triangles: longest edge 20 sqrt 2 = 28.3 m -> n = 15 at 2 m.
  EXPECT_EQ(a.triangle_n[0], 15);
  EXPECT_EQ(a.triangle_n[2], static_cast<int>(std::ceil(std::hypot(2.0, 2.0) / 0.5)));  // top
  EXPECT_EQ(a.triangle_n[4], static_cast<int>(std::ceil(std::hypot(2.0, 5.0) / 0.5)));  // south
  // The count the solve checks its memory with, before making the grid.
  EXPECT_EQ(CountGridPoints(m, o), a.size());
  o.spacing_m = 0.01;  // the documented minimum: counted, not made
  EXPECT_GT(CountGridPoints(m, o), 200 * 200 * 10);
  o.spacing_m = 0.5;
  // Options survive JSON.
  const GridOptions back = nlohmann::json(o).get<GridOptions>();
  EXPECT_EQ(back.subdivision, GridSubdivision::kLongestEdge);
  EXPECT_EQ(back.SpacingFor("plaza"), 2.0);
  EXPECT_EQ(back.SpacingFor("roof"), 0.5);
}

TEST(GridTest, EquivalentAreaRuleMatchesEquilateralAndThinsSlivers) {
  Mesh m;
  const int b = m.AddBlock("wall");
  const double s = 3.0, h = s * std::sqrt(3.0) / 2;
  m.vertices = {{0, 0, 0}, {s, 0, 0}, {s / 2, h, 0}, {0, 0, 1}, {40, 0, 1}, {0, 9, 1}};
  m.AddTriangle(0, 1, 2, b);  // equilateral, edge 3
  m.AddTriangle(3, 4, 5, b);  // sliver 40 x 9
  GridOptions o;
  o.spacing_m = 0.6;
  const SurfaceGrid area_rule = BuildSurfaceGrid(m, o);
  o.subdivision = GridSubdivision::kLongestEdge;
  const SurfaceGrid edge_rule = BuildSurfaceGrid(m, o);
  EXPECT_EQ(area_rule.triangle_n[0], 5);
  EXPECT_EQ(edge_rule.triangle_n[0], 5);
  EXPECT_EQ(edge_rule.triangle_n[1], static_cast<int>(std::ceil(std::hypot(40.0, 9.0) / 0.6)));
  // Equal cell area to an equilateral cell of edge <= 0.6 m.
  const int n = area_rule.triangle_n[1];
  const double cell_area = m.Area(1) / (n * n);
  EXPECT_LE(cell_area, std::sqrt(3.0) / 4 * 0.36 + 1e-12);
  EXPECT_GT(cell_area, std::sqrt(3.0) / 4 * 0.36 * 0.8);
  EXPECT_LT(area_rule.size(), edge_rule.size() / 3);
}

TEST(GridTest, DegenerateTrianglesAreSkippedAndCounted) {
  Mesh m = OneTriangle(1.0);
  m.vertices.push_back({2, 2, 0});
  m.AddTriangle(0, 1, 1, 0);  // repeated vertex
  m.vertices.push_back({0.5, 0, 0});
  m.AddTriangle(0, 1, 4, 0);  // collinear
  const SurfaceGrid g = BuildSurfaceGrid(m, GridOptions());
  EXPECT_EQ(g.skipped_triangles, 2);
  EXPECT_EQ(g.triangle_n[1], 0);
  EXPECT_EQ(g.NearestPoint(1, 0.2, 0.2), -1);
  EXPECT_EQ(g.Stencil(2, 0.2, 0.2).count, 0);
  EXPECT_EQ(g.NearestPoint(99, 0.2, 0.2), -1);
  for (const auto& p : g.points) EXPECT_EQ(p.triangle, 0);
}

TEST(GridTest, BadOptionsThrow) {
  GridOptions o;
  o.spacing_m = 0;
  EXPECT_THROW(BuildSurfaceGrid(OneTriangle(1), o), Error);
  o.spacing_m = 1;
  o.block_spacing_m["plaza"] = -1;
  EXPECT_THROW(o.Validate(), Error);
  EXPECT_THROW(nlohmann::json({{"spacing_m", "x"}}).get<GridOptions>(), Error);
}

}  // namespace
}  // namespace rouen
