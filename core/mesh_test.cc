#include "core/mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/files.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

class MeshTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rouen_core_mesh_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const std::string p = (dir_ / name).string();
    WriteFileAtomic(p, text);
    return p;
  }
  // Expects ReadObj to fail with "<file>:<line>:" and a phrase.
  void ExpectError(const std::string& text, int line, const std::string& phrase) {
    const std::string p = Write("bad.obj", text);
    try {
      ReadObj(p);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(p + ":" + std::to_string(line) + ":"), std::string::npos) << msg;
      EXPECT_NE(msg.find(phrase), std::string::npos) << msg;
    }
  }
  fs::path dir_;
};

TEST_F(MeshTest, ReadsAllFaceFormsAndGroups) {
  const std::string p = Write("a.obj", R"(# a unit square on the ground and a wall
mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 1
f 1 2 3
f 1/1 3/1 4/1
g wall north
usemtl brick
s off
v 0 1 0   # again, for the wall
v 1 1 0
v 1 1 1
v 0 1 1
f -4//1 -1//1 -2//1 -3//1
o roof
v 0 0 1
v 1 0 1
v 1 1 1.5
f 9/1/1 10/1/1 11/1/1
unknownstatement 1 2 3
g default
f 1 3 2
)");
  const Mesh m = ReadObj(p);
  EXPECT_EQ(m.vertices.size(), 11u);
  ASSERT_EQ(m.triangles.size(), 6u);
  ASSERT_EQ(m.block_names.size(), 3u);
  EXPECT_EQ(m.block_names[0], "default");
  EXPECT_EQ(m.block_names[1], "wall north");
  EXPECT_EQ(m.block_names[2], "roof");
  EXPECT_EQ(m.triangle_block, (std::vector<int>{0, 0, 1, 1, 2, 0}));
  // The quad was fanned from its first vertex (negative indices: -4 -> vertex 5 (0-based 4)).
  EXPECT_EQ(m.triangles[2], Eigen::Vector3i(4, 7, 6));
  EXPECT_EQ(m.triangles[3], Eigen::Vector3i(4, 6, 5));
  EXPECT_TRUE(m.Normal(0).isApprox(Eigen::Vector3d(0, 0, 1)));
  EXPECT_TRUE(m.Normal(5).isApprox(Eigen::Vector3d(0, 0, -1)));
  EXPECT_DOUBLE_EQ(m.Area(0) + m.Area(1), 1.0);
  // The wall, listed (0,1,0) (0,1,1) (1,1,1) (1,1,0), is counter-clockwise seen from +y.
  EXPECT_TRUE(m.Normal(2).isApprox(Eigen::Vector3d(0, 1, 0)));
  EXPECT_TRUE(m.Normal(3).isApprox(Eigen::Vector3d(0, 1, 0)));
}

TEST_F(MeshTest, ErrorsNameFileAndLine) {
  ExpectError("v 0 0 0\nv 1 0 x\n", 2, "bad number");
  ExpectError("v 0 0 0\nv 1 0\n", 2, "3 coordinates");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 4\n", 5, "out of range");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", 4, "out of range");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 2 3\n", 4, "out of range");
  ExpectError("v 0 0 0\nv 1 0 0\nf 1 2\n", 3, "at least 3");
  ExpectError("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", 4, "degenerate");
  ExpectError("v 0 0 0\nv 1 0 0\nf 1 2 2\n", 3, "degenerate");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", 4, "bad vertex index");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1e999 0 0\n", 4, "bad number");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1e300 0\n", 3, "vertex: coordinate 1e+300 m is outside");
  EXPECT_THROW(ReadObj((dir_ / "missing.obj").string()), Error);
}

TEST_F(MeshTest, AModelWithoutFacesIsRefusedNamingTheFile) {
  // Empty, comments only, or vertices without faces: nothing to render, refused when read
  // rather than minutes later in the solve.
  for (const char* text : {"", "# just a comment\n\n   # another\n", "v 0 0 0\nv 1 0 0\n"}) {
    const std::string p = Write("empty.obj", text);
    try {
      ReadObj(p);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(p + ": no faces"), std::string::npos) << e.what();
    }
  }
}

TEST_F(MeshTest, AByteOrderMarkDoesNotHideTheFirstVertex) {
  const Mesh m = ReadObj(Write("bom.obj", "\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
  EXPECT_EQ(m.vertices.size(), 3u);
  EXPECT_EQ(m.triangles.size(), 1u);
}

TEST_F(MeshTest, WriteReadRoundTrip) {
  Mesh m;
  const int ground = m.AddBlock("ground");
  const int tower = m.AddBlock("tower east");
  m.AddPolygon({{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}}, ground);
  m.AddPolygon({{10, 0, 0}, {10, 10, 0}, {10, 10, 30.25}, {10, 0, 30.25}}, tower);
  m.AddTriangle(0, 2, 1, ground);  // blocks may interleave
  m.vertices[3].x() = 1.0 / 3.0;   // needs all 17 digits
  const std::string p = (dir_ / "out.obj").string();
  WriteObj(p, m);
  const Mesh back = ReadObj(p);
  EXPECT_EQ(back.vertices, m.vertices);
  EXPECT_EQ(back.block_names, m.block_names);
  ASSERT_EQ(back.triangles.size(), m.triangles.size());
  // WriteObj groups triangles by block, keeping their order within a block.
  std::vector<std::pair<int, Eigen::Vector3i>> expected;
  for (int b = 0; b < 2; ++b) {
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      if (m.triangle_block[t] == b) expected.emplace_back(b, m.triangles[t]);
    }
  }
  for (size_t t = 0; t < back.triangles.size(); ++t) {
    EXPECT_EQ(back.triangle_block[t], expected[t].first);
    EXPECT_EQ(back.triangles[t], expected[t].second);
  }
}

TEST(MeshGeometryTest, NormalAreaPolygon) {
  Mesh m;
  const int b = m.AddBlock("wall");
  // A 2 x 3 rectangle in the plane x = 5, counter-clockwise seen from +x.
  m.AddPolygon({{5, 0, 0}, {5, 2, 0}, {5, 2, 3}, {5, 0, 3}}, b);
  ASSERT_EQ(m.triangles.size(), 2u);
  double area = 0;
  for (int t = 0; t < 2; ++t) {
    EXPECT_TRUE(m.Normal(t).isApprox(Eigen::Vector3d(1, 0, 0)));
    area += m.Area(t);
  }
  EXPECT_DOUBLE_EQ(area, 6.0);
  EXPECT_EQ(m.triangle_block, (std::vector<int>{b, b}));
}

// Surroundings appended to a building: their triangles after the building's, their vertices
// renumbered, their blocks after the building's; a block name in both is refused by name.
TEST(MeshGeometryTest, AppendKeepsBothModelsAndRefusesASharedBlock) {
  Mesh building;
  building.AddPolygon({{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}}, building.AddBlock("wall"));
  Mesh around;
  const int house = around.AddBlock("house");
  around.AddBlock("unused");
  around.AddPolygon({{0, 9, 0}, {0, 9, 3}, {2, 9, 3}}, house);
  Mesh both = building;
  both.Append(around);
  EXPECT_EQ(both.block_names, (std::vector<std::string>{"wall", "house", "unused"}));
  ASSERT_EQ(both.triangles.size(), 3u);
  EXPECT_EQ(both.triangle_block, (std::vector<int>{0, 0, 1}));
  EXPECT_EQ(both.triangles[2], Eigen::Vector3i(4, 5, 6));
  EXPECT_TRUE(both.Normal(2).isApprox(around.Normal(0)));
  Mesh clash;
  clash.AddPolygon({{0, 5, 0}, {1, 5, 0}, {1, 5, 1}}, clash.AddBlock("wall"));
  try {
    both.Append(clash);
    ADD_FAILURE() << "a shared block name was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()),
              "block 'wall' is in both models (rename the group in one of them)");
  }
  EXPECT_EQ(both.triangles.size(), 3u);  // untouched
}

}  // namespace
}  // namespace rouen
