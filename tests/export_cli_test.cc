// rouen export, rouen envmap and rouen render's alpha and header, end to end on a small scene
// written without a session (pipeline/export_test_util.h): the GLB checked by the Khronos glTF
// validator (node + npm gltf-validator) and imported by Blender, the envmap's irradiance
// re-integrated and rendered by Blender/Cycles on a white plane, the render's header read back
// with OpenImageIO. The Blender and validator parts skip, saying so, when those are missing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/files.h"
#include "core/image.h"
#include "core/solar.h"
#include "pipeline/export.h"
#include "pipeline/export_test_util.h"
#include "render/envmap.h"
#include "render/render.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;
using cli_test::RunShell;

// The JSON after `tag` on each line of `out` that starts with it.
std::vector<nlohmann::json> Tagged(const std::string& out, const std::string& tag) {
  std::vector<nlohmann::json> found;
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(tag + " ", 0) == 0)
      found.push_back(nlohmann::json::parse(line.substr(tag.size() + 1)));
  return found;
}

std::map<std::string, ImageAttribute::Value> Attributes(const fs::path& file) {
  std::map<std::string, ImageAttribute::Value> m;
  for (const ImageAttribute& a : ReadImageAttributes(file.string())) m[a.name] = a.value;
  return m;
}

class ExportCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(cli_test::TempDir("export_cli"));
    testing::WriteExportTestScene(*dir_ / "scene");
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static fs::path Scene() { return *dir_ / "scene"; }
  static fs::path* dir_;
};
fs::path* ExportCli::dir_ = nullptr;

TEST_F(ExportCli, TheGlbPassesTheKhronosValidator) {
  const fs::path glb = *dir_ / "validated.glb";
  const Result r = RunRouen("export " + Q(Scene()) + " --gltf " + Q(glb));
  ASSERT_EQ(r.code, 0) << r.out;
  ASSERT_EQ(testing::ReadGlb(ReadFileToString(glb)).error, "");
  if (FindOnPath("node").empty() || FindOnPath("npm").empty())
    GTEST_SKIP() << "node and npm are not installed (Debian: nodejs, npm): the Khronos glTF "
                    "validator (npm gltf-validator) cannot run";
  // Installed once per build folder, beside the binary under test.
  const fs::path prefix = fs::path(ROUEN_BINARY).parent_path().parent_path() / "npm";
  const fs::path modules = prefix / "node_modules";
  if (!fs::exists(modules / "gltf-validator" / "package.json")) {
    const Result npm =
        RunShell("npm install --no-audit --no-fund --prefix " + Q(prefix) + " gltf-validator");
    if (npm.code != 0 || !fs::exists(modules / "gltf-validator" / "package.json"))
      GTEST_SKIP() << "npm could not install gltf-validator (no registry?): " << npm.out;
  }
  const Result v = RunShell("node " + Q(fs::path(ROUEN_SOURCE_DIR) / "tests/gltf_validate.js") +
                            " " + Q(modules) + " " + Q(glb));
  ASSERT_EQ(v.code, 0) << v.out;
  const nlohmann::json report = nlohmann::json::parse(v.out.substr(v.out.find('{')));
  const nlohmann::json& issues = report["issues"];
  EXPECT_EQ(issues["numErrors"], 0) << issues.dump(1);
  std::printf("gltf-validator %s: %d errors, %d warnings, %d infos, %d hints\n",
              report.value("validatorVersion", "?").c_str(), issues["numErrors"].get<int>(),
              issues["numWarnings"].get<int>(), issues["numInfos"].get<int>(),
              issues["numHints"].get<int>());
  for (const nlohmann::json& m : issues["messages"])
    std::printf("  %s %s: %s\n", m.value("pointer", "").c_str(), m.value("code", "").c_str(),
                m.value("message", "").c_str());
  EXPECT_EQ(report["info"]["drawCallCount"], 2);  // one per block
}

TEST_F(ExportCli, BlenderImportsTheGlbInTheScenesFrame) {
  const fs::path glb = *dir_ / "blender.glb";
  const Result r = RunRouen("export " + Q(Scene()) + " --gltf " + Q(glb));
  ASSERT_EQ(r.code, 0) << r.out;
  if (FindOnPath("blender").empty())
    GTEST_SKIP() << "blender is not installed: the import is not checked";
  const Result b =
      RunShell("blender -b --factory-startup --python " +
               Q(fs::path(ROUEN_SOURCE_DIR) / "tests/blender_gltf_import.py") + " -- " + Q(glb));
  const std::vector<nlohmann::json> found = Tagged(b.out, "ROUEN_GLTF");
  ASSERT_EQ(found.size(), 1u) << b.out;
  const nlohmann::json& j = found[0];
  EXPECT_EQ(j["meshes"], nlohmann::json({"plaza", "tower"}));
  // Blender's importer turns glTF's y-up back into z-up: the scene's ENU bounds (the plaza
  // 40 x 40 m at z = 0, the tower 15 m high).
  const double lo[3] = {-20, -20, 0}, hi[3] = {20, 20, 15};
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(j["min"][c].get<double>(), lo[c], 1e-4) << c;
    EXPECT_NEAR(j["max"][c].get<double>(), hi[c], 1e-4) << c;
  }
  const LoadedScene scene = LoadScene(Scene());
  EXPECT_EQ(j["triangles"], scene.solved.mesh.triangles.size());
  EXPECT_EQ(j["materials"], nlohmann::json({{"plaza", true}, {"tower", true}}));
  // The importer loads the images materials use: each block's sun albedo (the sky +
  // environment albedo, named only in extras, stays in the file).
  EXPECT_EQ(j["images"], 2);
}

TEST_F(ExportCli, ExportRefusesBadArgumentsBeforeWriting) {
  Result r = RunRouen("export " + Q(*dir_ / "none") + " --gltf " + Q(*dir_ / "none.glb"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("no such scene folder"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(*dir_ / "none.glb"));
  r = RunRouen("export " + Q(Scene()) + " --gltf " + Q(*dir_ / "missing" / "b.glb"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("--gltf"), std::string::npos) << r.out;
  // A .gltf name promises JSON glTF; rouen writes the binary form.
  r = RunRouen("export " + Q(Scene()) + " --gltf " + Q(*dir_ / "b.gltf"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("rouen writes binary glTF; name it .glb"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(*dir_ / "b.gltf"));
  r = RunRouen("envmap " + Q(Scene()) + " --slot 0 --out " + Q(*dir_ / "sky.png"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("--out"), std::string::npos) << r.out;
  r = RunRouen("envmap " + Q(Scene()) + " --slot 3 --out " + Q(*dir_ / "sky3.exr"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("slot 3"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(*dir_ / "sky3.exr"));
  r = RunRouen("envmap " + Q(Scene()) + " --out " + Q(*dir_ / "sky4.exr"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("exactly one of --slot"), std::string::npos) << r.out;
}

// The envmap of the scene's slot: its header, its irradiance re-integrated on planes against
// rouen's (the bound of render/envmap_test.cc at width 512 is a few tenths of a percent for the
// sky and environment and ~2% of the sun's share; 2% overall), and the same planes rendered
// white in Blender/Cycles lit by the file.
TEST_F(ExportCli, TheEnvmapLightsPlanesAsRouenPredicts) {
  const fs::path sky = *dir_ / "sky.exr";
  const Result r = RunRouen("envmap " + Q(Scene()) + " --slot 0 --width 512 --out " + Q(sky));
  ASSERT_EQ(r.code, 0) << r.out;
  auto attrs = Attributes(sky);
  EXPECT_EQ(std::get<std::string>(attrs.at("rouen:time")), "2026-06-21T16:00:00.000Z");
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_azimuth_deg")), 130, 1e-3);
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_elevation_deg")), 35, 1e-3);
  EXPECT_NE(std::get<std::string>(attrs.at("rouen:orientation")).find("Blender"),
            std::string::npos);
  const Image map = ReadImage(sky.string());
  ASSERT_EQ(map.width, 512);
  ASSERT_EQ(map.height, 256);
  const Lighting lighting = testing::ExportTestSlot().ToLighting();
  const std::vector<Eigen::Vector3d> normals = {EnuFromAzEl(0, 90), EnuFromAzEl(90, 0),
                                                EnuFromAzEl(0, 0), EnuFromAzEl(270, 0),
                                                EnuFromAzEl(180, 0)};
  std::vector<Eigen::Vector3d> rouen;
  for (const Eigen::Vector3d& n : normals) {
    rouen.push_back(UnoccludedIrradiance(lighting, n, 0));
    const Eigen::Vector3d e = LatLongIrradiance(map, n);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], rouen.back()[c], 0.02 * rouen.back()[c]);
  }
  if (FindOnPath("blender").empty())
    GTEST_SKIP() << "blender is not installed: Cycles is not asked";
  std::string args;
  for (const Eigen::Vector3d& n : normals)
    args += " " + std::to_string(n.x()) + "," + std::to_string(n.y()) + "," + std::to_string(n.z());
  const Result b = RunShell("blender -b --factory-startup --python " +
                            Q(fs::path(ROUEN_SOURCE_DIR) / "tests/blender_envmap_plane.py") +
                            " -- " + Q(sky) + " " + Q(*dir_) + " 512" + args);
  const std::vector<nlohmann::json> planes = Tagged(b.out, "ROUEN_PLANE");
  ASSERT_EQ(planes.size(), normals.size()) << b.out;
  for (size_t i = 0; i < normals.size(); ++i) {
    // Cycles' estimate: 256 pixels x 512 samples, the sun (two thirds of a sunlit plane's
    // irradiance) importance-sampled from the map; its noise is well under 1%. A map turned or
    // mirrored would move the sun from the east and south walls to others (factors of 2 and more).
    for (int c = 0; c < 3; ++c) {
      const double e = planes[i]["irradiance"][c];
      EXPECT_NEAR(e, rouen[i][c], 0.03 * rouen[i][c])
          << "normal " << normals[i].transpose() << " channel " << c;
    }
    std::printf("plane (%+.2f %+.2f %+.2f): Cycles %.4g, rouen %.4g (G)\n", normals[i].x(),
                normals[i].y(), normals[i].z(), planes[i]["irradiance"][1].get<double>(),
                rouen[i][1]);
  }
}

// rouen render writes RGBA: alpha is the building's coverage; the header holds the time, the
// sun and the camera.
TEST_F(ExportCli, RenderWritesAlphaAndItsTimeSunAndCameraInTheHeader) {
  const fs::path exr = *dir_ / "r.exr", png = *dir_ / "r.png";
  Result r = RunRouen("render " + Q(Scene()) + " --slot 0 --out " + Q(exr) + " --png " + Q(png));
  ASSERT_EQ(r.code, 0) << r.out;
  auto attrs = Attributes(exr);
  EXPECT_EQ(std::get<std::string>(attrs.at("rouen:time")), "2026-06-21T16:00:00.000Z");
  EXPECT_EQ(std::get<int>(attrs.at("rouen:slot")), 0);
  EXPECT_EQ(std::get<std::string>(attrs.at("rouen:lighting")), "slot 0 (measured)");
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_azimuth_deg")), 130, 1e-3);
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_elevation_deg")), 35, 1e-3);
  const nlohmann::json camera =
      nlohmann::json::parse(std::get<std::string>(attrs.at("rouen:camera")));
  const LoadedScene scene = LoadScene(Scene());
  const SceneView& view = FindView(scene, "");
  EXPECT_EQ(camera["intrinsics"], nlohmann::json(view.intrinsics));
  EXPECT_EQ(camera["pose"], nlohmann::json(view.pose));
  const Image image = ReadImage(exr.string(), /*keep_alpha=*/true);
  ASSERT_EQ(image.channels, 4);
  const Image ids =
      RenderBlockIds(scene.solved.mesh, *scene.solved.caster, view.intrinsics, view.pose);
  int building = 0, partial = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const float a = image.at(x, y, 3);
      building += ids.at(x, y) >= 0;
      partial += a > 0 && a < 1;
      if (ids.at(x, y) >= 0)
        EXPECT_GT(a, 0.f) << x << "," << y;
      else
        EXPECT_LT(a, 1.f) << x << "," << y;
      // Where every ray escapes, the colour is still the sky's (not premultiplied away).
      if (a == 0) {
        EXPECT_GT(image.at(x, y, 2), 0.f);
      }
    }
  EXPECT_GT(building, 1000);
  EXPECT_LT(partial, building / 10);
  EXPECT_EQ(ReadImage(png.string()).channels, 3);
  // A predicted time says so, with its time in UTC.
  const fs::path later = *dir_ / "later.exr";
  r = RunRouen("render " + Q(Scene()) + " --time 2026-06-21T18:20:00+02:00 --out " + Q(later));
  ASSERT_EQ(r.code, 0) << r.out;
  attrs = Attributes(later);
  EXPECT_EQ(std::get<std::string>(attrs.at("rouen:time")), "2026-06-21T16:20:00.000Z");
  EXPECT_EQ(std::get<std::string>(attrs.at("rouen:lighting")), "predicted");
  EXPECT_EQ(attrs.count("rouen:slot"), 0u);
  double az = 0, el = 0;
  // The sun of the predicted lighting is the site's at that time (within refraction, 0.03 deg).
  AzElFromEnu(
      ComputeSunPosition(ParseIso8601("2026-06-21T16:20:00Z"), scene.scene.site).DirectionEnu(),
      &az, &el);
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_azimuth_deg")), az, 0.05);
  EXPECT_NEAR(std::get<float>(attrs.at("rouen:sun_elevation_deg")), el, 0.05);
}

}  // namespace
}  // namespace rouen
