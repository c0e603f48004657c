// rouen on a church with a street of houses along its shady side: tests/data/blender_nave holds
// Cycles renders of a nave, two ground panoramas per time (one in the square, one in the
// street), four eye-height views, and the houses around it as a city model would give them
// (surroundings.obj, footprints extruded to their heights; see its README.md and gen.py).
//
// The user's path twice, with and without `import --surroundings`: the houses shade the nave's
// north wall, which a model of the church alone lights with the sun.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/files.h"
#include "solve/scene.h"
#include "solve/specular.h"
#include "tests/cli_util.h"
#include "tests/light_passes.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_nave"; }

// Import, solve (the held-out slot kept out of the albedos) and validate the held-out slot:
// the church alone, the church with its surroundings and the ground field off ([ground_field]
// enabled = false), with them by default (the field on, as the surroundings are given; the
// specular lobes' two models tried), and with eq. 13's lobe alone.
class BlenderNaveTest : public ::testing::Test {
 protected:
  using Run = light_passes::HeldOutRun;
  static void SetUpTestSuite() {
    dir_ = new fs::path(cli_test::TempDir("blender_nave"));
    alone_ = new Run(light_passes::RunHeldOut(Data(), *dir_, "alone", ""));
    const std::string surroundings = " --surroundings " + Q(Data() / "surroundings.obj");
    const fs::path no_field = *dir_ / "no_field.toml";
    WriteFileAtomic(no_field, "[ground_field]\nenabled = false\n");
    around_ = new Run(light_passes::RunHeldOut(Data(), *dir_, "around", surroundings,
                                               " --config " + Q(no_field)));
    field_ = new Run(light_passes::RunHeldOut(Data(), *dir_, "field", surroundings));
    const fs::path eq13 = *dir_ / "eq13.toml";
    WriteFileAtomic(eq13, "[albedo.sun_lobe]\nmodel = \"lafortune\"\n");
    lafortune_ = new Run(
        light_passes::RunHeldOut(Data(), *dir_, "lafortune", surroundings, " --config " + Q(eq13)));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete alone_;
    delete around_;
    delete field_;
    delete lafortune_;
  }
  void SetUp() override {
    ASSERT_TRUE(alone_->validation.contains("photos")) << alone_->log;
    ASSERT_TRUE(around_->validation.contains("photos")) << around_->log;
    ASSERT_TRUE(field_->validation.contains("photos")) << field_->log;
    ASSERT_TRUE(lafortune_->validation.contains("photos")) << lafortune_->log;
    ASSERT_EQ(alone_->validation["photos"].size(), around_->validation["photos"].size());
  }

  static fs::path* dir_;
  static Run* alone_;
  static Run* around_;
  static Run* field_;
  static Run* lafortune_;
};
fs::path* BlenderNaveTest::dir_ = nullptr;
BlenderNaveTest::Run* BlenderNaveTest::alone_ = nullptr;
BlenderNaveTest::Run* BlenderNaveTest::around_ = nullptr;
BlenderNaveTest::Run* BlenderNaveTest::field_ = nullptr;
BlenderNaveTest::Run* BlenderNaveTest::lafortune_ = nullptr;

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

// The landscape panoramas read the surroundings' albedos too (SolveConfig::
// surroundings_from_panoramas): the house south-west of the square, which no architecture view
// shows, took the fill of the observed points before (0.571 / 0.488 / 0.392 against its
// 0.55 / 0.53 / 0.50); the square's panorama sees it at every training time, so both its
// albedos come out within the 5% the issue asks of the building's.
TEST_F(BlenderNaveTest, AHouseOnlyThePanoramasSeeIsReadFromThem) {
  EXPECT_NE(field_->log.find("observations of the surroundings in 8 landscape panoramas"),
            std::string::npos)
      << field_->log;
  int channels = 0;
  for (const light_passes::BlockAlbedo& a :
       light_passes::SurroundingAlbedos(Data(), field_->scene)) {
    if (a.block != "house_sw") continue;
    ++channels;
    EXPECT_GT(a.points, 20) << a.channel;
    EXPECT_NEAR(a.rho_sun / a.base, 1, 0.05) << a.channel;
    EXPECT_NEAR(a.rho_se / a.base, 1, 0.05) << a.channel;
  }
  EXPECT_EQ(channels, 3);
}

// The slate roof's north slope throws the high sun's glint onto the houses across the street
// (house_n2 to house_n4, whose south walls the nave shades but at midday): without that light in
// the bounce, the panoramas' pixels of their sunlit walls gave sun albedos 5-10% above the base
// colours (house_n4 +10%), and their light on the nave's north wall at the held-out evening was
// as much too bright. With it, the 5% of the building's blocks holds for them too.
TEST_F(BlenderNaveTest, TheRoofsGlintLightsTheHousesAcrossTheStreet) {
  int channels = 0;
  for (const light_passes::BlockAlbedo& a :
       light_passes::SurroundingAlbedos(Data(), field_->scene)) {
    if (a.block != "house_n2" && a.block != "house_n3" && a.block != "house_n4") continue;
    ++channels;
    EXPECT_GT(a.points, 20) << a.block << " " << a.channel;
    EXPECT_NEAR(a.rho_sun / a.base, 1, 0.05) << a.block << " " << a.channel;
  }
  EXPECT_EQ(channels, 9);
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

// The ground as a light field, on by default with the surroundings. The panoramas see the square
// and the street at grazing angles, where the rough ground (Principled roughness 0.9) sends the sun
// back brighter than towards the walls; the environment's fit of that roughness from its regions
// over the day finds none here (two panoramas pooled in one layer, one of them in a shaded street),
// so the environment lights the walls with a ground too bright and too red, most on the south wall
// in sun: its sun albedo in red comes out about 24% low. The field fits the roughness from the
// ground itself (one albedo per spot at every time and from both panoramas) and lights each wall
// with the ground it sees.
TEST_F(BlenderNaveTest, TheGroundFieldSeesTheSquareAsTheWallsSeeIt) {
  const std::string& log = field_->log;
  const size_t at = log.find("ground field: ground retro ");
  ASSERT_NE(at, std::string::npos) << log;
  // Burley's roughness 0.9 is rouen's retro 0.9 up to 0.05 in F (solve/retro.h).
  const double retro = std::stod(log.substr(at + 27));
  EXPECT_NEAR(retro, 0.9, 0.15) << log.substr(at, 200);

  // Term by term against Cycles' passes: on the matte blocks' sunlit faces, pooled over the
  // times, the sun's radiance from the telephoto frame is within 3% (blender_sun_test) and the
  // rest of the light (up to 40% of it there) within 12.5%: 8% per block and channel.
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(Data() / "truth.json"));
  const auto field = light_passes::TermTable(Data(), field_->scene);
  const auto around = light_passes::TermTable(Data(), around_->scene);
  int worse_without = 0;
  for (const auto& [block, t] : truth["blocks"].items()) {
    if (t["glossy"].get<bool>()) continue;
    const std::string key = "all " + block + " sunlit";
    ASSERT_TRUE(field.count(key) && around.count(key)) << key;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(field.at(key).TotalRatio()[c], 1.0, 0.08) << key << " " << c;
      worse_without += std::abs(around.at(key).TotalRatio()[c] - 1) > 0.08;
    }
  }
  EXPECT_GT(worse_without, 0) << "the environment's ground lights the walls right already";

  // The sun pseudo-albedos of the matte blocks within the 5% of the base colours.
  for (const light_passes::BlockAlbedo& a : light_passes::BlockAlbedos(Data(), field_->scene))
    if (!a.glossy) {
      EXPECT_NEAR(a.rho_sun / a.base, 1.0, 0.05) << a.block << " " << a.channel;
    }

  // The held-out evening under the lighting measured then: the south-east view (the south wall
  // in its own shade, lit by the square) gains, and no view loses more than 1 dB.
  for (size_t k = 0; k < around_->validation["photos"].size(); ++k) {
    const nlohmann::json& a = around_->validation["photos"][k];
    const nlohmann::json& b = field_->validation["photos"][k];
    ASSERT_EQ(a["view"], b["view"]);
    const double before = a["measured"]["psnr_db"], after = b["measured"]["psnr_db"];
    std::printf("%s: measured %.2f -> %.2f dB, predicted %.2f -> %.2f dB\n",
                a["view"].get<std::string>().c_str(), before, after,
                a["predicted"]["psnr_db"].get<double>(), b["predicted"]["psnr_db"].get<double>());
    EXPECT_GE(after, before - 1) << a["view"];
    if (a["view"] == "slot4/architecture/view1") {
      EXPECT_GE(after, before + 3);
    }
  }
}

// The slate roof (Principled specular 0.5, roughness 0.35: GGX with alpha 0.1225 and a
// dielectric's F0 0.04, seen near its mirror direction by the glint view at 09:00). Eq. 13's
// lobe cannot be fifty times brighter at grazing than near normal incidence; the microfacet
// lobe, tried beside it by default, is kept, with the material's roughness. It explains the
// glint photographed at 09:00 (eq. 13's lobe leaves that photo at 18 dB), and where the photos
// determine the roof's albedos they come out nearer its base colour: the sun's within the
// issue's 5%, the sky's (its reflection of the sky now in the lobe, not in the diffuse albedo)
// nearer than with eq. 13's lobe.
TEST_F(BlenderNaveTest, TheSlateRoofsGlintIsAMicrofacetLobe) {
  Mesh mesh;
  const SceneModel scene = ReadScene(field_->scene, &mesh);
  const auto roof = std::find(mesh.block_names.begin(), mesh.block_names.end(), "roof");
  ASSERT_NE(roof, mesh.block_names.end());
  const SpecularLobe lobe = BlockLobe(scene.albedo.sun_lobes, roof - mesh.block_names.begin());
  ASSERT_FALSE(lobe.IsZero()) << field_->log;
  EXPECT_EQ(lobe.model, LobeModel::kMicrofacet) << lobe.Text();
  EXPECT_NEAR(std::sqrt(2 / (lobe.n + 2)), 0.1225, 0.1 * 0.1225) << lobe.Text();
  // The same lobe reflects the sky (one material).
  const SpecularLobe sky = BlockLobe(scene.albedo.sky_lobes, roof - mesh.block_names.begin());
  EXPECT_EQ(sky.rho_s, lobe.rho_s);

  // Both albedos where the photos determine both: the roof's points seen in sun and in shadow
  // (the west end, in the facade's shadow at some training times). Elsewhere the roof is never in
  // shadow, eq. 11 is missing and its rho_se rests on the block-ratio prior.
  const auto with_lafortune = light_passes::BlockAlbedos(Data(), lafortune_->scene, true);
  const auto with_micro = light_passes::BlockAlbedos(Data(), field_->scene, true);
  ASSERT_EQ(with_lafortune.size(), with_micro.size());
  for (size_t k = 0; k < with_micro.size(); ++k) {
    const light_passes::BlockAlbedo &a = with_micro[k], &l = with_lafortune[k];
    if (a.block != "roof") continue;
    EXPECT_NEAR(a.rho_sun / a.base, 1.0, 0.05) << a.channel;
    EXPECT_LT(std::abs(a.rho_se / a.base - 1), std::abs(l.rho_se / l.base - 1)) << a.channel;
  }

  // The glint view at 09:00, a training photo: the roof's glint, up to 200 times its diffuse
  // light, explained by the microfacet lobe (issue's bar for training photos: 35 dB).
  const fs::path json = *dir_ / "glint_0900.json";
  const auto glint_psnr = [&](const Run& run) {
    const Result r = RunRouen("validate " + Q(run.scene) + " --session " + Q(run.session) +
                              " --slot 0 --json " + Q(json));
    EXPECT_EQ(r.code, 0) << r.out;
    const nlohmann::json v = nlohmann::json::parse(ReadFileToString(json));
    for (const nlohmann::json& p : v["photos"])
      if (p["view"] == "slot0/architecture/view0") return p["measured"]["psnr_db"].get<double>();
    ADD_FAILURE() << "no glint view at slot 0";
    return 0.0;
  };
  const double micro_0900 = glint_psnr(*field_), lafortune_0900 = glint_psnr(*lafortune_);
  std::printf("glint view at 09:00: eq. 13's lobe %.2f dB, the microfacet lobe %.2f dB\n",
              lafortune_0900, micro_0900);
  EXPECT_GE(micro_0900, 35);

  // The views at the held-out evening: none explained worse than with eq. 13's lobe (0.3 dB,
  // the sky lobe's sampling noise in the render), the south-east view, where the roof fills a
  // third of the building's pixels, better.
  for (size_t k = 0; k < field_->validation["photos"].size(); ++k) {
    const nlohmann::json& l = lafortune_->validation["photos"][k];
    const nlohmann::json& a = field_->validation["photos"][k];
    ASSERT_EQ(l["view"], a["view"]);
    const double before = l["measured"]["psnr_db"], after = a["measured"]["psnr_db"];
    std::printf("%s: eq. 13's lobe %.2f dB, microfacet %.2f dB (predicted %.2f -> %.2f)\n",
                l["view"].get<std::string>().c_str(), before, after,
                l["predicted"]["psnr_db"].get<double>(), a["predicted"]["psnr_db"].get<double>());
    EXPECT_GE(after, before - 0.3) << l["view"];
    if (l["view"] == "slot4/architecture/view1") {
      EXPECT_GT(after, before) << l["view"];
    }
  }
}

}  // namespace
}  // namespace rouen
