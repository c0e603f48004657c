#include "pipeline/scene.h"

#include <unistd.h>

#include <memory>
#include <system_error>
#include <utility>

#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/solar.h"
#include "core/temporaries.h"
#include "render/render.h"

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

void CheckSceneOutput(const fs::path& out) {
  std::error_code ec;
  if (out.filename().empty()) throw Error(out.string() + ": a scene folder needs a name");
  if (!fs::exists(out, ec)) {
    const fs::path parent = out.parent_path().empty() ? fs::path(".") : out.parent_path();
    if (!fs::is_directory(parent, ec))
      throw Error(out.string() + ": the folder " + parent.string() + " does not exist");
    return;
  }
  if (!fs::is_directory(out, ec)) throw Error(out.string() + ": exists and is not a folder");
  if (!fs::exists(out / "scene.json", ec) && !fs::is_empty(out, ec))
    throw Error(out.string() +
                ": exists and is not a scene folder (no scene.json); give a new folder");
}

SolveResult SolveToScene(const Session& session, const PipelineOptions& options,
                         const fs::path& out) {
  CheckSceneOutput(out);
  const CalibResult calib = CalibrateSession(session, options);
  SolveResult solved = SolveSession(session, calib, options);

  SceneModel scene;
  scene.site = SessionSite(session);
  scene.response = calib.response;
  scene.grid_options = options.grid;
  scene.hemisphere = options.hemisphere;
  for (const SlotSolve& s : solved.slots)
    scene.slots.push_back(SlotModel::FromLighting(s.lighting));
  scene.albedo = solved.albedo;
  scene.model_file = "model.obj";
  for (const auto& [name, g] : calib.groups)
    scene.views[name] = SceneView{g.slot, TargetName(g.target), g.utc, g.intrinsics, g.pose};
  scene.holdout_slots = options.exclude_albedo_slots;

  const fs::path tmp = SiblingTemporary(out);
  std::error_code ec;
  fs::remove_all(tmp, ec);
  WatchForTemporaries(out.parent_path().empty() ? fs::path(".") : out.parent_path());
  try {
    fs::create_directories(tmp);
    // The session's model file itself, byte for byte: the grid is rebuilt from it.
    WriteFileAtomic(tmp / scene.model_file,
                    ReadFileToString(ResolveInside(session.dir(), session.info().model)));
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
  return solved;
}

LoadedScene LoadScene(const fs::path& dir, const std::function<void(const std::string&)>& log) {
  LoadedScene r;
  r.dir = dir;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(dir.string() + ": no such scene folder (rouen solve writes one)");
  r.scene = ReadScene(dir, &r.solved.mesh, &r.solved.grid);
  r.solved.caster = std::make_unique<RayCaster>(r.solved.mesh);
  r.solved.hemisphere = BuildHemisphereCache(r.solved.grid, *r.solved.caster, r.scene.hemisphere);
  r.solved.albedo = std::move(r.scene.albedo);
  r.scene.albedo = AlbedoResult{};
  for (size_t s = 0; s < r.scene.slots.size(); ++s) {
    SlotSolve ss;
    ss.slot = static_cast<int>(s);
    ss.utc = r.scene.slots[s].utc;
    ss.sun = ComputeSunPosition(ss.utc, r.scene.site);
    ss.lighting = r.scene.slots[s].ToLighting();
    r.solved.slots.push_back(std::move(ss));
  }
  Log(log, "scene " + dir.string() + ": " + std::to_string(r.solved.slots.size()) + " slots, " +
               std::to_string(r.solved.grid.size()) + " grid points, " +
               std::to_string(r.scene.views.size()) + " views");
  return r;
}

const SceneView& FindView(const LoadedScene& scene, const std::string& name) {
  const std::map<std::string, SceneView>& views = scene.scene.views;
  if (name.empty()) {
    for (const auto& [n, v] : views)
      if (v.target == "architecture") return v;
    throw Error(scene.dir.string() + ": the scene has no architecture view; give a camera");
  }
  const auto it = views.find(name);
  if (it != views.end()) return it->second;
  std::string known;
  for (const auto& [n, v] : views)
    if (v.target == "architecture") known += (known.empty() ? "" : ", ") + n;
  throw Error(scene.dir.string() + ": no view named '" + name +
              "' (architecture views: " + (known.empty() ? "none" : known) + ")");
}

void CheckRenderRequest(const LoadedScene& scene, const RenderRequest& request) {
  if (request.slot.has_value() == request.time.has_value())
    throw Error("give exactly one of a captured slot or a time");
  const int nslots = static_cast<int>(scene.solved.slots.size());
  if (request.slot && (*request.slot < 0 || *request.slot >= nslots))
    throw Error(scene.dir.string() + ": slot " + std::to_string(*request.slot) +
                " is not in the scene (it has slots 0.." + std::to_string(nslots - 1) + ")");
  if (request.time) {
    const SunPosition sun = ComputeSunPosition(*request.time, scene.scene.site);
    if (!(sun.elevation_deg > 0))
      throw Error(request.time->Iso8601() + ": the sun is below the horizon there (elevation " +
                  FormatNumber(sun.elevation_deg) + " deg); rouen renders daylight only");
    request.relight.Validate();
  }
  request.intrinsics.Validate();
}

Image RenderScene(const LoadedScene& scene, const RenderRequest& request,
                  const std::function<void(const std::string&)>& log) {
  CheckRenderRequest(scene, request);
  const SolveResult& solved = scene.solved;
  Lighting lighting;
  if (request.slot) {
    lighting = solved.slots[*request.slot].lighting;
  } else {
    std::vector<Lighting> measured;
    for (const SlotSolve& ss : solved.slots) measured.push_back(ss.lighting);
    Log(log, "fitting the sun's extinction, the sky interpolation and the environment's normals");
    LightingPredictor predictor(std::move(measured), request.relight);
    Log(log, predictor.environment().summary.BriefReport());
    RelightSummary rs;
    lighting = predictor.At(*request.time, scene.scene.site, &rs);
    Log(log, rs.Describe());
  }
  Log(log, "irradiance at " + std::to_string(solved.grid.size()) + " grid points");
  const SlotIrradiance irr = IrradianceFor(solved, lighting);
  Log(log, "rendering " + std::to_string(request.intrinsics.width) + "x" +
               std::to_string(request.intrinsics.height));
  return RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo, lighting, irr,
                    request.intrinsics, request.pose, RenderOptions{});
}

}  // namespace rouen
