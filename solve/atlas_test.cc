#include "solve/atlas.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "core/error.h"
#include "core/files.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

Mesh TwoBlocks() {
  Mesh m;
  const int box = m.AddBlock("box");
  testing::AddBox(&m, {0, 0, 0}, {2, 3, 4}, box, true);
  const int ground = m.AddBlock("ground");
  m.AddPolygon({{-5, -5, 0}, {5, -5, 0}, {5, 5, 0}, {-5, 5, 0}}, ground);
  return m;
}

// A smooth value per grid point, so that the atlas can be read back against the grid.
std::vector<Eigen::Vector3d> Field(const SurfaceGrid& g) {
  std::vector<Eigen::Vector3d> v;
  for (const GridPoint& p : g.points)
    v.push_back(Eigen::Vector3d(0.2 + 0.05 * p.position.x(), 0.3 + 0.02 * p.position.z(),
                                0.5 + 0.01 * p.position.y()));
  return v;
}

// Bilinear lookup at a texture coordinate (origin bottom-left), as a renderer samples.
Eigen::Vector3d Sample(const Image& im, const Eigen::Vector2d& uv) {
  const double x = uv.x() * im.width, y = (1 - uv.y()) * im.height;
  return Eigen::Vector3d(im.Sample(x, y, 0), im.Sample(x, y, 1), im.Sample(x, y, 2));
}

TEST(AtlasTest, TilesAreDisjointAndInsideTheirAtlas) {
  const Mesh m = TwoBlocks();
  GridOptions go;
  go.spacing_m = 0.5;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const AtlasLayout layout = LayoutAtlases(m, g, AtlasOptions{});
  for (int b = 0; b < 2; ++b) {
    ASSERT_GT(layout.width[b], 0);
    std::vector<int> owner(static_cast<size_t>(layout.width[b]) * layout.height[b], -1);
    for (int t = 0; t < static_cast<int>(layout.tiles.size()); ++t) {
      const AtlasTile& tile = layout.tiles[t];
      if (tile.block != b) continue;
      EXPECT_EQ(tile.size, g.triangle_n[t] * 2);
      ASSERT_LE(tile.x + tile.size + 2, layout.width[b]);
      ASSERT_LE(tile.y + tile.size + 2, layout.height[b]);
      for (int y = tile.y; y < tile.y + tile.size + 2; ++y)
        for (int x = tile.x; x < tile.x + tile.size + 2; ++x) {
          int& o = owner[static_cast<size_t>(y) * layout.width[b] + x];
          EXPECT_EQ(o, -1) << "texel " << x << "," << y << " of block " << b << " used twice";
          o = t;
        }
      for (const auto& [u, v] : {std::pair{0.0, 0.0}, std::pair{1.0, 0.0}, std::pair{0.0, 1.0}}) {
        const Eigen::Vector2d uv = layout.Uv(t, u, v);
        EXPECT_GE(uv.x(), 0);
        EXPECT_LE(uv.x(), 1);
        EXPECT_GE(uv.y(), 0);
        EXPECT_LE(uv.y(), 1);
      }
    }
  }
}

// A renderer sampling the atlas at a surface point's texture coordinate gets the grid's
// value there: bilinear between texel centres of a piecewise-linear field, so within the
// field's change across one texel.
TEST(AtlasTest, SamplingTheAtlasGivesTheGridsValue) {
  const Mesh m = TwoBlocks();
  GridOptions go;
  go.spacing_m = 0.5;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const std::vector<Eigen::Vector3d> values = Field(g);
  const AtlasLayout layout = LayoutAtlases(m, g, AtlasOptions{});
  const Image atlas[2] = {BakeAtlas(layout, g, values, 0), BakeAtlas(layout, g, values, 1)};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(0, 1);
  for (int t = 0; t < static_cast<int>(m.triangles.size()); ++t) {
    // The field changes by at most 0.05 per metre; a texel spans cell / 2 metres of the
    // triangle's edges: the longest edge / (2 n).
    double edge = 0;
    for (int k = 0; k < 3; ++k)
      edge = std::max(
          edge, (m.vertices[m.triangles[t][k]] - m.vertices[m.triangles[t][(k + 1) % 3]]).norm());
    const double tol = 0.05 * edge / layout.tiles[t].size * 2 + 1e-6;
    for (int s = 0; s < 20; ++s) {
      double u = uni(rng), v = uni(rng);
      if (u + v > 1) {
        u = 1 - u;
        v = 1 - v;
      }
      const Eigen::Vector3d want = g.Interpolate(values, t, u, v);
      const Eigen::Vector3d got = Sample(atlas[m.triangle_block[t]], layout.Uv(t, u, v));
      EXPECT_LT((got - want).cwiseAbs().maxCoeff(), tol)
          << "triangle " << t << " at " << u << "," << v;
    }
  }
}

TEST(AtlasTest, TexturedObjNamesEachBlocksAtlas) {
  const Mesh m = TwoBlocks();
  GridOptions go;
  go.spacing_m = 1;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const AtlasLayout layout = LayoutAtlases(m, g, AtlasOptions{});
  const fs::path dir = fs::temp_directory_path() / ("rouen_atlas_" + std::to_string(getpid()));
  fs::create_directories(dir);
  WriteTexturedObj(dir / "model_textured.obj", m, layout, {"atlas/box.exr", ""});
  const std::string obj = ReadFileToString(dir / "model_textured.obj");
  const std::string mtl = ReadFileToString(dir / "model_textured.mtl");
  EXPECT_NE(obj.find("mtllib model_textured.mtl"), std::string::npos);
  EXPECT_NE(obj.find("usemtl box"), std::string::npos);
  EXPECT_NE(mtl.find("map_Kd atlas/box.exr"), std::string::npos);
  // The OBJ reads back as the same mesh (texture coordinates are ignored by the reader).
  const Mesh back = ReadObj((dir / "model_textured.obj").string());
  EXPECT_EQ(back.triangles.size(), m.triangles.size());
  EXPECT_EQ(back.block_names, m.block_names);
  fs::remove_all(dir);
}

TEST(AtlasTest, TooLargeAnAtlasIsRefusedNamingTheBlock) {
  const Mesh m = TwoBlocks();
  GridOptions go;
  go.spacing_m = 0.02;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  AtlasOptions o;
  o.max_side = 256;
  try {
    LayoutAtlases(m, g, o);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("block '"), std::string::npos) << e.what();
  }
  o.texels_per_cell = 0;
  EXPECT_THROW(LayoutAtlases(m, g, o), Error);
}

}  // namespace
}  // namespace rouen
