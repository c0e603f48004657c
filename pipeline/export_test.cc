#include "pipeline/export.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>

#include "core/error.h"
#include "core/files.h"
#include "pipeline/export_test_util.h"
#include "render/render.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

class ExportTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("rouen_export_test_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    testing::WriteExportTestScene(*dir_ / "scene");
    scene_ = new LoadedScene(LoadScene(*dir_ / "scene"));
  }
  static void TearDownTestSuite() {
    delete scene_;
    fs::remove_all(*dir_);
    delete dir_;
  }
  static fs::path* dir_;
  static LoadedScene* scene_;
};
fs::path* ExportTest::dir_ = nullptr;
LoadedScene* ExportTest::scene_ = nullptr;

std::vector<float> Floats(const std::string& bytes) {
  std::vector<float> v(bytes.size() / sizeof(float));
  std::memcpy(v.data(), bytes.data(), v.size() * sizeof(float));
  return v;
}

double SrgbDecode(double encoded) {
  return encoded <= 0.04045 ? encoded / 12.92 : std::pow((encoded + 0.055) / 1.055, 2.4);
}

TEST(ExportFrameTest, EnuToGltfIsARotationToYUp) {
  EXPECT_EQ(EnuToGltf({1, 0, 0}), Eigen::Vector3d(1, 0, 0));   // east: +x
  EXPECT_EQ(EnuToGltf({0, 0, 1}), Eigen::Vector3d(0, 1, 0));   // up: +y
  EXPECT_EQ(EnuToGltf({0, 1, 0}), Eigen::Vector3d(0, 0, -1));  // north: -z
  Eigen::Matrix3d m;
  for (int i = 0; i < 3; ++i) m.col(i) = EnuToGltf(Eigen::Vector3d::Unit(i));
  EXPECT_NEAR(m.determinant(), 1.0, 1e-12);  // no mirror: faces keep their winding
}

TEST_F(ExportTest, TheGlbParsesBackWithTheMeshAndBothAlbedoSets) {
  const fs::path out = *dir_ / "building.glb";
  const GltfSummary summary = WriteSceneGltf(*scene_, out);
  const std::string bytes = ReadFileToString(out);
  EXPECT_EQ(summary.bytes, bytes.size());
  const testing::ParsedGlb glb = testing::ReadGlb(bytes);
  ASSERT_EQ(glb.error, "");
  const nlohmann::json& j = glb.json;
  EXPECT_EQ(j["asset"]["version"], "2.0");
  const Mesh& mesh = scene_->solved.mesh;
  const SurfaceGrid& grid = scene_->solved.grid;
  const AlbedoResult& albedo = scene_->solved.albedo;
  ASSERT_EQ(j["meshes"].size(), mesh.block_names.size());
  ASSERT_EQ(j["nodes"].size(), mesh.block_names.size());
  EXPECT_EQ(summary.triangles, static_cast<int64_t>(mesh.triangles.size()));
  EXPECT_EQ(summary.vertices, 3 * static_cast<int64_t>(mesh.triangles.size()));
  EXPECT_EQ(summary.clipped_texels, 0);
  for (size_t b = 0; b < mesh.block_names.size(); ++b) {
    const nlohmann::json& m = j["meshes"][b];
    EXPECT_EQ(m["name"], mesh.block_names[b]);
    EXPECT_EQ(j["nodes"][b]["name"], mesh.block_names[b]);
    std::vector<int> tris;
    for (int t = 0; t < static_cast<int>(mesh.triangles.size()); ++t)
      if (mesh.triangle_block[t] == static_cast<int>(b)) tris.push_back(t);
    const nlohmann::json& prim = m["primitives"][0];
    const nlohmann::json& acc = j["accessors"];
    const int pos = prim["attributes"]["POSITION"], nrm = prim["attributes"]["NORMAL"];
    const int uv = prim["attributes"]["TEXCOORD_0"], idx = prim["indices"];
    EXPECT_EQ(acc[pos]["count"], 3 * tris.size());
    EXPECT_EQ(acc[nrm]["count"], 3 * tris.size());
    EXPECT_EQ(acc[uv]["count"], 3 * tris.size());
    EXPECT_EQ(acc[idx]["count"], 3 * tris.size());  // triangles x 3
    // Positions are the model's vertices turned into glTF's frame; min/max their bounds.
    const std::vector<float> p = Floats(glb.View(acc[pos]["bufferView"]));
    const std::vector<float> n = Floats(glb.View(acc[nrm]["bufferView"]));
    const std::vector<float> t = Floats(glb.View(acc[uv]["bufferView"]));
    ASSERT_EQ(p.size(), 9 * tris.size());
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e30), hi = -lo;
    for (size_t k = 0; k < tris.size(); ++k)
      for (int c = 0; c < 3; ++c) {
        const Eigen::Vector3d want = EnuToGltf(mesh.vertices[mesh.triangles[tris[k]][c]]);
        const Eigen::Vector3d got(p[9 * k + 3 * c], p[9 * k + 3 * c + 1], p[9 * k + 3 * c + 2]);
        EXPECT_LT((got - want).norm(), 1e-5);
        const Eigen::Vector3d normal(n[9 * k + 3 * c], n[9 * k + 3 * c + 1], n[9 * k + 3 * c + 2]);
        EXPECT_LT((normal - EnuToGltf(mesh.Normal(tris[k]))).norm(), 1e-6);
        lo = lo.cwiseMin(want);
        hi = hi.cwiseMax(want);
      }
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(acc[pos]["min"][c].get<double>(), lo[c], 1e-5);
      EXPECT_NEAR(acc[pos]["max"][c].get<double>(), hi[c], 1e-5);
    }
    // The material: the sun albedo as base colour, the other set and the retro in extras.
    const nlohmann::json& mat = j["materials"][prim["material"].get<int>()];
    const nlohmann::json& extras = mat["extras"]["rouen"];
    EXPECT_NEAR(extras["retro"].get<double>(), albedo.retro[b], 1e-12);
    // The sun lobe where the block has one (the tower), none on the matte plaza.
    const SpecularLobe lobe = BlockLobe(albedo.sun_lobes, b);
    ASSERT_EQ(extras.contains("sun_lobe"), !lobe.IsZero()) << mesh.block_names[b];
    if (!lobe.IsZero()) {
      EXPECT_EQ(extras["sun_lobe"]["rho_s"].get<std::vector<double>>(),
                (std::vector<double>{lobe.rho_s[0], lobe.rho_s[1], lobe.rho_s[2]}));
      EXPECT_EQ(extras["sun_lobe"]["n"].get<double>(), lobe.n);
      EXPECT_EQ(extras["sun_lobe"]["kappa"].get<double>(), lobe.kappa);
    }
    const int sun_tex = mat["pbrMetallicRoughness"]["baseColorTexture"]["index"];
    EXPECT_EQ(extras["albedo_sun_texture"], sun_tex);
    const int se_tex = extras["albedo_sky_env_texture"];
    // Both images decode; at each grid point of the block, the texel its UV falls on holds the
    // point's albedo (sRGB-decoded; 8 bits and the texel's 0.25 m offset: within 0.01).
    Image images[2];
    int k = 0;
    for (int tex : {sun_tex, se_tex}) {
      const nlohmann::json& image = j["images"][j["textures"][tex]["source"].get<int>()];
      EXPECT_EQ(image["mimeType"], "image/png");
      const fs::path png = *dir_ / ("tex" + std::to_string(tex) + ".png");
      WriteFileAtomic(png, glb.View(image["bufferView"]));
      images[k++] = ReadImage(png.string());
    }
    ASSERT_GT(images[0].width, 0);
    int checked = 0;
    for (int i = 0; i < grid.size(); i += 7) {
      const GridPoint& g = grid.points[i];
      const auto it = std::find(tris.begin(), tris.end(), g.triangle);
      if (it == tris.end()) continue;
      const size_t kk = it - tris.begin();
      const Eigen::Vector3i& tri = mesh.triangles[g.triangle];
      Eigen::Matrix<double, 3, 2> e;
      e.col(0) = mesh.vertices[tri[1]] - mesh.vertices[tri[0]];
      e.col(1) = mesh.vertices[tri[2]] - mesh.vertices[tri[0]];
      const Eigen::Vector2d bary =
          e.colPivHouseholderQr().solve(g.position - mesh.vertices[tri[0]]);
      Eigen::Vector2d at = Eigen::Vector2d::Zero();
      const double w[3] = {1 - bary[0] - bary[1], bary[0], bary[1]};
      for (int c = 0; c < 3; ++c)
        at += w[c] * Eigen::Vector2d(t[6 * kk + 2 * c], t[6 * kk + 2 * c + 1]);
      for (int set = 0; set < 2; ++set) {
        const Image& im = images[set];
        const int x = std::clamp(static_cast<int>(at.x() * im.width), 0, im.width - 1);
        const int y = std::clamp(static_cast<int>(at.y() * im.height), 0, im.height - 1);
        const Eigen::Vector3d want = set == 0 ? albedo.rho_sun[i] : albedo.rho_se[i];
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(SrgbDecode(im.at(x, y, c) / 255.0), want[c], 0.01)
              << mesh.block_names[b] << " point " << i << " set " << set << " channel " << c;
      }
      ++checked;
    }
    EXPECT_GT(checked, 3) << mesh.block_names[b];
  }
}

TEST_F(ExportTest, BadModelsAreRefused) {
  Mesh empty;
  EXPECT_THROW(EncodeGlb(empty, SurfaceGrid{}, AlbedoResult{}, {}), Error);
  AlbedoResult short_albedo;
  EXPECT_THROW(EncodeGlb(scene_->solved.mesh, scene_->solved.grid, short_albedo, {}), Error);
  GltfOptions o;
  o.texels_per_cell = 0;
  EXPECT_THROW(EncodeGlb(scene_->solved.mesh, scene_->solved.grid, scene_->solved.albedo, {}, o),
               Error);
}

// The render with alpha is the plain render's image (render/render.h without alpha) plus a
// fourth channel: the building's coverage.
TEST_F(ExportTest, RenderSceneViewAddsAlphaAndTheHeader) {
  RenderRequest request;
  request.slot = 0;
  const SceneView& view = FindView(*scene_, "");
  request.intrinsics = view.intrinsics;
  request.pose = view.pose;
  const RenderedView r = RenderSceneView(*scene_, request);
  const SolveResult& solved = scene_->solved;
  const Lighting& lighting = solved.slots[0].lighting;
  // Its irradiance exact where the view looks (GridPointsInView), as RenderSceneView takes it.
  const std::vector<uint8_t> in_view =
      GridPointsInView(solved.grid, *solved.caster, view.intrinsics, view.pose);
  const Image plain = RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo, lighting,
                                 IrradianceFor(solved, lighting, &in_view), view.intrinsics,
                                 view.pose, RenderOptions{});
  ASSERT_EQ(r.rgba.channels, 4);
  ASSERT_EQ(r.rgb.data.size(), plain.data.size());
  for (size_t i = 0; i < plain.data.size(); ++i) ASSERT_EQ(r.rgb.data[i], plain.data[i]) << i;
  const Image ids =
      RenderBlockIds(scene_->solved.mesh, *scene_->solved.caster, view.intrinsics, view.pose);
  int building = 0, partial = 0;
  for (int y = 0; y < ids.height; ++y)
    for (int x = 0; x < ids.width; ++x) {
      const float a = r.rgba.at(x, y, 3);
      const bool hit = ids.at(x, y) >= 0;
      building += hit;
      partial += a > 0 && a < 1;
      if (hit)
        EXPECT_GT(a, 0.f) << x << "," << y;
      else
        EXPECT_LT(a, 1.f) << x << "," << y;
    }
  EXPECT_GT(building, 1000);
  EXPECT_LT(partial, building / 10);  // silhouettes only
  std::map<std::string, ImageAttribute::Value> attrs;
  for (const ImageAttribute& a : r.attributes) attrs[a.name] = a.value;
  EXPECT_EQ(std::get<std::string>(attrs.at("rouen:time")), "2026-06-21T16:00:00.000Z");
  EXPECT_EQ(std::get<int>(attrs.at("rouen:slot")), 0);
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_azimuth_deg")), 130, 1e-4);
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_elevation_deg")), 35, 1e-4);
  const nlohmann::json camera =
      nlohmann::json::parse(std::get<std::string>(attrs.at("rouen:camera")));
  EXPECT_EQ(camera["intrinsics"]["width"], 160);
}

TEST_F(ExportTest, TheEnvmapOfASlotKeepsItsHorizontalIrradiance) {
  RenderRequest request;
  request.slot = 0;
  LatLongOptions o;
  o.width = 256;
  const SceneEnvmap env = SceneEnvmapFor(*scene_, request, o);
  EXPECT_EQ(env.map.width, 256);
  EXPECT_EQ(env.map.height, 128);
  // The bound of render/envmap_test.cc at this width is ~2%; the sun's share dominates it.
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(env.horizontal_from_map[c], env.horizontal_rouen[c],
                0.02 * env.horizontal_rouen[c]);
}

}  // namespace
}  // namespace rouen
