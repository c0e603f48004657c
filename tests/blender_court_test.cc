// rouen on the town hall on a courtyard (tests/data/blender_court: a brick range, a rendered
// wing and a stone campanile at Toulouse, two eye-height panoramas per time, four eye-height
// views; see its README.md). Trees stand in the square: one in front of the range in the south
// view, and at the held-out evening their shadows fall on the walls.
//
// The user's path with the houses as surroundings (import --surroundings), without and with the
// trees as a survey or a map gives them (import --trees trees.csv: position, height, crown).
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/cli_util.h"
#include "tests/light_passes.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_court"; }

TEST(BlenderCourtTest, TreesTheUserGivesShadeTheWallsAndHideThemFromTheViews) {
  const fs::path dir = cli_test::TempDir("blender_court");
  const std::string surroundings = " --surroundings " + Q(Data() / "surroundings.obj");
  const light_passes::HeldOutRun bare = light_passes::RunHeldOut(Data(), dir, "bare", surroundings);
  const light_passes::HeldOutRun trees = light_passes::RunHeldOut(
      Data(), dir, "trees", surroundings + " --trees " + Q(Data() / "trees.csv"));
  ASSERT_TRUE(bare.validation.contains("photos")) << bare.log;
  ASSERT_TRUE(trees.validation.contains("photos")) << trees.log;
  ASSERT_EQ(bare.validation["photos"].size(), trees.validation["photos"].size());

  // Every held-out view at the evening sun (9 degrees high) meets the 35 dB under the
  // lighting measured then and under the lighting predicted from the other times, measured not
  // worse than predicted by more than 0.5 dB (41.4-46 dB here; without the trees 22-27 dB: the
  // tree in front of the range painted on its wall, their shadows missing). A view a tree
  // stands in front of scores fewer of the building's pixels (the tree is not the building);
  // one no tree stands in front of, the same.
  for (size_t k = 0; k < trees.validation["photos"].size(); ++k) {
    const nlohmann::json &t = trees.validation["photos"][k], &b = bare.validation["photos"][k];
    ASSERT_EQ(t["view"], b["view"]);
    const std::string view = t["view"];
    const double measured = t["measured"]["psnr_db"], predicted = t["predicted"]["psnr_db"];
    std::printf(
        "%s: measured %.2f -> %.2f dB (median %.4f), predicted %.2f -> %.2f dB "
        "(median %.4f), pixels %d -> %d\n",
        view.c_str(), b["measured"]["psnr_db"].get<double>(), measured,
        t["measured"]["median_rel_error"].get<double>(), b["predicted"]["psnr_db"].get<double>(),
        predicted, t["predicted"]["median_rel_error"].get<double>(),
        b["measured"]["pixels"].get<int>(), t["measured"]["pixels"].get<int>());
    EXPECT_GE(measured, 35) << view;
    EXPECT_GE(predicted, 35) << view;
    EXPECT_GE(measured, predicted - 0.5) << view;
    EXPECT_LE(t["measured"]["pixels"].get<int>(), b["measured"]["pixels"].get<int>()) << view;
  }

  // The building's pseudo-albedos, where the photos saw it lit and shaded: the 5% of
  // the base colour per block and channel, with the trees (within 1.5% here), but for the clay
  // roof's sky + environment albedo in red, +6.8% here (+5.0% in green), as on the hall
  // world's roof: printed, asserted within 10%.
  for (const light_passes::BlockAlbedo& a : light_passes::BlockAlbedos(Data(), trees.scene, true)) {
    EXPECT_NEAR(a.rho_sun / a.base, 1.0, 0.05) << a.block << " " << a.channel;
    EXPECT_NEAR(a.rho_se / a.base, 1.0, a.block == "roof" ? 0.10 : 0.05)
        << a.block << " " << a.channel;
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
