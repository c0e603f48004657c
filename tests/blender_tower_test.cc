// rouen on a world photographed only from the ground: tests/data/blender_tower holds Cycles
// renders of an 82 m campanile with an open belfry, one panorama per time at eye height 30 m
// south of it (the landscape and the sky photo at once), a telephoto sun frame, three views
// 100 m out, and beside each view Cycles' Diffuse Direct and Indirect light passes: the true
// irradiance of every pixel's surface (see its README.md and gen.py).
//
// The user's path (import, status, solve, validate) and, term by term, rouen's irradiance at
// its grid points against Cycles' passes per block and time.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "core/files.h"
#include "tests/cli_util.h"
#include "tests/light_passes.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;
using light_passes::TermSums;
using light_passes::TermTable;

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_tower"; }

nlohmann::json Truth() { return nlohmann::json::parse(ReadFileToString(Data() / "truth.json")); }

// One import and one default solve (held-out slot kept out of the albedos) for every test here.
class BlenderTowerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(cli_test::TempDir("blender_tower"));
    const nlohmann::json truth = Truth();
    Result r = RunRouen(light_passes::ImportCommand(Data()) + " --out " + Q(Session()));
    import_log_ = new std::string(r.out);
    if (r.code != 0) return;
    r = RunRouen("solve " + Q(Session()) + " --out " + Q(Scene()) + " --holdout-slot " +
                 std::to_string(truth["heldout_slot"].get<int>()));
    solve_log_ = new std::string(r.out);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete import_log_;
    delete solve_log_;
  }
  static fs::path Session() { return *dir_ / "session"; }
  static fs::path Scene() { return *dir_ / "scene"; }
  void SetUp() override {
    ASSERT_TRUE(import_log_ && fs::exists(Session() / "session.json")) << *import_log_;
    ASSERT_TRUE(solve_log_ && fs::exists(Scene() / "scene.json"))
        << (solve_log_ ? *solve_log_ : "");
  }

  static fs::path* dir_;
  static std::string* import_log_;
  static std::string* solve_log_;
};
fs::path* BlenderTowerTest::dir_ = nullptr;
std::string* BlenderTowerTest::import_log_ = nullptr;
std::string* BlenderTowerTest::solve_log_ = nullptr;

// The default solve's irradiance against Cycles' light passes.
TEST_F(BlenderTowerTest, IrradianceTermsAgainstCyclesLightPasses) {
  const nlohmann::json truth = Truth();
  const std::map<std::string, TermSums> table = TermTable(Data(), Scene());
  TermTable(Data(), Scene(), true);  // printed: what the prediction adds
  for (const std::string block : {"base", "shaft", "belfry", "roof"}) {
    for (int slot = 0; slot < 5; ++slot) {
      for (const char* lit : {" sunlit", " shaded"})
        EXPECT_GT(table.count(std::to_string(slot) + " " + block + lit), 0u) << block << slot;
    }
    if (truth["blocks"][block]["glossy"].get<bool>()) continue;
    // On the sunlit faces of the matte blocks the light is mostly the sun's: its radiance from
    // the telephoto frame (within 3% of Cycles' disc, tests/blender_sun_test.cc) and the
    // surface's Burley factor, exact here. The rest (8-25% of it) is the sky and the ground,
    // which rouen gets within 20% (the shaded faces' figures printed): pooled over the times,
    // within 3% + 20% x 25% = 8% per matte block and channel. rouen comes within 1%.
    const TermSums& m = table.at("all " + block + " sunlit");
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.TotalRatio()[c], 1.0, 0.08) << block << " " << c;
  }
}

// The user's path on the ground-only capture: the held-out low sun and every training time,
// view by view, and the albedos against the base colours.
TEST_F(BlenderTowerTest, HeldOutAndTrainingPhotosExplained) {
  const nlohmann::json truth = Truth();
  const int heldout = truth["heldout_slot"].get<int>();
  for (int slot = 0; slot < 5; ++slot) {
    std::string vname = "v";
    vname += std::to_string(slot);
    const fs::path vjson = *dir_ / (vname + ".json");
    const Result r = RunRouen("validate " + Q(Scene()) + " --session " + Q(Session()) + " --slot " +
                              std::to_string(slot) + " --json " + Q(vjson));
    ASSERT_EQ(r.code, 0) << r.out;
    const nlohmann::json v = nlohmann::json::parse(ReadFileToString(vjson));
    ASSERT_EQ(v["photos"].size(), 3u);
    for (const nlohmann::json& p : v["photos"]) {
      const std::string name = p["view"].get<std::string>();
      const double meas = p["measured"]["psnr_db"], pred = p["predicted"]["psnr_db"];
      std::cout << name << ": measured " << meas << " dB, median "
                << p["measured"]["median_rel_error"] << "; predicted " << pred << " dB, median "
                << p["predicted"]["median_rel_error"] << "\n";
      // The bar for photographs a model explains: 35 dB per view, for the training
      // times (a fit) and the held-out time under the lighting measured then.
      EXPECT_GE(meas, 35) << name;
      // Under lighting predicted from the other times too, at the held-out time, within 2%
      // median (the bars; 39.2-44.9 dB, 0.8-1.7% here. Before the sky fit weighed its
      // samples by solid angle the south-east view scored 34.0 dB, 3.4%). Under the lighting
      // measured then the north view's median is 2.07%: not asserted.
      if (slot == heldout) {
        EXPECT_GE(pred, 35) << name;
        EXPECT_LE(p["predicted"]["median_rel_error"].get<double>(), 0.02) << name;
      }
    }
  }
  // The sun pseudo-albedos against the base colours: per matte block and channel, the median
  // over its observed points within 5% (the bar; the sun's radiance 1-3%, the retro fit).
  for (const light_passes::BlockAlbedo& a : light_passes::BlockAlbedos(Data(), Scene())) {
    if (!a.glossy) {
      EXPECT_NEAR(a.rho_sun / a.base, 1.0, 0.05) << a.block << " " << a.channel;
    }
  }
}

// A grid spacing for a block the model lacks (a misspelt block) is refused before any work,
// naming the blocks there are.
TEST_F(BlenderTowerTest, ABlockSpacingForNoBlockIsRefused) {
  const fs::path config = *dir_ / "misspelt.toml";
  WriteFileAtomic(config, "[grid.block_spacing_m]\nbelfy = 0.3\n");
  const Result r = RunRouen("solve " + Q(Session()) + " --out " + Q(*dir_ / "misspelt_scene") +
                            " --config " + Q(config));
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("grid.block_spacing_m.belfy: the model"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("its blocks: base, shaft, belfry, roof"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(*dir_ / "misspelt_scene"));
}

// The ground as a light field, on by default when the session gives the surroundings: the same
// photographs imported again with the houses, the block, the shed and the wall as boxes
// (surroundings.obj, as a city model's extruded footprints; not the trees), solved by default
// and with the field off. The field sees the ground from the wall; the houses' sunlit walls,
// which a wall 40 m up sees below its horizon, come from the surroundings. On the shaft's shaded
// faces -- the light the issue is about -- the field is within 0.979-1.003 of Cycles' light at
// every time (without it 1.012-1.066: the warm ground seen from the panorama at grazing angles).
// Without the surroundings the field missed the houses' walls: the west face 8-9% too dark in
// the morning, so the field stays off there (the default solve above logs no field).
TEST_F(BlenderTowerTest, GroundFieldWithTheSurroundingsSeesTheGroundFromTheWall) {
  EXPECT_EQ(solve_log_->find("ground field:"), std::string::npos) << *solve_log_;
  const fs::path session = *dir_ / "session_around";
  Result r = RunRouen(light_passes::ImportCommand(Data()) + " --surroundings " +
                      Q(Data() / "surroundings.obj") + " --out " + Q(session));
  ASSERT_EQ(r.code, 0) << r.out;
  const fs::path field = *dir_ / "scene_field", plain = *dir_ / "scene_plain";
  r = RunRouen("solve " + Q(session) + " --out " + Q(field) + " --holdout-slot 4");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("ground field:"), std::string::npos) << r.out;
  const fs::path config = *dir_ / "no_field.toml";
  WriteFileAtomic(config, "[ground_field]\nenabled = false\n");
  r = RunRouen("solve " + Q(session) + " --out " + Q(plain) + " --holdout-slot 4 --config " +
               Q(config));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.out.find("ground field:"), std::string::npos) << r.out;

  const std::map<std::string, TermSums> with = TermTable(Data(), field);
  const std::map<std::string, TermSums> without = TermTable(Data(), plain);
  // The bar for the albedos is 5%; an albedo is the photo over this light, so the light
  // must be within 5% at every time.
  for (int slot = 0; slot < 5; ++slot) {
    const std::string key = std::to_string(slot) + " shaft shaded";
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(with.at(key).TotalRatio()[c], 1.0, 0.05) << key;
  }
  for (int c = 0; c < 3; ++c)
    EXPECT_LT(std::abs(with.at("all shaft shaded").TotalRatio()[c] - 1),
              std::abs(without.at("all shaft shaded").TotalRatio()[c] - 1))
        << c;
  // And so the matte blocks' sky + environment albedos, where the photos saw them lit and
  // shaded, reach the bar (-0.8..+1.1% here; without the field the belfry's red is 5.3% low).
  for (const light_passes::BlockAlbedo& a : light_passes::BlockAlbedos(Data(), field, true)) {
    if (a.glossy) continue;
    EXPECT_NEAR(a.rho_se / a.base, 1.0, 0.05) << a.block << " " << a.channel;
    EXPECT_NEAR(a.rho_sun / a.base, 1.0, 0.05) << a.block << " " << a.channel;
  }
}

}  // namespace
}  // namespace rouen
