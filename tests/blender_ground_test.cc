// The ground as a surface, on a world rouen did not make: tests/data/blender_ground is the
// Blender world of tests/data/blender_world (its README.md and gen.py --ground-patch) with a
// bright patch of ground (base colour 0.60 0.55 0.48 against 0.26 0.23 0.19) north of the
// building, about half of it hidden from the landscape panorama by the tower and the annex. A
// wall facing it is lit mostly by that ground. Read from the panorama's directions, the ground
// in front of the north walls is the dark ground the panorama sees that way, and their
// pseudo-albedos absorb the missing light; modelled as a surface ([ground] radius_m), each wall
// sees the ground in front of it with the albedo the photos give it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/files.h"
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

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_ground"; }

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? NAN : v[v.size() / 2];
}

struct Solved {
  nlohmann::json validation;  // rouen validate --json of the held-out slot
  Mesh mesh;
  SurfaceGrid grid;
  SceneModel model;
  // Median green rho_sun over the observed points of `block` whose normal is `normal` (unit)
  // and, for the ground, inside the plan rectangle [x0, x1] x [y0, y1].
  double MedianAlbedo(const std::string& block, const Eigen::Vector3d& normal, int channel,
                      double x0 = -1e9, double x1 = 1e9, double y0 = -1e9, double y1 = 1e9) const {
    const auto it = std::find(mesh.block_names.begin(), mesh.block_names.end(), block);
    if (it == mesh.block_names.end()) return NAN;
    const int b = static_cast<int>(it - mesh.block_names.begin());
    std::vector<double> v;
    for (size_t i = 0; i < grid.points.size(); ++i) {
      const GridPoint& p = grid.points[i];
      if (p.block != b || model.albedo.observations[i] == 0 || p.normal.dot(normal) < 0.99)
        continue;
      if (p.position.x() < x0 || p.position.x() > x1 || p.position.y() < y0 || p.position.y() > y1)
        continue;
      v.push_back(model.albedo.rho_sun[i][channel]);
    }
    return v.size() < 20 ? NAN : Median(v);
  }
};

Solved SolveAndValidate(const fs::path& dir, const std::string& config) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(Data() / "truth.json"));
  const fs::path session = dir / "session", scene = dir / "scene", toml = dir / "solve.toml";
  Solved out;
  if (!fs::exists(session)) {
    const Result r =
        RunRouen("import --photos " + Q(Data()) + " --list " + Q(Data() / "list.txt") +
                 " --cameras " + Q(Data() / "cameras.json") + " --site 45,7,300 --model " +
                 Q(Data() / "building.obj") + " --out " + Q(session));
    EXPECT_EQ(r.code, 0) << r.out;
  }
  WriteFileAtomic(toml, config);
  const std::string heldout = std::to_string(truth["heldout_slot"].get<int>());
  Result r = RunRouen("solve " + Q(session) + " --out " + Q(scene) + " --holdout-slot " + heldout +
                      " --quick --force --config " + Q(toml));
  EXPECT_EQ(r.code, 0) << r.out;
  const fs::path vjson = dir / "validate.json";
  r = RunRouen("validate " + Q(scene) + " --session " + Q(session) + " --slot " + heldout +
               " --json " + Q(vjson));
  EXPECT_EQ(r.code, 0) << r.out;
  std::cout << r.out;
  if (fs::exists(vjson)) out.validation = nlohmann::json::parse(ReadFileToString(vjson));
  out.model = ReadScene(scene, &out.mesh, &out.grid);
  return out;
}

TEST(BlenderGroundTest, AWallSeesTheGroundInFrontOfItWhenTheGroundIsModelled) {
  ASSERT_TRUE(fs::exists(Data() / "list.txt")) << Data();
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(Data() / "truth.json"));
  const fs::path dir = cli_test::TempDir("blender_ground");
  // Both solves iterate the albedos and the interreflection until they settle (the default
  // outer_tolerance): the modelled ground couples every wall to the ground's albedo.
  const Solved panorama = SolveAndValidate(dir, "");
  const Solved modelled = SolveAndValidate(dir, "[ground]\nradius_m = 30\n");
  ASSERT_TRUE(panorama.validation.contains("measured")) << panorama.validation.dump();
  ASSERT_TRUE(modelled.validation.contains("measured")) << modelled.validation.dump();

  // The modelled ground is a block of the scene but is never scored: the same building pixels.
  EXPECT_NE(std::find(modelled.mesh.block_names.begin(), modelled.mesh.block_names.end(), "ground"),
            modelled.mesh.block_names.end());
  EXPECT_EQ(modelled.validation["measured"]["pixels"], panorama.validation["measured"]["pixels"]);

  // Its albedo from the photos: the patch and the rest of the ground near the colours Blender
  // rendered. They came 4-10% low on the patch (red lowest; the two trees and the shed, not in
  // the model, stand on it and shade it) and 1-2% low elsewhere. The bound catches what would
  // be a fault (the ground's albedo from the wrong pixels, or the ground lit without the sun:
  // off by 2x or more), not the world's unmodelled objects: 20%.
  const nlohmann::json& patch = truth["ground_patch"];
  const double px0 = patch["rect"][0], px1 = patch["rect"][1];
  const double py0 = patch["rect"][2], py1 = patch["rect"][3];
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ(), north = Eigen::Vector3d::UnitY();
  for (int c = 0; c < 3; ++c) {
    const double want = patch["base_color"][c].get<double>();
    const double got = modelled.MedianAlbedo("ground", up, c, px0 + 2, px1 - 2, py0 + 2, py1 - 2);
    EXPECT_NEAR(got / want, 1, 0.20) << "patch channel " << c;
    const double want_g = truth["surroundings"]["ground"]["base_color"][c].get<double>();
    const double got_g = modelled.MedianAlbedo("ground", up, c, -1e9, 1e9, -1e9, py0 - 2);
    EXPECT_NEAR(got_g / want_g, 1, 0.20) << "ground channel " << c;
  }

  // The north walls face the patch. Read from the panorama, they were lit too little and their
  // sun albedos came 21% (tower) and 33% (annex) too bright in green; with the ground modelled,
  // 7% and 10%. The bound: at most half the error of the panorama's ground on each wall.
  for (const std::string block : {"tower", "annex"}) {
    const double want = truth["blocks"][block]["base_color"][1].get<double>();
    const double before = panorama.MedianAlbedo(block, north, 1) / want - 1;
    const double after = modelled.MedianAlbedo(block, north, 1) / want - 1;
    std::cout << block << " north wall, green rho_sun / base colour - 1: panorama's ground "
              << before << ", modelled ground " << after << "\n";
    EXPECT_GT(before, 0.10) << block;  // the test world shows the fault it is for
    EXPECT_LT(std::abs(after), 0.5 * before) << block;
  }

  // And the held-out time: the pooled relative RMSE of both lightings is lower (0.0323 and 0.0313
  // with the panorama's ground, 0.0225 and 0.0218 modelled), within the fidelity issue's bar on
  // every view.
  for (const char* lighting : {"measured", "predicted"}) {
    EXPECT_LT(modelled.validation[lighting]["rel_rmse"].get<double>(),
              0.9 * panorama.validation[lighting]["rel_rmse"].get<double>())
        << lighting;
    for (const nlohmann::json& p : modelled.validation["photos"]) {
      EXPECT_GE(p[lighting]["psnr_db"].get<double>(), 32) << p["view"] << " " << lighting;
      EXPECT_LE(p[lighting]["median_rel_error"].get<double>(), 0.03)
          << p["view"] << " " << lighting;
    }
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
