#include "render/texture.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "solve/specular.h"

namespace rouen {
namespace {

bool HasLobes(const AlbedoResult& albedo) {
  for (const auto* lobes : {&albedo.sun_lobes, &albedo.sky_lobes})
    for (const SpecularLobe& l : *lobes)
      if (!l.IsZero()) return true;
  return false;
}

// The median of `v` (not empty); reorders it.
double Median(std::vector<float>* v) {
  const size_t mid = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(mid), v->end());
  return (*v)[mid];
}

}  // namespace

void PhotoTextureOptions::Validate() const {
  if (!(min_diffuse_fraction >= 0 && min_diffuse_fraction < 1))
    throw Error("texture: the minimum diffuse fraction must be in [0, 1), not " +
                std::to_string(min_diffuse_fraction));
  if (!(max_texture_gain > 0 && std::isfinite(max_texture_gain)))
    throw Error("texture: the maximum texture gain must be positive and finite, not " +
                std::to_string(max_texture_gain));
  if (!(min_coverage > 0 && min_coverage <= 1))
    throw Error("texture: the minimum coverage must be in (0, 1], not " +
                std::to_string(min_coverage));
  render.Validate();
}

PhotoTextureResult RenderWithPhotoTexture(
    const Mesh& mesh, const SurfaceGrid& grid, const RayCaster& model, const AlbedoResult& albedo,
    const Image& photo, const std::vector<uint8_t>& photo_valid, const Lighting& photo_lighting,
    const SlotIrradiance& photo_irr, const Lighting& novel_lighting,
    const SlotIrradiance& novel_irr, const Intrinsics& intrinsics, const Pose& pose,
    const PhotoTextureOptions& options) {
  options.Validate();
  intrinsics.Validate();
  const int w = intrinsics.width, h = intrinsics.height;
  const size_t n = static_cast<size_t>(w) * h;
  if (photo.width != w || photo.height != h)
    throw Error("texture: the photo is " + std::to_string(photo.width) + "x" +
                std::to_string(photo.height) + " but its camera is " + std::to_string(w) + "x" +
                std::to_string(h));
  if (photo.channels != 3)
    throw Error("texture: the photo has " + std::to_string(photo.channels) + " channels, not RGB");
  if (!photo_valid.empty() && photo_valid.size() != n)
    throw Error("texture: the photo's valid mask is not the photo's size");

  // §6.4, eq. 19: rho = I / E~ with E~ = I~ / rho~. rouen takes I~, the photo at the grid's
  // resolution, from its own render under the photo's lighting (rho~ E~: crisp shadows, no
  // blur across edges), so the texture factor t = rho / rho~ = I / I~; as the grid's two
  // pseudo-albedos (rho_sun, rho_se) share it and the per-block specular lobes are not
  // textured, t = (I - S) / D per channel with D, S the diffuse and specular parts of that
  // render, and the novel render is t D' + S' (D', S' under the novel lighting): I D' / D
  // without lobes, and exactly the photo under its own lighting.
  RenderOptions ro = options.render;
  ro.alpha = true;
  const bool lobes = HasLobes(albedo);
  AlbedoResult diffuse_albedo;
  if (lobes) {
    diffuse_albedo.rho_sun = albedo.rho_sun;
    diffuse_albedo.rho_se = albedo.rho_se;
    diffuse_albedo.retro = albedo.retro;
  }
  const AlbedoResult& diffuse = lobes ? diffuse_albedo : albedo;
  auto render = [&](const AlbedoResult& a, const Lighting& l, const SlotIrradiance& irr) {
    return RenderView(mesh, grid, model, a, l, irr, intrinsics, pose, ro);
  };
  PhotoTextureResult out;
  out.grid = render(albedo, novel_lighting, novel_irr);
  const Image photo_full = render(albedo, photo_lighting, photo_irr);
  const Image novel_diffuse = lobes ? render(diffuse, novel_lighting, novel_irr) : out.grid;
  const Image photo_diffuse = lobes ? render(diffuse, photo_lighting, photo_irr) : photo_full;

  // The building's pixels and, per channel, the median of D over them.
  std::vector<uint8_t> building(n, 0);
  std::vector<float> level[3];
  for (size_t p = 0; p < n; ++p) {
    if (!(photo_full.data[p * 4 + 3] >= options.min_coverage)) continue;
    building[p] = 1;
    ++out.building_pixels;
    for (int c = 0; c < 3; ++c) level[c].push_back(photo_diffuse.data[p * 4 + c]);
  }
  double min_d[3] = {0, 0, 0};
  if (out.building_pixels > 0)
    for (int c = 0; c < 3; ++c) min_d[c] = options.min_diffuse_fraction * Median(&level[c]);

  out.textured = out.grid;
  out.textured_mask.assign(n, 0);
  for (size_t p = 0; p < n; ++p) {
    if (!building[p] || (!photo_valid.empty() && !photo_valid[p])) continue;
    double t[3];
    bool ok = true;
    for (int c = 0; c < 3 && ok; ++c) {
      const double d = photo_diffuse.data[p * 4 + c];
      const double s = photo_full.data[p * 4 + c] - d;
      t[c] = (photo.data[p * 3 + c] - s) / d;
      ok = d > 0 && d >= min_d[c] && std::isfinite(t[c]) && t[c] >= 0 &&
           t[c] <= options.max_texture_gain;
    }
    if (!ok) continue;
    for (int c = 0; c < 3; ++c) {
      const double d = novel_diffuse.data[p * 4 + c];
      const double s = out.grid.data[p * 4 + c] - d;
      out.textured.data[p * 4 + c] = static_cast<float>(t[c] * d + s);
    }
    out.textured_mask[p] = 1;
    ++out.textured_pixels;
  }
  return out;
}

}  // namespace rouen
