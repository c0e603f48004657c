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
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/files.h"
#include "core/image.h"
#include "core/mesh.h"
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

  r = RunRouen("solve " + Q(session) + " --out " + Q(scene) + " --holdout-slot " +
               std::to_string(heldout) + " --quick");
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
               std::to_string(heldout) + " --json " + Q(vjson));
  ASSERT_EQ(r.code, 0) << r.out;
  const nlohmann::json v = nlohmann::json::parse(ReadFileToString(vjson));
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
  // smallest gross failure, 0.25: it leaves room for what the paper's model does not
  // represent here and rouen cannot remove, chiefly that Blender's Principled diffuse is not
  // Lambertian (1.4x brighter for the held-out sun on the south walls of view0): rouen scored
  // 0.127 predicted and 0.117 measured on this data, and 0.025 / 0.020 on the same world
  // rendered with Lambertian materials (gen.py --lambert, README.md).
  EXPECT_LT(v["predicted"]["rel_rmse"].get<double>(), 0.25) << r.out;
  EXPECT_LT(v["measured"]["rel_rmse"].get<double>(), 0.25) << r.out;
  // The overall brightness: a 2x albedo error gives 2 or 0.5.
  EXPECT_GT(v["predicted"]["mean_ratio"].get<double>(), 0.8) << r.out;
  EXPECT_LT(v["predicted"]["mean_ratio"].get<double>(), 1.25) << r.out;

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
      // light, so the sun albedo comes out a little high: rouen's medians were 3-5% above the
      // base colour on this data. 15% allows for that; a sun measured 2x too bright (sun
      // frames scaled by 2) gave medians of half the base colour.
      if (!glossy) EXPECT_NEAR(Median(vals) / want, 1.0, 0.15) << block << " channel " << c;
    }
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
