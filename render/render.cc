#include "render/render.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/hash_random.h"
#include "core/memory.h"
#include "solve/retro.h"
#include "solve/specular.h"

namespace rouen {

namespace {

void CheckSizes(const SurfaceGrid& grid, const AlbedoResult& albedo, const SlotIrradiance& irr) {
  const size_t n = grid.points.size();
  if (albedo.rho_sun.size() != n || albedo.rho_se.size() != n || irr.se.size() != n) {
    throw Error("render: albedo (" + std::to_string(albedo.rho_sun.size()) + "), irradiance (" +
                std::to_string(irr.se.size()) + ") and grid (" + std::to_string(n) +
                ") sizes differ");
  }
}

// A sky lobe and its directional albedo (LobeDirectionalAlbedo) at kAlbedoSteps + 1 view
// angles, cos 0 to 1, between which it is interpolated.
struct SkyLobe {
  static constexpr int kAlbedoSteps = 128;
  SpecularLobe lobe;
  std::vector<double> albedo;

  explicit SkyLobe(const SpecularLobe& l) : lobe(l), albedo(kAlbedoSteps + 1) {
    tbb::parallel_for(0, kAlbedoSteps + 1, [&](int k) {
      albedo[k] = LobeDirectionalAlbedo(lobe, static_cast<double>(k) / kAlbedoSteps);
    });
  }
  double AlbedoAt(double cos_view) const {
    const double x = std::clamp(cos_view, 0.0, 1.0) * kAlbedoSteps;
    const int k = std::min(static_cast<int>(x), kAlbedoSteps - 1);
    return albedo[k] + (x - k) * (albedo[k + 1] - albedo[k]);
  }
};

// §4.2.1: the sky and environment a block's lobe reflects towards v from surface point p, as
// the lobe's directional albedo times the mean radiance the lobe sees: samples x samples
// stratified directions, the first half drawn about v's mirror direction with the lobe's
// MirrorExponent and the rest cosine-distributed about the normal, each weighing L(u) by
// f_s(u, v) and MixtureWeight. The ratio leaves out the spread of those weights (a lobe at
// grazing is stretched far from its draws' density), which summing f_s L alone carries into
// every pixel as noise; L's own variation over the lobe remains. A direction the model blocks
// brings the diffuse radiance of the grid point it meets (as the albedo solve's lobe light has
// it: solve/albedo.cc Pieces), none where it meets a back face.
Eigen::Vector3d SkyLobeLight(const SkyLobe& sky_lobe, const Eigen::Vector3d& n,
                             const Eigen::Vector3d& v, const Eigen::Vector3d& p,
                             const Lighting& lighting, const RayCaster& model,
                             const SurfaceGrid& grid, const AlbedoResult& albedo,
                             const SlotIrradiance& irr, int samples) {
  const SpecularLobe& lobe = sky_lobe.lobe;
  const Eigen::Vector3d m = 2 * v.dot(n) * n - v;
  const double e = lobe.MirrorExponent();
  uint64_t seed = 0;
  for (int c = 0; c < 3; ++c) {
    const float f = static_cast<float>(v[c]);
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    seed = MixHash(seed ^ bits);
  }
  const int total = samples * samples, mirror = (total + 1) / 2, cosine = total - mirror;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double weights = 0;
  for (int a = 0; a < samples; ++a) {
    for (int b = 0; b < samples; ++b) {
      const int k = a * samples + b;
      const uint64_t h = MixHash(seed + static_cast<uint64_t>(k));
      // Each half stratified on its own: draw k of a half takes stratum k of `half` rows.
      const bool about_mirror = k < mirror;
      const int j = about_mirror ? k : k - mirror, half = about_mirror ? mirror : cosine;
      const double u1 = (j + HashUniformHigh(h)) / half, u2 = HashUniformLow(h);
      const Eigen::Vector3d u =
          about_mirror ? DrawAboutAxis(m, e, u1, u2) : DrawAboutAxis(n, 1, u1, u2);
      const double w = lobe.Shape(n, u, v) * MixtureWeight(n, m, u, e, cosine, mirror);
      if (!(w > 0)) continue;
      weights += w;
      const RayHit hit = model.Intersect(p, u, 0.0);
      if (!hit.hit) {
        sum += w * lighting.EscapedRadiance(u, p.z());
        continue;
      }
      const int g = grid.NearestPoint(hit.triangle, hit.u, hit.v);
      if (g < 0 || grid.points[g].normal.dot(u) >= 0) continue;
      sum +=
          w *
          (albedo.rho_sun[g].cwiseProduct(irr.sun[g]) + albedo.rho_se[g].cwiseProduct(irr.se[g])) /
          kPi;
    }
  }
  if (!(weights > 0)) return Eigen::Vector3d::Zero();
  return lobe.rho_s.cwiseProduct(sum) * (sky_lobe.AlbedoAt(v.dot(n)) / weights);
}

}  // namespace

void RenderOptions::Validate() const {
  if (supersample < 1 || supersample > 16) throw Error("RenderOptions: supersample must be 1..16");
  if (sky_lobe_samples < 1 || sky_lobe_samples > 64)
    throw Error("RenderOptions: sky_lobe_samples must be 1..64");
}

// §6: re-rendering with the recovered pseudo-albedos.
Image RenderView(const Mesh& mesh, const SurfaceGrid& grid, const RayCaster& model,
                 const AlbedoResult& albedo, const Lighting& lighting, const SlotIrradiance& irr,
                 const Intrinsics& intrinsics, const Pose& pose, const RenderOptions& options,
                 RenderStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  intrinsics.Validate();
  CheckSizes(grid, albedo, irr);
  if (grid.triangle_n.size() != mesh.triangles.size()) {
    throw Error("render: the grid was built for " + std::to_string(grid.triangle_n.size()) +
                " triangles, the mesh has " + std::to_string(mesh.triangles.size()));
  }
  const int w = intrinsics.width, h = intrinsics.height, ss = options.supersample;
  const int channels = options.alpha ? 4 : 3;
  // The image, its copy for the file and the adaptive sampling's corner keys.
  CheckMemory(static_cast<int64_t>(w + 1) * (h + 1) * (2 * 4 * channels + 8),
              "render: a " + std::to_string(w) + "x" + std::to_string(h) + " image",
              "a smaller --size");
  Image out(w, h, channels, PixelUnits::kRadiance, 0.f);
  const Eigen::Vector3d s = lighting.sun_dir.normalized();
  const Eigen::Vector3d sun_e = lighting.sun_radiance * lighting.sun_solid_angle_sr;
  const double cos_sun_radius = std::cos(lighting.SunAngularRadius());
  const double offset = model.surface_offset();
  const bool env_ok =
      lighting.env.num_regions() > 0 && !lighting.env.layer_z.empty() &&
      lighting.env.radiance.size() ==
          static_cast<size_t>(lighting.env.num_regions()) * lighting.env.layer_z.size();

  // Where a supersample looks at the sun (one point of the disc each, or its centre), and the
  // disc's rim, which tells a corner in part of the sun (the penumbra) from one in all or none.
  const std::vector<Eigen::Vector3d> disc =
      SunDiscDirections(s, lighting.SunAngularRadius(), options.soft_shadows ? ss * ss : 1);
  const int disc_points = static_cast<int>(disc.size());
  // A stride coprime with the count (a square of at most 16^2: 5, or 7 when 5 divides it).
  const int disc_stride = disc_points % 5 == 0 ? 7 : 5;
  const std::vector<Eigen::Vector3d> rim =
      options.soft_shadows ? SunDiscDirections(s, lighting.SunAngularRadius(), 0, 4)
                           : std::vector<Eigen::Vector3d>();

  std::vector<std::optional<SkyLobe>> sky_lobes(albedo.sky_lobes.size());
  for (size_t b = 0; b < sky_lobes.size(); ++b)
    if (!albedo.sky_lobes[b].IsZero()) sky_lobes[b].emplace(albedo.sky_lobes[b]);

  // *hit_model: whether the ray hits the model (the alpha channel's coverage). `to_sun`: the
  // shadow ray's direction (a point of the sun's disc).
  auto shade = [&](const Eigen::Vector3d& dir, const Eigen::Vector3d& to_sun,
                   bool* hit_model) -> Eigen::Vector3d {
    const RayHit hit = model.Intersect(pose.position, dir, 0.0);
    *hit_model = hit.hit;
    if (!hit.hit) {
      if (!options.draw_background) return Eigen::Vector3d::Zero();
      if (dir.dot(s) >= cos_sun_radius) return lighting.sun_radiance;
      if (dir.z() >= 0) return lighting.sky.Radiance(dir);
      return env_ok ? lighting.env.Radiance(dir, pose.position.z()) : Eigen::Vector3d::Zero();
    }
    Eigen::Vector3d n = mesh.Normal(hit.triangle);
    if (n.dot(dir) > 0) n = -n;  // seen from behind: light the side facing the camera
    const int block = hit.triangle < static_cast<int>(mesh.triangle_block.size())
                          ? mesh.triangle_block[hit.triangle]
                          : -1;
    const double retro = BlockRetro(albedo.retro, block);
    Eigen::Vector3d rho_sun, rho_se, e_se;
    // Where E_se comes from (a rough block's only), mixed over the points as E_se is.
    LightMoments se_light;
    if (options.interpolate) {
      const GridStencil st = grid.Stencil(hit.triangle, hit.u, hit.v);
      if (st.count == 0) return Eigen::Vector3d::Zero();
      rho_sun.setZero();
      rho_se.setZero();
      e_se.setZero();
      double mixed = 0;
      for (int k = 0; k < st.count; ++k) {
        const int j = st.index[k];
        rho_sun += st.weight[k] * albedo.rho_sun[j];
        rho_se += st.weight[k] * albedo.rho_se[j];
        e_se += st.weight[k] * irr.se[j];
        if (retro == 0) continue;
        const double w = st.weight[k] * irr.se[j].sum();
        const LightMoments at = LightAt(irr.se_light, j, n);
        se_light = k == 0 ? at : LightMoments::Mix(se_light, mixed, at, w);
        mixed += w;
      }
    } else {
      const int j = grid.NearestPoint(hit.triangle, hit.u, hit.v);
      if (j < 0) return Eigen::Vector3d::Zero();
      rho_sun = albedo.rho_sun[j];
      rho_se = albedo.rho_se[j];
      e_se = irr.se[j];
      if (retro != 0) se_light = LightAt(irr.se_light, j, n);
    }
    const Eigen::Vector3d p = pose.position + hit.t * dir + offset * n;
    Eigen::Vector3d e_sun = Eigen::Vector3d::Zero(), specular = Eigen::Vector3d::Zero();
    const double cosi = n.dot(s);
    if (block >= 0 && block < static_cast<int>(sky_lobes.size()) && sky_lobes[block])
      specular = SkyLobeLight(*sky_lobes[block], n, -dir, p, lighting, model, grid, albedo, irr,
                              options.sky_lobe_samples);
    if (cosi > 0 && !model.Occluded(p, to_sun, 0.0)) {
      e_sun = sun_e * (cosi * RetroFactor(retro, n, s, -dir));
      // §4.2: the block's sun lobe (eq. 13) under the sun's irradiance on the surface.
      const SpecularLobe lobe = BlockLobe(albedo.sun_lobes, block);
      if (!lobe.IsZero()) specular += lobe.Eval(n, s, -dir).cwiseProduct(sun_e * cosi);
    }
    // The rough block's sky and environment light brightens towards oblique views as its sun
    // does (solve/retro.h AmbientRetroFactor; 1 for Lambert).
    const double se_factor = AmbientRetroFactor(retro, n, -dir, se_light);
    return (rho_sun.cwiseProduct(e_sun) + se_factor * rho_se.cwiseProduct(e_se)) / kPi + specular;
  };

  // What a ray through image point (x, y) sees, coarsely: the triangle it hits and whether the
  // sun reaches that point (2 t + lit), -1 when it escapes, -2 when it escapes near the sun
  // disc, cannot be cast, or (soft_shadows) sees part of the disc's rim. Pixels whose four
  // corners agree (and are not -2) are shaded once.
  const double cos_near_sun = std::cos(3 * lighting.SunAngularRadius());
  auto corner_key = [&](double x, double y) -> int64_t {
    Eigen::Vector3d d = pose.rotation * Unproject(intrinsics, Eigen::Vector2d(x, y));
    if (!d.allFinite() || d.squaredNorm() == 0) return -2;
    d.normalize();
    const RayHit hit = model.Intersect(pose.position, d, 0.0);
    if (!hit.hit) return d.dot(s) >= cos_near_sun ? -2 : -1;
    Eigen::Vector3d n = mesh.Normal(hit.triangle);
    if (n.dot(d) > 0) n = -n;
    const Eigen::Vector3d p = pose.position + hit.t * d + offset * n;
    const bool faces_sun = n.dot(s) > 0;
    const bool lit = faces_sun && !model.Occluded(p, s, 0.0);
    for (size_t k = 0; faces_sun && k < rim.size(); ++k)
      if (model.Occluded(p, rim[k], 0.0) == lit) return -2;
    return 2 * static_cast<int64_t>(hit.triangle) + (lit ? 1 : 0);
  };
  std::vector<int64_t> corners;
  if (options.adaptive && ss > 1) {
    corners.resize(static_cast<size_t>(w + 1) * (h + 1));
    tbb::parallel_for(0, h + 1, [&](int y) {
      for (int x = 0; x <= w; ++x) corners[static_cast<size_t>(y) * (w + 1) + x] = corner_key(x, y);
    });
  }
  auto uniform = [&](int x, int y) {
    if (corners.empty()) return false;
    const size_t i = static_cast<size_t>(y) * (w + 1) + x;
    const int64_t k = corners[i];
    return k != -2 && corners[i + 1] == k && corners[i + w + 1] == k && corners[i + w + 2] == k;
  };

  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      int hits = 0;
      const int n_sub = uniform(x, y) ? 1 : ss;
      // The sun's disc points shuffled over the pixel's supersamples (a stride coprime with
      // their count, an offset per pixel): no pattern from pixel to pixel.
      const int offset_k =
          static_cast<int>((7919 * static_cast<int64_t>(x) + 104729 * y) % disc_points);
      for (int a = 0; a < n_sub; ++a) {
        for (int b = 0; b < n_sub; ++b) {
          const Eigen::Vector2d px(x + (b + 0.5) / n_sub, y + (a + 0.5) / n_sub);
          const Eigen::Vector3d d = pose.rotation * Unproject(intrinsics, px);
          if (!d.allFinite() || d.squaredNorm() == 0) continue;
          bool hit = false;
          const Eigen::Vector3d& to_sun =
              n_sub == 1 ? s : disc[(offset_k + disc_stride * (a * n_sub + b)) % disc_points];
          sum += shade(d.normalized(), to_sun, &hit);
          hits += hit;
        }
      }
      sum /= n_sub * n_sub;
      if (options.alpha) out.at(x, y, 3) = static_cast<float>(hits) / (n_sub * n_sub);
      if (!sum.allFinite()) {
        throw Error("render: non-finite radiance at pixel (" + std::to_string(x) + ", " +
                    std::to_string(y) + ")");
      }
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = static_cast<float>(sum[c]);
    }
  });
  if (stats) {
    int64_t samples = 0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) samples += uniform(x, y) ? 1 : ss * ss;
    }
    stats->rays = 2 * (samples + static_cast<int64_t>(corners.size()));
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return out;
}

std::vector<uint8_t> GridPointsInView(const SurfaceGrid& grid, const RayCaster& model,
                                      const Intrinsics& intrinsics, const Pose& pose,
                                      int supersample) {
  intrinsics.Validate();
  if (supersample < 1 || supersample > 16)
    throw Error("GridPointsInView: supersample must be 1..16");
  const int w = intrinsics.width, h = intrinsics.height;
  // Per thread, then merged: no two threads write one flag.
  tbb::enumerable_thread_specific<std::vector<uint8_t>> seen_by(
      [&] { return std::vector<uint8_t>(grid.size(), 0); });
  // The ray through image point (x, y): its hit's stencil flagged, the triangle hit returned
  // (-1: none).
  const auto cast = [&](double x, double y, std::vector<uint8_t>* seen) {
    const Eigen::Vector3d d = pose.rotation * Unproject(intrinsics, Eigen::Vector2d(x, y));
    if (!d.allFinite() || d.squaredNorm() == 0) return -1;
    const RayHit hit = model.Intersect(pose.position, d.normalized(), 0.0);
    if (!hit.hit) return -1;
    const GridStencil st = grid.Stencil(hit.triangle, hit.u, hit.v);
    for (int k = 0; k < st.count; ++k) (*seen)[st.index[k]] = 1;
    const int j = grid.NearestPoint(hit.triangle, hit.u, hit.v);
    if (j >= 0) (*seen)[j] = 1;
    return hit.triangle;
  };
  // Rays at half-pixel steps (corners, edge middles and centres); a pixel whose nine do not all
  // meet one triangle (a silhouette, a fold, a triangle's edge) casts its supersamples as well:
  // those are where a render's rays meet points that the rays around them do not.
  const int lw = 2 * w + 1;
  std::vector<int> lattice(static_cast<size_t>(lw) * (2 * h + 1));
  tbb::parallel_for(0, 2 * h + 1, [&](int y2) {
    std::vector<uint8_t>& seen = seen_by.local();
    for (int x2 = 0; x2 < lw; ++x2)
      lattice[static_cast<size_t>(y2) * lw + x2] = cast(0.5 * x2, 0.5 * y2, &seen);
  });
  tbb::parallel_for(0, h, [&](int y) {
    std::vector<uint8_t>& seen = seen_by.local();
    for (int x = 0; x < w; ++x) {
      const int first = lattice[static_cast<size_t>(2 * y) * lw + 2 * x];
      bool one = true;
      for (int a = 0; a < 3 && one; ++a)
        for (int b = 0; b < 3 && one; ++b)
          one = lattice[static_cast<size_t>(2 * y + a) * lw + 2 * x + b] == first;
      if (one) continue;
      for (int a = 0; a < supersample; ++a)
        for (int b = 0; b < supersample; ++b)
          cast(x + (b + 0.5) / supersample, y + (a + 0.5) / supersample, &seen);
    }
  });
  std::vector<uint8_t> out(grid.size(), 0);
  for (const std::vector<uint8_t>& seen : seen_by)
    for (int i = 0; i < grid.size(); ++i) out[i] |= seen[i];
  return out;
}

Image RenderBlockIds(const Mesh& mesh, const RayCaster& model, const Intrinsics& intrinsics,
                     const Pose& pose) {
  intrinsics.Validate();
  Image out(intrinsics.width, intrinsics.height, 1, PixelUnits::kOther, -1.f);
  tbb::parallel_for(0, intrinsics.height, [&](int y) {
    for (int x = 0; x < intrinsics.width; ++x) {
      const Eigen::Vector3d d =
          pose.rotation * Unproject(intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
      if (!d.allFinite() || d.squaredNorm() == 0) continue;
      const RayHit hit = model.Intersect(pose.position, d.normalized(), 0.0);
      if (hit.hit && hit.triangle < static_cast<int>(mesh.triangle_block.size())) {
        out.at(x, y) = static_cast<float>(mesh.triangle_block[hit.triangle]);
      }
    }
  });
  return out;
}

std::vector<uint8_t> BlockMask(const Image& block_ids, const std::vector<int>& blocks) {
  std::vector<uint8_t> mask(static_cast<size_t>(block_ids.width) * block_ids.height, 0);
  for (int y = 0; y < block_ids.height; ++y) {
    for (int x = 0; x < block_ids.width; ++x) {
      const int b = static_cast<int>(std::lround(block_ids.at(x, y, 0)));
      bool in = b >= 0;
      if (in && !blocks.empty()) {
        in = false;
        for (int k : blocks) in = in || k == b;
      }
      mask[static_cast<size_t>(y) * block_ids.width + x] = in ? 1 : 0;
    }
  }
  return mask;
}

}  // namespace rouen
