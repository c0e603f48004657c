// rouen's user path on a world it did not make: tests/data/blender_world holds renders of a
// campanile by Blender/Cycles (Nishita sky with its sun disc, Principled BSDF, path traced;
// see its README.md and gen.py) at four training times and one held-out low-sun time. The
// test imports them with the building model, checks the session, solves it with the held-out
// time kept out of the albedos, renders the held-out time and validates against the held-out
// renders, then compares the recovered albedos with the base colours Blender rendered with.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/files.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/text.h"
#include "pipeline/export_test_util.h"
#include "solve/grid.h"
#include "solve/scene.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_world"; }

bool FiniteFigures(const nlohmann::json& m) {
  for (const char* k : {"rel_rmse", "psnr_db", "median_rel_error", "mean_ratio"}) {
    if (!m.contains(k) || !m[k].is_number() || !std::isfinite(m[k].get<double>())) return false;
  }
  return m.contains("pixels") && m["pixels"].get<int64_t>() > 0;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? NAN : v[v.size() / 2];
}

TEST(BlenderWorldTest, ImportStatusSolveRenderValidate) {
  ASSERT_TRUE(fs::exists(Data() / "list.txt")) << Data();
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(Data() / "truth.json"));
  const int heldout = truth["heldout_slot"].get<int>();
  const nlohmann::json& site = truth["site"];
  const std::string site_arg = std::to_string(site["lat_deg"].get<double>()) + "," +
                               std::to_string(site["lon_deg"].get<double>()) + "," +
                               std::to_string(site["height_m"].get<double>());
  const fs::path dir = cli_test::TempDir("blender_world");
  const fs::path session = dir / "session", scene = dir / "scene";

  Result r = RunRouen("import --photos " + Q(Data()) + " --list " + Q(Data() / "list.txt") +
                      " --cameras " + Q(Data() / "cameras.json") + " --site " + site_arg +
                      " --model " + Q(Data() / "building.obj") + " --out " + Q(session));
  ASSERT_EQ(r.code, 0) << r.out;

  r = RunRouen("status " + Q(session));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("solvable: yes"), std::string::npos) << r.out;

  // The solve a user runs (not --quick): its held-out figures are the ones the bar is for.
  r = RunRouen("solve " + Q(session) + " --out " + Q(scene) + " --holdout-slot " +
               std::to_string(heldout));
  ASSERT_EQ(r.code, 0) << r.out;
  ASSERT_TRUE(fs::is_regular_file(scene / "scene.json")) << r.out;

  // The held-out time under lighting predicted from the other times, from the first view.
  const std::string view = "slot" + std::to_string(heldout) + "/architecture/view0";
  const std::string local = truth["times"][heldout]["local"].get<std::string>();
  r = RunRouen("render " + Q(scene) + " --time " + local + " --view " + view + " --out " +
               Q(dir / "heldout.exr") + " --png " + Q(dir / "heldout.png"));
  ASSERT_EQ(r.code, 0) << r.out;
  // The photos were HDR (no response curve): the PNG is the sRGB encoding.
  EXPECT_NE(r.out.find("the sRGB encoding"), std::string::npos) << r.out;
  EXPECT_EQ(ReadImage((dir / "heldout.png").string()).width, 480);
  const Image img = ReadImage((dir / "heldout.exr").string());
  EXPECT_EQ(img.width, 480);
  EXPECT_EQ(img.height, 360);
  ASSERT_GE(img.channels, 3);
  int64_t lit = 0;
  for (float v : img.data) {
    ASSERT_TRUE(std::isfinite(v));
    lit += v > 0 ? 1 : 0;
  }
  EXPECT_GT(lit, 20000) << "the building covers about 30000 pixels of this view";

  const fs::path vjson = dir / "validate.json";
  r = RunRouen("validate " + Q(scene) + " --session " + Q(session) + " --slot " +
               std::to_string(heldout) + " --terms --json " + Q(vjson));
  ASSERT_EQ(r.code, 0) << r.out;
  const nlohmann::json v = nlohmann::json::parse(ReadFileToString(vjson));
  // What lights the faces the sun does not reach at the low held-out sun: the three terms
  // account for all of it, per channel; the environment -- the warm ground the sun lights --
  // gives more of the red than of the blue, the blue sky more of the blue.
  ASSERT_TRUE(v.contains("shaded_terms")) << r.out;
  ASSERT_GE(v["shaded_terms"].size(), 2u) << r.out;
  EXPECT_EQ(v["shaded_terms"][0]["block"], "all");
  for (const nlohmann::json& t : v["shaded_terms"]) {
    EXPECT_GT(t["points"].get<int>(), 0);
    for (int c = 0; c < 3; ++c) {
      const double sky = t["sky"][c], env = t["environment"][c], bounce = t["interreflection"][c];
      EXPECT_NEAR(sky + env + bounce, 1.0, 1e-9) << t.dump();
      EXPECT_GE(sky, 0) << t.dump();
      EXPECT_GE(env, 0) << t.dump();
      EXPECT_GE(bounce, 0) << t.dump();
    }
  }
  const nlohmann::json& shaded = v["shaded_terms"][0];
  EXPECT_GT(shaded["environment"][0].get<double>(), shaded["environment"][2].get<double>());
  EXPECT_GT(shaded["sky"][2].get<double>(), shaded["sky"][0].get<double>());
  EXPECT_NE(r.out.find("faces the sun does not reach"), std::string::npos) << r.out;
  EXPECT_EQ(v["held_out"], true);
  ASSERT_EQ(v["photos"].size(), 3u) << r.out;
  for (const nlohmann::json& p : v["photos"]) {
    EXPECT_TRUE(FiniteFigures(p["measured"])) << p.dump();
    EXPECT_TRUE(FiniteFigures(p["predicted"])) << p.dump();
  }
  ASSERT_TRUE(FiniteFigures(v["measured"])) << v.dump();
  ASSERT_TRUE(FiniteFigures(v["predicted"])) << v.dump();
  // rel RMSE = RMS(R - T) / RMS(T) over the building's pixels: an all-black render scores 1,
  // albedos 2x too bright score 1 and 2x too dark 0.5 (held-out photos scaled by 0.5 scored
  // 1.14). Yu & Malik give no figure for it (they compared with photographs by eye); their
  // one stated accuracy is the sky fit's "within 5% at most places". The bound is half the
  // smallest gross failure, 0.25 (the paper's Lambertian model scored 0.127 predicted and
  // 0.117 measured here: Blender's Principled diffuse is up to 1.4x brighter than Lambert for
  // the low held-out sun); the figures below hold rouen to what it does now.
  EXPECT_LT(v["predicted"]["rel_rmse"].get<double>(), 0.25) << r.out;
  EXPECT_LT(v["measured"]["rel_rmse"].get<double>(), 0.25) << r.out;
  // What a user of a relit model expects (the fidelity issue's bar): every view of the
  // held-out time at 32 dB or better on the building under either lighting, within 3% median
  // relative error under either lighting, and the lighting measured at that time not worse
  // than the lighting predicted from the other times (once it was: 23 against 29 dB). rouen
  // scores 42.5-44.8 dB and 0.5-0.8% measured, 42.6-44.9 dB and 0.5-1.1% predicted
  // (tests/data/blender_world/README.md), measured 0.7-2.2% above predicted in rel. RMSE (the
  // power-law sky, 2-3% too bright at the held-out sun, was 0.5-5% above the measured); the
  // Lambertian model of the paper scored 23-29 dB.
  for (const nlohmann::json& p : v["photos"]) {
    const std::string name = p["view"].get<std::string>();
    EXPECT_GE(p["measured"]["psnr_db"].get<double>(), 32) << name;
    EXPECT_GE(p["predicted"]["psnr_db"].get<double>(), 32) << name;
    EXPECT_LE(p["measured"]["median_rel_error"].get<double>(), 0.03) << name;
    EXPECT_LE(p["predicted"]["median_rel_error"].get<double>(), 0.03) << name;
    // "Not worse" within what the measured lighting itself can resolve: an error e in it adds
    // about e in quadrature to the rel RMSE r (1.2-1.7% here), so 0.5% of lighting error (the
    // sky fit's own median error is 1-3%) moves r by up to 5%.
    EXPECT_LE(p["measured"]["rel_rmse"].get<double>(),
              1.05 * p["predicted"]["rel_rmse"].get<double>())
        << name;
  }
  // The overall brightness: a 2x albedo error gives 2 or 0.5.
  EXPECT_GT(v["predicted"]["mean_ratio"].get<double>(), 0.8) << r.out;
  EXPECT_LT(v["predicted"]["mean_ratio"].get<double>(), 1.25) << r.out;
  // The environment's stereo fit the scene keeps is the one rouen validate would make: this
  // world's ground is rough (its retro fitted > 0), so the solve reads the ground again at that
  // retro and fits the kept stereo on those maps (once it kept the fit of the maps before, and
  // predicted 0.13 dB worse than a fresh fit). The same scene without the kept fit predicts
  // the same figures.
  EXPECT_NE(r.out.find("as the solve fitted them"), std::string::npos) << r.out;
  const fs::path unfitted = dir / "scene_unfitted";
  fs::copy(scene, unfitted, fs::copy_options::recursive);
  {
    nlohmann::json sj = nlohmann::json::parse(ReadFileToString(unfitted / "scene.json"));
    ASSERT_TRUE(sj["environment"].contains("stereo"));
    ASSERT_GT(sj["environment"]["ground_retro"].get<double>(), 0);
    sj["environment"].erase("stereo");
    std::ofstream(unfitted / "scene.json") << sj.dump();
  }
  const fs::path ujson = dir / "validate_unfitted.json";
  const auto u = RunRouen("validate " + Q(unfitted) + " --session " + Q(session) + " --slot " +
                          std::to_string(heldout) + " --json " + Q(ujson));
  ASSERT_EQ(u.code, 0) << u.out;
  EXPECT_EQ(u.out.find("as the solve fitted them"), std::string::npos) << u.out;
  const nlohmann::json uv = nlohmann::json::parse(ReadFileToString(ujson));
  for (const char* figure : {"rel_rmse", "psnr_db", "median_rel_error"}) {
    EXPECT_NEAR(uv["predicted"][figure].get<double>(), v["predicted"][figure].get<double>(),
                1e-9 * std::abs(v["predicted"][figure].get<double>()))
        << figure;
  }

  // --sky-interp elevation predicts the sky another way (every part a power law in the sine of
  // the sun's elevation) from the same scene: the measured lighting's figures are the same, the
  // prediction's differ and stay finite.
  const fs::path ajson = dir / "validate_elevation.json";
  const auto a = RunRouen("validate " + Q(scene) + " --session " + Q(session) + " --slot " +
                          std::to_string(heldout) + " --sky-interp elevation --json " + Q(ajson));
  ASSERT_EQ(a.code, 0) << a.out;
  const nlohmann::json av = nlohmann::json::parse(ReadFileToString(ajson));
  ASSERT_TRUE(FiniteFigures(av["predicted"])) << av.dump();
  EXPECT_EQ(av["measured"]["rel_rmse"].get<double>(), v["measured"]["rel_rmse"].get<double>());
  EXPECT_NE(av["predicted"]["rel_rmse"].get<double>(), v["predicted"]["rel_rmse"].get<double>());

  // The recovered sun pseudo-albedos against the base colours Blender rendered with: the
  // median over each matte block's observed grid points, per channel (the glossy roof is
  // printed, not checked). A global scale error (e.g. in the sun's radiance) leaves the
  // held-out renders consistent with the photos; this catches it.
  Mesh mesh;
  SurfaceGrid grid;
  const SceneModel model = ReadScene(scene, &mesh, &grid);
  ASSERT_EQ(model.albedo.rho_sun.size(), grid.points.size());
  for (const std::string block : {"tower", "annex", "roof"}) {
    const nlohmann::json& t = truth["blocks"][block];
    const bool glossy = t["glossy"].get<bool>();
    const auto it = std::find(mesh.block_names.begin(), mesh.block_names.end(), block);
    ASSERT_NE(it, mesh.block_names.end()) << block;
    const int b = static_cast<int>(it - mesh.block_names.begin());
    for (int c = 0; c < 3; ++c) {
      std::vector<double> vals, se;
      for (size_t i = 0; i < grid.points.size(); ++i) {
        if (grid.points[i].block == b && model.albedo.observations[i] > 0) {
          vals.push_back(model.albedo.rho_sun[i][c]);
          se.push_back(model.albedo.rho_se[i][c]);
        }
      }
      ASSERT_GT(vals.size(), glossy ? 10u : 100u) << block;
      const double want = t["base_color"][c].get<double>();
      std::cout << block << " channel " << c << ": base colour " << want << ", median rho_sun "
                << Median(vals) << ", median rho_se " << Median(se) << " (" << vals.size()
                << " observed points)\n";
      // Blender's Principled diffuse is Lambert at normal incidence and brighter at grazing
      // light; with a Lambertian model the sun albedo came out 3-5% high here. With each
      // block's retro fitted (solve/retro.h) rho_sun is the albedo seen head-on, as Blender's
      // base colour is: the medians came within 2%. 5% leaves room for the sun's and sky's
      // calibration (1% and 2%) and the retro fit; a sun measured 2x too bright (sun frames
      // scaled by 2) gave medians of half the base colour.
      if (!glossy) {
        EXPECT_NEAR(Median(vals) / want, 1.0, 0.05) << block << " channel " << c;
        // The sky + environment albedo is the same colour seen under sky light: with the rough
        // block's ambient factor (solve/retro.h) the tower's came within 1% and the annex's
        // within 5.6% (without it the tower's was 5-7% high: the sky light brightening towards
        // oblique views was read as albedo). With the ground read sunlit where the model's
        // shadow lay in front of the panorama (EnvOptions::lit_ground), the tower's came 2.9%
        // and the annex's 6.1% low in red, 1% and 4% in blue: the shadow is put back where a
        // wall sees it as ground lit by the whole sky, where the tower hides part of that sky
        // from its shadow, so walls that see that shadow get too much of it. 7%: the sky fit's
        // p90 (1.8%), the interreflection's (1%) and that sky's share of the light on the
        // walls that see the shadow (up to 4%).
        EXPECT_NEAR(Median(se) / want, 1.0, 0.07) << block << " channel " << c;
      }
    }
    // §4.2.2: the glossy block (Principled specular 0.5, roughness 0.35) gets a sun lobe; the
    // matte ones (specular 0) none.
    EXPECT_EQ(BlockLobe(model.albedo.sun_lobes, b).IsZero(), !glossy) << block;
  }
  fs::remove_all(dir);
}

// Issue 13's outputs on a session imported from another renderer's photos (not simulated by
// rouen): the report, the glTF, an environment map, the viewer and a short time-lapse, each
// from the one solved scene.
TEST(BlenderWorldTest, ReportExportEnvmapViewAndTimelapseOfTheImportedSession) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(Data() / "truth.json"));
  const nlohmann::json& site = truth["site"];
  const std::string site_arg = std::to_string(site["lat_deg"].get<double>()) + "," +
                               std::to_string(site["lon_deg"].get<double>()) + "," +
                               std::to_string(site["height_m"].get<double>());
  const fs::path dir = cli_test::TempDir("blender_share");
  const fs::path session = dir / "session", scene = dir / "scene";
  Result r = RunRouen("import --photos " + Q(Data()) + " --list " + Q(Data() / "list.txt") +
                      " --cameras " + Q(Data() / "cameras.json") + " --site " + site_arg +
                      " --model " + Q(Data() / "building.obj") + " --out " + Q(session));
  ASSERT_EQ(r.code, 0) << r.out;
  r = RunRouen("solve " + Q(session) + " --out " + Q(scene) + " --holdout-slot 4 --quick");
  ASSERT_EQ(r.code, 0) << r.out;

  // The report: every section, the glossy roof's sun lobe in the albedo table.
  r = RunRouen("report " + Q(scene) + " --session " + Q(session) + " --out " +
               Q(dir / "report.html"));
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string html = ReadFileToString(dir / "report.html");
  for (const char* id : {"timeline", "sunpath", "sky", "environment", "albedo", "timings"})
    EXPECT_NE(html.find(std::string("id=\"") + id + "\""), std::string::npos) << id;
  EXPECT_NE(html.find("Sun specular lobes"), std::string::npos);
  // Nothing loaded from the network (SVG's xmlns is a name, not a load).
  for (const char* load : {"src=\"http", "href=\"http", "url(http"})
    EXPECT_EQ(html.find(load), std::string::npos) << load;

  // The glTF: one mesh per block, the roof's lobe among its material's extras.
  r = RunRouen("export " + Q(scene) + " --gltf " + Q(dir / "tower.glb"));
  ASSERT_EQ(r.code, 0) << r.out;
  const testing::ParsedGlb glb = testing::ReadGlb(ReadFileToString(dir / "tower.glb"));
  ASSERT_TRUE(glb.error.empty()) << glb.error;
  EXPECT_EQ(glb.json["meshes"].size(), 3u);
  int with_lobe = 0;
  for (const nlohmann::json& m : glb.json["materials"]) {
    const nlohmann::json& x = m["extras"]["rouen"];
    if (x.contains("sun_lobe")) {
      ++with_lobe;
      EXPECT_EQ(x["block"], "roof");
    }
  }
  EXPECT_EQ(with_lobe, 1);

  // The environment map at the held-out time: a lat-long float EXR with its time in the header.
  const std::string local = truth["times"][4]["local"].get<std::string>();
  r = RunRouen("envmap " + Q(scene) + " --time " + local + " --width 256 --out " +
               Q(dir / "sky.exr"));
  ASSERT_EQ(r.code, 0) << r.out;
  const Image env = ReadImage((dir / "sky.exr").string());
  EXPECT_EQ(env.width, 256);
  EXPECT_EQ(env.height, 128);
  for (float v : env.data) ASSERT_TRUE(std::isfinite(v) && v >= 0);

  // The viewer: its page and data.
  r = RunRouen("view " + Q(scene) + " --out " + Q(dir / "view") + " --times 4");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(fs::is_regular_file(dir / "view" / "index.html"));
  EXPECT_GT(fs::file_size(dir / "view" / "viewer_data.js"), 10000u);

  // A short time-lapse, 17:15 to 18:15 local every 30 minutes: three frames, named by time.
  const std::string date = local.substr(0, 10), tz = local.substr(19);
  r = RunRouen("timelapse " + Q(scene) + " --date " + date + " --tz " + tz +
               " --from 17:15 --to 18:15 --step 30min --no-video --view slot4/architecture/view0 "
               "--out " +
               Q(dir / "day"));
  ASSERT_EQ(r.code, 0) << r.out;
  int exr = 0;
  for (const auto& e : fs::directory_iterator(dir / "day")) exr += e.path().extension() == ".exr";
  EXPECT_EQ(exr, 3) << r.out;
  fs::remove_all(dir);
}

// A session of the world without its telephoto sun frames, whose sky photos are `sky` (the
// half-float panoramas, or the float32 ones under the same names).
fs::path ImportWithoutSunFrames(const fs::path& dir, bool float_sky) {
  const fs::path photos = dir / "photos";
  fs::create_directories(photos);
  std::string list;
  for (const std::string& line : ReadTextLines((Data() / "list.txt").string(), "list")) {
    if (line.find("_sun.exr") == std::string::npos) list += line + "\n";
  }
  WriteFileAtomic(photos / "list.txt", list);
  for (const auto& e : fs::directory_iterator(Data())) {
    const std::string name = e.path().filename().string();
    if (e.path().extension() != ".exr" || name.find("_sun.exr") != std::string::npos) continue;
    const bool sky = name.find("_sky_pano.exr") != std::string::npos;
    const fs::path from = sky && float_sky
                              ? Data() / "sky_f32" / (name.substr(0, name.size() - 4) + "_f32.exr")
                              : e.path();
    fs::copy_file(from, photos / name);
  }
  nlohmann::json cameras = nlohmann::json::parse(ReadFileToString(Data() / "cameras.json"));
  std::function<void(nlohmann::json&)> drop_sun = [&](nlohmann::json& j) {
    if (!j.is_object()) return;
    for (auto it = j.begin(); it != j.end();) {
      if (it.key().find("_sun.exr") != std::string::npos) {
        it = j.erase(it);
      } else {
        drop_sun(it.value());
        ++it;
      }
    }
  };
  drop_sun(cameras);
  WriteFileAtomic(dir / "cameras.json", cameras.dump());
  const Result r = RunRouen("import --photos " + Q(photos) + " --list " + Q(photos / "list.txt") +
                            " --cameras " + Q(dir / "cameras.json") + " --site 45,7,300 --model " +
                            Q(Data() / "building.obj") + " --out " + Q(dir / "s"));
  EXPECT_EQ(r.code, 0) << r.out;
  return dir / "s";
}

// Without the telephoto sun frames the solve looks for the sun in each slot's sky and landscape
// panoramas (§3.1 from any HDR frame). In half-float EXRs the disc is clipped at 65504, so the
// solve must refuse them by name rather than take a sun 4-10x too dim.
TEST(BlenderWorldTest, WithoutSunFramesAClippedPanoramaSunIsRefusedByName) {
  const fs::path dir = cli_test::TempDir("blender_world_nosun");
  const fs::path s = ImportWithoutSunFrames(dir, false);
  Result r = RunRouen("status " + Q(s));
  EXPECT_EQ(r.code, 0) << r.out;  // a sun bracket is not required of HDR panoramas
  EXPECT_NE(r.out.find("slot 4 has no sun bracket"), std::string::npos) << r.out;
  r = RunRouen("solve " + Q(s) + " --out " + Q(dir / "scene") + " --quick");
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("slot0/sky/view0: the disc is clipped or saturated"), std::string::npos)
      << r.out;
  EXPECT_FALSE(fs::exists(dir / "scene" / "scene.json"));
  fs::remove_all(dir);
}

// With float32 sky panoramas (a 360-degree HDR camera, no telephoto sun frame) the sun comes
// from the panorama, where the disc is smaller than a pixel, and the held-out time is rendered
// as well as with the sun frames (tests/blender_sun_test.cc: the two suns agree within 1%).
TEST(BlenderWorldTest, WithoutSunFramesTheSunComesFromAFloatPanorama) {
  if (!fs::exists(Data() / "sky_f32" / "t0_sky_pano_f32.exr"))
    GTEST_SKIP() << "no float32 sky panoramas in " << Data() / "sky_f32";
  const fs::path dir = cli_test::TempDir("blender_world_f32");
  const fs::path s = ImportWithoutSunFrames(dir, true);
  Result r = RunRouen("solve " + Q(s) + " --out " + Q(dir / "scene") + " --quick --holdout-slot 4");
  ASSERT_EQ(r.code, 0) << r.out;
  for (int k = 0; k < 5; ++k) {
    const std::string slot =
        "slot " + std::to_string(k) + ": sun from slot" + std::to_string(k) + "/sky/view0";
    EXPECT_NE(r.out.find(slot), std::string::npos) << slot << "\n" << r.out;
  }
  r = RunRouen("validate " + Q(dir / "scene") + " --session " + Q(s) + " --slot 4 --json " +
               Q(dir / "v.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  const nlohmann::json v = nlohmann::json::parse(ReadFileToString(dir / "v.json"));
  for (const nlohmann::json& p : v["photos"]) {
    EXPECT_GE(p["measured"]["psnr_db"].get<double>(), 32) << p["view"];
    EXPECT_GE(p["predicted"]["psnr_db"].get<double>(), 32) << p["view"];
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
