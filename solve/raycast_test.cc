#include "solve/raycast.h"

#include <gtest/gtest.h>

#include "solve/test_scenes.h"

namespace rouen {
namespace {

TEST(RayCasterTest, HitsMissesAndBarycentrics) {
  Mesh m;
  const int b = m.AddBlock("plane");
  m.vertices = {{0, 0, 1}, {4, 0, 1}, {0, 4, 1}};
  m.AddTriangle(0, 1, 2, b);
  const RayCaster rc(m);
  EXPECT_EQ(rc.num_triangles(), 1);
  EXPECT_NEAR(rc.scene_scale(), std::sqrt(32.0), 1e-9);
  const RayHit h = rc.Intersect({1, 2, 5}, {0, 0, -1});
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.t, 4, 1e-5);
  EXPECT_EQ(h.triangle, 0);
  EXPECT_NEAR(h.u, 0.25, 1e-6);
  EXPECT_NEAR(h.v, 0.5, 1e-6);
  // Two-sided.
  EXPECT_TRUE(rc.Intersect({1, 2, -5}, {0, 0, 1}).hit);
  EXPECT_FALSE(rc.Intersect({3, 3, 5}, {0, 0, -1}).hit);          // outside the triangle
  EXPECT_FALSE(rc.Intersect({1, 2, 5}, {0, 0, -1}, 0, 3.9).hit);  // tmax
  EXPECT_TRUE(rc.Occluded({1, 2, 5}, {0, 0, -1}));
  EXPECT_FALSE(rc.Occluded({1, 2, 5}, {0, 0, -1}, 0, 3.9));
  EXPECT_FALSE(rc.Occluded({1, 2, 5}, {0, 0, 1}));
}

TEST(RayCasterTest, DegenerateTrianglesNeverHitAndIdsStayMeshIndices) {
  Mesh m;
  const int b = m.AddBlock("x");
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 0, 2}, {2, 0, 2}};
  m.AddTriangle(0, 1, 2, b);  // collinear: degenerate
  m.AddTriangle(0, 2, 4, b);
  m.AddTriangle(0, 4, 3, b);
  const RayCaster rc(m);
  EXPECT_EQ(rc.num_degenerate(), 1);
  const RayHit h = rc.Intersect({0.2, -1, 1.5}, {0, 1, 0});
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.triangle, 2);
  const RayHit h2 = rc.Intersect({1.8, -1, 0.5}, {0, 1, 0});
  ASSERT_TRUE(h2.hit);
  EXPECT_EQ(h2.triangle, 1);
}

TEST(RayCasterTest, EmptyMeshNeverHits) {
  const RayCaster rc{Mesh()};
  EXPECT_FALSE(rc.Intersect({0, 0, 0}, {0, 0, 1}).hit);
  EXPECT_FALSE(rc.Occluded({0, 0, 0}, {0, 0, 1}));
}

}  // namespace
}  // namespace rouen
