#include "pipeline/scene.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <system_error>
#include <utility>

#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/outputs.h"
#include "core/solar.h"
#include "core/temporaries.h"
#include "core/version.h"
#include "pipeline/solve_controller.h"

namespace rouen {
namespace fs = std::filesystem;
namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

// "<out>.tmp-<pid><suffix>", beside `out` (core/temporaries.h removes it on a signal).
fs::path SiblingTemporary(const fs::path& out, const std::string& suffix = "") {
  return out.parent_path() /
         (out.filename().string() + ".tmp-" + std::to_string(::getpid()) + suffix);
}

}  // namespace

void CheckSceneOutput(const fs::path& out, const fs::path& session) {
  if (!session.empty() && !out.filename().empty()) {
    if (IsWithin(out, session))
      throw Error(out.string() + ": lies inside the session " + session.string() +
                  ", whose files the solve reads; write the scene beside the session");
    if (IsWithin(session, out))
      throw Error(out.string() + ": holds the session " + session.string() +
                  "; write the scene beside the session");
  }
  CheckReplaceableFolder(out.string(), out, "scene.json", "scene");
  std::error_code ec;
  if (session.empty() || !fs::is_regular_file(out / "scene.json", ec)) return;
  std::string from;
  try {
    const nlohmann::json j = nlohmann::json::parse(ReadFileToString(out / "scene.json"));
    from = j.at("provenance").value("session", "");
  } catch (const std::exception&) {
    return;  // an unreadable scene is solved again and replaced
  }
  if (!from.empty() && fs::is_directory(from, ec) && !fs::equivalent(from, session, ec))
    throw Error(out.string() + ": is the scene of another session (" + from +
                "); give a new folder, or remove it first");
}

nlohmann::json SolveOptionsJson(const PipelineOptions& options) {
  std::vector<int> holdout = options.exclude_albedo_slots;
  std::sort(holdout.begin(), holdout.end());
  holdout.erase(std::unique(holdout.begin(), holdout.end()), holdout.end());
  nlohmann::json j = {{"holdout_slots", holdout}, {"config", SolveConfigJson(options.config)}};
  j["response"] = options.response ? nlohmann::json(*options.response) : nlohmann::json(nullptr);
  return j;
}

std::string SolveInputsSha256(const Session& session, const PipelineOptions& options) {
  return Sha256Hex(std::string("rouen ") + RouenVersion() + "\n" +
                   SolveOptionsJson(options).dump() + "\n" + SessionFilesStamp(session));
}

SceneSolve SolveToScene(const Session& session, const PipelineOptions& options, const fs::path& out,
                        bool force) {
  CheckSceneOutput(out, session.dir());
  SceneSolve result;
  result.inputs_sha256 = SolveInputsSha256(session, options);
  std::error_code ec;
  if (!force && fs::is_regular_file(out / "scene.json", ec)) {
    try {
      const nlohmann::json j = nlohmann::json::parse(ReadFileToString(out / "scene.json"));
      if (j.contains("provenance") &&
          j["provenance"].value("inputs_sha256", "") == result.inputs_sha256) {
        Log(options.log, out.string() +
                             " is up to date: solved from the same session files, "
                             "model and options; nothing to do");
        result.up_to_date = true;
        return result;
      }
    } catch (const nlohmann::json::exception&) {
      // An unreadable scene is solved again and replaced.
    }
  }
  const CalibResult calib = CalibrateSession(session, options);
  result.solved = SolveSession(session, calib, options);
  const SolveResult& solved = result.solved;

  SceneModel scene;
  scene.site = SessionSite(session);
  scene.response = calib.response;
  scene.grid_options = solved.grid_options;
  scene.ground = options.config.ground;
  scene.hemisphere = options.config.hemisphere;
  for (const SlotSolve& s : solved.slots)
    scene.slots.push_back(SlotModel::FromLighting(s.lighting));
  scene.albedo = solved.albedo;
  scene.env_ground_retro = solved.env_ground_retro;
  scene.env_stereo = solved.env_stereo;
  scene.env_stereo_slots = solved.env_stereo_slots;
  scene.ground_field = solved.ground_field;
  scene.model_file = "model.obj";
  if (!session.info().surroundings.empty()) scene.surroundings_file = "surroundings.obj";
  for (const auto& [name, g] : calib.groups)
    scene.views[name] = SceneView{g.slot, TargetName(g.target), g.utc, g.intrinsics, g.pose};
  scene.holdout_slots = options.exclude_albedo_slots;
  scene.inputs_sha256 = result.inputs_sha256;
  scene.session_dir = fs::absolute(session.dir(), ec).lexically_normal().string();
  scene.rouen_version = RouenVersion();
  scene.options = SolveOptionsJson(options);
  result.stages = calib.stages;
  result.stages.insert(result.stages.end(), solved.stages.begin(), solved.stages.end());
  scene.timings = nlohmann::json::array();
  for (const StageTime& t : result.stages)
    scene.timings.push_back({{"stage", t.stage}, {"seconds", t.seconds}});
  const auto write_start = std::chrono::steady_clock::now();

  const fs::path tmp = SiblingTemporary(out);
  fs::remove_all(tmp, ec);
  WatchForTemporaries(out.parent_path().empty() ? fs::path(".") : out.parent_path());
  try {
    fs::create_directories(tmp);
    // The session's model file itself, byte for byte: the grid is rebuilt from it.
    WriteFileAtomic(tmp / scene.model_file,
                    ReadFileToString(ResolveInside(session.dir(), session.info().model)));
    if (!scene.surroundings_file.empty()) {
      WriteFileAtomic(tmp / scene.surroundings_file,
                      ReadFileToString(ResolveInside(session.dir(), session.info().surroundings)));
    }
    WriteScene(tmp, scene);
    ReadScene(tmp);  // what render will read: whole and consistent
    FsyncDirectory(tmp);
    if (fs::exists(out)) {
      const fs::path old = SiblingTemporary(out, "-old");
      fs::rename(out, old);
      fs::rename(tmp, out);
      fs::remove_all(old);
    } else {
      fs::rename(tmp, out);
    }
    FsyncDirectory(out.parent_path().empty() ? fs::path(".") : out.parent_path());
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(tmp, ec);
    throw Error(out.string() + ": cannot write the scene: " + e.code().message());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  result.stages.push_back(
      {"write the scene",
       std::chrono::duration<double>(std::chrono::steady_clock::now() - write_start).count()});
  if (options.log) options.log("wrote " + out.string());
  return result;
}

SolveConfig RequestedSolveConfig(const SolveFolderRequest& request, const SessionInfo& info,
                                 const std::string& session_json) {
  SolveConfig config = SessionSolveConfig(info, session_json, request.quick);
  if (!request.config_file.empty()) config = ReadSolveConfigFile(request.config_file, config);
  if (!request.config_overrides.empty())
    config = ApplySolveConfig(request.config_overrides, config, "the options given");
  return config;
}

SceneSolve SolveSessionFolder(const SolveFolderRequest& request) {
  fs::path out = request.out.lexically_normal();
  if (!out.has_filename()) out = out.parent_path();  // "s.scene/" -> "s.scene"
  fs::path session_dir = request.session.lexically_normal();
  if (!session_dir.has_filename()) session_dir = session_dir.parent_path();
  CheckSceneOutput(out, session_dir);
  const fs::path work = request.work.empty() ? fs::path(out.string() + ".work") : request.work;
  const bool work_inside = IsWithin(work, session_dir);
  if (work_inside || IsWithin(session_dir, work))
    throw Error((request.work.empty() ? "the working folder " : "--work ") + work.string() +
                (work_inside ? ": lies inside the session " : ": holds the session ") +
                session_dir.string() + ", whose files the solve reads; give a folder beside it");
  CheckWritableFolder(request.work.empty() ? "the working folder" : "--work", work.string());
  // The user's options are checked before the session is read.
  RequestedSolveConfig(request, SessionInfo{}, "the defaults");

  const Session session = Session::Load(session_dir);
  // What the solve reads besides the frames, checked before the long work.
  CheckSessionFrames(session);
  const Site site = SessionSite(session);
  const std::vector<std::optional<UtcTime>> times = SlotTimes(session.frames());
  for (size_t k = 0; k < times.size(); ++k)
    if (times[k])
      Require(NightSlotProblem(static_cast<int>(k), *times[k], site), session_dir.string());
  const Mesh model = ReadSessionModel(session);
  int nslots = 0;
  for (const FrameRecord& f : session.frames()) nslots = std::max(nslots, f.slot + 1);
  for (int h : request.holdout_slots)
    if (h < 0 || h >= nslots)
      throw Error("held-out slot " + std::to_string(h) + ": " + session_dir.string() +
                  " has slots 0.." + std::to_string(nslots - 1));

  PipelineOptions po;
  po.config =
      RequestedSolveConfig(request, session.info(), (session_dir / "session.json").string());
  // A grid spacing for a block the model does not have is a mistake (a misspelt block), not a
  // choice to ignore; the defaults' own entries and the modelled ground's block excepted.
  const SolveConfig defaults = DefaultSolveConfig(request.quick);
  for (const auto& [block, spacing] : po.config.grid.block_spacing_m) {
    if (defaults.grid.block_spacing_m.count(block) ||
        (po.config.ground.radius_m > 0 && block == po.config.ground.block) ||
        std::count(model.block_names.begin(), model.block_names.end(), block))
      continue;
    std::string names;
    for (const std::string& b : model.block_names) names += (names.empty() ? "" : ", ") + b;
    throw Error("grid.block_spacing_m." + block + ": the model (" +
                (session_dir / session.info().model).string() + ") has no block '" + block +
                "'; its blocks: " + names);
  }
  po.work_dir = work;
  po.exclude_albedo_slots = request.holdout_slots;
  po.log = request.log;
  po.progress = request.progress;
  po.cancel = request.cancel;
  return SolveToScene(session, po, out, request.force);
}

LoadedScene LoadScene(const fs::path& dir, const std::function<void(const std::string&)>& log) {
  LoadedScene r;
  r.dir = dir;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(dir.string() + ": no such scene folder (rouen solve writes one)");
  r.scene = ReadScene(dir, &r.solved.mesh, &r.solved.grid);
  r.config = SceneSolveConfig(r.scene, (dir / "scene.json").string());
  r.solved.albedo_options = r.config.albedo;
  r.solved.surrounding_blocks = r.scene.surrounding_blocks;
  r.solved.grid_options = r.scene.grid_options;
  r.solved.caster = std::make_unique<RayCaster>(r.solved.mesh);
  r.solved.hemisphere = BuildHemisphereCache(r.solved.grid, *r.solved.caster, r.scene.hemisphere);
  r.solved.albedo = std::move(r.scene.albedo);
  r.solved.env_ground_retro = r.scene.env_ground_retro;
  r.solved.env_stereo = std::move(r.scene.env_stereo);
  r.solved.env_stereo_slots = r.scene.env_stereo_slots;
  r.solved.ground_field = r.scene.ground_field;
  r.scene.env_stereo.reset();
  r.scene.albedo = AlbedoResult{};
  for (size_t s = 0; s < r.scene.slots.size(); ++s) {
    SlotSolve ss;
    ss.slot = static_cast<int>(s);
    ss.utc = r.scene.slots[s].utc;
    ss.sun = ComputeSunPosition(ss.utc, r.scene.site);
    ss.lighting = r.scene.slots[s].ToLighting();
    ss.lighting.ground = r.solved.ground_field;
    r.solved.slots.push_back(std::move(ss));
  }
  Log(log, "scene " + dir.string() + ": " + std::to_string(r.solved.slots.size()) + " slots, " +
               std::to_string(r.solved.grid.size()) + " grid points, " +
               std::to_string(r.scene.views.size()) + " views");
  return r;
}

}  // namespace rouen
