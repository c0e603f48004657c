// rouen view: a static web page (WebGL 2, opened as a file, no server) that relights a solved
// scene's building in the browser at any time of its day and under any degree of overcast.
// rouen bakes, once, what the page needs: the building's triangles with texture coordinates
// into one atlas of all blocks, the two pseudo-albedos (Yu & Malik 1998 eqs. 11-12) in it, and
// per time of a day from sunrise to sunset an irradiance "basis" (the sun's visibility, ray-cast
// per texel of a finer atlas, E_se
// under the predicted clear sky and E_se under the same time's fully overcast sky, §6.3); the
// page's shader computes L = (rho_sun E_sun D + rho_se E_se) / pi + f_s E_sun (render/render.h
// RenderView) between the two nearest times.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/mesh.h"
#include "core/solar.h"
#include "core/time.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"
#include "solve/atlas.h"
#include "solve/grid.h"
#include "solve/raycast.h"

namespace rouen {

struct ViewerOptions {
  int times = 24;                  // irradiance bases from sunrise to sunset, 2..96
  int texels_per_cell = 1;         // atlas texels along a grid cell's edge (solve/atlas.h), 1..16
  int shadow_texels_per_cell = 4;  // the sun-visibility atlas's (ray-cast per texel), 1..16
  double min_elevation_deg = 1;    // "sunrise" and "sunset": the sun this high (deg), 0.1..20
  int max_atlas_side = 8192;       // the one atlas of all blocks, texels
  void Validate() const;           // throws rouen::Error naming the option
};

// The day the page shows: the solar noon nearest to `day` (the highest sun within 12 h) and the
// times around it when the sun's apparent elevation is `min_elevation_deg` (polar day: noon
// +-12 h), and `n` times evenly spaced from that sunrise to that sunset, both included.
// Throws rouen::Error when the sun stays lower than `min_elevation_deg` that day.
struct ViewerDay {
  UtcTime noon, sunrise, sunset;
  std::vector<UtcTime> times;
};
ViewerDay ViewerDayOf(const Site& site, UtcTime day, int n, double min_elevation_deg);

// Every block's atlas (LayoutAtlases) packed on shelves into one atlas, so the page draws the
// building with one set of textures. Texel coordinates: column from the left edge, row from the
// top (row 0 is the first row of the image and of the texture).
struct ViewerAtlas {
  AtlasLayout layout;                 // per block
  std::vector<int> block_x, block_y;  // each block's atlas's top-left texel in the combined one
  int width = 0, height = 0;

  // Texel coordinates (continuous; texel centres at integer + 0.5) of barycentric (u, v) of
  // `triangle` (p = (1-u-v) a + u b + v c); (-1, -1) for a triangle without grid points.
  Eigen::Vector2d Texel(int triangle, double u, double v) const;
  // The grid's values interpolated at every texel centre of every tile (BakeAtlas per block);
  // texels outside the tiles are 0.
  Image Bake(const SurfaceGrid& grid, const std::vector<Eigen::Vector3d>& values) const;
};
ViewerAtlas PackViewerAtlas(const Mesh& mesh, const SurfaceGrid& grid, int texels_per_cell,
                            int max_side);

// Whether the sun (direction `sun_dir`, unit ENU) reaches each texel centre of each tile of
// `atlas` on the model: 1 when the face turns towards it and a shadow ray from the point (lifted
// by the caster's surface offset) escapes, as render/render.h RenderView decides per pixel;
// border texels repeat the tile's edge as BakeAtlas does. One channel, texels outside tiles 0.
Image SunVisibilityAtlas(const ViewerAtlas& atlas, const Mesh& mesh, const RayCaster& caster,
                         const Eigen::Vector3d& sun_dir);

// The lighting of one time on the grid, as the page uses it.
struct ViewerBasis {
  UtcTime utc;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();  // unit ENU, towards the sun
  Eigen::Vector3d sun_e = Eigen::Vector3d::Zero();     // L_sun Omega: irradiance normal to it
  // Per grid point: the fraction of the sun disc seen (ComputeIrradiance's sun_visibility; 0
  // where the sun is behind the face), so E_sun = sun_e max(0, n.s) V as ComputeIrradiance's
  // (the page takes V from the finer SunVisibilityAtlas instead, for sharper shadows);
  // E_se with the interreflection (IrradianceFor) under the clear predicted lighting (pbs 0),
  // and under the same time's fully overcast lighting (pbs 1: no sun, a CIE overcast sky).
  std::vector<float> sun_visibility;
  std::vector<Eigen::Vector3d> sun;  // E_sun (clear), for checks and the exposure
  std::vector<Eigen::Vector3d> se, se_overcast;
  double exposure = 1, exposure_overcast = 1;  // as ViewerData::exposure, at this time
};

// Everything the page shows, in rouen's units (relative radiance x sr for irradiance).
struct ViewerData {
  ViewerDay day;
  std::vector<ViewerBasis> bases;  // one per day.times
  double exposure = 1;  // L x exposure -> 0.9 of white for the 99th percentile at noon's basis
};
// The lighting predicted for each time (RequestedLighting's way: from the scene's slots less the
// held-out ones; pbs 0 and pbs 1) and its irradiance on the grid with the interreflection.
// `progress(done, total)` after each time.
ViewerData ComputeViewerData(const LoadedScene& scene, const ViewerOptions& options,
                             const std::function<void(int, int)>& progress = {});

// 8-bit encoding of a non-negative quantity in a PNG: stored = round(255 (value / scale)^(1 /
// 2.2)), scale the map's largest value (per channel set); the page decodes scale x s^2.2.
constexpr double kViewerGamma = 2.2;
uint8_t ViewerEncode(double value, double scale);
double ViewerDecode(uint8_t stored, double scale);

struct ViewerSummary {
  int times = 0;
  int atlas_width = 0, atlas_height = 0;
  int shadow_width = 0, shadow_height = 0;
  int64_t triangles = 0;
  size_t bytes = 0;  // index.html and viewer_data.js
  double seconds_lighting = 0, seconds_baking = 0;
};

// Writes the page folder `out`: index.html (the viewer) and viewer_data.js (the data, loaded by
// a <script> tag, so the page works from file://). The folder is built as "<out>.tmp-<pid>"
// and renamed into place when whole; an earlier viewer folder there (it holds
// viewer_data.js) is replaced, anything else is refused. Throws rouen::Error naming `out`.
void CheckViewerOutput(const std::filesystem::path& out);
ViewerSummary WriteViewer(const LoadedScene& scene, const std::filesystem::path& out,
                          const ViewerOptions& options,
                          const std::function<void(const std::string&)>& log = {},
                          const std::function<void(int, int)>& progress = {});

// The page (pipeline/viewer_page.cc): HTML, CSS and the WebGL 2 code, data-free.
const char* ViewerPageHtml();

}  // namespace rouen
