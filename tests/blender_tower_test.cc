// rouen on a world photographed only from the ground: tests/data/blender_tower holds Cycles
// renders of an 82 m campanile with an open belfry, one panorama per time at eye height 30 m
// south of it (the landscape and the sky photo at once), a telephoto sun frame, three views
// 100 m out, and beside each view Cycles' Diffuse Direct and Indirect light passes: the true
// irradiance of every pixel's surface (see its README.md and gen.py).
//
// The user's path (import, status, solve, validate) and, term by term, rouen's irradiance at
// its grid points against Cycles' passes per block and time.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/camera.h"
#include "core/files.h"
#include "core/image.h"
#include "core/stats.h"
#include "pipeline/scene.h"
#include "pipeline/session_solve.h"
#include "solve/grid.h"
#include "solve/retro.h"
#include "solve/scene.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;

fs::path Data() { return fs::path(ROUEN_SOURCE_DIR) / "tests/data/blender_tower"; }

nlohmann::json Truth() { return nlohmann::json::parse(ReadFileToString(Data() / "truth.json")); }

std::string SiteArg(const nlohmann::json& truth) {
  const nlohmann::json& site = truth["site"];
  return std::to_string(site["lat_deg"].get<double>()) + "," +
         std::to_string(site["lon_deg"].get<double>()) + "," +
         std::to_string(site["height_m"].get<double>());
}

// One import and one default solve (held-out slot kept out of the albedos) for every test here.
class BlenderTowerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(cli_test::TempDir("blender_tower"));
    const nlohmann::json truth = Truth();
    Result r = RunRouen("import --photos " + Q(Data()) + " --list " + Q(Data() / "list.txt") +
                        " --cameras " + Q(Data() / "cameras.json") + " --site " + SiteArg(truth) +
                        " --model " + Q(Data() / "building.obj") + " --sky-mask auto --out " +
                        Q(Session()));
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

// Burley's diffuse factor for roughness r, Cycles' Principled diffuse ("Physically Based Shading
// at Disney", 2012): (1 + (F - 1)(1 - n.l)^5)(1 + (F - 1)(1 - n.v)^5), F = 1/2 + 2 r (l.h)^2.
double Burley(double r, const Eigen::Vector3d& n, const Eigen::Vector3d& l,
              const Eigen::Vector3d& v) {
  const double nl = std::max(0.0, n.dot(l)), nv = std::max(0.0, n.dot(v));
  const Eigen::Vector3d h = (l + v).normalized();
  const double f = 0.5 + 2 * r * std::pow(l.dot(h), 2);
  return (1 + (f - 1) * std::pow(1 - nl, 5)) * (1 + (f - 1) * std::pow(1 - nv, 5));
}

// Sums over a set of visible grid points: Cycles' passes x pi and rouen's terms in the same
// units (the block's Burley factor for the sun, its ambient factor for the rest).
struct TermSums {
  int points = 0;
  Eigen::Vector3d truth_direct = Eigen::Vector3d::Zero(), truth_indirect = Eigen::Vector3d::Zero();
  Eigen::Vector3d sun = Eigen::Vector3d::Zero(), sky = Eigen::Vector3d::Zero(),
                  env = Eigen::Vector3d::Zero(), bounce = Eigen::Vector3d::Zero();
  void Add(const TermSums& o) {
    points += o.points;
    truth_direct += o.truth_direct;
    truth_indirect += o.truth_indirect;
    sun += o.sun;
    sky += o.sky;
    env += o.env;
    bounce += o.bounce;
  }
  // rouen / Cycles per channel: all the light (sun, sky, environment, interreflection
  // against Diffuse Direct + Indirect), and the sun and sky against the direct light alone.
  // rouen's sky is what arrives from above the horizon, the landscape photographed there
  // included, which Cycles counts as indirect: only the total compares like with like.
  Eigen::Vector3d TotalRatio() const {
    return (sun + sky + env + bounce).cwiseQuotient(truth_direct + truth_indirect);
  }
  Eigen::Vector3d DirectRatio() const { return (sun + sky).cwiseQuotient(truth_direct); }
  Eigen::Vector3d Share(const Eigen::Vector3d& term) const {
    return term.cwiseQuotient(sun + sky + env + bounce);
  }
};

std::string Rgb(const Eigen::Vector3d& v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.3f %.3f %.3f", v.x(), v.y(), v.z());
  return b;
}

// The grid points each view sees whole (the pixel they project to and its 8 neighbours hit
// the point's face, the centre within 3 pixel footprints of it), with Cycles' light at that
// pixel and rouen's terms under `irr` (and `sky`: the same lighting with nothing below the
// horizon), summed per block and lit state: index 2 block + 1 where the sun does not reach.
std::vector<TermSums> SumTerms(const LoadedScene& sc, const SceneView& view, const Image& dd,
                               const Image& di, const SlotIrradiance& irr,
                               const SlotIrradiance& sky, const Eigen::Vector3d& sun_dir,
                               const std::vector<double>& roughness) {
  const SolveResult& s = sc.solved;
  const RayCaster& caster = *s.caster;
  const Intrinsics& k = view.intrinsics;
  std::vector<TermSums> out(2 * s.mesh.block_names.size());
  // The block a pixel's ray meets, -1 for none or a face not in the plane of `normal` (a pixel
  // across a corner sees two faces of one block, one of them perhaps sunlit).
  auto block_at = [&](double x, double y, const Eigen::Vector3d& normal, double* t) {
    const Eigen::Vector3d d = view.pose.rotation * Unproject(k, Eigen::Vector2d(x, y));
    const RayHit h = caster.Intersect(view.pose.position, d);
    if (t) *t = h.t;
    if (!h.hit || s.mesh.Normal(h.triangle).dot(normal) < 0.999) return -1;
    return s.mesh.triangle_block[h.triangle];
  };
  for (int i = 0; i < s.grid.size(); ++i) {
    const GridPoint& p = s.grid.points[i];
    const auto px = Project(k, view.pose.WorldToCamera(p.position));
    if (!px) continue;
    const int x = static_cast<int>(std::floor(px->x())), y = static_cast<int>(std::floor(px->y()));
    if (x < 1 || y < 1 || x >= k.width - 1 || y >= k.height - 1) continue;
    const double dist = (p.position - view.pose.position).norm();
    double t = 0;
    if (block_at(x + 0.5, y + 0.5, p.normal, &t) != p.block) continue;
    if (std::abs(t - dist) >
        3 * dist / k.fx /
            std::max(0.2, std::abs((view.pose.position - p.position).normalized().dot(p.normal))))
      continue;
    bool whole = true;
    for (int dy = -1; dy <= 1 && whole; ++dy)
      for (int dx = -1; dx <= 1 && whole; ++dx)
        whole = block_at(x + dx + 0.5, y + dy + 0.5, p.normal, nullptr) == p.block;
    if (!whole) continue;
    const Eigen::Vector3d v = (view.pose.position - p.position).normalized();
    const double r = roughness[p.block];
    const double d_sun = irr.sun[i].maxCoeff() > 0 ? Burley(r, p.normal, sun_dir, v) : 0;
    const double a = AmbientRetroFactor(r, p.normal, v);
    TermSums& o = out[2 * p.block + (irr.sun[i].maxCoeff() > 0 ? 0 : 1)];

    ++o.points;
    for (int c = 0; c < 3; ++c) {
      o.truth_direct[c] += kPi * dd.at(x, y, c);
      o.truth_indirect[c] += kPi * di.at(x, y, c);
    }
    o.sun += irr.sun[i] * d_sun;
    o.sky += sky.direct_se[i] * a;
    o.env += (irr.direct_se[i] - sky.direct_se[i]) * a;
    o.bounce += (irr.se[i] - irr.direct_se[i]) * a;
  }
  return out;
}

// rouen's irradiance at the grid points the views see, term by term, against Cycles' Diffuse
// Direct and Indirect passes, under each slot's measured lighting of the scene in `scene_dir`
// (`predicted`: the lighting predicted for the slot's time from the other slots, §5):
// keyed "<slot> <block> sunlit|shaded" and "all <block> sunlit|shaded" (pooled over the slots),
// each printed. Fails the calling test (gtest) on a missing pass or camera.
std::map<std::string, TermSums> TermTable(const fs::path& scene_dir, bool predicted = false) {
  const nlohmann::json truth = Truth();
  const LoadedScene sc = LoadScene(scene_dir);
  const SolveResult& s = sc.solved;
  const nlohmann::json cams = nlohmann::json::parse(ReadFileToString(Data() / "cameras.json"));
  // Each block's Principled roughness (Burley's r): matte 1, the glossy roof 0.35.
  std::vector<double> roughness;
  for (const std::string& b : s.mesh.block_names)
    roughness.push_back(truth["blocks"][b]["roughness"].get<double>());
  std::map<std::string, TermSums> table;
  for (const nlohmann::json& t : truth["times"]) {
    const int slot = t["slot"].get<int>();
    RenderRequest request;
    request.time = s.slots[slot].utc;
    request.predict_without_slots = {slot};
    request.intrinsics = FindView(sc, "").intrinsics;  // checked, not used for the lighting
    request.pose = FindView(sc, "").pose;
    const Lighting lighting = predicted ? RequestedLighting(sc, request) : s.slots[slot].lighting;
    const std::vector<SlotIrradiance> irr = IrradianceFor(s, {lighting, lighting.SkyOnly()});
    std::vector<TermSums> slot_sums(2 * s.mesh.block_names.size());
    for (const auto& [name, view] : sc.scene.views) {
      if (view.slot != slot || view.target != "architecture") continue;
      // The view's group: the camera of cameras.json at the same place.
      std::string group;
      for (const auto& [key, cam] : cams.items()) {
        if (key.rfind("group=", 0) != 0) continue;
        const Eigen::Vector3d at(cam["pose"]["position"][0].get<double>(),
                                 cam["pose"]["position"][1].get<double>(),
                                 cam["pose"]["position"][2].get<double>());
        if ((at - view.pose.position).norm() < 1e-3) group = key.substr(6);
      }
      EXPECT_FALSE(group.empty()) << name;
      std::string stem = "t";
      stem += std::to_string(slot) + "_" + group;
      const Image dd = ReadImage((Data() / "passes" / (stem + "_diffdir.exr")).string());
      const Image di = ReadImage((Data() / "passes" / (stem + "_diffind.exr")).string());
      EXPECT_EQ(dd.width, view.intrinsics.width);
      EXPECT_EQ(di.height, view.intrinsics.height);
      const std::vector<TermSums> sums =
          SumTerms(sc, view, dd, di, irr[0], irr[1], lighting.sun_dir, roughness);
      for (size_t b = 0; b < sums.size(); ++b) slot_sums[b].Add(sums[b]);
    }
    for (size_t b = 0; b < slot_sums.size(); ++b) {
      const TermSums& m = slot_sums[b];
      if (m.points == 0) continue;
      std::string block = s.mesh.block_names[b / 2];
      block += b % 2 ? " shaded" : " sunlit";
      std::string key = std::to_string(slot);
      key += " ";
      table[key + block] = m;
      table["all " + block].Add(m);
      std::cout << (predicted ? "predicted, " : "") << "slot " << slot << " " << block << " ("
                << m.points << " points): all light rouen/Cycles " << Rgb(m.TotalRatio())
                << "; rouen's sky, environment, interreflection shares " << Rgb(m.Share(m.sky))
                << ", " << Rgb(m.Share(m.env)) << ", " << Rgb(m.Share(m.bounce))
                << "; Cycles' indirect share "
                << Rgb(m.truth_indirect.cwiseQuotient(m.truth_direct + m.truth_indirect)) << "\n";
    }
  }
  for (const auto& [key, m] : table) {
    if (key.rfind("all ", 0) == 0)
      std::cout << (predicted ? "predicted, " : "") << key << ": all light " << Rgb(m.TotalRatio())
                << ", direct light " << Rgb(m.DirectRatio()) << "\n";
  }
  return table;
}

// The default solve's irradiance against Cycles' light passes.
TEST_F(BlenderTowerTest, IrradianceTermsAgainstCyclesLightPasses) {
  const nlohmann::json truth = Truth();
  const std::map<std::string, TermSums> table = TermTable(Scene());
  TermTable(Scene(), true);  // printed: what the prediction adds
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
      // median (the bars; 39.3-41.6 dB, 1.4-1.7% here. Before the sky fit weighed its
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
  Mesh mesh;
  SurfaceGrid grid;
  const SceneModel model = ReadScene(Scene(), &mesh, &grid);
  for (size_t b = 0; b < mesh.block_names.size(); ++b) {
    const nlohmann::json& t = truth["blocks"][mesh.block_names[b]];
    for (int c = 0; c < 3; ++c) {
      std::vector<double> sun, se;
      for (size_t i = 0; i < grid.points.size(); ++i) {
        if (grid.points[i].block != static_cast<int>(b) || model.albedo.observations[i] == 0)
          continue;
        sun.push_back(model.albedo.rho_sun[i][c]);
        se.push_back(model.albedo.rho_se[i][c]);
      }
      ASSERT_GT(sun.size(), 100u);
      const double want = t["base_color"][c].get<double>();
      const double rho_sun = Median(sun), rho_se = Median(se);
      std::cout << mesh.block_names[b] << " channel " << c << ": base colour " << want
                << ", median rho_sun " << rho_sun << ", rho_se " << rho_se << "\n";
      if (!t["glossy"].get<bool>()) {
        EXPECT_NEAR(rho_sun / want, 1.0, 0.05) << mesh.block_names[b] << " " << c;
      }
    }
  }
}

// The ground as a light field ([ground_field] enabled): the panorama's ground re-projected and
// seen from where each point stands. On the shaft's shaded faces -- the light the issue is
// about -- the default overestimates red by 7-9% at every time (the rough ground is brighter
// seen from the panorama at grazing angles than from the wall); the field brings every time
// within 4% per channel.
TEST_F(BlenderTowerTest, GroundFieldSeesTheGroundFromTheWall) {
  const fs::path config = *dir_ / "field.toml";
  WriteFileAtomic(config, "[ground_field]\nenabled = true\n");
  const fs::path scene = *dir_ / "scene_field";
  const Result r = RunRouen("solve " + Q(Session()) + " --out " + Q(scene) +
                            " --holdout-slot 4 --config " + Q(config));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("ground field:"), std::string::npos) << r.out;
  const std::map<std::string, TermSums> with = TermTable(scene);
  const std::map<std::string, TermSums> without = TermTable(Scene());
  for (int slot = 0; slot < 5; ++slot) {
    const std::string key = std::to_string(slot) + " shaft shaded";
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(with.at(key).TotalRatio()[c], 1.0, 0.04) << key;
  }
  EXPECT_LT(std::abs(with.at("all shaft shaded").TotalRatio()[0] - 1),
            std::abs(without.at("all shaft shaded").TotalRatio()[0] - 1));
}

}  // namespace
}  // namespace rouen
