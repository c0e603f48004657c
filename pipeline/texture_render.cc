#include "pipeline/texture_render.h"

#include <cmath>

#include "core/error.h"
#include "core/limits.h"
#include "pipeline/render_scene.h"
#include "pipeline/session_solve.h"

namespace rouen {
namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

// The scene's view of photograph `name` (`what` says which option named it). Throws
// rouen::Error naming it when the scene has no camera for it, or the session no such bracket.
const SceneView& PhotoView(const LoadedScene& scene, const Session& session,
                           const std::string& name, const std::string& what) {
  if (name.empty()) throw Error(what + ": name a photograph, e.g. slot0/architecture/view0");
  bool in_session = false;
  for (const FrameRecord& f : session.frames()) in_session = in_session || f.group == name;
  const auto it = scene.scene.views.find(name);
  if (it == scene.scene.views.end()) {
    std::string known;
    for (const auto& [n, v] : scene.scene.views)
      if (v.target == "architecture") known += (known.empty() ? "" : ", ") + n;
    if (in_session)
      throw Error(what + " " + name + ": the photograph has no camera in " + scene.dir.string() +
                  " (the solve posed only its views: " + (known.empty() ? "none" : known) + ")");
    throw Error(what + " " + name + ": no such photograph in " + session.dir().string() + " or " +
                scene.dir.string() + " (architecture views: " + (known.empty() ? "none" : known) +
                ")");
  }
  if (!in_session)
    throw Error(what + " " + name + ": the scene has its camera but " + session.dir().string() +
                " has no such bracket: was the scene solved from this session?");
  const int nslots = static_cast<int>(scene.solved.slots.size());
  if (it->second.slot < 0 || it->second.slot >= nslots)
    throw Error(what + " " + name + ": its time (slot " + std::to_string(it->second.slot) +
                ") has no slot in " + scene.dir.string() + " (slots 0.." +
                std::to_string(nslots - 1) + "): no measured lighting to take its albedo under");
  return it->second;
}

// The bracket merged to radiance, checked against its camera's size.
HdrGroup MergePhoto(const LoadedScene& scene, const Session& session, const std::string& name,
                    const SceneView& view) {
  HdrGroup g = MergeSessionBracket(session, name, scene.scene.response, scene.config);
  if (g.radiance.width != view.intrinsics.width || g.radiance.height != view.intrinsics.height)
    throw Error(name + ": the photograph is " + std::to_string(g.radiance.width) + "x" +
                std::to_string(g.radiance.height) + " but its camera in " + scene.dir.string() +
                " is " + std::to_string(view.intrinsics.width) + "x" +
                std::to_string(view.intrinsics.height) +
                ": was the scene solved from this session?");
  // Non-finite radiance is unusable, as an unexposed pixel is.
  for (size_t p = 0; p < g.valid.size(); ++p)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(g.radiance.data[p * 3 + c])) {
        g.valid[p] = 0;
        g.radiance.data[p * 3 + c] = 0;
      }
  return g;
}

std::vector<ImageAttribute> Attributes(const LoadedScene& scene, const RenderRequest& request,
                                       const Lighting& lighting) {
  std::vector<ImageAttribute> a = LightingAttributes(scene, request, lighting);
  const nlohmann::json camera = {{"intrinsics", request.intrinsics}, {"pose", request.pose}};
  a.push_back({"rouen:camera", camera.dump()});
  a.push_back({"rouen:alpha", std::string("fraction of the pixel's rays that hit the building")});
  return a;
}

RenderedView View(Image rgba, Lighting lighting, std::vector<ImageAttribute> attributes) {
  RenderedView v;
  v.rgb = Image(rgba.width, rgba.height, 3, rgba.units);
  for (size_t p = 0; p < static_cast<size_t>(rgba.width) * rgba.height; ++p)
    for (int c = 0; c < 3; ++c) v.rgb.data[p * 3 + c] = rgba.data[p * 4 + c];
  v.rgba = std::move(rgba);
  v.lighting = std::move(lighting);
  v.attributes = std::move(attributes);
  return v;
}

}  // namespace

void CheckTextureRenderRequest(const LoadedScene& scene, const Session& session,
                               const TextureRenderRequest& request) {
  request.options.Validate();
  const SceneView& view = PhotoView(scene, session, request.photo, "--texture-from");
  RenderRequest r = request.lighting;
  r.intrinsics = view.intrinsics;
  r.pose = view.pose;
  CheckRenderRequest(scene, r);
  if (!request.compare.empty()) {
    const SceneView& other = PhotoView(scene, session, request.compare, "--compare");
    if (other.intrinsics.width != view.intrinsics.width ||
        other.intrinsics.height != view.intrinsics.height)
      throw Error("--compare " + request.compare + ": its camera is " +
                  std::to_string(other.intrinsics.width) + "x" +
                  std::to_string(other.intrinsics.height) + ", not the photograph's " +
                  std::to_string(view.intrinsics.width) + "x" +
                  std::to_string(view.intrinsics.height));
  }
}

TextureRender RenderSceneWithPhotoTexture(const LoadedScene& scene, const Session& session,
                                          const TextureRenderRequest& request,
                                          const std::function<void(const std::string&)>& log) {
  CheckTextureRenderRequest(scene, session, request);
  const SolveResult& solved = scene.solved;
  const SceneView& view = scene.scene.views.at(request.photo);
  RenderRequest r = request.lighting;
  r.intrinsics = view.intrinsics;
  r.pose = view.pose;

  TextureRender out;
  out.photo_slot = view.slot;
  Log(log, "merging " + request.photo + " (slot " + std::to_string(view.slot) + ")");
  HdrGroup photo = MergePhoto(scene, session, request.photo, view);
  const Lighting& photo_lighting = solved.slots[view.slot].lighting;
  const Lighting novel = RequestedLighting(scene, r, log);
  Log(log, "irradiance at " + std::to_string(solved.grid.size()) +
               " grid points under the photograph's lighting and the requested one");
  const std::vector<SlotIrradiance> irr = IrradianceFor(solved, {photo_lighting, novel});
  const SlotIrradiance& photo_irr = irr[0];
  const SlotIrradiance& novel_irr = irr[1];
  Log(log, "rendering " + std::to_string(r.intrinsics.width) + "x" +
               std::to_string(r.intrinsics.height) + " with the photograph's texture (§6.4)");
  PhotoTextureResult t = RenderWithPhotoTexture(
      solved.mesh, solved.grid, *solved.caster, solved.albedo, photo.radiance, photo.valid,
      photo_lighting, photo_irr, novel, novel_irr, r.intrinsics, r.pose, request.options);
  if (t.building_pixels == 0)
    throw Error("--texture-from " + request.photo + ": the building is not in view");
  out.building_pixels = t.building_pixels;
  out.textured_pixels = t.textured_pixels;
  Log(log, std::to_string(t.textured_pixels) + " of " + std::to_string(t.building_pixels) +
               " building pixels took the photograph's texture");
  std::vector<ImageAttribute> attributes = Attributes(scene, r, novel);
  out.grid = View(std::move(t.grid), novel, attributes);
  attributes.push_back({"rouen:texture_from", request.photo});
  out.textured = View(std::move(t.textured), novel, std::move(attributes));

  if (!request.compare.empty()) {
    const SceneView& other = scene.scene.views.at(request.compare);
    if ((other.pose.position - view.pose.position).norm() > 0.01)
      Log(log, "--compare " + request.compare + " was taken " +
                   FormatNumber((other.pose.position - view.pose.position).norm()) + " m from " +
                   request.photo + ": its pixels do not align exactly");
    const HdrGroup truth = MergePhoto(scene, session, request.compare, other);
    std::vector<uint8_t> mask(t.textured_mask.size(), 0);
    for (size_t p = 0; p < mask.size(); ++p)
      mask[p] = out.grid.rgba.data[p * 4 + 3] >= request.options.min_coverage && truth.valid[p];
    mask = ErodeMask(mask, r.intrinsics.width, r.intrinsics.height, 1);
    MetricsOptions mo;
    mo.response = &scene.scene.response;
    out.textured_metrics = CompareRadiance(out.textured.rgb, truth.radiance, mask, mo);
    out.grid_metrics = CompareRadiance(out.grid.rgb, truth.radiance, mask, mo);
  }
  out.photo = std::move(photo.radiance);
  return out;
}

}  // namespace rouen
