// rouen solve: a session calibrated and solved once into a scene folder, which render (and
// every later command) reads.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/files.h"
#include "core/session.h"
#include "pipeline/scene.h"

namespace rouen {
namespace {

struct SolveArgs {
  std::string session, out, work, config;
  std::vector<int> holdout;
  bool quick = false, force = false, print_config = false;
};

void Run(const SolveArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  SolveFolderRequest request;
  request.session = a.session;
  request.out = a.out;
  request.work = a.work;
  request.holdout_slots = a.holdout;
  request.quick = a.quick;
  request.config_file = a.config;
  if (a.print_config) {
    // The session's own options when a session is given, else the defaults; then --config.
    SessionInfo info;
    std::string where = "the defaults";
    if (!a.session.empty()) {
      where = (std::filesystem::path(a.session) / "session.json").string();
      info = ParseSessionInfo(ReadFileToString(where), where);
    }
    std::printf("%s\n",
                SolveConfigJson(RequestedSolveConfig(request, info, where)).dump(2).c_str());
    return;
  }
  if (a.session.empty() || a.out.empty())
    throw Error("rouen solve needs a SESSION folder and --out SCENE (see rouen solve --help)");
  request.force = a.force;
  request.log = [](const std::string& s) { std::fprintf(stderr, "solve: %s\n", s.c_str()); };
  request.progress = [](const SolveEvent& e) {
    if (e.fraction == 0)
      std::fprintf(stderr, "solve: stage %d of %d: %s\n", e.index, e.count, e.stage.c_str());
    else if (e.fraction < 1)
      std::fprintf(stderr, "solve: stage %d of %d: %s %.0f%% (%s)\n", e.index, e.count,
                   e.stage.c_str(), 100 * e.fraction, e.message.c_str());
  };
  const SceneSolve r = SolveSessionFolder(request);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (r.up_to_date) {
    std::printf(
        "%s: up to date (session, model and options unchanged); nothing to do (%.1f s; "
        "--force solves again)\n",
        a.out.c_str(), seconds);
    return;
  }
  const SolveResult& solved = r.solved;
  std::printf("%s: %zu slots, %d grid points, %s (%.1f s)\n", a.out.c_str(), solved.slots.size(),
              solved.grid.size(), solved.albedo.summary.BriefReport().c_str(), seconds);
  std::printf("  %-44s %8s\n", "stage", "seconds");
  for (const StageTime& t : r.stages) std::printf("  %-44s %8.2f\n", t.stage.c_str(), t.seconds);
  for (const SlotSolve& s : solved.slots)
    std::printf("  slot %d: sun elevation %.2f deg, sky fit median/p90 error %.4f/%.4f (green)\n",
                s.slot, s.sun.elevation_deg, s.sky_summary.channel[1].rel_error_median,
                s.sky_summary.channel[1].rel_error_p90);
}

}  // namespace

void RegisterSolve(CLI::App& app) {
  auto a = std::make_shared<SolveArgs>();
  CLI::App* c = app.add_subcommand("solve", CommandSummary("solve"));
  c->footer(
      "Recovers the response curve and merges every bracket to radiance (files in --work), then\n"
      "per time of day the sun (§3.1), the sky model (§3.2) and the environment (§3.3), the\n"
      "irradiance at the building's surface grid and its two pseudo-albedos (§4). Writes the\n"
      "scene folder OUT (scene.json, model.obj, albedo_*.exr) whole, replacing an earlier scene\n"
      "only once the new one is complete; `rouen render OUT ...` then renders without solving.\n"
      "When OUT was solved from the same session files (names, sizes, times), model and\n"
      "options by this version of rouen, nothing is done: a workflow engine can run it again.\n"
      "--holdout-slot keeps a time of day's architecture photos out of the albedos, so that\n"
      "renders at that time can be compared with them.\n"
      "Every choice of the solve (grid spacing per block, the sky fit's weighting and norm, the\n"
      "environment's sampling, the albedo and irradiance options, the response's brackets) is\n"
      "an option with a default, recorded in the scene. The session may carry its own (its\n"
      "rig's [solve] table, session.json extra.solve_config); --config FILE.toml then sets any\n"
      "of them with the tables and keys --print-config shows (SESSION --print-config: with the\n"
      "session's own applied), e.g.\n"
      "  [sky_fit]\n  norm_p = 2\n  [grid.block_spacing_m]\n  plaza = 2.0\n"
      "[ground] radius_m = 30 models the ground within 30 m of the building as a surface (block\n"
      "'ground', not scored by rouen validate): its albedo from the photos, lit with the\n"
      "building's shadow, so a wall sees the ground in front of it rather than the ground the\n"
      "panoramas saw in its direction. Off by default.\n"
      "The ground as a light field: the landscape panoramas' ground re-projected onto the level\n"
      "ground around the building (2 m cells, out to 3x its height) as an albedo per cell,\n"
      "pooled over the times; each grid point then sees that ground lit at the time rendered\n"
      "(the building's shadow from the geometry, the rough ground's grazing reflection towards\n"
      "the point, not towards the panorama). The walls around a spot of ground light it too:\n"
      "the field is read again with the light of the walls solved once without it, and the\n"
      "albedos solved again, so a street's ground is its own albedo and the walls light it at\n"
      "any time. On by default when the session has surroundings\n"
      "(import --surroundings), which give the houses' walls a tall building sees below its\n"
      "horizon; [ground_field] enabled = true or false sets it for any session.\n"
      "The sky and environment's light reaches each photographed grid point exactly (App. A's\n"
      "vector flux of the visible regions); [albedo.irradiance] method = \"monte_carlo\" takes\n"
      "the faster, noisier estimate over the hemisphere cache's directions instead.\n"
      "Each sky region of the environment keeps its measured mean but is spread over 4 x 4\n"
      "cells as the sky model times the panoramas' residual against it there, so the structure\n"
      "near the sun and the horizon reaches the walls; [environment] sky_detail = 1 makes the\n"
      "regions uniform, as the paper's map.\n"
      "A glossy block's sun lobe (§4.2.2) is eq. 13's; [albedo.sun_lobe] model = \"microfacet\"\n"
      "fits a microfacet lobe instead (GGX with a dielectric's Fresnel: the glint of a slate or\n"
      "glazed roof seen near grazing), \"auto\" both, keeping the lower cost per block; with\n"
      "ground-level panoramas use it with [ground_field]. The sky lobe is the same lobe (one\n"
      "material) unless the sky's reflection in the photos contradicts it: then the sun lobe is\n"
      "fitted again among those the sky allows ([albedo.sky_lobe] source = \"fit\": the paper's\n"
      "own sky lobe, §4.2.1).\n"
      "A key rouen does not know is an error, not a silent default.\n"
      "Example: rouen solve s --out s.scene --holdout-slot 2");
  c->add_option("session", a->session, "Session folder (from rouen capture or rouen import)");
  c->add_option("--out", a->out, "Scene folder to write (new, or an earlier scene)");
  c->add_option("--holdout-slot", a->holdout,
                "A slot whose architecture photos the albedos do not use (repeatable)")
      ->check(Within(0, kMaxSlot));
  c->add_option("--work", a->work, "Working folder for calib/ (default: OUT.work)");
  c->add_flag("--quick", a->quick, "Fewer samples (faster, rougher)");
  c->add_flag("--force", a->force, "Solve even when OUT is up to date");
  c->add_option("--config", a->config,
                "TOML file overriding the solve's options (rouen solve --print-config lists them)");
  c->add_flag("--print-config", a->print_config,
              "Print every option of the solve with its value (with --quick and --config "
              "applied) as TOML-like JSON, and exit");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
