#include "solve/irradiance.h"

#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/hash_random.h"
#include "solve/vector_flux_cache.h"

namespace rouen {

namespace {

// Orthonormal tangent frame (t, b) for a unit normal n (Duff et al. 2017).
void TangentFrame(const Eigen::Vector3d& n, Eigen::Vector3d* t, Eigen::Vector3d* b) {
  const double sign = std::copysign(1.0, n.z());
  const double a = -1.0 / (sign + n.z());
  const double c = n.x() * n.y() * a;
  *t = Eigen::Vector3d(1.0 + sign * n.x() * n.x() * a, sign * c, -sign * n.x());
  *b = Eigen::Vector3d(c, sign + n.y() * n.y() * a, -n.y());
}

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

double Lighting::SunAngularRadius() const {
  // Omega = 2 pi (1 - cos r)
  const double c = 1.0 - sun_solid_angle_sr / (2 * kPi);
  return std::acos(std::clamp(c, -1.0, 1.0));
}

Eigen::Vector3d Lighting::EscapedRadiance(const Eigen::Vector3d& dir, double z) const {
  if (use_env) return env.Radiance(dir, z);
  return dir.z() >= 0 ? sky.Radiance(dir) : Eigen::Vector3d::Zero();
}

void HemisphereOptions::Validate() const {
  if (directions < 1 || directions > 65536) {
    throw Error("HemisphereOptions: directions must be in 1..65536, got " +
                std::to_string(directions));
  }
}

void IrradianceOptions::Validate() const {
  if (sun_samples < 1 || sun_samples > 1024) {
    throw Error("IrradianceOptions: sun_samples must be in 1..1024");
  }
  if (method == IrradianceMethod::kVectorFlux) {
    if (mesh == nullptr) {
      throw Error("IrradianceOptions: the vector-flux method needs the model mesh (mesh)");
    }
    vector_flux.Validate();
  }
}

Eigen::Vector3d HemisphereCache::Direction(const GridPoint& p, int point_index, int k) const {
  const uint64_t h = MixHash(seed * 0x100000001B3ull + static_cast<uint64_t>(point_index));
  const double s1 = HashUniform53(h), s2 = HashUniform53(MixHash(h));
  const int a = k / strata, b = k % strata;
  double u1 = (a + 0.5) / strata + s1;
  double u2 = (b + 0.5) / strata + s2;
  u1 -= std::floor(u1);
  u2 -= std::floor(u2);
  // Malley's method: uniform on the disc, projected up: density cos(theta) / pi.
  const double r = std::sqrt(u1), phi = 2 * kPi * u2;
  const double z = std::sqrt(std::max(0.0, 1.0 - u1));
  Eigen::Vector3d t, bt;
  TangentFrame(p.normal, &t, &bt);
  return (r * std::cos(phi) * t + r * std::sin(phi) * bt + z * p.normal).normalized();
}

HemisphereCache BuildHemisphereCache(const SurfaceGrid& grid, const RayCaster& model,
                                     const HemisphereOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  HemisphereCache cache;
  cache.strata =
      static_cast<int>(std::ceil(std::sqrt(static_cast<double>(options.directions)) - 1e-9));
  cache.directions = cache.strata * cache.strata;
  cache.seed = options.seed;
  const int n = grid.size();
  const int K = cache.directions;
  cache.hit.assign(static_cast<size_t>(n) * K, -1);
  cache.escaped_fraction.assign(n, 0.f);
  const double offset = model.surface_offset();
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 16), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i < range.end(); ++i) {
      const GridPoint& p = grid.points[i];
      const Eigen::Vector3d origin = p.position + offset * p.normal;
      int escaped = 0;
      for (int k = 0; k < K; ++k) {
        const Eigen::Vector3d d = cache.Direction(p, i, k);
        const RayHit h = model.Intersect(origin, d, 0.0);
        int32_t code = -1;
        if (h.hit) {
          const GridPoint* q = nullptr;
          const int j = grid.NearestPoint(h.triangle, h.u, h.v);
          if (j >= 0) q = &grid.points[j];
          code = (q == nullptr || q->normal.dot(d) >= 0) ? -2 : j;
        } else {
          ++escaped;
        }
        cache.hit[static_cast<size_t>(i) * K + k] = code;
      }
      cache.escaped_fraction[i] = static_cast<float>(escaped) / K;
    }
  });
  cache.rays = static_cast<int64_t>(n) * K;
  cache.seconds = Seconds(start);
  return cache;
}

SlotIrradiance ComputeIrradiance(const SurfaceGrid& grid, const HemisphereCache& cache,
                                 const RayCaster& model, const Lighting& lighting,
                                 const IrradianceOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  const int n = grid.size();
  if (static_cast<int64_t>(cache.hit.size()) != static_cast<int64_t>(n) * cache.directions) {
    throw Error("irradiance: the hemisphere cache has " + std::to_string(cache.hit.size()) +
                " entries but the grid needs " + std::to_string(n) + " x " +
                std::to_string(cache.directions));
  }
  if (!lighting.sun_dir.allFinite() || std::abs(lighting.sun_dir.norm() - 1) > 1e-3) {
    throw Error("irradiance: the sun direction is not a unit vector");
  }
  if (!lighting.sun_radiance.allFinite() || lighting.sun_radiance.minCoeff() < 0 ||
      !(lighting.sun_solid_angle_sr >= 0 && lighting.sun_solid_angle_sr < 1)) {
    throw Error("irradiance: sun radiance must be finite and >= 0, solid angle in [0, 1) sr");
  }
  if (lighting.use_env) lighting.env.Validate();
  const bool vector_flux = options.method == IrradianceMethod::kVectorFlux;
  if (vector_flux && static_cast<int>(options.mesh->triangles.size()) != model.num_triangles()) {
    throw Error("irradiance: the mesh has " + std::to_string(options.mesh->triangles.size()) +
                " triangles but the ray-casting model " + std::to_string(model.num_triangles()) +
                " (not the same model)");
  }
  std::vector<SphericalPolygon> regions;
  std::unique_ptr<FaceAdjacency> adjacency;
  std::unique_ptr<SkyPatchTree> tree;
  std::unique_ptr<SkyTreeRadiance> sky_tree;
  if (vector_flux) {
    if (lighting.use_env) {
      regions = EnvironmentRegionPolygons(lighting.env, options.vector_flux);
    } else {
      tree = std::make_unique<SkyPatchTree>(options.vector_flux.sky_tree_levels);
      sky_tree = std::make_unique<SkyTreeRadiance>(*tree, lighting.sky, options.vector_flux);
    }
    if (options.vector_flux.select_occluders) {
      adjacency = std::make_unique<FaceAdjacency>(*options.mesh);
    }
  }

  SlotIrradiance irr;
  irr.sun.assign(n, Eigen::Vector3d::Zero());
  irr.direct_se.assign(n, Eigen::Vector3d::Zero());
  irr.sun_visibility.assign(n, 0.f);
  const int K = cache.directions;
  const double offset = model.surface_offset();
  const Eigen::Vector3d s = lighting.sun_dir;
  const Eigen::Vector3d sun_e = lighting.sun_radiance * lighting.sun_solid_angle_sr;
  // Sun-disc sample directions (stratified rings) for soft shadow edges.
  std::vector<Eigen::Vector3d> disc;
  if (options.sun_samples == 1) {
    disc.push_back(s);
  } else {
    Eigen::Vector3d t, b;
    TangentFrame(s, &t, &b);
    const double radius = std::tan(lighting.SunAngularRadius());
    for (int m = 0; m < options.sun_samples; ++m) {
      // Fibonacci spiral over the disc: uniform in area.
      const double rr = radius * std::sqrt((m + 0.5) / options.sun_samples);
      const double phi = m * 2.399963229728653;
      disc.push_back((s + rr * (std::cos(phi) * t + std::sin(phi) * b)).normalized());
    }
  }
  // Ground beyond the model (see IrradianceOptions::ground_shadow): its level, and the
  // shadowed/sunlit radiance ratio of horizontal Lambertian ground.
  const bool ground_shadow =
      options.ground_shadow && lighting.use_env && s.z() > 0 && n > 0 && sun_e.maxCoeff() > 0;
  double ground_z = 0;
  Eigen::Vector3d shadow_ratio = Eigen::Vector3d::Ones();
  if (ground_shadow) {
    ground_z = grid.points[0].position.z();
    for (const auto& p : grid.points) ground_z = std::min(ground_z, p.position.z());
    const Eigen::Vector3d e_sky = lighting.env.HorizontalSkyIrradiance();
    const Eigen::Vector3d e_total = e_sky + sun_e * s.z();
    for (int c = 0; c < 3; ++c) shadow_ratio[c] = e_total[c] > 0 ? e_sky[c] / e_total[c] : 1.0;
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 32), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i < range.end(); ++i) {
      const GridPoint& p = grid.points[i];
      const Eigen::Vector3d origin = p.position + offset * p.normal;
      const double cosi = p.normal.dot(s);
      if (cosi > 0 && sun_e.maxCoeff() > 0) {
        int visible = 0;
        for (const auto& d : disc) visible += !model.Occluded(origin, d, 0.0);
        const double v = static_cast<double>(visible) / disc.size();
        irr.sun_visibility[i] = static_cast<float>(v);
        irr.sun[i] = sun_e * (cosi * v);
      }
      if (vector_flux) {
        // App. A: vector flux of the visible sky patches / environment regions.
        // The faces in front of the point: an id buffer cast with Embree, or all of them.
        const auto visibility = [&]() {
          if (!adjacency) return PointVisibility(*options.mesh, origin, p.normal, p.triangle);
          return PointVisibility(*options.mesh, origin, p.normal, p.triangle,
                                 SelectOccluders(*options.mesh, model, *adjacency, origin, p.normal,
                                                 p.triangle, options.vector_flux.select));
        };
        const PointVisibility vis = visibility();
        if (lighting.use_env) {
          std::vector<ConvexSpherical> shadow;
          if (ground_shadow && origin.z() > ground_z) {
            shadow = GroundShadowPolygons(*options.mesh, s, ground_z, origin);
          }
          irr.direct_se[i] =
              EnvironmentIrradianceVectorFlux(vis, lighting.env, p.position.z(), regions,
                                              ground_shadow ? &shadow : nullptr, shadow_ratio);
        } else {
          // The sky tree clipped for this point, against the sky integrated once per lighting.
          PointFluxCache c;
          CacheSky(vis, *tree, &c);
          irr.direct_se[i] = EvaluateSky(c, *sky_tree);
        }
        continue;
      }
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int k = 0; k < K; ++k) {
        if (cache.Hit(i, k) != -1) continue;
        const Eigen::Vector3d d = cache.Direction(p, i, k);
        Eigen::Vector3d l = lighting.EscapedRadiance(d, p.position.z());
        if (ground_shadow && d.z() < -1e-3 && origin.z() > ground_z) {
          const Eigen::Vector3d q = origin + ((origin.z() - ground_z) / -d.z()) * d;
          if (model.Occluded(q + Eigen::Vector3d(0, 0, offset), s, 0.0)) {
            l = l.cwiseProduct(shadow_ratio);
          }
        }
        sum += l;
      }
      irr.direct_se[i] = sum * (kPi / K);
    }
  });
  for (int i = 0; i < n; ++i) {
    if (!irr.sun[i].allFinite() || !irr.direct_se[i].allFinite()) {
      throw Error("irradiance: non-finite irradiance at grid point " + std::to_string(i) +
                  " (check the sky model and environment map)");
    }
  }
  irr.se = irr.direct_se;
  irr.seconds = Seconds(start);
  return irr;
}

// §4.1: one-bounce interreflection between model faces.
void AddInterreflection(const SurfaceGrid& grid, const HemisphereCache& cache,
                        const std::vector<Eigen::Vector3d>& rho_sun,
                        const std::vector<Eigen::Vector3d>& rho_se, SlotIrradiance* irr,
                        int bounces) {
  const int n = grid.size();
  if (static_cast<int>(rho_sun.size()) != n || static_cast<int>(rho_se.size()) != n ||
      static_cast<int>(irr->sun.size()) != n || static_cast<int>(irr->direct_se.size()) != n) {
    throw Error("interreflection: albedo and irradiance sizes do not match the grid (" +
                std::to_string(n) + " points)");
  }
  if (bounces < 1) throw Error("interreflection: bounces must be >= 1");
  const int K = cache.directions;
  std::vector<Eigen::Vector3d> se_prev = irr->direct_se;
  std::vector<Eigen::Vector3d> radiosity(n);
  std::vector<Eigen::Vector3d> se(n);
  for (int pass = 0; pass < bounces; ++pass) {
    for (int j = 0; j < n; ++j) {
      radiosity[j] = rho_sun[j].cwiseProduct(irr->sun[j]) + rho_se[j].cwiseProduct(se_prev[j]);
    }
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& range) {
      for (int i = range.begin(); i < range.end(); ++i) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int k = 0; k < K; ++k) {
          const int j = cache.Hit(i, k);
          if (j >= 0) sum += radiosity[j];
        }
        // (B_j / pi) (pi / K)
        se[i] = irr->direct_se[i] + sum / K;
      }
    });
    se_prev = se;
  }
  for (int i = 0; i < n; ++i) {
    if (!se[i].allFinite()) {
      throw Error("interreflection: non-finite irradiance at grid point " + std::to_string(i) +
                  " (non-finite albedo?)");
    }
  }
  irr->se = se;
  irr->has_bounce = true;
}

}  // namespace rouen
