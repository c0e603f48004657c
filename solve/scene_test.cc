#include "solve/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <typeinfo>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("rouen_scene_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  return dir;
}

SceneModel MakeScene(const Mesh& mesh, SurfaceGrid* grid_out) {
  SceneModel s;
  s.site.lat_deg = 37.87;
  s.site.lon_deg = -122.26;
  s.grid_options.spacing_m = 0.5;
  s.grid_options.block_spacing_m["plaza"] = 1.5;
  s.model_file = "model.obj";
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, s.grid_options);
  SlotModel slot;
  slot.utc = ParseIso8601("2024-08-28T20:15:00.123456789Z");
  slot.sun_dir = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
  slot.sun_radiance = Eigen::Vector3d(1.5e4, 1.4e4, 1.2e4);
  slot.sun_solid_angle_sr = 6.79e-5;
  slot.sky.channel[0].Lz = 0.7;
  slot.sky.channel[2].c = 3.5;
  slot.sky.sun_dir = slot.sun_dir;
  slot.env = EnvironmentMap::Constant(EnvOptions(), {1, 2, 3}, {0.5, 0.4, 0.3});
  s.slots = {slot, slot};
  for (int i = 0; i < grid.size(); ++i) {
    s.albedo.rho_sun.emplace_back(0.1 + 1e-4 * i, 0.2, 0.3);
    s.albedo.rho_se.emplace_back(0.4, 0.5 + 1e-5 * i, 0.6);
    s.albedo.observations.push_back(i % 7);
    s.albedo.flags.push_back(static_cast<uint8_t>(i % 5));
  }
  SceneView view;
  view.slot = 1;
  view.target = "architecture";
  view.utc = ParseIso8601("2024-08-28T20:16:01.5Z");
  view.intrinsics = Intrinsics::PinholeFov(64, 48, 50.3);
  view.pose = Pose::LookAt({10.25, -30.5, 1.7}, {0, 0, 12});
  s.views["slot1/architecture/view0"] = view;
  s.holdout_slots = {1};
  s.inputs_sha256 = std::string(64, 'a');
  s.rouen_version = "9.8.7";
  s.options = {{"quick", true}, {"grid", {{"spacing_m", 0.6}}}};
  s.hemisphere.directions = 64;
  s.hemisphere.seed = 7;
  s.albedo.retro = {0.0, 0.75};  // plaza Lambertian, shaft rough
  s.albedo.sun_lobes.resize(2);  // plaza matte, shaft glossy
  s.albedo.sun_lobes[1].rho_s = Eigen::Vector3d(0.02, 0.03, 0.04);
  s.albedo.sun_lobes[1].kappa = 0.9;
  s.albedo.sun_lobes[1].n = 35.5;
  s.albedo.sky_lobes = s.albedo.sun_lobes;
  s.albedo.sky_lobes[1].n = 12;
  s.albedo.sky_lobes[1].kappa = 1;
  s.albedo.sky_lobes[1].model = LobeModel::kMicrofacet;
  s.albedo.summary.points = grid.size();
  s.albedo.summary.residual_rms_rel = 0.0123;
  s.albedo.summary.residual_p90_rel = 0.0456;
  // An environment fit from slot 0 alone (underdetermined: every landscape region sky-only).
  EnvObservation seen;
  seen.env = slot.env;
  seen.lighting.sun_dir = slot.sun_dir;
  seen.lighting.sun_radiance = slot.sun_radiance;
  seen.lighting.sky = slot.sky;
  s.env_stereo = SolveEnvStereo({seen});
  s.env_stereo_slots = {0};
  if (grid_out) *grid_out = grid;
  return s;
}

Mesh MakeMesh() {
  Mesh m;
  const int plaza = m.AddBlock("plaza");
  const int shaft = m.AddBlock("shaft");
  testing::AddHorizontalRect(&m, -20, 20, -20, 20, 0, true, plaza);
  testing::AddBox(&m, {-2, -2, 0}, {2, 2, 30}, shaft);
  return m;
}

TEST(SceneTest, RoundTrip) {
  const auto dir = TempDir("roundtrip");
  const Mesh mesh = MakeMesh();
  SurfaceGrid grid;
  const SceneModel s = MakeScene(mesh, &grid);
  ASSERT_GT(grid.size(), kAlbedoImageWidth);  // more than one image row
  WriteScene(dir, s, &mesh);
  Mesh mesh2;
  SurfaceGrid grid2;
  const SceneModel r = ReadScene(dir, &mesh2, &grid2);
  EXPECT_EQ(grid2.size(), grid.size());
  EXPECT_EQ(mesh2.triangles.size(), mesh.triangles.size());
  EXPECT_EQ(r.site.lat_deg, s.site.lat_deg);
  EXPECT_EQ(r.grid_options.SpacingFor("plaza"), 1.5);
  ASSERT_EQ(r.slots.size(), 2u);
  EXPECT_EQ(r.slots[0].utc, s.slots[0].utc);
  EXPECT_NEAR((r.slots[0].sun_dir - s.slots[0].sun_dir).norm(), 0, 1e-15);
  EXPECT_EQ(r.slots[1].sun_radiance, s.slots[1].sun_radiance);
  EXPECT_EQ(r.slots[0].sky.channel[2].c, 3.5);
  EXPECT_EQ(r.slots[0].env.radiance, s.slots[0].env.radiance);
  ASSERT_EQ(r.albedo.rho_sun.size(), s.albedo.rho_sun.size());
  for (size_t i = 0; i < s.albedo.rho_sun.size(); ++i) {
    // Stored as 32-bit floats.
    EXPECT_NEAR((r.albedo.rho_sun[i] - s.albedo.rho_sun[i]).norm(), 0, 1e-6);
    EXPECT_NEAR((r.albedo.rho_se[i] - s.albedo.rho_se[i]).norm(), 0, 1e-6);
    EXPECT_EQ(r.albedo.observations[i], s.albedo.observations[i]);
    EXPECT_EQ(r.albedo.flags[i], s.albedo.flags[i]);
  }
  EXPECT_EQ(r.albedo.summary.residual_rms_rel, 0.0123);
  EXPECT_EQ(r.albedo.summary.residual_p90_rel, 0.0456);
  EXPECT_EQ(r.albedo.retro, s.albedo.retro);
  ASSERT_EQ(r.albedo.sun_lobes.size(), 2u);
  EXPECT_TRUE(r.albedo.sun_lobes[0].IsZero());
  EXPECT_EQ(r.albedo.sun_lobes[1].rho_s, s.albedo.sun_lobes[1].rho_s);
  EXPECT_EQ(r.albedo.sun_lobes[1].kappa, 0.9);
  EXPECT_EQ(r.albedo.sun_lobes[1].n, 35.5);
  ASSERT_EQ(r.albedo.sky_lobes.size(), 2u);
  EXPECT_TRUE(r.albedo.sky_lobes[0].IsZero());
  EXPECT_EQ(r.albedo.sky_lobes[1].n, 12);
  EXPECT_EQ(r.albedo.sun_lobes[1].model, LobeModel::kLafortune);
  EXPECT_EQ(r.albedo.sky_lobes[1].model, LobeModel::kMicrofacet);
  EXPECT_EQ(r.albedo.sky_lobes[1].rho_s, s.albedo.sky_lobes[1].rho_s);
  // Views keep their cameras exactly (JSON doubles round-trip).
  ASSERT_EQ(r.views.size(), 1u);
  const SceneView& v = r.views.at("slot1/architecture/view0");
  const SceneView& w = s.views.at("slot1/architecture/view0");
  EXPECT_EQ(v.slot, 1);
  EXPECT_EQ(v.target, "architecture");
  EXPECT_EQ(v.utc, w.utc);
  EXPECT_EQ(v.intrinsics.fx, w.intrinsics.fx);
  EXPECT_EQ(v.intrinsics.width, 64);
  EXPECT_EQ(v.pose.rotation, w.pose.rotation);
  EXPECT_EQ(v.pose.position, w.pose.position);
  EXPECT_EQ(r.holdout_slots, std::vector<int>{1});
  EXPECT_EQ(r.inputs_sha256, s.inputs_sha256);
  EXPECT_EQ(r.rouen_version, "9.8.7");
  EXPECT_EQ(r.options, s.options);
  EXPECT_EQ(r.hemisphere.directions, 64);
  EXPECT_EQ(r.hemisphere.seed, 7u);
  ASSERT_TRUE(r.env_stereo.has_value());
  EXPECT_EQ(r.env_stereo_slots, std::vector<int>{0});
  ASSERT_EQ(r.env_stereo->regions.size(), s.env_stereo->regions.size());
  EXPECT_EQ(r.env_stereo->regions[5].rho_sky, s.env_stereo->regions[5].rho_sky);
  EXPECT_TRUE(r.env_stereo->options == s.env_stereo->options);
  std::filesystem::remove_all(dir);
}

// A stored environment fit naming a slot the scene lacks, or fitted from another number of
// times than it names, is refused; a scene without one (from before) reads without.
TEST(SceneTest, StoredEnvironmentFitMustMatchItsSlots) {
  const auto dir = TempDir("stereo");
  const Mesh mesh = MakeMesh();
  WriteScene(dir, MakeScene(mesh, nullptr), &mesh);
  const std::string text = ReadFileToString(dir / "scene.json");
  for (const auto& [slots, expect] : std::vector<std::pair<std::string, std::string>>{
           {"[5]", "slot 5 is not in the scene"}, {"[0, 1]", "fitted from 1 times but names 2"}}) {
    nlohmann::json j = nlohmann::json::parse(text);
    j["environment"]["stereo"]["slots"] = nlohmann::json::parse(slots);
    WriteFileAtomic(dir / "scene.json", j.dump());
    try {
      ReadScene(dir);
      ADD_FAILURE() << slots << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  nlohmann::json j = nlohmann::json::parse(text);
  j["environment"].erase("stereo");
  WriteFileAtomic(dir / "scene.json", j.dump());
  EXPECT_FALSE(ReadScene(dir).env_stereo.has_value());
  std::filesystem::remove_all(dir);
}

TEST(SceneTest, BadRetroIsRefusedNamingTheBlock) {
  const auto dir = TempDir("retro");
  const Mesh mesh = MakeMesh();
  WriteScene(dir, MakeScene(mesh, nullptr), &mesh);
  const std::string text = ReadFileToString(dir / "scene.json");
  for (const auto& [bad, expect] :
       std::vector<std::pair<std::string, std::string>>{{"{\"shaft\": 7}", "block 'shaft'"},
                                                        {"{\"tower\": 0.5}", "block 'tower'"},
                                                        {"[1, 2]", "albedo.retro"}}) {
    nlohmann::json j = nlohmann::json::parse(text);
    j["albedo"]["retro"] = nlohmann::json::parse(bad);
    WriteFileAtomic(dir / "scene.json", j.dump());
    try {
      ReadScene(dir);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove_all(dir);
}

TEST(SceneTest, BadSunLobeIsRefusedNamingTheBlock) {
  const auto dir = TempDir("lobe");
  const Mesh mesh = MakeMesh();
  WriteScene(dir, MakeScene(mesh, nullptr), &mesh);
  const std::string text = ReadFileToString(dir / "scene.json");
  const std::string ok = R"("rho_s": [0.1, 0.1, 0.1], "kappa": 1, "n": 10)";
  for (
      const auto& [bad, expect] : std::vector<std::pair<std::string, std::string>>{
          {"{\"tower\": {" + ok + "}}", "no block 'tower'"},
          {R"({"shaft": {"rho_s": [0.1, 0.1], "kappa": 1, "n": 10}})", "sun_lobes.shaft"},
          {R"({"shaft": {"rho_s": [0.1, 0.1, 0.1], "kappa": 1, "n": 0}})", "exponent"},
          {R"({"shaft": {"rho_s": [0.1, 0.1, -1], "kappa": 1, "n": 10}})", "rho_s"},
          {R"({"shaft": {"rho_s": [9, 9, 9], "kappa": 1, "n": 10}})", "more light"},
          {R"({"shaft": {"rho_s": [0.1, 0.1, 0.1], "n": 10}})", "kappa"},
          {R"({"shaft": {"rho_s": [0.1, 0.1, 0.1], "kappa": 1, "n": 10, "model": "phong"}})",
           "unknown lobe model 'phong'"},
          {R"({"shaft": {"rho_s": [0.1, 0.1, 0.1], "kappa": 1.2, "n": 10, "model": "microfacet"}})",
           "microfacet lobe has kappa 1"},
          {"[1]", "albedo.sun_lobes"}}) {
    nlohmann::json j = nlohmann::json::parse(text);
    j["albedo"]["sun_lobes"] = nlohmann::json::parse(bad);
    // The sky lobes are read the same way.
    nlohmann::json k = nlohmann::json::parse(text);
    k["albedo"]["sky_lobes"] = nlohmann::json::parse(bad);
    WriteFileAtomic(dir / "scene.json", k.dump());
    try {
      ReadScene(dir);
      ADD_FAILURE() << bad << " was accepted as sky_lobes";
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(expect == "albedo.sun_lobes"  ? "albedo.sky_lobes"
                          : expect == "sun_lobes.shaft" ? "sky_lobes.shaft"
                                                        : expect),
                std::string::npos)
          << what;
    }
    WriteFileAtomic(dir / "scene.json", j.dump());
    try {
      ReadScene(dir);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove_all(dir);
}

TEST(SceneTest, MismatchedModelOrImagesAreRefused) {
  const auto dir = TempDir("mismatch");
  const Mesh mesh = MakeMesh();
  SceneModel s = MakeScene(mesh, nullptr);
  WriteScene(dir, s, &mesh);
  // A different model: the grid no longer matches the stored count.
  Mesh other = MakeMesh();
  testing::AddBox(&other, {5, 5, 0}, {6, 6, 1}, 1);
  WriteObj((dir / "model.obj").string(), other);
  try {
    ReadScene(dir);
    FAIL() << "expected rouen::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("scene.json"), std::string::npos) << e.what();
  }
  WriteObj((dir / "model.obj").string(), mesh);
  EXPECT_NO_THROW(ReadScene(dir));
  // A truncated albedo image.
  WriteImage((dir / "albedo_se.exr").string(), Image(kAlbedoImageWidth, 1, 3, PixelUnits::kOther),
             StoredType::kFloat);
  try {
    ReadScene(dir);
    FAIL() << "expected rouen::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("albedo_se.exr"), std::string::npos) << e.what();
  }
  // Mismatched albedo arrays are refused on write; paths may not leave the folder.
  s.albedo.flags.pop_back();
  EXPECT_THROW(WriteScene(dir, s), Error);
  s = MakeScene(mesh, nullptr);
  s.model_file = "../outside.obj";
  EXPECT_THROW(WriteScene(dir, s), Error);
  // A view of a slot the scene does not have.
  s = MakeScene(mesh, nullptr);
  s.views.begin()->second.slot = 2;
  WriteScene(dir, s);
  try {
    ReadScene(dir);
    FAIL() << "expected rouen::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("scene.json: view slot1/architecture/view0: slot 2 is "
                                         "not in the scene"),
              std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
  EXPECT_THROW(ReadScene(dir), Error);
}

// Every value of scene.json tampered with in turn (the first element of each list; removed, a
// string, 0, -1, +-1e300, 2.5): the scene reads with every number render uses finite and in range,
// or is refused with rouen::Error naming a file of the scene; never another exception.
TEST(SceneTest, ATamperedSceneIsReadOrRefusedByName) {
  const auto dir = TempDir("tampered");
  const Mesh mesh = MakeMesh();
  WriteScene(dir, MakeScene(mesh, nullptr), &mesh);
  const nlohmann::json original = nlohmann::json::parse(ReadFileToString(dir / "scene.json"));
  std::vector<nlohmann::json::json_pointer> leaves;
  const nlohmann::json flat = original.flatten();
  for (const auto& item : flat.items()) {
    const nlohmann::json::json_pointer p(item.key());
    bool first = true;  // only the first element of each list
    for (nlohmann::json::json_pointer q = p; !q.empty(); q = q.parent_pointer())
      if (original.at(q.parent_pointer()).is_array() && q.back() != "0") first = false;
    if (first) leaves.push_back(p);
  }
  ASSERT_GT(leaves.size(), 50u);
  const std::vector<nlohmann::json> values = {"x", 0, -1, 1e300, -1e300, nullptr, 2.5};
  int refused = 0, read = 0;
  for (const auto& p : leaves) {
    for (size_t m = 0; m <= values.size(); ++m) {
      nlohmann::json j = original;
      if (m == values.size()) {
        nlohmann::json& parent = j.at(p.parent_pointer());
        if (parent.is_array())
          parent.erase(std::stoul(p.back()));
        else
          parent.erase(p.back());
      } else {
        j.at(p) = values[m];
      }
      const std::string what =
          p.to_string() + (m < values.size() ? " = " + values[m].dump() : " removed");
      WriteFileAtomic(dir / "scene.json", j.dump());
      // An integer of the scene given a fraction is refused, not truncated (1e300 was converted
      // to int, undefined behaviour); the parts kept as given (the solve's options and
      // timings) and those no reader uses (the atlas, the albedo images' width) aside.
      const std::string at = p.to_string();
      const bool must_refuse =
          m < values.size() && values[m] == 2.5 && original.at(p).is_number_integer() &&
          !at.starts_with("/provenance/options") && !at.starts_with("/timings") &&
          !at.starts_with("/atlas") && at != "/albedo/width";
      try {
        const SceneModel s = ReadScene(dir);
        EXPECT_FALSE(must_refuse) << what << " read";
        ++read;
        EXPECT_TRUE(std::isfinite(s.site.lat_deg) && std::abs(s.site.lat_deg) <= 90 &&
                    std::isfinite(s.site.lon_deg) && std::abs(s.site.lon_deg) <= 360 &&
                    std::isfinite(s.site.height_m))
            << what;
        for (const SlotModel& slot : s.slots) {
          EXPECT_NEAR(slot.sun_dir.norm(), 1, 1e-6) << what;
          EXPECT_TRUE(slot.sun_radiance.allFinite() && slot.sun_radiance.minCoeff() >= 0) << what;
          EXPECT_TRUE(std::isfinite(slot.sun_solid_angle_sr) && slot.sun_solid_angle_sr > 0)
              << what;
          for (const SkyParams& c : slot.sky.channel)
            EXPECT_TRUE(std::isfinite(c.Lz) && c.Lz >= 0 && std::isfinite(c.a) &&
                        std::isfinite(c.b) && std::isfinite(c.c) && std::isfinite(c.d) &&
                        std::isfinite(c.e))
                << what;
          for (const Eigen::Vector3d& r : slot.env.radiance)
            EXPECT_TRUE(r.allFinite() && r.minCoeff() >= 0) << what;
        }
        for (const auto& [name, v] : s.views) {
          EXPECT_NO_THROW(v.intrinsics.Validate()) << what;
          EXPECT_TRUE(v.pose.rotation.allFinite() && v.pose.position.allFinite()) << what;
        }
        EXPECT_NO_THROW(s.grid_options.Validate()) << what;
      } catch (const Error& e) {
        ++refused;
        EXPECT_NE(std::string(e.what()).find(dir.string()), std::string::npos)
            << what << ": " << e.what();
      } catch (const std::exception& e) {
        ADD_FAILURE() << what << ": " << typeid(e).name() << ": " << e.what();
      }
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(read, 0);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace rouen
