// High-resolution re-rendering (Yu & Malik 1998, §6.4, eq. 19): a photograph's pixels give the
// per-pixel pseudo-albedo the surface grid cannot hold, and the building is re-rendered under
// other lighting from the photograph's viewpoint with it.
#pragma once

#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/mesh.h"
#include "render/render.h"
#include "solve/albedo.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"

namespace rouen {

struct PhotoTextureOptions {
  // A pixel keeps the plain render where its diffuse render under the photo's lighting (rho~ E~)
  // is below this fraction of that render's median over the building in some channel: eq. 19's
  // ratio divides by ~0 there.
  double min_diffuse_fraction = 0.02;
  // A pixel keeps the plain render where its texture factor t = rho / rho~ is above this (or
  // negative) in some channel: the photograph and the model disagree there (a shadow the model
  // misplaces, an occluder it lacks, a glint), which is not texture to carry to other lighting.
  double max_texture_gain = 4;
  // Only pixels whose rays all hit the building (the render's alpha at least this) take the
  // photo's texture: silhouette pixels mix the building with what lies behind it.
  double min_coverage = 0.999;
  RenderOptions render;   // of the grid-resolution renders (their alpha is always on)
  void Validate() const;  // throws rouen::Error
};

struct PhotoTextureResult {
  Image textured;  // RGBA radiance under the novel lighting, per-pixel albedo; alpha as `grid`
  Image grid;      // RGBA: the plain (grid-resolution) render under the novel lighting
  std::vector<uint8_t> textured_mask;  // 1 where the photo's texture was used
  int64_t building_pixels = 0;         // pixels with coverage >= min_coverage
  int64_t textured_pixels = 0;         // of those, the pixels that took the texture
};

// §6.4, eq. 19. `photo` is the photograph's radiance (RGB, the camera's size) taken under
// `photo_lighting` (whose grid irradiance is `photo_irr`), `photo_valid` (empty: every pixel)
// nonzero where it is well exposed; the result is seen through the same camera under
// `novel_lighting` (irradiance `novel_irr`). Pixels off the building, unexposed, or where the
// options refuse eq. 19's ratio keep the plain render. Throws rouen::Error when the photo is not
// the camera's size or not RGB.
PhotoTextureResult RenderWithPhotoTexture(
    const Mesh& mesh, const SurfaceGrid& grid, const RayCaster& model, const AlbedoResult& albedo,
    const Image& photo, const std::vector<uint8_t>& photo_valid, const Lighting& photo_lighting,
    const SlotIrradiance& photo_irr, const Lighting& novel_lighting,
    const SlotIrradiance& novel_irr, const Intrinsics& intrinsics, const Pose& pose,
    const PhotoTextureOptions& options = {});

}  // namespace rouen
