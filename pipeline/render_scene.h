// Rendering a solved scene (§6): what to render (a captured slot's lighting, or lighting
// predicted for a time), the checks before any work, the lighting, and the one path from a
// request to a radiance image with its header, which the CLI, Python, timelapse and export use.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/time.h"
#include "pipeline/scene.h"
#include "solve/irradiance.h"
#include "solve/relight.h"

namespace rouen {

// What to render: the lighting measured at a captured slot, or predicted for another time
// (§5: sun from the site and time, sky interpolated, environment from its normals; §6.3
// overcast through `relight`), seen through a camera.
struct RenderRequest {
  std::optional<int> slot;
  std::optional<UtcTime> time;
  RelightOptions relight;  // used with `time`
  // With `time`: slots whose measured lighting the prediction leaves out (e.g. the slot being
  // validated, so its lighting is predicted from the other times only). The scene's held-out
  // slots are left out too, unless `use_held_out_lighting`: what was held out stays out.
  std::vector<int> predict_without_slots;
  bool use_held_out_lighting = false;
  Intrinsics intrinsics;
  Pose pose;
};

// Irradiance of the solved model's grid under other lighting (a novel time), with the
// interreflection from the recovered albedos, computed as SolveSession computed the slots':
// the direct sky and environment term exact at the points flagged in `exact` (one flag per
// grid point, e.g. render/'s GridPointsInView: the points a view shades), the Monte Carlo
// estimate elsewhere (the light those points send by interreflection); null: exact everywhere.
SlotIrradiance IrradianceFor(const SolveResult& solved, const Lighting& lighting,
                             const std::vector<uint8_t>* exact = nullptr);
// The same for several lightings in one pass over the grid: what depends only on the geometry
// (the vector flux's clipping, the Monte Carlo's escaping directions) is found once per point.
std::vector<SlotIrradiance> IrradianceFor(const SolveResult& solved,
                                          const std::vector<Lighting>& lightings,
                                          const std::vector<uint8_t>* exact = nullptr);

// The camera of the scene's view `name` (e.g. "slot0/architecture/view0"; empty: the first
// architecture view). Throws rouen::Error listing the scene's views when there is no such one.
const SceneView& FindView(const LoadedScene& scene, const std::string& name);

// Checks a request against the scene before any work: exactly one of slot and time, the slot
// is in the scene, the sun is above the horizon at the time, the camera is valid. Throws
// rouen::Error saying what is wrong.
void CheckRenderRequest(const LoadedScene& scene, const RenderRequest& request);

// The predictor of lighting at other times from the scene's slots (less the request's
// predict_without_slots, and the held-out slots unless use_held_out_lighting), with the
// request's relighting options: fitted once, asked for many times (rouen timelapse). The
// environment's stereo is the solve's when it was made from the same slots.
LightingPredictor PredictorFor(const LoadedScene& scene, const RenderRequest& request,
                               const std::function<void(const std::string&)>& log = {});

// The lighting a request asks for: the slot's measured lighting, or the lighting predicted for
// the time from the scene's slots (less `predict_without_slots`).
Lighting RequestedLighting(const LoadedScene& scene, const RenderRequest& request,
                           const std::function<void(const std::string&)>& log = {});

// Header attributes of an image of a scene under the request's lighting: "rouen:time" (ISO 8601
// UTC: the slot's time or the requested one), "rouen:lighting" ("slot N (measured)" or
// "predicted"), "rouen:slot" (with a slot), "rouen:sun_azimuth_deg" (from north through east)
// and "rouen:sun_elevation_deg" of the sun direction the lighting holds, "rouen:site" (JSON).
std::vector<ImageAttribute> LightingAttributes(const LoadedScene& scene,
                                               const RenderRequest& request,
                                               const Lighting& lighting);

struct RenderedView {
  Image rgba;  // radiance and alpha (the fraction of the pixel's rays that hit the building)
  Image rgb;   // the same without alpha
  Lighting lighting;
  // LightingAttributes and "rouen:camera" (JSON: the intrinsics and the pose, as the lens and
  // pose files hold them: x_world = rotation x_cam + position, camera x right, y down, z
  // forward) and "rouen:alpha" (what the alpha channel means).
  std::vector<ImageAttribute> attributes;
};

// The building's radiance through the request's camera (§6), with irradiance (sun, sky,
// environment and the interreflection) computed for the requested lighting; with the alpha
// channel and the header attributes. The one render path of the CLI, Python and timelapse.
RenderedView RenderSceneView(const LoadedScene& scene, const RenderRequest& request,
                             const std::function<void(const std::string&)>& log = {});
// The same under `lighting` (the request's, already made: e.g. PredictorFor(...).At(time)).
RenderedView RenderSceneViewUnder(const LoadedScene& scene, const RenderRequest& request,
                                  Lighting lighting,
                                  const std::function<void(const std::string&)>& log = {});

}  // namespace rouen
