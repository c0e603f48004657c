// The ground around the building as a light field (beyond Yu & Malik 1998; §3.3 notes that a
// large building needs more than one environment map, "the surrounding light field is a four
// dimensional distribution"). A panorama at eye height sees the ground at grazing angles, a
// wall 40 m up sees it at 30-70 deg and farther out, and the two see different ground: one map
// of directions cannot light both. Here the landscape panoramas' pixels below the horizon are
// re-projected onto the level ground around the model, and each becomes an albedo: its radiance
// over what lights that spot of ground at its time -- the sun unless the model shades it (from
// the geometry), the sky the model leaves it, the light of the walls it sees (once the model is
// solved) -- through the ground's rough diffuse reflection (solve/retro.h), pooled per plan cell
// over every time. A grid point then sees, along each direction that meets the ground, that
// albedo lit at the time being rendered and seen from where the point stands: the model's cast
// shadow where it lies at that time, the sun's grazing reflection towards the point, not towards
// the panorama, and the walls' light of that time (GroundBounce, solve/irradiance.h).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <nlohmann/json_fwd.hpp>
#include <vector>

#include "solve/environment.h"
#include "solve/raycast.h"

namespace rouen {

// When the solve lights the building with the field. Without it the ground is the environment
// map's directions (§3.3). The field is ground only: the sunlit walls of houses around a tall
// building, which it sees below its horizon, are in it only as the session's surroundings (on
// a tower photographed from the ground, leaving them out made the field's shaded walls 4-9% too
// dark where they face a sunlit house; with them it is within 1-4% of Cycles' light).
enum class GroundFieldUse {
  kNever,
  kWithSurroundings,  // when the session has surroundings (import --surroundings)
  kAlways,
};

struct GroundFieldOptions {
  GroundFieldUse use = GroundFieldUse::kWithSurroundings;
  double cell_m = 2.0;  // plan cell size, metres
  // The field reaches this far beyond the model's footprint: radius_factor x the model's height
  // above the ground, at least min_radius_m (a wall sees the ground within a few heights of it
  // under most of its solid angle).
  double radius_factor = 3.0;
  double min_radius_m = 60.0;
  int64_t max_cells = int64_t{1} << 22;  // refused beyond (memory: 20 bytes a cell)
  // Rays per cell for the sky the model leaves the ground (cosine-weighted over the hemisphere).
  int sky_rays = 64;
  // Read the field again with the light of the walls around each cell, from the model solved
  // with the field read without it, and solve the albedos again (GroundFieldTime::walls_e; the
  // solve's time grows by one albedo solve). false: the walls' light stays in the ground's
  // albedos as it was at the photographed times.
  bool walls = true;
  // Ground no panorama saw takes the albedo of the nearest seen cell that sees at least this
  // part of the sky (open ground, whose light the field models best), of any seen cell where
  // none does.
  double open_sky = 0.9;
  // Fit the ground's rough diffuse reflection (solve/retro.h) to the panoramas: the retro at
  // which every spot of ground seen at several times or from several panoramas reads one albedo
  // (BuildGroundField). false: the retro BuildGroundField is given.
  bool fit_retro = true;
  void Validate() const;  // throws rouen::Error naming the bad field
};

// The sky's radiance arriving from a unit direction above the horizon (RGB; e.g. a lighting's
// escaped radiance).
using SkyByDirection = std::function<Eigen::Vector3d(const Eigen::Vector3d&)>;

// One time's panoramas and what lit the ground then.
struct GroundFieldTime {
  std::vector<EnvPanorama> panoramas;  // landscape panoramas (sky_only ones are skipped)
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();  // unit ENU
  Eigen::Vector3d sun_e = Eigen::Vector3d::Zero();     // sun radiance x solid angle, RGB
  Eigen::Vector3d sky_e = Eigen::Vector3d::Zero();     // sky irradiance on level open ground
  // The sky by direction: a cell loses the sky its walls hide as it is there (HiddenSkyExcess);
  // empty: as the sky's mean (sky_e x the hidden share).
  SkyByDirection sky;
  // The walls' irradiance on each cell of the field being built (its layout as a field built
  // without it has), from the model solved with that field (GroundWallsIrradiance,
  // solve/irradiance.h); empty: not known.
  std::vector<Eigen::Vector3f> walls_e;
};

struct GroundField {
  double level_z = 0;     // the ground's height (GroundLevel)
  double x0 = 0, y0 = 0;  // plan corner of cell (0, 0), metres
  double cell_m = 2;
  int nx = 0, ny = 0;
  double retro = 0;                     // the ground's rough diffuse reflection (solve/retro.h)
  std::vector<Eigen::Vector3f> albedo;  // per cell (row-major in y), observed or filled
  std::vector<uint8_t> observed;        // per cell: 1 when some panorama pixel fell in it
  std::vector<float> sky_visibility;    // per cell: the part of the sky the model leaves it
  int sky_rays = 64;  // rays a cell cast for it (GroundFieldOptions::sky_rays; CastGroundWalls)
  // Whether the albedos were read with the walls' light on the ground (GroundFieldTime::walls_e):
  // then the interreflection adds that light at any time (GroundBounce, solve/irradiance.h).
  // false: the albedos hold it as it was at the times that made them.
  bool walls = false;
  Eigen::Vector3d far_albedo = Eigen::Vector3d::Zero();  // beyond the cells

  bool empty() const { return nx == 0 || ny == 0; }
  int Cell(double x, double y) const;  // -1 outside
  Eigen::Vector3d CellCentre(int cell) const;
  // The part of the sky the model leaves ground point q: the cells' bilinearly between their
  // centres, of the cells that see some sky (none: a cell under the model); 1 beyond the cells.
  double SkyVisibility(const Eigen::Vector3d& q) const;
  Eigen::Vector3d Albedo(int cell) const {
    return cell < 0 ? far_albedo : albedo[cell].cast<double>();
  }

  void Validate() const;  // throws rouen::Error when sizes disagree or values are not finite
};

// What each cell of the field sees of the model: the hits of the cosine-weighted rays cast
// from its four spots outside the model (a spot that sees no sky lies under a wall and casts
// none). The rest of a cell's rays reach the sky: its sky visibility is 1 - hits x weight.
struct GroundWalls {
  struct Hit {
    int triangle = -1;
    float u = 0, v = 0;                                  // barycentric (RayHit)
    Eigen::Vector3f position = Eigen::Vector3f::Zero();  // where the ray met the model
    Eigen::Vector3f from = Eigen::Vector3f::Zero();      // the spot of ground it left
  };
  std::vector<int32_t> begin;  // per cell into `hits`; size cells + 1
  std::vector<Hit> hits;
  std::vector<float> weight;  // per cell: one ray's share of its hemisphere (0: none cast)
  // The part of the sky `cell` sees: 1 - hits x weight; 0 under the model.
  float SkyVisibility(int cell) const;
};

// Casts f.sky_rays rays a cell from every cell of f's layout (level_z, x0, y0, cell_m, nx, ny),
// or with `only_shaded` from the cells whose sky_visibility is below 1 (the others saw no wall
// when the field was built).
GroundWalls CastGroundWalls(const GroundField& f, const RayCaster& model, bool only_shaded);

struct GroundFieldSummary {
  int cells = 0, cells_observed = 0;
  int64_t pixels_used = 0, pixels_model = 0, pixels_far = 0;
  // The ground's retro: given, and the field's (fitted with GroundFieldOptions::fit_retro); the
  // fit's cost (the median cell's RMS log-albedo spread over its times and panoramas) at each,
  // over the cells seen by two or more of them.
  double retro_given = 0, retro = 0, retro_cost_given = 0, retro_cost = 0;
  int retro_cells = 0;
  double seconds = 0;
};

// Re-projects every time's landscape panorama pixels below the horizon onto the level ground
// (GroundLevel of `model`), skipping those whose ray meets the model first, and pools their
// albedo per cell: per time the mean, over the times the median (of the times that saw it in
// sun, where some did). A pixel's albedo is its radiance over what lit that spot: the sun
// unless the model shades it, the sky the model leaves it, and, where every time gives it
// (GroundFieldTime::walls_e), the walls' light (the field's `walls`). The ground
// reflects with `retro`, or with the retro fitted to the pixels (options.fit_retro; `retro`
// where too few cells are seen twice). Cells no pixel fell in take the nearest observed cell's
// albedo, of the open ground's (GroundFieldOptions::open_sky); beyond the cells, the median of the
// observed cells at the field's rim. Throws rouen::Error for bad options or when no pixel meets the
// ground.
GroundField BuildGroundField(const std::vector<GroundFieldTime>& times, const RayCaster& model,
                             double retro, const GroundFieldOptions& options,
                             GroundFieldSummary* summary = nullptr);

// Per cell of `walls`' field: how much more sky irradiance its walls hide than the sky's mean
// would (sky_e x the share of its rays they stop): sum over the rays a wall stops of the ray's
// weight x (pi L(ray) - sky_e). A spot beside a wall facing away from a low sun loses the bright
// sky round the sun, not an average sky; a cell no wall hides any sky of has 0. Empty when
// `sky` is.
std::vector<Eigen::Vector3d> HiddenSkyExcess(const GroundWalls& walls, const SkyByDirection& sky,
                                             const Eigen::Vector3d& sky_e);

// The ground at one time: the field lit by a sun and a sky, the model's shadow where each
// query meets the ground (one shadow ray: a cell's 2 m would make the shadow's edge a staircase
// and darken the cells whose centre lies under a wall). The walls' light on the ground depends
// on the model's albedos: the interreflection adds it (GroundBounce, solve/irradiance.h).
class GroundLight {
 public:
  // `hidden_excess` (per cell, HiddenSkyExcess of the field's walls under this time's sky;
  // empty: none): the sky a cell's walls hide taken as it is in their directions, as
  // BuildGroundField read the albedos given GroundFieldTime::sky.
  GroundLight(const GroundField& field, const RayCaster& model, const Eigen::Vector3d& sun_dir,
              const Eigen::Vector3d& sun_e, const Eigen::Vector3d& sky_e,
              std::vector<Eigen::Vector3d> hidden_excess = {});
  // Radiance leaving ground point q (on the ground plane) towards unit direction `to_viewer`.
  Eigen::Vector3d Radiance(const Eigen::Vector3d& q, const Eigen::Vector3d& to_viewer) const;
  // Radiance arriving from unit direction d (d.z < 0) at `origin` (above the ground), the ray
  // assumed to meet nothing of the model before the ground.
  Eigen::Vector3d Arriving(const Eigen::Vector3d& origin, const Eigen::Vector3d& d) const;
  const GroundField& field() const { return *field_; }

 private:
  const GroundField* field_;
  const RayCaster* model_;
  Eigen::Vector3d sun_dir_, sun_e_, sky_e_;
  std::vector<Eigen::Vector3d> hidden_excess_;  // per cell (HiddenSkyExcess); empty: none
};

// The options as SolveConfigJson records them ([ground_field]; ApplySolveConfig reads them).
void to_json(nlohmann::json& j, const GroundFieldOptions& o);
void to_json(nlohmann::json& j, const GroundField& f);
void from_json(const nlohmann::json& j, GroundField& f);  // validates

}  // namespace rouen
