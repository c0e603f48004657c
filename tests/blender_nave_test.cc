// rouen on a church with a street of houses along its shady side: tests/data/blender_nave holds
// Cycles renders of a nave, two ground panoramas per time (one in the square, one in the
// street), four eye-height views, and the houses around it as a city model would give them
// (surroundings.obj, footprints extruded to their heights; see its README.md and gen.py).
//
// The user's path twice, with and without `import --surroundings`: the houses shade the nave's
// north wall, which a model of the church alone lights with the sun.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/files.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_nave"; }

// Import, solve (the held-out slot kept out of the albedos) and validate the held-out slot,
// once with the church alone and once with its surroundings.
class BlenderNaveTest : public ::testing::Test {
 protected:
  struct Run {
    std::string log;
    nlohmann::json validation;  // rouen validate --json
  };
  static void SetUpTestSuite() {
    dir_ = new fs::path(cli_test::TempDir("blender_nave"));
    alone_ = new Run(UserPath("alone", ""));
    around_ = new Run(UserPath("around", " --surroundings " + Q(Data() / "surroundings.obj")));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete alone_;
    delete around_;
  }
  static Run UserPath(const std::string& name, const std::string& surroundings) {
    const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(Data() / "truth.json"));
    const nlohmann::json& site = truth["site"];
    const std::string heldout = std::to_string(truth["heldout_slot"].get<int>());
    const fs::path session = *dir_ / (name + "_session"), scene = *dir_ / (name + "_scene");
    Run run;
    Result r = RunRouen(
        "import --photos " + Q(Data()) + " --list " + Q(Data() / "list.txt") + " --cameras " +
        Q(Data() / "cameras.json") + " --site=" + std::to_string(site["lat_deg"].get<double>()) +
        "," + std::to_string(site["lon_deg"].get<double>()) + "," +
        std::to_string(site["height_m"].get<double>()) + " --model " + Q(Data() / "building.obj") +
        surroundings + " --sky-mask auto --out " + Q(session));
    run.log += r.out;
    if (r.code != 0) return run;
    r = RunRouen("solve " + Q(session) + " --out " + Q(scene) + " --holdout-slot " + heldout);
    run.log += r.out;
    if (r.code != 0) return run;
    const fs::path json = *dir_ / (name + "_validation.json");
    r = RunRouen("validate " + Q(scene) + " --session " + Q(session) + " --slot " + heldout +
                 " --json " + Q(json));
    run.log += r.out;
    if (r.code == 0) run.validation = nlohmann::json::parse(ReadFileToString(json));
    return run;
  }
  void SetUp() override {
    ASSERT_TRUE(alone_->validation.contains("photos")) << alone_->log;
    ASSERT_TRUE(around_->validation.contains("photos")) << around_->log;
    ASSERT_EQ(alone_->validation["photos"].size(), around_->validation["photos"].size());
  }

  static fs::path* dir_;
  static Run* alone_;
  static Run* around_;
};
fs::path* BlenderNaveTest::dir_ = nullptr;
BlenderNaveTest::Run* BlenderNaveTest::alone_ = nullptr;
BlenderNaveTest::Run* BlenderNaveTest::around_ = nullptr;

// The houses are solved with the church (they shade it, hide its sky and light it) but never
// scored: every view scores the same pixels of the church with or without them (no house
// hides the church from a view: gen.py checks it).
TEST_F(BlenderNaveTest, SurroundingsAreSolvedButNeverScored) {
  EXPECT_NE(around_->log.find("surroundings: 12 blocks from surroundings.obj (not scored)"),
            std::string::npos)
      << around_->log;
  for (size_t k = 0; k < alone_->validation["photos"].size(); ++k) {
    const nlohmann::json& a = alone_->validation["photos"][k];
    const nlohmann::json& b = around_->validation["photos"][k];
    ASSERT_EQ(a["view"], b["view"]);
    EXPECT_EQ(a["measured"]["pixels"], b["measured"]["pixels"]) << a["view"];
    EXPECT_GT(a["measured"]["pixels"].get<int>(), 0) << a["view"];
  }
}

// At the held-out evening time the houses across the street shade the nave's north wall: the
// church alone lights it with the sun (several times too bright), the church with its
// surroundings does not. Every view is explained at least as well under the lighting measured
// at that time; the street view by far.
TEST_F(BlenderNaveTest, TheHousesShadeTheStreetWall) {
  for (size_t k = 0; k < alone_->validation["photos"].size(); ++k) {
    const nlohmann::json& a = alone_->validation["photos"][k];
    const nlohmann::json& b = around_->validation["photos"][k];
    const double before = a["measured"]["psnr_db"], after = b["measured"]["psnr_db"];
    std::printf("%s: measured %.2f -> %.2f dB, predicted %.2f -> %.2f dB\n",
                a["view"].get<std::string>().c_str(), before, after,
                a["predicted"]["psnr_db"].get<double>(), b["predicted"]["psnr_db"].get<double>());
    EXPECT_GE(after, before) << a["view"];
  }
  // The scene's views in name order: glint, se, street, west.
  const nlohmann::json& a = alone_->validation["photos"][2];
  const nlohmann::json& b = around_->validation["photos"][2];
  ASSERT_EQ(a["view"], "slot4/architecture/view2");
  EXPECT_GT(a["measured"]["mean_ratio"].get<double>(), 2) << "the wall lit by the sun";
  for (const char* lighting : {"measured", "predicted"}) {
    EXPECT_GE(b[lighting]["psnr_db"].get<double>(), a[lighting]["psnr_db"].get<double>() + 10)
        << lighting;
  }
}

}  // namespace
}  // namespace rouen
