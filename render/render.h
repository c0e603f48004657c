// Re-rendering the model under given lighting (Yu & Malik 1998, §6): radiance images of the
// Lambertian model from the two pseudo-albedos and the irradiance, with the sky, environment
// and sun disc where rays escape.
#pragma once

#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/mesh.h"
#include "solve/albedo.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"

namespace rouen {

struct RenderOptions {
  // Samples per pixel along each axis (regular grid): a box-filtered pixel like a camera's;
  // 1 aliases shadow edges and silhouettes badly in comparisons with photographs.
  int supersample = 4;
  // Supersample only where it matters: a pixel whose four corner rays hit the same triangle
  // in the same sun or shadow (or all escape, away from the sun disc) is shaded once at its
  // centre, where the smooth albedo and irradiance make the box filter's mean the centre's
  // value to second order; others get supersample^2 samples. false: every pixel.
  bool adaptive = true;
  // The sun as the disc it is (0.53 deg across): a shadow's edge is a penumbra, as wide as the
  // occluder is far times the disc's angle (0.5 m from 60 m away). Each of an edge pixel's
  // supersamples looks at the sun through another point of the disc, and a pixel whose corners
  // see only part of the disc is an edge pixel. false: a point sun (crisp shadows).
  bool soft_shadows = true;
  bool interpolate = true;      // smooth albedo / E_se between grid points; false: nearest point
  bool draw_background = true;  // sky, environment and sun where rays escape; false: 0
  // A fourth channel, alpha: the fraction of the pixel's samples whose ray hits the model (1 on
  // the building, 0 where every ray escapes). The colour channels are unchanged by it.
  bool alpha = false;
  // §4.2.1: directions per axis (squared per shaded point) that sample the mean radiance a
  // block's sky/environment lobe sees, half about the mirror direction (its directional albedo
  // is tabulated per render, no ray cast).
  int sky_lobe_samples = 4;
  void Validate() const;  // throws rouen::Error
};

struct RenderStats {
  int64_t rays = 0;
  double seconds = 0;
};

// Per pixel: a ray into the model; on a hit L = (rho_sun E_sun D + rho_se E_se) / pi with E_sun
// computed at the hit with its own shadow ray (through a point of the sun's disc with
// soft_shadows), D the block's RetroFactor
// (albedo.retro, solve/retro.h; 1 when Lambertian) and rho, E_se interpolated from
// the grid; on escape the sun disc (sun_radiance) within the sun's radius, the sky model above
// the horizon and the environment map below. `irr` is the irradiance of `lighting` on the grid
// (with the interreflection added). Returns a kRadiance image (RGB, RGBA with options.alpha).
Image RenderView(const Mesh& mesh, const SurfaceGrid& grid, const RayCaster& model,
                 const AlbedoResult& albedo, const Lighting& lighting, const SlotIrradiance& irr,
                 const Intrinsics& intrinsics, const Pose& pose, const RenderOptions& options = {},
                 RenderStats* stats = nullptr);

// The grid points a view shades: the interpolation stencils (and nearest points) of the first
// hits of the rays through its pixels' corners, edge middles and centres, and of each
// `supersample`^2 rays where those do not all meet one triangle: where RenderView (with that
// supersampling) reads E_se. A view's irradiance needs its exact direct term only there
// (IrradianceOptions::exact_points); a point only a sky lobe's draw meets takes the Monte
// Carlo estimate. One flag per grid point.
std::vector<uint8_t> GridPointsInView(const SurfaceGrid& grid, const RayCaster& model,
                                      const Intrinsics& intrinsics, const Pose& pose,
                                      int supersample = RenderOptions{}.supersample);

// One channel, pixel centres: model block index of the first hit, -1 where the ray escapes.
Image RenderBlockIds(const Mesh& mesh, const RayCaster& model, const Intrinsics& intrinsics,
                     const Pose& pose);

// Mask (nonzero = building) from a block-id image: pixels with block >= 0, or only the
// listed blocks when `blocks` is not empty.
std::vector<uint8_t> BlockMask(const Image& block_ids, const std::vector<int>& blocks = {});

}  // namespace rouen
