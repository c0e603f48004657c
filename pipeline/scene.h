// The solved scene as a stage: `rouen solve` calibrates and solves a session once and writes
// its scene folder (solve/scene.h); render and every later command read that folder and never
// solve again.
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/session.h"
#include "core/time.h"
#include "pipeline/session_solve.h"
#include "solve/relight.h"
#include "solve/scene.h"

namespace rouen {

// Checks, before any work, that `out` can become a scene folder: it does not exist, or is an
// earlier scene (it holds scene.json) that a complete new one will replace. With `session` (the
// session folder solved into it), also that `out` neither lies inside the session (its
// outputs would become its inputs) nor holds it, and that an earlier scene there is not
// another session's (scene.json's provenance.session, a folder that still exists). Throws
// rouen::Error naming `out`.
void CheckSceneOutput(const std::filesystem::path& out, const std::filesystem::path& session = {});

// The solve's options as the scene records them (and as its inputs hash covers them): those
// that change the result, not where intermediate files go or how progress is told.
nlohmann::json SolveOptionsJson(const PipelineOptions& options);

// One hash of everything a solve of `session` with `options` reads: every file in the session
// folder (path, size and modification time: the journal holds each frame's sha256, and a file
// changed behind it changes its time), the options and rouen's version. Throws rouen::Error
// naming a file that cannot be read.
std::string SolveInputsSha256(const Session& session, const PipelineOptions& options);

struct SceneSolve {
  bool up_to_date = false;  // `out` was already solved from the same inputs: nothing was done
  SolveResult solved;       // empty when up_to_date
  std::string inputs_sha256;
  std::vector<StageTime> stages;  // calibration, solve and writing the scene, in order
};

// Calibrates and solves `session` (CalibrateSession, then SolveSession with
// options.exclude_albedo_slots held out) and writes the scene folder `out`: the folder is built
// as "<out>.tmp-<pid>" and renamed into place only when whole, so an error or a crash leaves
// the earlier scene (or none), never half of one. When `out` already holds a scene solved from
// the same inputs (SolveInputsSha256) it does nothing and says so, unless `force`.
SceneSolve SolveToScene(const Session& session, const PipelineOptions& options,
                        const std::filesystem::path& out, bool force = false);

// A whole `rouen solve` from folders: what the CLI and the Python bindings both call.
struct SolveFolderRequest {
  std::filesystem::path session;   // session folder (rouen capture / rouen import)
  std::filesystem::path out;       // scene folder: new, or an earlier scene
  std::filesystem::path work;      // calib/ goes here; empty: "<out>.work"
  std::vector<int> holdout_slots;  // slots whose architecture photos the albedos leave out
  // The options: the defaults (quick: fewer samples), then the session's own
  // (SessionSolveConfig), then `config_file` (TOML), then `config_overrides` (JSON, keyed the
  // same way), each setting the keys it names.
  bool quick = false;
  std::string config_file;
  nlohmann::json config_overrides = nlohmann::json::object();
  bool force = false;                               // solve even when `out` is up to date
  std::function<void(const std::string&)> log;      // what each stage found, as lines
  std::function<void(const SolveEvent&)> progress;  // each solve stage's start, progress, end
  // Stops the solve (Cancelled) when requested, within a few milliseconds of work; the scene
  // is then left as it was (not owned; null: the solve runs to its end).
  const Cancellation* cancel = nullptr;
};

// The options a request solves its session with (see SolveFolderRequest). Throws rouen::Error
// naming the file or key at fault.
SolveConfig RequestedSolveConfig(const SolveFolderRequest& request, const SessionInfo& info,
                                 const std::string& session_json);

// Checks every input before the long work (the output and work folders, the options, each
// frame record, the site, the model, the held-out slots against the session's), then
// SolveToScene. Throws rouen::Error naming the folder, file, key or slot that is wrong.
SceneSolve SolveSessionFolder(const SolveFolderRequest& request);

// A scene folder read back, ready to render: the model, its grid and visibility pattern
// rebuilt from the recorded options, each slot's lighting, the albedos, the views' cameras.
struct LoadedScene {
  std::filesystem::path dir;
  SceneModel scene;    // site, response, views, held-out slots (its albedo moved to `solved`)
  SolveResult solved;  // mesh, grid, caster, hemisphere, slots' lighting and times, albedo
  SolveConfig config;  // the options the scene was solved with
};
// Throws rouen::Error naming the file when the folder is not a whole, consistent scene.
LoadedScene LoadScene(const std::filesystem::path& dir,
                      const std::function<void(const std::string&)>& log = {});

}  // namespace rouen
