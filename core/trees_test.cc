#include "core/trees.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <string>
#include <utility>

#include "core/angles.h"
#include "core/error.h"
#include "core/mesh.h"

namespace rouen {
namespace {

// The message of the error ParseTrees throws on `text`, "" when it throws none.
std::string ErrorOf(const std::string& text) {
  try {
    ParseTrees(text, "trees.csv");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(TreesTest, ColumnsInAnyOrderWithTheirDefaults) {
  const std::vector<Tree> trees = ParseTrees(
      "\xEF\xBB\xBF# surveyed 2026-10-14\r\n"
      "height_m, x_m, y_m, crown_diameter_m, name, trunk_diameter_m\r\n"
      "\n"
      "10.5, -24, -30.5, 7, lime, 0.8\n"
      "# the plane tree\n"
      "12,3,4,8,plane.2,0.6\n",
      "trees.csv", TreeMeshOptions{.trunk_diameter_m = 0.4});
  ASSERT_EQ(trees.size(), 2u);
  EXPECT_EQ(trees[0].name, "lime");
  EXPECT_EQ(trees[0].position, Eigen::Vector2d(-24, -30.5));
  EXPECT_EQ(trees[0].height_m, 10.5);
  EXPECT_EQ(trees[0].crown_diameter_m, 7);
  EXPECT_EQ(trees[0].crown_depth_m, 7);  // round by default
  EXPECT_EQ(trees[0].trunk_diameter_m, 0.8);
  EXPECT_EQ(trees[0].base_z_m, 0);
  EXPECT_EQ(trees[1].name, "plane.2");
  // Without a name the line names the tree; without a trunk the options give it.
  const std::vector<Tree> unnamed = ParseTrees(
      "x_m,y_m,height_m,crown_diameter_m,crown_depth_m,"
      "base_z_m\n1,2,9,6,4,1.5\n",
      "t.csv", TreeMeshOptions{.trunk_diameter_m = 0.4});
  ASSERT_EQ(unnamed.size(), 1u);
  EXPECT_EQ(unnamed[0].name, "tree_2");
  EXPECT_EQ(unnamed[0].trunk_diameter_m, 0.4);
  EXPECT_EQ(unnamed[0].crown_depth_m, 4);
  EXPECT_EQ(unnamed[0].base_z_m, 1.5);
}

TEST(TreesTest, BadFilesAreNamedWithTheLine) {
  const std::string header = "name,x_m,y_m,height_m,crown_diameter_m\n";
  EXPECT_EQ(ErrorOf(""), "trees.csv: no header and no trees");
  EXPECT_EQ(ErrorOf(header), "trees.csv: a header and no trees");
  EXPECT_EQ(ErrorOf("x_m,y_m,height_m\n"),
            "trees.csv:1: the header has no column 'crown_diameter_m'");
  EXPECT_NE(ErrorOf("x_m,y_m,height_m,crown_diameter_m,girth\n").find("1: unknown column 'girth'"),
            std::string::npos);
  EXPECT_EQ(ErrorOf("x_m,y_m,x_m\n"), "trees.csv:1: column 'x_m' given twice");
  EXPECT_EQ(ErrorOf(header + "a,1,2,10\n"), "trees.csv:2: 4 fields, the header has 5");
  EXPECT_EQ(ErrorOf(header + "a,1,2,ten,5\n"), "trees.csv:2: height_m 'ten' is not a number");
  EXPECT_EQ(ErrorOf(header + "a,1,2,nan,5\n"), "trees.csv:2: height_m 'nan' is not a number");
  EXPECT_EQ(ErrorOf(header + "a,1,2,10,0\n"), "trees.csv:2: crown_diameter_m must be positive");
  EXPECT_EQ(ErrorOf(header + "a,1,2,-10,5\n"), "trees.csv:2: height_m must be positive");
  EXPECT_EQ(ErrorOf("x_m,y_m,height_m,crown_diameter_m,crown_depth_m\n1,2,5,4,6\n"),
            "trees.csv:2: the crown (crown_depth_m 6 m) is deeper than the tree is high "
            "(height_m 5 m)");
  EXPECT_EQ(ErrorOf("x_m,y_m,height_m,crown_diameter_m,trunk_diameter_m\n1,2,5,4,4\n"),
            "trees.csv:2: trunk_diameter_m must be >= 0 and less than crown_diameter_m");
  EXPECT_EQ(ErrorOf(header + "big lime,1,2,10,5\n"),
            "trees.csv:2: name 'big lime' is not one word of letters, digits, '_', '-' or '.'");
  EXPECT_EQ(ErrorOf(header + "a,1,2,10,5\n\na,3,4,10,5\n"),
            "trees.csv:4: the name 'a' is line 2's too");
}

TEST(TreesTest, ACrownIsAClosedEllipsoidOnATrunkThatMeetsIt) {
  Tree tree;
  tree.name = "lime";
  tree.position = {10, -20};
  tree.base_z_m = 1;
  tree.height_m = 11;  // the crown's top at z = 12
  tree.crown_diameter_m = 8;
  tree.crown_depth_m = 6;  // its centre at z = 9, semi-axes 4, 4, 3
  tree.trunk_diameter_m = 0.8;
  const TreeMeshOptions options;
  // The trees' text follows any OBJ: its indices are relative.
  const std::string text =
      "g house\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" + TreesObjText({tree}, options);
  const Mesh m = ParseObj(text, "trees");
  ASSERT_EQ(m.block_names, (std::vector<std::string>{"house", "lime"}));
  const Eigen::Vector3d centre(10, -20, 9);
  std::map<std::pair<int, int>, int> edges;  // the crown's directed edges
  int crown_triangles = 0;
  double top = -1e9, volume = 0;
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    if (m.triangle_block[t] != 1) continue;
    const auto& tri = m.triangles[t];
    bool crown = true;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = m.vertices[tri[k]] - centre;
      const double e = d.x() * d.x() / 16 + d.y() * d.y() / 16 + d.z() * d.z() / 9;
      crown = crown && std::abs(e - 1) < 1e-5;
      top = std::max(top, m.vertices[tri[k]].z());
    }
    const Eigen::Vector3d mid = (m.vertices[tri[0]] + m.vertices[tri[1]] + m.vertices[tri[2]]) / 3;
    if (crown) {
      ++crown_triangles;
      // Its signed volume (divergence theorem): positive when wound counter-clockwise outside.
      volume += (m.vertices[tri[0]] - centre)
                    .dot((m.vertices[tri[1]] - centre).cross(m.vertices[tri[2]] - centre)) /
                6;
      // Outward: the face's normal leaves the centre.
      EXPECT_GT(m.Normal(static_cast<int>(t)).dot(mid - centre), 0) << t;
      for (int k = 0; k < 3; ++k) ++edges[{tri[k], tri[(k + 1) % 3]}];
    } else {
      // A trunk face: vertical, its normal pointing away from the axis, between the ground and
      // the height where the crown is as wide as the trunk: 9 - 3 sqrt(1 - 0.1^2).
      const Eigen::Vector3d n = m.Normal(static_cast<int>(t));
      EXPECT_NEAR(n.z(), 0, 1e-9);
      EXPECT_GT(n.dot(mid - centre), 0);
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d p = m.vertices[tri[k]];
        EXPECT_NEAR((p - centre).head<2>().norm(), 0.4, 1e-5);
        EXPECT_TRUE(std::abs(p.z() - 1) < 1e-5 ||
                    std::abs(p.z() - (9 - 3 * std::sqrt(1 - 0.01))) < 1e-5)
            << p.z();
      }
    }
  }
  EXPECT_NEAR(top, 12, 1e-6);
  // 12 segments x 8 rings: two caps of 12 triangles, 6 bands of 12 quads.
  EXPECT_EQ(crown_triangles, 2 * 12 + 6 * 12 * 2);
  // Closed and consistently wound: every edge once each way.
  for (const auto& [e, count] : edges) {
    EXPECT_EQ(count, 1);
    EXPECT_EQ(edges.count({e.second, e.first}), 1u);
  }
  // An inscribed polyhedron: less than the ellipsoid's volume 4/3 pi 4 4 3, more than that of
  // the ellipsoid shrunk by the cosine of the widest facet's angular radius (under pi/8: a ring
  // step is pi/8, a segment pi/6, so a band's quad spans 11.25 deg by 15 deg about its middle).
  const double full = 4.0 / 3.0 * kPi * 4 * 4 * 3;
  EXPECT_LT(volume, full);
  EXPECT_GT(volume, full * std::pow(std::cos(kPi / 8), 3));
}

TEST(TreesTest, ABushWhoseCrownReachesTheGroundHasNoTrunk) {
  Tree bush;
  bush.name = "box";
  bush.height_m = 2;
  bush.crown_diameter_m = 3;
  bush.crown_depth_m = 2;
  bush.trunk_diameter_m = 0.2;
  const Mesh m = ParseObj(TreesObjText({bush}), "bush");
  for (const Eigen::Vector3d& v : m.vertices) EXPECT_GE(v.z(), -1e-9);
  EXPECT_EQ(m.triangles.size(), 2u * 12 + 6 * 12 * 2);
}

}  // namespace
}  // namespace rouen
