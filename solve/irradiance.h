// Irradiance at the surface grid points from the sun, the sky and the environment, with
// one-bounce interreflection between model faces (Yu & Malik 1998, §4.1 and App. A). The
// direct sky + environment term is either integrated numerically over cosine-distributed
// directions with ray-cast visibility (Monte Carlo) or, as the paper does, analytically as
// the vector flux of clipped spherical polygons (solve/vector_flux.h).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/cancel.h"
#include "core/mesh.h"
#include "core/time.h"
#include "solve/environment.h"
#include "solve/grid.h"
#include "solve/ground_field.h"
#include "solve/raycast.h"
#include "solve/retro.h"
#include "solve/sky_model.h"
#include "solve/specular.h"
#include "solve/vector_flux.h"

namespace rouen {

// Illumination at one time: sun (parallel source, §3.1), sky model (§3.2), environment (§3.3).
struct Lighting {
  UtcTime utc;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();      // unit ENU, towards the sun
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();  // relative radiance, RGB
  double sun_solid_angle_sr = 6.8e-5;
  SkyModel sky;
  EnvironmentMap env;
  // true: escaped directions take env.Radiance (which holds the observed sky and landscape);
  // false: the sky model above the horizon and nothing below.
  bool use_env = true;
  // With use_env: the ground as a light field (solve/ground_field.h), shared by every time;
  // escaped directions below the horizon take it lit at this time instead of the map's regions
  // there (and the map's ground shadow). Null: the map's directions alone.
  std::shared_ptr<const GroundField> ground;

  double SunAngularRadius() const;  // radians, from the solid angle
  // The same lighting with nothing below the horizon: the map's regions there zero and no
  // ground field (what the sky alone gives, for splitting the irradiance by term).
  Lighting SkyOnly() const;
  // Radiance arriving at height z (ENU metres) from direction `dir` when nothing of the model
  // is in the way (no sun): the environment's region means (the specular lobes' light);
  // ComputeIrradiance spreads the sky regions by the sky's shape (SkyShape) too.
  Eigen::Vector3d EscapedRadiance(const Eigen::Vector3d& dir, double z) const;
};

struct HemisphereOptions {
  int directions = 256;                  // per grid point; rounded up to a square number of strata
  uint64_t seed = 1;                     // per-point rotations and shifts (deterministic)
  const Cancellation* cancel = nullptr;  // polled per few points (not owned; null: none)
  void Validate() const;
};

// Which grid points each point's gathering directions hit, and through how many of them: the
// interreflection sums over these (AddInterreflection) instead of every direction.
struct HitLists {
  std::vector<int32_t> begin;  // per point, into `point` and `count`; size points + 1
  std::vector<int32_t> point;  // increasing per point
  std::vector<int32_t> count;
};

// Geometry-only gathering pattern, built once per model and reused for every time. For grid
// point i and direction k: dir(i, k) is a stratified cosine-distributed direction about the
// point's normal; hit(i, k) is -1 when the ray escapes the model, -2 when it hits the back of
// a face, else the grid point it hits. A cosine-weighted estimate of the irradiance is
// E = (pi / K) sum_k L(dir(i, k)).
struct HemisphereCache {
  int directions = 0;  // K
  int strata = 0;      // K = strata^2
  uint64_t seed = 1;
  std::vector<int32_t> hit;             // size points * K
  std::vector<float> escaped_fraction;  // per point: cosine-weighted sky view factor
  HitLists lists;  // of `hit` (BuildHemisphereCache; empty in a cache made otherwise)
  double seconds = 0;
  int64_t rays = 0;

  Eigen::Vector3d Direction(const GridPoint& p, int point_index, int k) const;
  // All K of them (the same values), the point's shift and each stratum's trigonometry shared.
  void Directions(const GridPoint& p, int point_index, std::vector<Eigen::Vector3d>* out) const;
  int Hit(int point, int k) const { return hit[static_cast<size_t>(point) * directions + k]; }
};

HemisphereCache BuildHemisphereCache(const SurfaceGrid& grid, const RayCaster& model,
                                     const HemisphereOptions& options = {});
// The hit lists of `cache.hit` for `points` grid points.
HitLists ListHits(const HemisphereCache& cache, int points);

// Irradiance per grid point, RGB, in the lighting's relative radiance units x sr.
struct SlotIrradiance {
  std::vector<Eigen::Vector3d> sun;        // E_sun: solar disc, with cast shadows
  std::vector<Eigen::Vector3d> direct_se;  // sky + environment reaching the point directly
  std::vector<Eigen::Vector3d> se;         // E_se = direct_se + interreflection (when added)
  // Beyond the paper: where the light comes from, per point (solve/retro.h; the rough
  // reflection's AmbientRetroFactor needs it): direct_se's from the hemisphere cache's escaped
  // directions (ComputeIrradiance), se's with the directions of the points and ground cells
  // that light it mixed in (AddInterreflection). Empty: from the whole hemisphere at one
  // radiance.
  std::vector<LightMoments> direct_se_light, se_light;
  std::vector<float> sun_visibility;  // fraction of the sun disc samples unoccluded
  bool has_bounce = false;
  double seconds = 0;
};

// Where point i's light comes from in `light` (SlotIrradiance::se_light or direct_se_light), or
// from the whole hemisphere above `normal` when the irradiance does not say.
inline LightMoments LightAt(const std::vector<LightMoments>& light, int i,
                            const Eigen::Vector3d& normal) {
  return static_cast<size_t>(i) < light.size() ? light[i] : UniformLight(normal);
}

enum class IrradianceMethod {
  kMonteCarlo,  // the hemisphere cache's directions (noisy, any geometry)
  kVectorFlux,  // App. A: vector flux of clipped spherical polygons (needs `mesh`)
};

struct IrradianceOptions {
  // How the direct sky + environment term E_direct_se is integrated. The sun and the
  // interreflection (AddInterreflection, through the hemisphere cache) are the same for both.
  IrradianceMethod method = IrradianceMethod::kMonteCarlo;
  VectorFluxOptions vector_flux;
  // The model mesh the RayCaster was built from (not owned); kVectorFlux projects its faces onto
  // each point's sphere of directions, and ComputeIrradiance refuses that method without it.
  const Mesh* mesh = nullptr;
  // kVectorFlux: the points (nonzero; one per grid point, not owned) whose direct term is
  // exact; the others take the hemisphere cache's Monte Carlo estimate (points only the
  // interreflection uses, as the light they send: its 2.9% noise per point averages out over
  // the many points each receiver sees). nullptr: every point exact.
  const std::vector<uint8_t>* exact_points = nullptr;
  int sun_samples = 1;  // shadow rays per point over the sun disc (1: centre only)
  // Where the light comes from (SlotIrradiance::direct_se_light, se_light), which only a rough
  // block's reflection needs: false leaves them empty (light as from the whole hemisphere) and
  // spares the vector-flux points a pass over their escaped directions.
  bool light_directions = true;
  // Beyond the paper: the environment below the horizon is taken as flat ground at the model's
  // lowest level (GroundLevel), sunlit as the map holds it (EnvOptions::lit_ground); where an
  // escaped ray meets that ground inside the model's cast shadow, its radiance is scaled by the
  // ground's shadowed/sunlit ratio seen along the ray (GroundShadowRatio; a tall building
  // darkens the far ground it sees in the morning and evening). kVectorFlux: the shadowed
  // ground is the model's faces projected along the sun onto that ground, clipped on the
  // sphere like the occluders, with one ratio per point, seen towards the shadow's middle.
  bool ground_shadow = true;
  // Polled per few points and per bounce (not owned; null: the work cannot be stopped).
  const Cancellation* cancel = nullptr;
  void Validate() const;
};

// E_sun[i] = L_sun Omega max(0, n.s) V and E_se[i] = (pi/K) sum over escaped directions of L
// (kMonteCarlo), or sum over visible sky patches / environment regions of L n.Phi
// (kVectorFlux; the sky as the SkyPatchTree clipped per point against the sky integrated once
// per call, solve/vector_flux_cache.h). With an environment map of detail > 1, L of a region
// above the horizon is its mean times the lighting's SkyShape (per detail cell; the vector flux
// takes a wholly visible region's shape moment, a part's shape towards its flux).
SlotIrradiance ComputeIrradiance(const SurfaceGrid& grid, const HemisphereCache& cache,
                                 const RayCaster& model, const Lighting& lighting,
                                 const IrradianceOptions& options = {});
// The same for several lightings at once: the vector flux's per-point geometry (the faces in
// front, each environment layout's and the sky tree's clipping) is computed once and shared by
// all of them; the result is as each lighting's own call. `seconds` is the mean per lighting.
std::vector<SlotIrradiance> ComputeIrradiance(const SurfaceGrid& grid, const HemisphereCache& cache,
                                              const RayCaster& model,
                                              const std::vector<Lighting>& lightings,
                                              const IrradianceOptions& options = {});

// n unit directions spread over the sun's disc of `angular_radius` (radians) around unit sun_dir,
// uniform in area (a Fibonacci spiral from the centre out; n = 1: the centre); `rim` more on the
// disc's edge, evenly round it, appended.
std::vector<Eigen::Vector3d> SunDiscDirections(const Eigen::Vector3d& sun_dir,
                                               double angular_radius, int n, int rim = 0);

// Beyond §4.1: the light the model's faces send each other by way of the ground field
// (Lighting::ground): the walls light the ground around them (GroundWalls), the ground lights
// the faces. Geometry only, shared by every time lit by that field.
struct GroundBounce {
  const GroundField* field = nullptr;  // not owned
  std::vector<int32_t> cells;          // the field's cells whose rays meet grid points
  // Per entry of `cells`, into cell_point and cell_weight: the grid points its rays meet, each
  // with the share of the cell's hemisphere they cover.
  std::vector<int32_t> cell_begin, cell_point;
  std::vector<float> cell_weight;
  // Per grid point, into point_cell (entries of `cells`) and point_weight: the cells its
  // hemisphere directions meet on the ground, each with (1 / K) x the sum over those directions
  // of the ground's reflection of ambient light towards the point (AmbientRetroFactor).
  std::vector<int32_t> point_begin, point_cell;
  std::vector<float> point_weight;
  bool empty() const { return cells.empty(); }
};

// `model` the ray-casting model of `grid`; the directions below the horizon that escape it in
// `cache` meet the ground as ComputeIrradiance's ground light does.
GroundBounce BuildGroundBounce(const GroundField& field, const RayCaster& model,
                               const SurfaceGrid& grid, const HemisphereCache& cache);
// Per lighting, the bounce of its ground field (use_env with a Lighting::ground whose albedos
// were read with the walls' light, GroundField::walls; built once per field), null for a
// lighting without one.
std::vector<std::shared_ptr<const GroundBounce>> GroundBouncesOf(
    const std::vector<Lighting>& lightings, const RayCaster& model, const SurfaceGrid& grid,
    const HemisphereCache& cache);
// The walls' irradiance on every cell of b.field at one time (zero on those that see none), from
// the radiosity of `grid`'s points B_j = rho_sun_j E_sun_j + rho_se_j E_se_j, sent towards the
// cell as AddInterreflection sends it (`retro` per block, the sun towards `sun_dir`, the
// blocks' `sun_lobes`): what
// GroundFieldTime::walls_e holds for a field read with the walls' light.
std::vector<Eigen::Vector3f> GroundWallsIrradiance(
    const GroundBounce& b, const SurfaceGrid& grid, const std::vector<Eigen::Vector3d>& rho_sun,
    const std::vector<Eigen::Vector3d>& rho_se, const SlotIrradiance& irr,
    const std::vector<double>& retro = {},
    const Eigen::Vector3d& sun_dir = Eigen::Vector3d::UnitZ(),
    const std::vector<SpecularLobe>& sun_lobes = {});

// One-bounce interreflection (§4.1): E_se[i] = E_direct_se[i] + (pi/K) sum over directions
// hitting point j of B_j / pi, with B_j = rho_sun_j E_sun_j + rho_se_j E_direct_se_j. With
// bounces > 1 the radiosity is iterated (B_j uses the previous E_se). Overwrites irr->se.
// Beyond the paper: a point of a rough block (`retro` per block, solve/retro.h; empty: Lambert
// everywhere) sends its light towards point i as the photos see it towards their cameras,
// B_j = rho_sun_j E_sun_j D(retro, n_j, sun_dir, v) + rho_se_j E_se_j A(retro, n_j, v), v
// towards i (RetroFactor, AmbientRetroFactor): rough ground seen from a wall at a grazing angle
// is brighter than Lambert's law, as the photos that gave its albedo saw it.
// `bounce_order` (when given) receives per point the sum over k of k x the light bounced k
// times: over the point's whole light, how fast it grows with the albedos (d log E / d log rho
// when every albedo scales alike), which the albedo solve's outer iteration steps by.
// With `ground`, each pass adds the light the points send by way of the ground: a cell's
// irradiance from the walls E_c = sum over its points j of share x B_j (sent towards the cell
// as towards a point), reflected
// towards point i with the cell's albedo, E_se[i] += sum_c weight x rho_c E_c.
// Beyond the paper: a point of a block with a sun lobe (`sun_lobes` per block, §4.2.2's eq. 13
// or the microfacet lobe; empty: none) also sends the sun's glint, B_j += pi f_s(sun_dir, v)
// E_sun_j: a slate roof's north slope under a high sun throws it onto the houses across the
// street (on the nave world, without it their sunlit walls got 6-10% less light than Cycles'
// passes say, with it 0.99-1.03 of it).
void AddInterreflection(const SurfaceGrid& grid, const HemisphereCache& cache,
                        const std::vector<Eigen::Vector3d>& rho_sun,
                        const std::vector<Eigen::Vector3d>& rho_se, SlotIrradiance* irr,
                        int bounces = 1, const std::vector<double>& retro = {},
                        const Eigen::Vector3d& sun_dir = Eigen::Vector3d::UnitZ(),
                        const Cancellation* cancel = nullptr,
                        std::vector<Eigen::Vector3d>* bounce_order = nullptr,
                        const GroundBounce* ground = nullptr,
                        const std::vector<SpecularLobe>& sun_lobes = {});

}  // namespace rouen
