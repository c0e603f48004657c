#include "pipeline/render_scene.h"

#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>
#include <utility>

#include "core/error.h"
#include "core/limits.h"
#include "core/solar.h"
#include "render/render.h"

namespace rouen {
namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

}  // namespace

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
  for (int s : request.predict_without_slots)
    if (s < 0 || s >= nslots)
      throw Error(scene.dir.string() + ": slot " + std::to_string(s) +
                  " (to predict without) is not in the scene");
  request.intrinsics.Validate();
}

LightingPredictor PredictorFor(const LoadedScene& scene, const RenderRequest& request,
                               const std::function<void(const std::string&)>& log) {
  const SolveResult& solved = scene.solved;
  std::vector<int> without = request.predict_without_slots;
  if (!request.use_held_out_lighting)
    without.insert(without.end(), scene.scene.holdout_slots.begin(),
                   scene.scene.holdout_slots.end());
  std::vector<Lighting> measured;
  std::vector<int> measured_slots;
  for (const SlotSolve& ss : solved.slots)
    if (std::find(without.begin(), without.end(), ss.slot) == without.end()) {
      measured.push_back(ss.lighting);
      measured_slots.push_back(ss.slot);
    }
  if (measured.empty())
    throw Error(scene.dir.string() +
                ": no slot is left to predict the lighting from (every slot is held out or left "
                "out)");
  RelightOptions relight = request.relight;
  relight.env = scene.config.env_stereo;               // the options the solve fitted with
  relight.env.ground_retro = solved.env_ground_retro;  // and its ground retro
  // The solve's environment fit when it was made from these slots with these options.
  const EnvStereoResult* fitted =
      FitFor(solved.env_stereo, solved.env_stereo_slots, measured_slots, relight.env);
  Log(log, std::string("fitting the sun's extinction, the sky interpolation") +
               (fitted ? "; the environment's normals as the solve fitted them"
                       : " and the environment's normals") +
               " (" + std::to_string(measured.size()) + " slots)");
  LightingPredictor predictor(std::move(measured), relight, fitted);
  Log(log, predictor.environment().summary.BriefReport());
  return predictor;
}

Lighting RequestedLighting(const LoadedScene& scene, const RenderRequest& request,
                           const std::function<void(const std::string&)>& log) {
  CheckRenderRequest(scene, request);
  if (request.slot) return scene.solved.slots[*request.slot].lighting;
  const LightingPredictor predictor = PredictorFor(scene, request, log);
  RelightSummary rs;
  Lighting lighting = predictor.At(*request.time, scene.scene.site, &rs);
  Log(log, rs.Describe());
  return lighting;
}

std::vector<ImageAttribute> LightingAttributes(const LoadedScene& scene,
                                               const RenderRequest& request,
                                               const Lighting& lighting) {
  std::vector<ImageAttribute> a;
  const UtcTime t = request.slot ? scene.solved.slots.at(*request.slot).utc : *request.time;
  a.push_back({"rouen:time", t.Iso8601(3)});
  if (request.slot) {
    a.push_back({"rouen:lighting", "slot " + std::to_string(*request.slot) + " (measured)"});
    a.push_back({"rouen:slot", *request.slot});
  } else {
    a.push_back({"rouen:lighting", std::string("predicted")});
  }
  double azimuth = 0, elevation = 0;
  AzElFromEnu(lighting.sun_dir.normalized(), &azimuth, &elevation);
  a.push_back({"rouen:sun_azimuth_deg", static_cast<float>(azimuth)});
  a.push_back({"rouen:sun_elevation_deg", static_cast<float>(elevation)});
  const Site& site = scene.scene.site;
  a.push_back({"rouen:site", nlohmann::json({{"lat_deg", site.lat_deg},
                                             {"lon_deg", site.lon_deg},
                                             {"height_m", site.height_m}})
                                 .dump()});
  return a;
}

RenderedView RenderSceneView(const LoadedScene& scene, const RenderRequest& request,
                             const std::function<void(const std::string&)>& log) {
  return RenderSceneViewUnder(scene, request, RequestedLighting(scene, request, log), log);
}

RenderedView RenderSceneViewUnder(const LoadedScene& scene, const RenderRequest& request,
                                  Lighting lighting,
                                  const std::function<void(const std::string&)>& log) {
  RenderedView out;
  out.lighting = std::move(lighting);
  const SolveResult& solved = scene.solved;
  // The direct light exact where the view looks, the rest only for what it bounces there.
  const std::vector<uint8_t> in_view =
      GridPointsInView(solved.grid, *solved.caster, request.intrinsics, request.pose);
  const int64_t seen = std::count(in_view.begin(), in_view.end(), 1);
  Log(log, "irradiance at " + std::to_string(solved.grid.size()) + " grid points (" +
               std::to_string(seen) + " in view)");
  const SlotIrradiance irr = IrradianceFor(solved, out.lighting, &in_view);
  Log(log, "rendering " + std::to_string(request.intrinsics.width) + "x" +
               std::to_string(request.intrinsics.height));
  RenderOptions ro;
  ro.alpha = true;
  out.rgba = RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo, out.lighting, irr,
                        request.intrinsics, request.pose, ro);
  out.rgb = Image(out.rgba.width, out.rgba.height, 3, out.rgba.units);
  for (size_t p = 0; p < static_cast<size_t>(out.rgba.width) * out.rgba.height; ++p)
    for (int c = 0; c < 3; ++c) out.rgb.data[p * 3 + c] = out.rgba.data[p * 4 + c];
  out.attributes = LightingAttributes(scene, request, out.lighting);
  const nlohmann::json camera = {{"intrinsics", request.intrinsics}, {"pose", request.pose}};
  out.attributes.push_back({"rouen:camera", camera.dump()});
  out.attributes.push_back(
      {"rouen:alpha",
       std::string("fraction of the pixel's rays that hit the building; colours keep the sky, "
                   "environment and sun where rays escape")});
  return out;
}

std::vector<SlotIrradiance> IrradianceFor(const SolveResult& solved,
                                          const std::vector<Lighting>& lightings,
                                          const std::vector<uint8_t>* exact) {
  const AlbedoOptions& ao = solved.albedo_options;
  IrradianceOptions io = ao.irradiance;
  io.mesh = &solved.mesh;
  io.exact_points = exact;
  // Where the light comes from matters only to a rough block's reflection.
  io.light_directions = std::any_of(solved.albedo.retro.begin(), solved.albedo.retro.end(),
                                    [](double r) { return r != 0; });
  std::vector<SlotIrradiance> irr =
      ComputeIrradiance(solved.grid, solved.hemisphere, *solved.caster, lightings, io);
  const std::vector<std::shared_ptr<const GroundBounce>> ground =
      GroundBouncesOf(lightings, *solved.caster, solved.grid, solved.hemisphere);
  for (size_t k = 0; k < irr.size(); ++k)
    AddInterreflection(solved.grid, solved.hemisphere, solved.albedo.rho_sun, solved.albedo.rho_se,
                       &irr[k], ao.bounces, solved.albedo.retro, lightings[k].sun_dir, nullptr,
                       nullptr, ground[k].get(), solved.albedo.sun_lobes);
  return irr;
}

SlotIrradiance IrradianceFor(const SolveResult& solved, const Lighting& lighting,
                             const std::vector<uint8_t>* exact) {
  return std::move(IrradianceFor(solved, std::vector<Lighting>{lighting}, exact)[0]);
}

}  // namespace rouen
