// `rouen render --texture-from`: a photograph of the session gives the building its per-pixel
// pseudo-albedo (§6.4, eq. 19, render/texture.h) and the building is re-rendered from the
// photograph's viewpoint under a captured slot's lighting or lighting predicted for a time.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/session.h"
#include "pipeline/export.h"
#include "pipeline/scene.h"
#include "render/metrics.h"
#include "render/texture.h"

namespace rouen {

struct TextureRenderRequest {
  // The photograph: a bracket of the session that is one of the scene's views (as rouen
  // validate names them, e.g. "slot0/architecture/view1"); its camera and slot are the view's.
  std::string photo;
  // The lighting to render under (slot, or time with the relighting options); its camera is
  // ignored: the photograph's is used.
  RenderRequest lighting;
  PhotoTextureOptions options;
  // Optional: another photograph of the session through the same camera (e.g. the same view at
  // a held-out slot) both renders are scored against, over the building's pixels.
  std::string compare;
};

struct TextureRender {
  int photo_slot = 0;
  Image photo;            // the photograph merged to radiance
  RenderedView textured;  // eq. 19's render (RGBA, header attributes)
  RenderedView grid;      // the plain grid-resolution render under the same lighting
  int64_t building_pixels = 0, textured_pixels = 0;
  // With `compare`: both renders against it (PSNR through the scene's response, render/metrics.h).
  std::optional<RenderMetrics> textured_metrics, grid_metrics;
};

// Checks the request against the scene and session before any work: the photograph (and the
// comparison) is a view of the scene with a camera, a bracket of the session, its slot is one
// of the scene's. Throws rouen::Error naming the photograph.
void CheckTextureRenderRequest(const LoadedScene& scene, const Session& session,
                               const TextureRenderRequest& request);

// The photograph merged through the scene's response, its slot's measured lighting and the
// requested lighting, then RenderWithPhotoTexture. Throws rouen::Error naming the photograph
// (not in the session, not the size of its camera) or the scene.
TextureRender RenderSceneWithPhotoTexture(const LoadedScene& scene, const Session& session,
                                          const TextureRenderRequest& request,
                                          const std::function<void(const std::string&)>& log = {});

}  // namespace rouen
