// The whole pipeline end to end: `rouen demo --quick` captures a simulated session through
// the capture controller, solves it and scores it; then the session is replayed through the
// replay devices on the same code path and must come out identical.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "core/files.h"
#include "core/image.h"
#include "core/session.h"
#include "tests/cli_util.h"

namespace {

namespace fs = std::filesystem;

// Exit code of `rouen ARGS`; its output appended to *out.
int RunRouen(const std::string& args, std::string* out) {
  const rouen::cli_test::Result r = rouen::cli_test::RunRouen(args);
  *out += r.out;
  return r.code;
}

// One demo run shared by the checks below (CTest runs each test in its own process, so they
// are one test).
TEST(DemoTest, QuickDemoEndToEndAndReplay) {
  fs::path dir = fs::temp_directory_path() / ("rouen_demo_test_" + std::to_string(getpid()));
  fs::remove_all(dir);
  std::string out;
  ASSERT_EQ(RunRouen("demo --quick --out " + dir.string(), &out), 0) << out;
  nlohmann::json m = nlohmann::json::parse(std::ifstream(dir / "metrics.json"));
  for (const char* k :
       {"response_max_rel_error", "sun_direction_error_deg", "sun_radiance_rel_error",
        "sky_rel_error_median", "sky_rel_error_p90", "albedo_sun_rel_error_mean",
        "albedo_skyenv_rel_error_mean", "heldout_render_rel_rmse", "heldout_render_psnr_db",
        "heldout_predicted_render_rel_rmse", "heldout_predicted_sky_rel_error_median",
        "heldout_predicted_sun_radiance_rel_error", "validate_measured_rel_rmse",
        "validate_measured_psnr_db", "validate_predicted_rel_rmse", "validate_predicted_psnr_db",
        "frames_captured", "wall_seconds"}) {
    ASSERT_TRUE(m.contains(k)) << k;
    ASSERT_TRUE(m[k].is_number()) << k;
  }
  // The acceptance figures of the walking skeleton (issue 2).
  EXPECT_LE(m["sky_rel_error_median"].get<double>(), 0.03);
  EXPECT_LE(m["sky_rel_error_p90"].get<double>(), 0.08);
  EXPECT_LE(m["heldout_render_rel_rmse"].get<double>(), 0.10);
  EXPECT_LE(m["albedo_sun_rel_error_mean"].get<double>(), 0.05);
  // With one landscape panorama (1.6 m) this was 5.2% (quick) / 5.5% (full): seen from the
  // belfry and the roof the environment differs (paper §3.3). The session now holds a second
  // panorama from the mast at the top, and the environment interpolates between the two by
  // height.
  EXPECT_LE(m["albedo_skyenv_rel_error_mean"].get<double>(), 0.05);
  // The sun direction comes from GPS + UTC through ERFA; the simulator computes its own with
  // an independent low-precision almanac (~0.01 deg) and GPS noise of metres (~1e-5 deg).
  EXPECT_LT(m["sun_direction_error_deg"].get<double>(), 0.05);
  EXPECT_TRUE(fs::exists(dir / "heldout.png"));
  EXPECT_TRUE(fs::exists(dir / "heldout_truth.png"));
  EXPECT_TRUE(fs::exists(dir / "heldout_predicted.png"));

  // Replay through the replay devices: the same frames, times and metadata.
  fs::path replayed = dir / "replayed";
  out.clear();
  ASSERT_EQ(
      RunRouen("capture --rig " + std::string(ROUEN_SOURCE_DIR) + "/rigs/replay.toml --from " +
                   (dir / "session").string() + " --out " + replayed.string(),
               &out),
      0)
      << out;
  rouen::Session a = rouen::Session::Load(dir / "session");
  rouen::Session b = rouen::Session::Load(replayed);
  ASSERT_EQ(a.frames().size(), b.frames().size());
  for (size_t i = 0; i < a.frames().size(); ++i) {
    const auto &fa = a.frames()[i], &fb = b.frames()[i];
    EXPECT_EQ(fa.group, fb.group) << i;
    EXPECT_EQ(fa.sha256, fb.sha256) << i;
    EXPECT_DOUBLE_EQ(fa.exposure_s, fb.exposure_s) << i;
    EXPECT_EQ(fa.utc, fb.utc) << i;
    EXPECT_DOUBLE_EQ(fa.sun_azimuth_deg, fb.sun_azimuth_deg) << i;
  }
  EXPECT_EQ(a.info().site_source, b.info().site_source);

  // The demo solved its session into DIR/scene through the library, as `rouen solve` does with
  // the same options: solving again finds the scene up to date and does nothing.
  for (const char* f : {"scene.json", "model.obj", "albedo_sun.exr", "albedo_se.exr", "points.exr",
                        "normals.exr", "model_textured.obj", "model_textured.mtl",
                        "atlas/1_shaft_sun.exr", "atlas/1_shaft_se.exr"})
    EXPECT_TRUE(fs::is_regular_file(dir / "scene" / f)) << f;
  // §4.2.2: the simulated world's copper roof is its one glossy block (sim_scene.h
  // MaterialSpecular): the solve gives it a sun lobe, a grey one, and the matte blocks none.
  {
    const nlohmann::json lobes = nlohmann::json::parse(
        rouen::ReadFileToString(dir / "scene" / "scene.json"))["albedo"]["sun_lobes"];
    ASSERT_TRUE(lobes.is_object());
    EXPECT_EQ(lobes.size(), 1u) << lobes.dump();
    ASSERT_TRUE(lobes.contains("roof")) << lobes.dump();
    const std::vector<double> rho = lobes["roof"]["rho_s"].get<std::vector<double>>();
    ASSERT_EQ(rho.size(), 3u);
    EXPECT_NEAR(rho[0] / rho[2], 1.0, 0.1);
  }
  const int heldout = 3;  // rigs/sim.toml: heldout = "16:00", the fourth of five times
  const std::string scene_json_before = rouen::ReadFileToString(dir / "scene" / "scene.json");
  out.clear();
  ASSERT_EQ(RunRouen("solve " + (dir / "session").string() + " --quick --holdout-slot " +
                         std::to_string(heldout) + " --out " + (dir / "scene").string(),
                     &out),
            0)
      << out;
  EXPECT_NE(out.find("up to date"), std::string::npos) << out;
  EXPECT_EQ(rouen::ReadFileToString(dir / "scene" / "scene.json"), scene_json_before);
  // The session carries its rig's [solve] options, which `rouen solve` starts from.
  {
    const rouen::cli_test::Result printed = rouen::cli_test::RunRouen(
        "solve " + (dir / "session").string() + " --quick --print-config");
    ASSERT_EQ(printed.code, 0) << printed.out;
    const nlohmann::json config = nlohmann::json::parse(printed.out);
    EXPECT_EQ(config["grid"]["block_spacing_m"]["plaza"], 1.5);
    EXPECT_EQ(config["grid"]["spacing_m"], 0.6);
  }
  // --force solves again; the calibration in the work folder (from the demo's solve) is read
  // back rather than made again, and the scene comes out the same.
  out.clear();
  ASSERT_EQ(RunRouen("solve " + (dir / "session").string() + " --quick --force --holdout-slot " +
                         std::to_string(heldout) + " --work " + (dir / "work").string() +
                         " --out " + (dir / "scene").string(),
                     &out),
            0)
      << out;
  EXPECT_NE(out.find("is up to date (same session files and options)"), std::string::npos) << out;
  {
    // The same scene but for the albedo solve's own timing.
    nlohmann::json before = nlohmann::json::parse(scene_json_before);
    nlohmann::json after =
        nlohmann::json::parse(rouen::ReadFileToString(dir / "scene" / "scene.json"));
    before["albedo"]["summary"].erase("seconds");
    after["albedo"]["summary"].erase("seconds");
    ASSERT_TRUE(after["timings"].is_array());  // every stage's seconds, which differ
    before.erase("timings");
    after.erase("timings");
    EXPECT_EQ(after, before);
  }

  // rouen validate on the demo's scene and held-out slot gives the demo's figures.
  out.clear();
  ASSERT_EQ(
      RunRouen("validate " + (dir / "scene").string() + " --session " + (dir / "session").string() +
                   " --slot " + std::to_string(heldout) + " --exclude-block plaza --json " +
                   (dir / "v.json").string() + " --images " + (dir / "v").string(),
               &out),
      0)
      << out;
  // The prediction takes the environment's stereo the solve fitted from the same slots (kept in
  // scene.json) instead of fitting it again, and gives the demo's figures with it.
  EXPECT_NE(out.find("the environment's normals as the solve fitted them"), std::string::npos)
      << out;
  {
    const nlohmann::json v = nlohmann::json::parse(std::ifstream(dir / "v.json"));
    EXPECT_TRUE(v["held_out"].get<bool>());
    for (const char* lighting : {"measured", "predicted"})
      for (const char* figure : {"rel_rmse", "psnr_db", "median_rel_error"})
        EXPECT_NEAR(v[lighting][figure].get<double>(),
                    m[std::string("validate_") + lighting + "_" + figure].get<double>(), 1e-3)
            << lighting << " " << figure;
    ASSERT_GE(v["photos"].size(), 1u);
    const std::string first = v["photos"][0]["view"].get<std::string>();
    std::string base = first;
    std::replace(base.begin(), base.end(), '/', '_');
    for (const char* suffix : {"_photo.exr", "_render.exr", "_difference.exr",
                               "_render_predicted.exr", "_difference_predicted.exr"})
      EXPECT_TRUE(fs::is_regular_file(dir / "v" / (base + suffix))) << base << suffix;
  }
  // The default irradiance is exact (App. A's vector flux: the solve gives it the model it
  // projects) and recorded in the scene; Monte Carlo, chosen in a config file, is recorded and
  // validates alike. The two differ by the Monte Carlo's noise, at most its 2.9% per point (256
  // directions), and much less once averaged over pixels.
  {
    const nlohmann::json d =
        nlohmann::json::parse(rouen::ReadFileToString(dir / "scene" / "scene.json"));
    EXPECT_EQ(d["provenance"]["options"]["config"]["albedo"]["irradiance"]["method"],
              "vector_flux");
    const fs::path toml = dir / "mc.toml";
    std::ofstream(toml) << "[albedo.irradiance]\nmethod = \"monte_carlo\"\n";
    out.clear();
    ASSERT_EQ(RunRouen("solve " + (dir / "session").string() + " --quick --holdout-slot " +
                           std::to_string(heldout) + " --work " + (dir / "work").string() +
                           " --config " + toml.string() + " --out " + (dir / "scene_mc").string(),
                       &out),
              0)
        << out;
    const nlohmann::json s =
        nlohmann::json::parse(rouen::ReadFileToString(dir / "scene_mc" / "scene.json"));
    const nlohmann::json& config = s["provenance"]["options"]["config"];
    EXPECT_EQ(config["albedo"]["irradiance"]["method"], "monte_carlo") << config.dump();
    out.clear();
    ASSERT_EQ(RunRouen("validate " + (dir / "scene_mc").string() + " --session " +
                           (dir / "session").string() + " --slot " + std::to_string(heldout) +
                           " --exclude-block plaza --json " + (dir / "v_mc.json").string(),
                       &out),
              0)
        << out;
    const nlohmann::json mc = nlohmann::json::parse(std::ifstream(dir / "v_mc.json"));
    const nlohmann::json exact = nlohmann::json::parse(std::ifstream(dir / "v.json"));
    for (const char* lighting : {"measured", "predicted"})
      for (const char* figure : {"rel_rmse", "median_rel_error"})
        EXPECT_NEAR(exact[lighting][figure].get<double>(), mc[lighting][figure].get<double>(),
                    0.029)
            << lighting << " " << figure;
  }
  // A block the model does not have is named with the ones it has; nothing is written.
  out.clear();
  EXPECT_NE(
      RunRouen("validate " + (dir / "scene").string() + " --session " + (dir / "session").string() +
                   " --slot 3 --exclude-block patio --json " + (dir / "w.json").string(),
               &out),
      0);
  EXPECT_NE(out.find("no block named 'patio' (blocks: "), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "w.json"));
  // Scoring one block: the roof, a few pixels wide in the quick demo's views, vanishes from
  // most of them once eroded by 3 pixels. Those photos are skipped and named; the others are
  // scored. Eroded by 64 pixels it is in no photo: an error, and nothing written.
  const std::string roof_only =
      " --slot 3 --exclude-block base --exclude-block shaft "
      "--exclude-block belfry --exclude-block plaza --erode ";
  out.clear();
  ASSERT_EQ(
      RunRouen("validate " + (dir / "scene").string() + " --session " + (dir / "session").string() +
                   roof_only + "3 --json " + (dir / "roof.json").string(),
               &out),
      0)
      << out;
  {
    const nlohmann::json v = nlohmann::json::parse(std::ifstream(dir / "roof.json"));
    ASSERT_TRUE(v.contains("skipped")) << v.dump();
    EXPECT_GE(v["photos"].size(), 1u);
    EXPECT_EQ(v["photos"].size() + v["skipped"].size(), 4u);  // the slot's four views
    for (const auto& name : v["skipped"])
      EXPECT_NE(out.find(name.get<std::string>() + ": skipped, no building pixel to score"),
                std::string::npos)
          << out;
  }
  out.clear();
  EXPECT_NE(
      RunRouen("validate " + (dir / "scene").string() + " --session " + (dir / "session").string() +
                   roof_only + "64 --json " + (dir / "none.json").string(),
               &out),
      0);
  EXPECT_NE(out.find("slot 3 has no building pixel to score in any photo"), std::string::npos)
      << out;
  EXPECT_FALSE(fs::exists(dir / "none.json"));

  // The environment's stereo options are the solve's ([env_stereo]) and the scene records
  // them: a prediction made from the same slots reuses the solve's fit with non-default ones
  // too (it refitted with the defaults before).
  rouen::WriteFileAtomic(dir / "env.toml", "[env_stereo]\nalpha = 500\nmax_albedo = 1.2\n");
  out.clear();
  ASSERT_EQ(RunRouen("solve " + (dir / "session").string() + " --quick --holdout-slot 3 --out " +
                         (dir / "env_scene").string() + " --config " + (dir / "env.toml").string(),
                     &out),
            0)
      << out;
  {
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "env_scene/scene.json"));
    const nlohmann::json& recorded = j.at("provenance").at("options").at("config");
    EXPECT_EQ(recorded.at("env_stereo").at("alpha").get<double>(), 500);
    EXPECT_EQ(recorded.at("env_stereo").at("max_albedo").get<double>(), 1.2);
  }
  out.clear();
  ASSERT_EQ(RunRouen("render " + (dir / "env_scene").string() +
                         " --time 2026-08-25T17:00:00-07:00 --out " + (dir / "env.exr").string(),
                     &out),
            0)
      << out;
  EXPECT_NE(out.find("the environment's normals as the solve fitted them"), std::string::npos)
      << out;

  fs::rename(dir / "session", dir / "session-away");
  const std::string scene = " " + (dir / "scene").string();
  out.clear();
  ASSERT_EQ(RunRouen("render" + scene + " --slot 1 --view slot1/architecture/view0 --out " +
                         (dir / "slot1.exr").string(),
                     &out),
            0)
      << out;
  out.clear();
  ASSERT_EQ(RunRouen("render" + scene + " --time 2026-08-25T17:00:00-07:00 --pbs 0.5 --out " +
                         (dir / "p.exr").string() + " --png " + (dir / "p.png").string(),
                     &out),
            0)
      << out;
  EXPECT_NE(out.find("air mass"), std::string::npos) << out;
  for (const char* f : {"slot1.exr", "p.exr"}) {
    const rouen::Image im = rouen::ReadImage((dir / f).string());
    double sum = 0;
    for (float v : im.data) {
      ASSERT_TRUE(std::isfinite(v)) << f;
      ASSERT_GE(v, 0) << f;
      sum += v;
    }
    EXPECT_GT(sum, 0) << f;
  }
  EXPECT_TRUE(fs::exists(dir / "p.png"));
  // The same view from a lens file and a pose file (as `rouen calib intrinsics` and `rouen
  // calib pose` write them) renders the same image: JSON keeps every double exactly.
  {
    const rouen::Session s = rouen::Session::Load(dir / "session-away");
    const rouen::FrameRecord* view = nullptr;
    for (const rouen::FrameRecord& f : s.frames())
      if (f.group == "slot1/architecture/view0") view = &f;
    ASSERT_TRUE(view && view->intrinsics && view->pose);
    rouen::WriteFileAtomic(dir / "lens.json", nlohmann::json(*view->intrinsics).dump());
    rouen::WriteFileAtomic(dir / "pose.json", nlohmann::json(*view->pose).dump());
  }
  out.clear();
  ASSERT_EQ(
      RunRouen("render" + scene + " --slot 1 --lens " + (dir / "lens.json").string() + " --pose " +
                   (dir / "pose.json").string() + " --out " + (dir / "files.exr").string(),
               &out),
      0)
      << out;
  {
    const rouen::Image a = rouen::ReadImage((dir / "slot1.exr").string());
    const rouen::Image b = rouen::ReadImage((dir / "files.exr").string());
    ASSERT_EQ(a.width, b.width);
    ASSERT_EQ(a.height, b.height);
    EXPECT_EQ(a.data, b.data);
  }
  // A bad lens file fails before the scene is read, naming the file.
  rouen::WriteFileAtomic(dir / "bad-lens.json", "{\"projection\": \"pinhole\"");
  out.clear();
  EXPECT_NE(
      RunRouen("render" + scene + " --slot 1 --lens " + (dir / "bad-lens.json").string() +
                   " --pose " + (dir / "pose.json").string() + " --out " + (dir / "n.exr").string(),
               &out),
      0);
  EXPECT_NE(out.find("bad-lens.json: not a valid lens file"), std::string::npos) << out;
  // Night, and contradictory options, fail at once with the reason.
  out.clear();
  EXPECT_NE(RunRouen("render" + scene + " --time 2026-08-25T23:30:00-07:00 --out " +
                         (dir / "n.exr").string(),
                     &out),
            0);
  EXPECT_NE(out.find("below the horizon"), std::string::npos) << out;
  out.clear();
  EXPECT_NE(RunRouen("render" + scene + " --slot 0 --time 2026-08-25T12:00:00-07:00 --out " +
                         (dir / "n.exr").string(),
                     &out),
            0);
  EXPECT_NE(out.find("exactly one"), std::string::npos) << out;
  // A slot or a view the scene does not have is named with what it has.
  out.clear();
  EXPECT_NE(RunRouen("render" + scene + " --slot 7 --out " + (dir / "n.exr").string(), &out), 0);
  EXPECT_NE(out.find("slot 7 is not in the scene (it has slots 0..4)"), std::string::npos) << out;
  out.clear();
  EXPECT_NE(RunRouen("render" + scene + " --slot 1 --view slot1/architecture/view9 --out " +
                         (dir / "n.exr").string(),
                     &out),
            0);
  EXPECT_NE(out.find("no view named 'slot1/architecture/view9' (architecture views: "
                     "slot0/architecture/view0"),
            std::string::npos)
      << out;
  EXPECT_FALSE(fs::exists(dir / "n.exr"));
  // Predicting the held-out time leaves the held-out slot's own lighting out, unless asked.
  for (const char* flag : {"", " --use-held-out"}) {
    out.clear();
    ASSERT_EQ(RunRouen("render" + scene + " --time 2026-08-25T16:00:00-07:00" + flag + " --out " +
                           (dir / (std::string("held") + (*flag ? "-used" : "") + ".exr")).string(),
                       &out),
              0)
        << out;
  }
  EXPECT_NE(rouen::ReadImage((dir / "held.exr").string()).data,
            rouen::ReadImage((dir / "held-used.exr").string()).data);
  // A sequence: one EXR (and PNG) per time, named by the time, each the image a single --time
  // render of that time gives.
  out.clear();
  ASSERT_EQ(RunRouen("render" + scene +
                         " --from 2026-08-25T09:00:00-07:00 --to 2026-08-25T10:00:00-07:00"
                         " --step 30min --out " +
                         (dir / "seq").string() + " --png " + (dir / "seq-png").string(),
                     &out),
            0)
      << out;
  EXPECT_NE(out.find("2/3 2026-08-25T16:30:00Z"), std::string::npos) << out;
  for (const char* name : {"20260825T160000Z", "20260825T163000Z", "20260825T170000Z"}) {
    EXPECT_TRUE(fs::is_regular_file(dir / "seq" / (std::string(name) + ".exr"))) << name;
    EXPECT_TRUE(fs::is_regular_file(dir / "seq-png" / (std::string(name) + ".png"))) << name;
  }
  EXPECT_EQ(std::distance(fs::directory_iterator(dir / "seq"), fs::directory_iterator()), 3);
  out.clear();
  ASSERT_EQ(RunRouen("render" + scene + " --time 2026-08-25T09:30:00-07:00 --out " +
                         (dir / "one.exr").string(),
                     &out),
            0)
      << out;
  EXPECT_EQ(rouen::ReadImage((dir / "one.exr").string()).data,
            rouen::ReadImage((dir / "seq" / "20260825T163000Z.exr").string()).data);
  // A sequence reaching into the night is refused before any work, naming the time, and
  // leaves no folder; so are a bad step and too many frames.
  const auto refused_sequence = [&](const std::string& from, const std::string& to,
                                    const std::string& step) {
    std::string said;
    EXPECT_NE(RunRouen("render" + scene + " --from " + from + " --to " + to + " --step " + step +
                           " --out " + (dir / "night").string(),
                       &said),
              0)
        << step;
    return said;
  };
  out = refused_sequence("2026-08-25T19:00:00-07:00", "2026-08-25T23:00:00-07:00", "1h");
  EXPECT_NE(out.find("below the horizon"), std::string::npos) << out;
  EXPECT_NE(out.find("at 2026-08-26T"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "night"));
  out = refused_sequence("2026-08-25T09:00:00-07:00", "2026-08-25T10:00:00-07:00", "15m");
  EXPECT_NE(out.find("--step '15m': unknown unit 'm'"), std::string::npos) << out;
  // Hexadecimal, which std::stod reads (as 16 s): not a duration people write.
  out = refused_sequence("2026-08-25T09:00:00-07:00", "2026-08-25T10:00:00-07:00", "0x10");
  EXPECT_NE(out.find("--step '0x10': not a duration"), std::string::npos) << out;
  out = refused_sequence("2026-08-25T09:00:00-07:00", "2026-08-25T12:00:00-07:00", "1s");
  EXPECT_NE(out.find("10801 frames, more than 5000"), std::string::npos) << out;
  // A step too short for any integer to count its frames: counted all the same (it was printed
  // as -9223372036854775807 frames, an overflow).
  out = refused_sequence("2026-08-25T09:00:00-07:00", "2026-08-25T12:00:00-07:00", "1e-300");
  EXPECT_NE(out.find("1.08e+304 frames, more than 5000"), std::string::npos) << out;
  // A new camera from a point, a target, a field of view and a size.
  out.clear();
  ASSERT_EQ(RunRouen("render" + scene +
                         " --slot 2 --look-at 0,0,20 --from-point 60,-45,12 --fov 60 --size "
                         "160x120 --out " +
                         (dir / "look.exr").string(),
                     &out),
            0)
      << out;
  {
    const rouen::Image im = rouen::ReadImage((dir / "look.exr").string());
    EXPECT_EQ(im.width, 160);
    EXPECT_EQ(im.height, 120);
    // The target is the building's centre: the middle pixel sees it, lit.
    for (int c = 0; c < 3; ++c) EXPECT_GT(im.at(80, 60, c), 0.f) << c;
    for (float v : im.data) ASSERT_TRUE(std::isfinite(v));
  }
  out.clear();
  EXPECT_NE(RunRouen("render" + scene + " --slot 2 --look-at 1,2,3 --from-point 1,2,3 --out " +
                         (dir / "n.exr").string(),
                     &out),
            0);
  EXPECT_NE(out.find("the same point"), std::string::npos) << out;
  out.clear();
  EXPECT_NE(RunRouen("render" + scene +
                         " --slot 2 --look-at 1,2,3 --view slot0/architecture/view0"
                         " --from-point 9,2,3 --out " +
                         (dir / "n.exr").string(),
                     &out),
            0);
  EXPECT_NE(out.find("give one camera"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "n.exr"));
  {
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "scene" / "scene.json"));
    EXPECT_EQ(j["holdout_slots"], nlohmann::json::array({heldout}));
    EXPECT_EQ(j["slots"].size(), 5u);
  }
  // A frame changed behind the journal makes the scene out of date (its file's time changed);
  // the solve then fails half-way, and leaves the earlier scene as it was and no temporary
  // folder.
  const std::string scene_json = rouen::ReadFileToString(dir / "scene" / "scene.json");
  {
    const rouen::Session s = rouen::Session::Load(dir / "session-away");
    const fs::path last = dir / "session-away" / s.frames().back().file;
    std::string bytes = rouen::ReadFileToString(last);
    bytes.back() ^= 1;
    rouen::WriteFileAtomic(last, bytes);
  }
  out.clear();
  EXPECT_NE(RunRouen("solve " + (dir / "session-away").string() + " --quick --holdout-slot " +
                         std::to_string(heldout) + " --out " + (dir / "scene").string(),
                     &out),
            0);
  EXPECT_NE(out.find("does not match its journal"), std::string::npos) << out;
  EXPECT_EQ(rouen::ReadFileToString(dir / "scene" / "scene.json"), scene_json);
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  fs::remove_all(dir);
}

TEST(DemoTest, DemoRefusesAForeignFolder) {
  fs::path foreign = fs::temp_directory_path() / ("rouen_demo_foreign_" + std::to_string(getpid()));
  fs::create_directories(foreign);
  std::ofstream(foreign / "precious.txt") << "keep me";
  std::string out;
  EXPECT_NE(RunRouen("demo --quick --out " + foreign.string(), &out), 0);
  EXPECT_NE(out.find("not a rouen demo folder"), std::string::npos) << out;
  EXPECT_TRUE(fs::exists(foreign / "precious.txt"));
  fs::remove_all(foreign);
}

}  // namespace
