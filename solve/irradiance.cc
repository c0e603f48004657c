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
#include "solve/retro.h"
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

std::vector<Eigen::Vector3d> SunDiscDirections(const Eigen::Vector3d& sun_dir,
                                               double angular_radius, int n, int rim) {
  Eigen::Vector3d t, b;
  TangentFrame(sun_dir, &t, &b);
  const double radius = std::tan(angular_radius);
  std::vector<Eigen::Vector3d> out;
  if (n == 1) {
    out.push_back(sun_dir);
  } else {
    for (int m = 0; m < n; ++m) {
      // Fibonacci spiral over the disc: uniform in area.
      const double rr = radius * std::sqrt((m + 0.5) / n);
      const double phi = m * 2.399963229728653;
      out.push_back((sun_dir + rr * (std::cos(phi) * t + std::sin(phi) * b)).normalized());
    }
  }
  for (int m = 0; m < rim; ++m) {
    const double phi = 2 * kPi * m / rim;
    out.push_back((sun_dir + radius * (std::cos(phi) * t + std::sin(phi) * b)).normalized());
  }
  return out;
}

double Lighting::SunAngularRadius() const {
  // Omega = 2 pi (1 - cos r)
  const double c = 1.0 - sun_solid_angle_sr / (2 * kPi);
  return std::acos(std::clamp(c, -1.0, 1.0));
}

Lighting Lighting::SkyOnly() const {
  Lighting out = *this;
  ZeroBelowHorizon(&out.env);
  out.ground.reset();
  return out;
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
  if (method == IrradianceMethod::kVectorFlux) vector_flux.Validate();
}

namespace {

// One point's share of its directions: the tangent frame and the Cranley-Patterson shift of
// its strata (u1 by s1; the azimuth by 2 pi s2, as its cosine and sine).
struct PointShift {
  Eigen::Vector3d t, b, n;
  double s1 = 0, cos2 = 1, sin2 = 0;
};

PointShift ShiftOf(const HemisphereCache& c, const GridPoint& p, int point_index) {
  PointShift q;
  const uint64_t h = MixHash(c.seed * 0x100000001B3ull + static_cast<uint64_t>(point_index));
  q.s1 = HashUniform53(h);
  const double s2 = HashUniform53(MixHash(h));
  q.cos2 = std::cos(2 * kPi * s2);
  q.sin2 = std::sin(2 * kPi * s2);
  TangentFrame(p.normal, &q.t, &q.b);
  q.n = p.normal;
  return q;
}

// Stratum row a's radius and height (Malley's method: uniform on the disc, projected up, so
// the density is cos(theta) / pi).
void RowOf(const PointShift& q, int strata, int a, double* r, double* z) {
  double u1 = (a + 0.5) / strata + q.s1;
  u1 -= std::floor(u1);
  *r = std::sqrt(u1);
  *z = std::sqrt(std::max(0.0, 1.0 - u1));
}

// The direction of row (r, z) and column angle phi_b = 2 pi (b + 0.5) / strata (its cosine and
// sine), shifted by the point's azimuth.
Eigen::Vector3d DirectionOf(const PointShift& q, double r, double z, double cos_b, double sin_b) {
  const double cp = cos_b * q.cos2 - sin_b * q.sin2, sp = sin_b * q.cos2 + cos_b * q.sin2;
  return (r * cp * q.t + r * sp * q.b + z * q.n).normalized();
}

}  // namespace

Eigen::Vector3d HemisphereCache::Direction(const GridPoint& p, int point_index, int k) const {
  const PointShift q = ShiftOf(*this, p, point_index);
  const int a = k / strata, b = k % strata;
  double r, z;
  RowOf(q, strata, a, &r, &z);
  const double phi_b = 2 * kPi * (b + 0.5) / strata;
  return DirectionOf(q, r, z, std::cos(phi_b), std::sin(phi_b));
}

void HemisphereCache::Directions(const GridPoint& p, int point_index,
                                 std::vector<Eigen::Vector3d>* out) const {
  const PointShift q = ShiftOf(*this, p, point_index);
  thread_local std::vector<double> cos_b, sin_b;
  cos_b.resize(strata);
  sin_b.resize(strata);
  for (int b = 0; b < strata; ++b) {
    const double phi_b = 2 * kPi * (b + 0.5) / strata;
    cos_b[b] = std::cos(phi_b);
    sin_b[b] = std::sin(phi_b);
  }
  out->resize(directions);
  for (int a = 0; a < strata; ++a) {
    double r, z;
    RowOf(q, strata, a, &r, &z);
    for (int b = 0; b < strata; ++b)
      (*out)[a * strata + b] = DirectionOf(q, r, z, cos_b[b], sin_b[b]);
  }
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
    if (IsCancelled(options.cancel)) return;
    std::vector<Eigen::Vector3d> dirs;
    for (int i = range.begin(); i < range.end(); ++i) {
      const GridPoint& p = grid.points[i];
      const Eigen::Vector3d origin = p.position + offset * p.normal;
      int escaped = 0;
      cache.Directions(p, i, &dirs);
      for (int k = 0; k < K; ++k) {
        const Eigen::Vector3d& d = dirs[k];
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
  ThrowIfCancelled(options.cancel);
  cache.rays = static_cast<int64_t>(n) * K;
  cache.lists = ListHits(cache, n);
  cache.seconds = Seconds(start);
  return cache;
}

HitLists ListHits(const HemisphereCache& cache, int points) {
  const int K = cache.directions;
  if (points < 0 || static_cast<int64_t>(cache.hit.size()) != static_cast<int64_t>(points) * K) {
    throw Error("hemisphere cache: " + std::to_string(cache.hit.size()) + " entries for " +
                std::to_string(points) + " points x " + std::to_string(K) + " directions");
  }
  // Per point: its hits sorted, then run lengths; counted first, written into place after.
  auto sorted_hits = [&](int i, std::vector<int32_t>* h) {
    h->clear();
    for (int k = 0; k < K; ++k)
      if (cache.Hit(i, k) >= 0) h->push_back(cache.Hit(i, k));
    std::sort(h->begin(), h->end());
  };
  HitLists lists;
  lists.begin.assign(static_cast<size_t>(points) + 1, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, points, 256), [&](const tbb::blocked_range<int>& r) {
    std::vector<int32_t> h;
    for (int i = r.begin(); i < r.end(); ++i) {
      sorted_hits(i, &h);
      lists.begin[i + 1] = static_cast<int32_t>(std::unique(h.begin(), h.end()) - h.begin());
    }
  });
  for (int i = 0; i < points; ++i) lists.begin[i + 1] += lists.begin[i];
  lists.point.resize(lists.begin[points]);
  lists.count.resize(lists.begin[points]);
  tbb::parallel_for(tbb::blocked_range<int>(0, points, 256), [&](const tbb::blocked_range<int>& r) {
    std::vector<int32_t> h;
    for (int i = r.begin(); i < r.end(); ++i) {
      sorted_hits(i, &h);
      int32_t m = lists.begin[i];
      for (size_t a = 0; a < h.size();) {
        size_t b = a;
        while (b < h.size() && h[b] == h[a]) ++b;
        lists.point[m] = h[a];
        lists.count[m] = static_cast<int32_t>(b - a);
        ++m;
        a = b;
      }
    }
  });
  return lists;
}

namespace {

// What ComputeIrradiance needs of one lighting besides the lighting itself.
struct LightingSetup {
  const Lighting* lighting = nullptr;
  Eigen::Vector3d sun_e = Eigen::Vector3d::Zero();  // radiance x solid angle
  std::vector<Eigen::Vector3d> disc;                // shadow-ray directions over the sun disc
  // Ground beyond the model (IrradianceOptions::ground_shadow): its sky irradiance for the
  // shadowed/sunlit radiance ratio (GroundShadowRatio), and (vector flux) the model's shadow on
  // it and that shadow's middle.
  bool ground_shadow = false;
  Eigen::Vector3d ground_e_sky = Eigen::Vector3d::Zero();
  std::vector<std::vector<Eigen::Vector3d>> shadow_on_ground;
  Eigen::Vector3d shadow_centre = Eigen::Vector3d::Zero();
  // The ratio seen from `view` (ground to viewer).
  Eigen::Vector3d ShadowRatio(const Eigen::Vector3d& view) const {
    return GroundShadowRatio(lighting->env.ground_retro, ground_e_sky, sun_e, lighting->sun_dir,
                             view);
  }
  // Lighting::ground lit at this time, and (vector flux) the map with nothing below the horizon:
  // the regions above it by the vector flux, the ground by the hemisphere cache's directions.
  std::unique_ptr<GroundLight> ground;
  EnvironmentMap above_only;
  int layout = -1;                            // vector flux, environment: index into the layouts
  std::unique_ptr<SkyTreeRadiance> sky_tree;  // vector flux, sky model
  // The environment's regions above the horizon spread by the sky's shape (EnvOptions::
  // sky_detail); null when uniform. Vector flux: its moments over the layout's regions.
  std::unique_ptr<SkyShape> shape;
  std::unique_ptr<ShapedRegions> shaped;
};

void CheckLighting(const Lighting& lighting) {
  if (!lighting.sun_dir.allFinite() || std::abs(lighting.sun_dir.norm() - 1) > 1e-3) {
    throw Error("irradiance: the sun direction is not a unit vector");
  }
  if (!lighting.sun_radiance.allFinite() || lighting.sun_radiance.minCoeff() < 0 ||
      !(lighting.sun_solid_angle_sr >= 0 && lighting.sun_solid_angle_sr < 1)) {
    throw Error("irradiance: sun radiance must be finite and >= 0, solid angle in [0, 1) sr");
  }
  if (lighting.use_env) lighting.env.Validate();
}

}  // namespace

SlotIrradiance ComputeIrradiance(const SurfaceGrid& grid, const HemisphereCache& cache,
                                 const RayCaster& model, const Lighting& lighting,
                                 const IrradianceOptions& options) {
  std::vector<SlotIrradiance> irr =
      ComputeIrradiance(grid, cache, model, std::vector<Lighting>{lighting}, options);
  return std::move(irr[0]);
}

std::vector<SlotIrradiance> ComputeIrradiance(const SurfaceGrid& grid, const HemisphereCache& cache,
                                              const RayCaster& model,
                                              const std::vector<Lighting>& lightings,
                                              const IrradianceOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  const int n = grid.size();
  if (static_cast<int64_t>(cache.hit.size()) != static_cast<int64_t>(n) * cache.directions) {
    throw Error("irradiance: the hemisphere cache has " + std::to_string(cache.hit.size()) +
                " entries but the grid needs " + std::to_string(n) + " x " +
                std::to_string(cache.directions));
  }
  for (const Lighting& l : lightings) CheckLighting(l);
  const bool vector_flux = options.method == IrradianceMethod::kVectorFlux;
  if (vector_flux && options.mesh == nullptr)
    throw Error(
        "irradiance: the vector-flux method needs the model mesh (IrradianceOptions::mesh)");
  if (vector_flux && static_cast<int>(options.mesh->triangles.size()) != model.num_triangles()) {
    throw Error("irradiance: the mesh has " + std::to_string(options.mesh->triangles.size()) +
                " triangles but the ray-casting model " + std::to_string(model.num_triangles()) +
                " (not the same model)");
  }
  if (options.exact_points && static_cast<int>(options.exact_points->size()) != n)
    throw Error("irradiance: exact_points has " + std::to_string(options.exact_points->size()) +
                " entries for " + std::to_string(n) + " grid points");
  const double ground_z = GroundLevel(model);

  const int nl = static_cast<int>(lightings.size());
  std::vector<LightingSetup> setup(nl);
  // The walls each ground field's cells see (geometry only): cast once per field, shared by
  // every lighting it lights.
  std::vector<std::pair<const GroundField*, GroundWalls>> field_walls;
  // Vector flux: one set of region polygons per environment layout, one sky tree, shared by
  // every lighting (and each point's clipping by every lighting that uses it).
  std::vector<std::unique_ptr<EnvironmentRegions>> layouts;
  std::vector<bool> layout_shadow;
  std::unique_ptr<SkyPatchTree> tree;
  std::unique_ptr<FaceAdjacency> adjacency;
  std::unique_ptr<OccluderFaces> faces;
  for (int li = 0; li < nl; ++li) {
    const Lighting& lighting = lightings[li];
    LightingSetup& ls = setup[li];
    ls.lighting = &lighting;
    const Eigen::Vector3d s = lighting.sun_dir;
    ls.sun_e = lighting.sun_radiance * lighting.sun_solid_angle_sr;
    // Sun-disc sample directions (stratified rings) for soft shadow edges.
    ls.disc = SunDiscDirections(s, lighting.SunAngularRadius(), options.sun_samples);
    if (lighting.use_env && lighting.ground) {
      const GroundField* field = lighting.ground.get();
      auto walls = std::find_if(field_walls.begin(), field_walls.end(),
                                [field](const auto& fw) { return fw.first == field; });
      if (walls == field_walls.end())
        walls = field_walls.insert(field_walls.end(),
                                   {field, CastGroundWalls(*field, model, /*only_shaded=*/true)});
      const Eigen::Vector3d sky_e = lighting.env.HorizontalSkyIrradiance();
      ls.ground =
          std::make_unique<GroundLight>(*field, model, s, ls.sun_e, sky_e,
                                        HiddenSkyExcess(
                                            walls->second,
                                            [&lighting, ground_z](const Eigen::Vector3d& d) {
                                              return lighting.EscapedRadiance(d, ground_z);
                                            },
                                            sky_e));
      if (vector_flux) {
        ls.above_only = lighting.env;
        ZeroBelowHorizon(&ls.above_only);
      }
    }
    ls.ground_shadow = options.ground_shadow && lighting.use_env && !ls.ground && s.z() > 0 &&
                       n > 0 && ls.sun_e.maxCoeff() > 0;
    if (ls.ground_shadow) {
      ls.ground_e_sky = lighting.env.HorizontalSkyIrradiance();
      if (vector_flux) {
        if (!faces) faces = std::make_unique<OccluderFaces>(*options.mesh);
        // Merged into fewer polygons where their union is convex, before the cut (less to
        // cut) and after it (the cut's pieces of neighbouring polygons join again).
        ls.shadow_on_ground = MergeGroundShadow(ShadowBeyondGroundFaces(
            MergeGroundShadow(GroundShadowOnPlane(*options.mesh, *faces, s, ground_z)), *faces,
            ground_z));
        int vertices = 0;
        for (const auto& poly : ls.shadow_on_ground) {
          for (const Eigen::Vector3d& v : poly) ls.shadow_centre += v;
          vertices += static_cast<int>(poly.size());
        }
        if (vertices > 0) ls.shadow_centre /= vertices;
      }
    }
    if (lighting.use_env && lighting.env.detail > 1) {
      ls.shape = std::make_unique<SkyShape>(lighting.env, lighting.sky);
      if (ls.shape->uniform()) ls.shape.reset();
    }
    if (!vector_flux) continue;
    if (lighting.use_env) {
      for (size_t k = 0; k < layouts.size() && ls.layout < 0; ++k) {
        if (layouts[k]->Fits(lighting.env)) ls.layout = static_cast<int>(k);
      }
      if (ls.layout < 0) {
        ls.layout = static_cast<int>(layouts.size());
        layouts.push_back(std::make_unique<EnvironmentRegions>(lighting.env, options.vector_flux));
        layout_shadow.push_back(false);
      }
      if (ls.ground_shadow && !ls.shadow_on_ground.empty()) layout_shadow[ls.layout] = true;
      if (ls.shape) ls.shaped = std::make_unique<ShapedRegions>(*ls.shape, *layouts[ls.layout]);
    } else {
      if (!tree) tree = std::make_unique<SkyPatchTree>(options.vector_flux.sky_tree_levels);
      ls.sky_tree = std::make_unique<SkyTreeRadiance>(*tree, lighting.sky, options.vector_flux);
    }
  }
  if (vector_flux && !faces) faces = std::make_unique<OccluderFaces>(*options.mesh);
  if (vector_flux && options.vector_flux.select_occluders) {
    adjacency = std::make_unique<FaceAdjacency>(*options.mesh);
  }

  std::vector<SlotIrradiance> out(nl);
  for (auto& irr : out) {
    irr.sun.assign(n, Eigen::Vector3d::Zero());
    irr.direct_se.assign(n, Eigen::Vector3d::Zero());
    if (options.light_directions) irr.direct_se_light.assign(n, LightMoments{});
    irr.sun_visibility.assign(n, 0.f);
  }
  const int K = cache.directions;
  const double offset = model.surface_offset();
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 32), [&](const tbb::blocked_range<int>& range) {
    if (IsCancelled(options.cancel)) return;
    std::vector<EnvironmentView> views(layouts.size());
    PointFluxCache sky_cache;
    // Monte Carlo: the point's escaping directions, and their environment regions, found once
    // for every lighting (the same values, in the same order, as found per lighting).
    std::vector<Eigen::Vector3d> escaped, dirs;
    std::vector<int> regions, cells;
    const EnvironmentMap* regions_of = nullptr;
    // The ground's light field (Lighting::ground) at point i by the hemisphere cache's escaped
    // directions below the horizon, found once per point: (pi / K) sum of L.
    std::vector<Eigen::Vector3d> ground_dirs;
    int ground_dirs_of = -1;
    auto ground_light = [&](int i, const GridPoint& p, const Eigen::Vector3d& origin,
                            const GroundLight& g) {
      if (ground_dirs_of != i) {
        ground_dirs.clear();
        cache.Directions(p, i, &dirs);
        for (int k = 0; k < K; ++k)
          if (cache.Hit(i, k) == -1 && dirs[k].z() < 0) ground_dirs.push_back(dirs[k]);
        ground_dirs_of = i;
      }
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (const Eigen::Vector3d& d : ground_dirs) sum += g.Arriving(origin, d);
      return Eigen::Vector3d(sum * (kPi / K));
    };
    for (int i = range.begin(); i < range.end(); ++i) {
      const GridPoint& p = grid.points[i];
      const Eigen::Vector3d origin = p.position + offset * p.normal;
      for (int li = 0; li < nl; ++li) {
        const LightingSetup& ls = setup[li];
        const double cosi = p.normal.dot(ls.lighting->sun_dir);
        if (cosi > 0 && ls.sun_e.maxCoeff() > 0) {
          int visible = 0;
          for (const auto& d : ls.disc) visible += !model.Occluded(origin, d, 0.0);
          const double v = static_cast<double>(visible) / ls.disc.size();
          out[li].sun_visibility[i] = static_cast<float>(v);
          out[li].sun[i] = ls.sun_e * (cosi * v);
        }
      }
      const bool exact = vector_flux && (!options.exact_points || (*options.exact_points)[i]);
      if (exact) {
        // App. A: vector flux of the visible sky patches / environment regions. The faces in
        // front of the point (an id buffer cast with Embree, or all of them) are projected
        // once, each layout's regions and the sky tree clipped once, for every lighting.
        const auto visibility = [&]() {
          if (!adjacency) return PointVisibility(*faces, origin, p.normal, p.triangle);
          const std::vector<int> candidates =
              SelectOccluders(*options.mesh, model, *adjacency, origin, p.normal, p.triangle,
                              options.vector_flux.select);
          return PointVisibility(*faces, origin, p.normal, p.triangle, &candidates);
        };
        const PointVisibility vis = visibility();
        for (size_t k = 0; k < layouts.size(); ++k) {
          SeeEnvironment(vis, *layouts[k], layout_shadow[k] && origin.z() > ground_z, &views[k]);
        }
        if (tree) CacheSky(vis, *tree, &sky_cache);
        for (int li = 0; li < nl; ++li) {
          const LightingSetup& ls = setup[li];
          if (ls.layout < 0) {
            out[li].direct_se[i] = EvaluateSky(sky_cache, *ls.sky_tree);
            continue;
          }
          const EnvironmentView& view = views[ls.layout];
          if (ls.ground) {
            out[li].direct_se[i] =
                EnvironmentIrradiance(view, ls.above_only, p.position.z(), ls.shaped.get()) +
                ground_light(i, p, origin, *ls.ground);
            continue;
          }
          Eigen::Vector3d e =
              EnvironmentIrradiance(view, ls.lighting->env, p.position.z(), ls.shaped.get());
          if (ls.ground_shadow && origin.z() > ground_z && !view.pieces.empty()) {
            // One ratio per point: seen from the point towards the shadow's middle.
            e += GroundShadowChange(view, *layouts[ls.layout], ls.lighting->env, p.position.z(),
                                    GroundShadowPolygons(ls.shadow_on_ground, origin),
                                    ls.ShadowRatio((origin - ls.shadow_centre).normalized()));
          }
          out[li].direct_se[i] = e;
        }
        if (!options.light_directions) continue;
      }
      // The Monte Carlo estimate (the direct term of points not made exact) and the directions
      // the light arrives from (every point): the hemisphere cache's escaped directions.
      escaped.clear();
      cache.Directions(p, i, &dirs);
      for (int k = 0; k < K; ++k)
        if (cache.Hit(i, k) == -1) escaped.push_back(dirs[k]);
      regions_of = nullptr;
      for (int li = 0; li < nl; ++li) {
        const LightingSetup& ls = setup[li];
        const Eigen::Vector3d& s = ls.lighting->sun_dir;
        const EnvironmentMap& env = ls.lighting->env;
        if (ls.lighting->use_env &&
            !(regions_of && regions_of->SameLayout(env) && regions_of->detail == env.detail)) {
          regions.resize(escaped.size());
          cells.resize(escaped.size());
          for (size_t k = 0; k < escaped.size(); ++k) {
            regions[k] = env.Region(escaped[k]);
            cells[k] = env.detail > 1 ? env.DetailCell(escaped[k]) : -1;
          }
          regions_of = &env;
        }
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        LightMomentsSum moments(p.normal);
        for (size_t k = 0; k < escaped.size(); ++k) {
          const Eigen::Vector3d& d = escaped[k];
          if (ls.ground && d.z() < 0) {  // the ground's light field instead of the map there
            const Eigen::Vector3d l = ls.ground->Arriving(origin, d);
            sum += l;
            if (options.light_directions && l.sum() > 0) moments.Add(d, l.sum());
            continue;
          }
          // Lighting::EscapedRadiance, with the region found above.
          Eigen::Vector3d l = ls.lighting->use_env
                                  ? env.RegionRadiance(regions[k], p.position.z())
                                  : ls.lighting->EscapedRadiance(d, p.position.z());
          if (ls.shape) l = l.cwiseProduct(ls.shape->OfCell(cells[k]));
          if (ls.ground_shadow && d.z() < -1e-3 && origin.z() > ground_z) {
            const Eigen::Vector3d q = origin + ((origin.z() - ground_z) / -d.z()) * d;
            if (model.Occluded(q + Eigen::Vector3d(0, 0, offset), s, 0.0)) {
              l = l.cwiseProduct(ls.ShadowRatio(-d));
            }
          }
          sum += l;
          if (options.light_directions && l.sum() > 0) moments.Add(d, l.sum());
        }
        if (!exact) out[li].direct_se[i] = sum * (kPi / K);
        if (options.light_directions)
          out[li].direct_se_light[i] = moments.Moments(UniformLight(p.normal));
      }
    }
  });
  ThrowIfCancelled(options.cancel);
  const double seconds = Seconds(start);
  for (auto& irr : out) {
    for (int i = 0; i < n; ++i) {
      if (!irr.sun[i].allFinite() || !irr.direct_se[i].allFinite()) {
        throw Error("irradiance: non-finite irradiance at grid point " + std::to_string(i) +
                    " (check the sky model and environment map)");
      }
    }
    irr.se = irr.direct_se;
    irr.se_light = irr.direct_se_light;
    irr.seconds = seconds / std::max(nl, 1);
  }
  return out;
}

namespace {

// Per entry of a list of (point, weight): the weight times the factor of the point's reflection
// of the sun's light and of the sky's towards where the list gathers light (RetroFactor,
// AmbientRetroFactor). They depend on the geometry and the sun only: computed once per time,
// used by every bounce.
struct ReflectionFactors {
  std::vector<double> sun, se;
  // pi f_s / rho_s of the sender's sun lobe towards the receiver, per entry (empty: no block
  // has a lobe); the light it sends is this times rho_s E_sun (LobeLight).
  std::vector<double> lobe;
};

bool AnyLobe(const std::vector<SpecularLobe>& lobes) {
  return std::any_of(lobes.begin(), lobes.end(), [](const SpecularLobe& l) { return !l.IsZero(); });
}

// Per grid point, rho_s E_sun of its block's sun lobe (zero without one): times
// ReflectionFactors::lobe, the sun's glint it sends on.
std::vector<Eigen::Vector3d> LobeLight(const SurfaceGrid& grid,
                                       const std::vector<SpecularLobe>& lobes,
                                       const SlotIrradiance& irr) {
  std::vector<Eigen::Vector3d> out(grid.size(), Eigen::Vector3d::Zero());
  if (!AnyLobe(lobes)) return out;
  for (int j = 0; j < grid.size(); ++j)
    out[j] = BlockLobe(lobes, grid.points[j].block).rho_s.cwiseProduct(irr.sun[j]);
  return out;
}

// pi f_s / rho_s of point q's block lobe for the sun towards v (0 without a lobe).
double LobeFactor(const std::vector<SpecularLobe>& lobes, const GridPoint& q,
                  const Eigen::Vector3d& sun_dir, const Eigen::Vector3d& v) {
  const SpecularLobe lobe = BlockLobe(lobes, q.block);
  return lobe.IsZero() ? 0.0 : kPi * lobe.Shape(q.normal, sun_dir, v);
}

// The factors of b's cell entries, each point sending light towards its cell's centre as
// towards another point (AddInterreflection).
ReflectionFactors CellFactors(const GroundBounce& b, const SurfaceGrid& grid,
                              const std::vector<double>& retro, const Eigen::Vector3d& sun_dir,
                              const SlotIrradiance& irr, const std::vector<SpecularLobe>& lobes) {
  ReflectionFactors f{
      std::vector<double>(b.cell_point.size()), std::vector<double>(b.cell_point.size()), {}};
  if (AnyLobe(lobes)) f.lobe.assign(b.cell_point.size(), 0.0);
  tbb::parallel_for(size_t{0}, b.cells.size(), [&](size_t w) {
    const Eigen::Vector3d centre = b.field->CellCentre(b.cells[w]);
    for (int m = b.cell_begin[w]; m < b.cell_begin[w + 1]; ++m) {
      const GridPoint& q = grid.points[b.cell_point[m]];
      const double r = BlockRetro(retro, q.block);
      const Eigen::Vector3d to_cell = (centre - q.position).normalized();
      f.sun[m] = f.se[m] = b.cell_weight[m];
      if (!f.lobe.empty() && to_cell.allFinite())
        f.lobe[m] = b.cell_weight[m] * LobeFactor(lobes, q, sun_dir, to_cell);
      if (r != 0 && to_cell.allFinite()) {
        f.sun[m] *= RetroFactor(r, q.normal, sun_dir, to_cell);
        f.se[m] *= AmbientRetroFactor(r, q.normal, to_cell,
                                      LightAt(irr.se_light, b.cell_point[m], q.normal));
      }
    }
  });
  return f;
}

// The walls' irradiance on entry w of b.cells: (pi / N) sum over its rays of B_j / pi, each
// point's light sent towards the cell as towards another point (`f`: CellFactors). An empty
// `from_*` leaves its term out.
Eigen::Vector3d WallsOnCell(const GroundBounce& b, size_t w, const ReflectionFactors& f,
                            const std::vector<Eigen::Vector3d>& from_sun,
                            const std::vector<Eigen::Vector3d>& from_se,
                            const std::vector<Eigen::Vector3d>& from_lobe) {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  for (int m = b.cell_begin[w]; m < b.cell_begin[w + 1]; ++m) {
    const int j = b.cell_point[m];
    if (!from_sun.empty()) e += f.sun[m] * from_sun[j];
    if (!from_se.empty()) e += f.se[m] * from_se[j];
    if (!f.lobe.empty() && !from_lobe.empty()) e += f.lobe[m] * from_lobe[j];
  }
  return e;
}

// Sorts (index, weight) entries by index and sums the weights of each index into one entry.
void MergeEntries(std::vector<std::pair<int32_t, float>>* entries) {
  std::sort(entries->begin(), entries->end());
  size_t m = 0;
  for (const auto& e : *entries) {
    if (m > 0 && (*entries)[m - 1].first == e.first) {
      (*entries)[m - 1].second += e.second;
    } else {
      (*entries)[m++] = e;
    }
  }
  entries->resize(m);
}

}  // namespace

GroundBounce BuildGroundBounce(const GroundField& field, const RayCaster& model,
                               const SurfaceGrid& grid, const HemisphereCache& cache) {
  const int n = grid.size();
  const int K = cache.directions;
  if (static_cast<int64_t>(cache.hit.size()) != static_cast<int64_t>(n) * K)
    throw Error("ground bounce: the hemisphere cache does not match the grid");
  GroundBounce b;
  b.field = &field;
  // Per cell, the grid points its rays meet on their front faces, merged.
  const GroundWalls walls = CastGroundWalls(field, model, true);
  const int cells = static_cast<int>(walls.weight.size());
  std::vector<int32_t> index(cells, -1);
  b.cell_begin.push_back(0);
  std::vector<std::pair<int32_t, float>> entries;
  for (int c = 0; c < cells; ++c) {
    entries.clear();
    for (int k = walls.begin[c]; k < walls.begin[c + 1]; ++k) {
      const GroundWalls::Hit& h = walls.hits[k];
      const int j = grid.NearestPoint(h.triangle, h.u, h.v);
      if (j < 0 || grid.points[j].normal.cast<float>().dot(h.position - h.from) >= 0) continue;
      entries.emplace_back(j, walls.weight[c]);
    }
    if (entries.empty()) continue;
    MergeEntries(&entries);
    index[c] = static_cast<int32_t>(b.cells.size());
    b.cells.push_back(c);
    for (const auto& [j, weight] : entries) {
      b.cell_point.push_back(j);
      b.cell_weight.push_back(weight);
    }
    b.cell_begin.push_back(static_cast<int32_t>(b.cell_point.size()));
  }
  // Per point, the cells of those cells its escaping directions below the horizon meet.
  std::vector<std::vector<std::pair<int32_t, float>>> per_point(n);
  const double offset = model.surface_offset();
  if (!b.cells.empty()) {
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& r) {
      std::vector<Eigen::Vector3d> dirs;
      for (int i = r.begin(); i < r.end(); ++i) {
        const GridPoint& p = grid.points[i];
        const Eigen::Vector3d origin = p.position + offset * p.normal;
        const double h = origin.z() - field.level_z;
        if (!(h > 0)) continue;
        cache.Directions(p, i, &dirs);
        std::vector<std::pair<int32_t, float>>& out = per_point[i];
        for (int k = 0; k < K; ++k) {
          const Eigen::Vector3d& d = dirs[k];
          if (cache.Hit(i, k) != -1 || !(d.z() < 0)) continue;
          const Eigen::Vector3d q = origin + (h / -d.z()) * d;
          const int c = field.Cell(q.x(), q.y());
          if (c < 0 || index[c] < 0) continue;
          out.emplace_back(index[c],
                           static_cast<float>(
                               AmbientRetroFactor(field.retro, Eigen::Vector3d::UnitZ(), -d) / K));
        }
        MergeEntries(&out);
      }
    });
  }
  b.point_begin.assign(static_cast<size_t>(n) + 1, 0);
  for (int i = 0; i < n; ++i)
    b.point_begin[i + 1] = b.point_begin[i] + static_cast<int32_t>(per_point[i].size());
  b.point_cell.reserve(b.point_begin[n]);
  b.point_weight.reserve(b.point_begin[n]);
  for (int i = 0; i < n; ++i) {
    for (const auto& [w, weight] : per_point[i]) {
      b.point_cell.push_back(w);
      b.point_weight.push_back(weight);
    }
  }
  return b;
}

std::vector<std::shared_ptr<const GroundBounce>> GroundBouncesOf(
    const std::vector<Lighting>& lightings, const RayCaster& model, const SurfaceGrid& grid,
    const HemisphereCache& cache) {
  std::vector<std::shared_ptr<const GroundBounce>> out(lightings.size());
  for (size_t k = 0; k < lightings.size(); ++k) {
    const Lighting& l = lightings[k];
    if (!l.use_env || !l.ground || !l.ground->walls) continue;
    for (size_t m = 0; m < k && !out[k]; ++m)
      if (out[m] && out[m]->field == l.ground.get()) out[k] = out[m];
    if (!out[k])
      out[k] =
          std::make_shared<const GroundBounce>(BuildGroundBounce(*l.ground, model, grid, cache));
  }
  return out;
}

std::vector<Eigen::Vector3f> GroundWallsIrradiance(const GroundBounce& b, const SurfaceGrid& grid,
                                                   const std::vector<Eigen::Vector3d>& rho_sun,
                                                   const std::vector<Eigen::Vector3d>& rho_se,
                                                   const SlotIrradiance& irr,
                                                   const std::vector<double>& retro,
                                                   const Eigen::Vector3d& sun_dir,
                                                   const std::vector<SpecularLobe>& sun_lobes) {
  const size_t n = b.point_begin.empty() ? 0 : b.point_begin.size() - 1;
  if (static_cast<size_t>(grid.size()) != n || rho_sun.size() != n || rho_se.size() != n ||
      irr.sun.size() != n || irr.se.size() != n)
    throw Error("ground bounce: albedo and irradiance sizes do not match the grid");
  std::vector<Eigen::Vector3d> from_sun(n), from_se(n);
  for (size_t j = 0; j < n; ++j) {
    from_sun[j] = rho_sun[j].cwiseProduct(irr.sun[j]);
    from_se[j] = rho_se[j].cwiseProduct(irr.se[j]);
  }
  const Eigen::Vector3d s = sun_dir.normalized();
  std::vector<Eigen::Vector3f> e(static_cast<size_t>(b.field->nx) * b.field->ny,
                                 Eigen::Vector3f::Zero());
  const ReflectionFactors f = CellFactors(b, grid, retro, s, irr, sun_lobes);
  const std::vector<Eigen::Vector3d> from_lobe = LobeLight(grid, sun_lobes, irr);
  for (size_t w = 0; w < b.cells.size(); ++w)
    e[b.cells[w]] = WallsOnCell(b, w, f, from_sun, from_se, from_lobe).cast<float>();
  return e;
}

// §4.1: one-bounce interreflection between model faces.
void AddInterreflection(const SurfaceGrid& grid, const HemisphereCache& cache,
                        const std::vector<Eigen::Vector3d>& rho_sun,
                        const std::vector<Eigen::Vector3d>& rho_se, SlotIrradiance* irr,
                        int bounces, const std::vector<double>& retro,
                        const Eigen::Vector3d& sun_dir, const Cancellation* cancel,
                        std::vector<Eigen::Vector3d>* bounce_order, const GroundBounce* ground,
                        const std::vector<SpecularLobe>& sun_lobes) {
  const int n = grid.size();
  if (static_cast<int>(rho_sun.size()) != n || static_cast<int>(rho_se.size()) != n ||
      static_cast<int>(irr->sun.size()) != n || static_cast<int>(irr->direct_se.size()) != n) {
    throw Error("interreflection: albedo and irradiance sizes do not match the grid (" +
                std::to_string(n) + " points)");
  }
  if (bounces < 1) throw Error("interreflection: bounces must be >= 1");
  if (!sun_dir.allFinite() || sun_dir.norm() == 0)
    throw Error("interreflection: the sun direction must be finite and non-zero");
  const Eigen::Vector3d s = sun_dir.normalized();
  const int K = cache.directions;
  HitLists made;
  if (cache.lists.begin.size() != static_cast<size_t>(n) + 1) made = ListHits(cache, n);
  const HitLists& lists = made.begin.empty() ? cache.lists : made;
  std::vector<Eigen::Vector3d> se_prev = irr->direct_se;
  std::vector<Eigen::Vector3d> from_sun(n), from_se(n);
  std::vector<Eigen::Vector3d> se(n);
  if (ground && static_cast<int>(ground->point_begin.size()) != n + 1)
    throw Error("interreflection: the ground bounce was built for another grid");
  // Per entry m of the hit lists (point i sees point j in count[m] directions): the count
  // times j's reflection towards i of the sun's light and of the sky's.
  ReflectionFactors f{
      std::vector<double>(lists.point.size()), std::vector<double>(lists.point.size()), {}};
  if (AnyLobe(sun_lobes)) f.lobe.assign(lists.point.size(), 0.0);
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i < range.end(); ++i) {
      for (int m = lists.begin[i]; m < lists.begin[i + 1]; ++m) {
        const GridPoint& q = grid.points[lists.point[m]];
        const double r = BlockRetro(retro, q.block);
        f.sun[m] = f.se[m] = lists.count[m];
        const Eigen::Vector3d to_i = grid.points[i].position - q.position;
        const double d = to_i.norm();
        if (!(d > 0)) continue;
        const Eigen::Vector3d v = to_i / d;
        if (!f.lobe.empty()) f.lobe[m] = lists.count[m] * LobeFactor(sun_lobes, q, s, v);
        if (r == 0) continue;
        f.sun[m] *= RetroFactor(r, q.normal, s, v);
        f.se[m] *=
            AmbientRetroFactor(r, q.normal, v, LightAt(irr->se_light, lists.point[m], q.normal));
      }
    }
  });
  const ReflectionFactors cell_factors =
      ground ? CellFactors(*ground, grid, retro, s, *irr, sun_lobes) : ReflectionFactors{};
  // The sun's glint, which does not change from pass to pass (E_sun does not).
  const std::vector<Eigen::Vector3d> from_lobe = LobeLight(grid, sun_lobes, *irr);
  // The directions the last pass's light comes from, mixed into the direct light's (se_light).
  std::vector<LightMoments> light(irr->direct_se_light.empty() ? 0 : n);
  // The light that no pass changes (E_sun does not): per point, what it gets from the sun's
  // light and glint its neighbours and the ground cells reflect; each pass adds their
  // reflection of the last pass's E_se. The last pass sums each entry whole, for the directions
  // of its light.
  std::vector<Eigen::Vector3d> fixed(n, Eigen::Vector3d::Zero());
  for (int j = 0; j < n; ++j) from_sun[j] = rho_sun[j].cwiseProduct(irr->sun[j]);
  std::vector<Eigen::Vector3d> walls_fixed, walls_e;  // per cell of the ground bounce
  if (ground) {
    // The walls' irradiance on each cell times the cell's albedo: what the cell reflects, over
    // pi, before its reflection towards a point.
    walls_fixed.assign(ground->cells.size(), Eigen::Vector3d::Zero());
    tbb::parallel_for(size_t{0}, ground->cells.size(), [&](size_t w) {
      walls_fixed[w] =
          ground->field->Albedo(ground->cells[w])
              .cwiseProduct(WallsOnCell(*ground, w, cell_factors, from_sun, {}, from_lobe));
    });
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i < range.end(); ++i) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int m = lists.begin[i]; m < lists.begin[i + 1]; ++m) {
        sum += f.sun[m] * from_sun[lists.point[m]];
        if (!f.lobe.empty()) sum += f.lobe[m] * from_lobe[lists.point[m]];
      }
      fixed[i] = sum / K;
      if (!ground) continue;
      for (int m = ground->point_begin[i]; m < ground->point_begin[i + 1]; ++m)
        fixed[i] += ground->point_weight[m] * walls_fixed[ground->point_cell[m]];
    }
  });
  for (int pass = 0; pass < bounces; ++pass) {
    ThrowIfCancelled(cancel);
    // Where the light comes from, when the direct light's directions are known.
    const bool last = pass + 1 == bounces && !irr->direct_se_light.empty();
    for (int j = 0; j < n; ++j) from_se[j] = rho_se[j].cwiseProduct(se_prev[j]);
    if (ground) {
      walls_e.assign(ground->cells.size(), Eigen::Vector3d::Zero());
      tbb::parallel_for(size_t{0}, ground->cells.size(), [&](size_t w) {
        walls_e[w] =
            ground->field->Albedo(ground->cells[w])
                .cwiseProduct(
                    last ? WallsOnCell(*ground, w, cell_factors, from_sun, from_se, from_lobe)
                         : WallsOnCell(*ground, w, cell_factors, {}, from_se, {}));
      });
    }
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& range) {
      for (int i = range.begin(); i < range.end(); ++i) {
        const GridPoint& p = grid.points[i];
        if (!last) {
          Eigen::Vector3d sum = Eigen::Vector3d::Zero();
          for (int m = lists.begin[i]; m < lists.begin[i + 1]; ++m)
            sum += f.se[m] * from_se[lists.point[m]];
          // (B_j / pi) (pi / K)
          se[i] = irr->direct_se[i] + fixed[i] + sum / K;
          if (!ground) continue;
          for (int m = ground->point_begin[i]; m < ground->point_begin[i + 1]; ++m)
            se[i] += ground->point_weight[m] * walls_e[ground->point_cell[m]];
          continue;
        }
        LightMomentsSum bounced(p.normal);
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int m = lists.begin[i]; m < lists.begin[i + 1]; ++m) {
          const int j = lists.point[m];
          Eigen::Vector3d b = f.sun[m] * from_sun[j] + f.se[m] * from_se[j];
          if (!f.lobe.empty()) b += f.lobe[m] * from_lobe[j];
          sum += b;
          const Eigen::Vector3d to_j = grid.points[j].position - p.position;
          if (b.sum() > 0 && to_j.norm() > 0) bounced.Add(to_j.normalized(), b.sum());
        }
        se[i] = irr->direct_se[i] + sum / K;
        if (ground) {
          for (int m = ground->point_begin[i]; m < ground->point_begin[i + 1]; ++m) {
            const Eigen::Vector3d e = ground->point_weight[m] * walls_e[ground->point_cell[m]];
            se[i] += e;
            const Eigen::Vector3d to_cell =
                ground->field->CellCentre(ground->cells[ground->point_cell[m]]) - p.position;
            if (e.sum() > 0 && to_cell.norm() > 0) bounced.Add(to_cell.normalized(), K * e.sum());
          }
        }
        light[i] = LightMoments::Mix(
            LightAt(irr->direct_se_light, i, p.normal), irr->direct_se[i].sum(),
            bounced.Moments(UniformLight(p.normal)), (se[i] - irr->direct_se[i]).sum());
      }
    });
    if (bounce_order) {  // the light this pass added was bounced pass + 1 times
      if (pass == 0) bounce_order->assign(n, Eigen::Vector3d::Zero());
      for (int i = 0; i < n; ++i) (*bounce_order)[i] += (pass + 1) * (se[i] - se_prev[i]);
    }
    se_prev = se;
  }
  for (int i = 0; i < n; ++i) {
    if (!se[i].allFinite()) {
      throw Error("interreflection: non-finite irradiance at grid point " + std::to_string(i) +
                  " (non-finite albedo?)");
    }
  }
  irr->se = se;
  if (!irr->direct_se_light.empty()) irr->se_light = std::move(light);
  irr->has_bounce = true;
}

}  // namespace rouen
