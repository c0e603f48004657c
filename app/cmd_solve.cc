// rouen solve: a session calibrated and solved once into a scene folder, which render (and
// every later command) reads.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/outputs.h"
#include "pipeline/scene.h"

namespace rouen {
namespace {

struct SolveArgs {
  std::string session, out, work;
  std::vector<int> holdout;
  bool quick = false, force = false;
};

void Run(const SolveArgs& a) {
  namespace fs = std::filesystem;
  const auto start = std::chrono::steady_clock::now();
  // The outputs first, then the session: every mistake is told before any work.
  fs::path out = fs::path(a.out).lexically_normal();
  if (!out.has_filename()) out = out.parent_path();  // "s.scene/" -> "s.scene"
  CheckSceneOutput(out);
  fs::path session_dir = fs::path(a.session).lexically_normal();
  if (!session_dir.has_filename()) session_dir = session_dir.parent_path();
  const fs::path work = a.work.empty() ? fs::path(out.string() + ".work") : fs::path(a.work);
  CheckWritableFolder(a.work.empty() ? "the working folder" : "--work", work.string());

  const Session session = Session::Load(session_dir);
  // What the solve reads besides the frames, checked before the long work.
  CheckSessionFrames(session);
  SessionSite(session);
  ReadSessionModel(session);
  int nslots = 0;
  for (const FrameRecord& f : session.frames()) nslots = std::max(nslots, f.slot + 1);
  for (int h : a.holdout)
    if (h >= nslots)
      throw Error("--holdout-slot " + std::to_string(h) + ": the session has slots 0.." +
                  std::to_string(nslots - 1));

  PipelineOptions po;
  po.work_dir = work;
  po.quick = a.quick;
  po.exclude_albedo_slots = a.holdout;
  po.log = [](const std::string& s) { std::fprintf(stderr, "solve: %s\n", s.c_str()); };
  const SceneSolve r = SolveToScene(session, po, out, a.force);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (r.up_to_date) {
    std::printf(
        "%s: up to date (session, model and options unchanged); nothing to do (%.1f s; "
        "--force solves again)\n",
        out.c_str(), seconds);
    return;
  }
  const SolveResult& solved = r.solved;
  std::printf("%s: %zu slots, %d grid points, %s (%.1f s)\n", out.c_str(), solved.slots.size(),
              solved.grid.size(), solved.albedo.summary.BriefReport().c_str(), seconds);
}

}  // namespace

void RegisterSolve(CLI::App& app) {
  auto a = std::make_shared<SolveArgs>();
  CLI::App* c = app.add_subcommand(
      "solve", "Calibrate and solve a session once; write the scene that render reads");
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
      "Example: rouen solve s --out s.scene --holdout-slot 2");
  c->add_option("session", a->session, "Session folder (from rouen capture or rouen import)")
      ->required();
  c->add_option("--out", a->out, "Scene folder to write (new, or an earlier scene)")->required();
  c->add_option("--holdout-slot", a->holdout,
                "A slot whose architecture photos the albedos do not use (repeatable)")
      ->check(Within(0, 1000));
  c->add_option("--work", a->work, "Working folder for calib/ (default: OUT.work)");
  c->add_flag("--quick", a->quick, "Fewer samples (faster, rougher)");
  c->add_flag("--force", a->force, "Solve even when OUT is up to date");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
