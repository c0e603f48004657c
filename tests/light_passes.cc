// rouen's irradiance against Cycles' light passes: see light_passes.h.
#include "tests/light_passes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/camera.h"
#include "core/files.h"
#include "core/image.h"
#include "core/stats.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"
#include "pipeline/session_solve.h"
#include "solve/grid.h"
#include "solve/ground_field.h"
#include "solve/irradiance.h"
#include "solve/retro.h"
#include "solve/scene.h"
#include "tests/cli_util.h"

namespace rouen::light_passes {

namespace fs = std::filesystem;

void TermSums::Add(const TermSums& o) {
  points += o.points;
  truth_direct += o.truth_direct;
  truth_indirect += o.truth_indirect;
  sun += o.sun;
  sky += o.sky;
  env += o.env;
  bounce += o.bounce;
}

Eigen::Vector3d TermSums::TotalRatio() const {
  return (sun + sky + env + bounce).cwiseQuotient(truth_direct + truth_indirect);
}

Eigen::Vector3d TermSums::DirectRatio() const { return (sun + sky).cwiseQuotient(truth_direct); }

Eigen::Vector3d TermSums::Share(const Eigen::Vector3d& term) const {
  return term.cwiseQuotient(sun + sky + env + bounce);
}

namespace {

// Burley's diffuse factor for roughness r, Cycles' Principled diffuse ("Physically Based Shading
// at Disney", 2012): (1 + (F - 1)(1 - n.l)^5)(1 + (F - 1)(1 - n.v)^5), F = 1/2 + 2 r (l.h)^2.
double Burley(double r, const Eigen::Vector3d& n, const Eigen::Vector3d& l,
              const Eigen::Vector3d& v) {
  const double nl = std::max(0.0, n.dot(l)), nv = std::max(0.0, n.dot(v));
  const Eigen::Vector3d h = (l + v).normalized();
  const double f = 0.5 + 2 * r * std::pow(l.dot(h), 2);
  return (1 + (f - 1) * std::pow(1 - nl, 5)) * (1 + (f - 1) * std::pow(1 - nv, 5));
}

std::string Rgb(const Eigen::Vector3d& v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.3f %.3f %.3f", v.x(), v.y(), v.z());
  return b;
}

// The grid points each view sees whole (the pixel they project to and its 8 neighbours hit
// the point's face, the centre within 3 pixel footprints of it), with Cycles' light at that
// pixel and rouen's terms under `irr` (and `sky`: the same lighting with nothing below the
// horizon), summed per block and lit state: index 2 block + 1 where the sun does not reach
// (blocks of negative roughness skipped).
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
    if (r < 0) continue;
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

// The group of cameras.json whose camera stands at `position`; empty when none does.
std::string GroupAt(const nlohmann::json& cams, const Eigen::Vector3d& position) {
  for (const auto& [key, cam] : cams.items()) {
    if (key.rfind("group=", 0) != 0) continue;
    const Eigen::Vector3d at(cam["pose"]["position"][0].get<double>(),
                             cam["pose"]["position"][1].get<double>(),
                             cam["pose"]["position"][2].get<double>());
    if ((at - position).norm() < 1e-3) return key.substr(6);
  }
  return "";
}

}  // namespace

std::map<std::string, TermSums> TermTable(const fs::path& data, const fs::path& scene_dir,
                                          bool predicted) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(data / "truth.json"));
  const LoadedScene sc = LoadScene(scene_dir);
  const SolveResult& s = sc.solved;
  const nlohmann::json cams = nlohmann::json::parse(ReadFileToString(data / "cameras.json"));
  // Each block's Principled roughness (Burley's r): matte 1, a glossy roof 0.35; -1 for the
  // surroundings, never summed.
  std::vector<double> roughness;
  for (const std::string& b : s.mesh.block_names)
    roughness.push_back(truth["blocks"].contains(b) ? truth["blocks"][b]["roughness"].get<double>()
                                                    : -1.0);
  // Every time's lighting and its sky alone, in one pass over the grid (the geometry found once
  // per point for all of them).
  std::vector<Lighting> lightings;
  for (const nlohmann::json& t : truth["times"]) {
    const int slot = t["slot"].get<int>();
    RenderRequest request;
    request.time = s.slots[slot].utc;
    request.predict_without_slots = {slot};
    request.intrinsics = FindView(sc, "").intrinsics;  // checked, not used for the lighting
    request.pose = FindView(sc, "").pose;
    lightings.push_back(predicted ? RequestedLighting(sc, request) : s.slots[slot].lighting);
    lightings.push_back(lightings.back().SkyOnly());
  }
  const std::vector<SlotIrradiance> all_irr = IrradianceFor(s, lightings);
  std::map<std::string, TermSums> table;
  size_t time_index = 0;
  for (const nlohmann::json& t : truth["times"]) {
    const int slot = t["slot"].get<int>();
    const Lighting& lighting = lightings[2 * time_index];
    const SlotIrradiance* irr = &all_irr[2 * time_index];
    ++time_index;
    std::vector<TermSums> slot_sums(2 * s.mesh.block_names.size());
    for (const auto& [name, view] : sc.scene.views) {
      if (view.slot != slot || view.target != "architecture") continue;
      // The view's group: the camera of cameras.json at the same place.
      const std::string group = GroupAt(cams, view.pose.position);
      EXPECT_FALSE(group.empty()) << name;
      std::string stem = "t";
      stem += std::to_string(slot) + "_" + group;
      const Image dd = ReadImage((data / "passes" / (stem + "_diffdir.exr")).string());
      const Image di = ReadImage((data / "passes" / (stem + "_diffind.exr")).string());
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

namespace {

// Per block named in `section` (truth.json's "blocks" or "surroundings") and channel: the base
// colour and the median pseudo-albedos over the block's observed grid points (see BlockAlbedos).
std::vector<BlockAlbedo> AlbedosOf(const nlohmann::json& section, const fs::path& scene_dir,
                                   bool both_lit_and_shaded, const char* what) {
  Mesh mesh;
  SurfaceGrid grid;
  const SceneModel model = ReadScene(scene_dir, &mesh, &grid);
  std::vector<BlockAlbedo> out;
  for (size_t b = 0; b < mesh.block_names.size(); ++b) {
    if (!section.contains(mesh.block_names[b])) continue;
    const nlohmann::json& t = section[mesh.block_names[b]];
    for (int c = 0; c < 3; ++c) {
      std::vector<double> sun, se;
      for (size_t i = 0; i < grid.points.size(); ++i) {
        if (grid.points[i].block != static_cast<int>(b) || model.albedo.observations[i] == 0)
          continue;
        if (both_lit_and_shaded &&
            (model.albedo.flags[i] & (kAlbedoNeverShadowed | kAlbedoSunUnobserved)))
          continue;
        sun.push_back(model.albedo.rho_sun[i][c]);
        se.push_back(model.albedo.rho_se[i][c]);
      }
      BlockAlbedo a{mesh.block_names[b],
                    c,
                    t.value("glossy", false),
                    t["base_color"][c].get<double>(),
                    sun.empty() ? 0.0 : Median(sun),
                    se.empty() ? 0.0 : Median(se),
                    static_cast<int>(sun.size())};
      std::printf(
          "%s %s channel %d%s: base colour %.3f, median rho_sun %.3f, rho_se %.3f over %d "
          "points\n",
          what, a.block.c_str(), c, both_lit_and_shaded ? " (seen lit and shaded)" : "", a.base,
          a.rho_sun, a.rho_se, a.points);
      out.push_back(a);
    }
  }
  return out;
}

}  // namespace

std::vector<BlockAlbedo> BlockAlbedos(const fs::path& data, const fs::path& scene_dir,
                                      bool both_lit_and_shaded) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(data / "truth.json"));
  std::vector<BlockAlbedo> out =
      AlbedosOf(truth["blocks"], scene_dir, both_lit_and_shaded, "block");
  for (const BlockAlbedo& a : out) EXPECT_GT(a.points, 100) << a.block;
  return out;
}

std::vector<BlockAlbedo> SurroundingAlbedos(const fs::path& data, const fs::path& scene_dir) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(data / "truth.json"));
  nlohmann::json in_obj = nlohmann::json::object();
  for (const auto& [name, s] : truth["surroundings"].items())
    if (s.value("in_surroundings_obj", false)) in_obj[name] = s;
  return AlbedosOf(in_obj, scene_dir, false, "surrounding");
}

GroundPrediction GroundBesideWalls(const fs::path& data, const fs::path& scene_dir, int slot) {
  const LoadedScene sc = LoadScene(scene_dir);
  const SolveResult& s = sc.solved;
  GroundPrediction out;
  EXPECT_TRUE(s.ground_field) << scene_dir << " has no ground field";
  if (!s.ground_field) return out;
  const GroundField& f = *s.ground_field;
  const nlohmann::json cams = nlohmann::json::parse(ReadFileToString(data / "cameras.json"));
  const SlotSolve* solve = nullptr;
  for (const SlotSolve& ss : s.slots)
    if (ss.slot == slot) solve = &ss;
  EXPECT_NE(solve, nullptr) << "no slot " << slot;
  if (!solve) return out;
  const Lighting& l = solve->lighting;
  // The field lit then: the sun and the sky (GroundLight), and the walls' light when the field
  // was read with it (from the scene's albedos and that time's irradiance, as the renderer's
  // interreflection has it).
  std::vector<Eigen::Vector3f> walls;
  if (f.walls) {
    const GroundBounce bounce = BuildGroundBounce(f, *s.caster, s.grid, s.hemisphere);
    walls =
        GroundWallsIrradiance(bounce, s.grid, s.albedo.rho_sun, s.albedo.rho_se,
                              IrradianceFor(s, l), s.albedo.retro, l.sun_dir, s.albedo.sun_lobes);
  }
  const GroundLight light(f, *s.caster, l.sun_dir, l.sun_radiance * l.sun_solid_angle_sr,
                          l.env.HorizontalSkyIrradiance());
  Eigen::Vector3d pred[2] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  Eigen::Vector3d meas[2] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  for (const auto& [name, view] : sc.scene.views) {
    if (view.slot != slot || view.target != "landscape") continue;
    const std::string group = GroupAt(cams, view.pose.position);
    EXPECT_FALSE(group.empty()) << name;
    const Image im =
        ReadImage((data / ("t" + std::to_string(slot) + "_" + group + ".exr")).string());
    EXPECT_EQ(im.width, view.intrinsics.width);
    if (im.width != view.intrinsics.width) continue;
    const Eigen::Vector3d o = view.pose.position;
    for (int y = 0; y < im.height; ++y) {
      for (int x = 0; x < im.width; ++x) {
        const Eigen::Vector3d d =
            view.pose.rotation * Unproject(view.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
        if (!(d.z() < 0)) continue;
        const double dist = (o.z() - f.level_z) / -d.z();
        if (s.caster->Occluded(o, d, 0.0, dist - s.caster->surface_offset())) continue;
        const Eigen::Vector3d q = o + dist * d;
        const int c = f.Cell(q.x(), q.y());
        if (c < 0 || !f.observed[c] || !(f.sky_visibility[c] < 0.5)) continue;
        Eigen::Vector3d p = light.Radiance(q, -d);
        if (!walls.empty())
          p += f.Albedo(c).cwiseProduct(walls[c].cast<double>()) *
               (AmbientRetroFactor(f.retro, Eigen::Vector3d::UnitZ(), -d) / kPi);
        const bool shaded = s.caster->Occluded(
            q + Eigen::Vector3d(0, 0, s.caster->surface_offset()), l.sun_dir, 0.0);
        pred[shaded] += p;
        meas[shaded] += Eigen::Vector3d(im.at(x, y, 0), im.at(x, y, 1), im.at(x, y, 2));
        ++(shaded ? out.shaded : out.sunlit);
      }
    }
  }
  out.sunlit_ratio = pred[0].cwiseQuotient(meas[0]);
  out.shaded_ratio = pred[1].cwiseQuotient(meas[1]);
  std::printf(
      "slot %d, ground beside the walls (%s): in shadow (%d pixels) rouen/Cycles %s, in sun "
      "(%d pixels) %s\n",
      slot, scene_dir.filename().string().c_str(), out.shaded, Rgb(out.shaded_ratio).c_str(),
      out.sunlit, Rgb(out.sunlit_ratio).c_str());
  return out;
}

std::string ImportCommand(const fs::path& data) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(data / "truth.json"));
  const nlohmann::json& site = truth["site"];
  return "import --photos " + cli_test::Q(data) + " --list " + cli_test::Q(data / "list.txt") +
         " --cameras " + cli_test::Q(data / "cameras.json") +
         " --site=" + std::to_string(site["lat_deg"].get<double>()) + "," +
         std::to_string(site["lon_deg"].get<double>()) + "," +
         std::to_string(site["height_m"].get<double>()) + " --model " +
         cli_test::Q(data / "building.obj") + " --sky-mask auto";
}

HeldOutRun RunHeldOut(const fs::path& data, const fs::path& dir, const std::string& name,
                      const std::string& import_options, const std::string& solve_options) {
  const nlohmann::json truth = nlohmann::json::parse(ReadFileToString(data / "truth.json"));
  const std::string heldout = std::to_string(truth["heldout_slot"].get<int>());
  HeldOutRun run;
  run.session = dir / (name + "_session");
  run.scene = dir / (name + "_scene");
  cli_test::Result r = cli_test::RunRouen(ImportCommand(data) + import_options + " --out " +
                                          cli_test::Q(run.session));
  run.log += r.out;
  if (r.code != 0) return run;
  r = cli_test::RunRouen("solve " + cli_test::Q(run.session) + " --out " + cli_test::Q(run.scene) +
                         " --holdout-slot " + heldout + solve_options);
  run.log += r.out;
  if (r.code != 0) return run;
  const fs::path json = dir / (name + "_validation.json");
  r = cli_test::RunRouen("validate " + cli_test::Q(run.scene) + " --session " +
                         cli_test::Q(run.session) + " --slot " + heldout + " --json " +
                         cli_test::Q(json));
  run.log += r.out;
  if (r.code == 0) run.validation = nlohmann::json::parse(ReadFileToString(json));
  return run;
}

}  // namespace rouen::light_passes
