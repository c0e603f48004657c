// Coarse environment radiance map (Yu & Malik 1998, §3.3): the sphere of directions divided
// into latitude-longitude regions, each holding the average radiance of the panorama pixels
// that fall into it. Directions are unit ENU vectors; azimuth from north eastward.
//
// §3.3 notes that a large building may need environment maps from several places: the map
// holds one layer per panorama height (e.g. one from the ground and one from a mast at the
// top of the building), and a point of the building looks the environment up at its own
// height, linearly between the layers.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <vector>

#include "core/angles.h"
#include "core/camera.h"
#include "core/image.h"
#include "solve/raycast.h"
#include "solve/sky_model.h"

namespace rouen {

struct EnvOptions {
  int bands_below = 9;             // elevation bands in [-90, 0] deg
  int bands_above = 9;             // elevation bands in [0, 90] deg
  int sectors = 24;                // azimuth sectors over 360 deg
  double sun_exclusion_deg = 2.0;  // panorama pixels this close to the sun are skipped
  int pixel_stride = 1;            // use every stride-th panorama pixel in x and y
  int min_region_pixels = 4;       // fewer pixels than this: the region counts as unobserved
  int sky_fill_samples = 8;        // per axis, to average the sky model over a region
  // Panoramas taken less than this far apart in height share one layer (their pixels are
  // pooled; the layer sits at their mean height), metres.
  double layer_merge_m = 2.0;
  // Beyond the paper: a panorama pixel whose ray meets the ground (the model's lowest level)
  // where the model casts its shadow is read as that ground sunlit, its radiance scaled by the
  // inverse of the ground's shadowed/sunlit ratio along its ray (GroundShadowRatio, with
  // EnvSun::ground_retro). The map then holds the ground as lit by sun and sky, and the
  // irradiance puts the model's shadow back where each grid point sees it
  // (IrradianceOptions::ground_shadow): a wall whose ground is sunlit no longer sees the
  // shadow that lay in front of the panorama. Needs EnvSun::irradiance.
  bool lit_ground = true;
  // Beyond the paper: the sky's detail inside each region above the horizon, on a finer grid of
  // sky_detail x sky_detail cells per region. A region keeps its measured mean, and the
  // irradiance spreads it over the region as the sky model times the panoramas' residual
  // against it per cell (SkyShape): the fine structure near the sun and the horizon survives.
  // 1: uniform regions, as the paper's map.
  int sky_detail = 4;
  // Beyond the paper: a region above the horizon no photograph saw takes the sky model's mean
  // times the median ratio of the observed regions of its elevation band to the model's mean
  // over them (when a quarter of the band's sectors or more were observed), not the model
  // alone: trees and distant roofs hide the low sky all round, and a seven-parameter sky
  // overestimates the horizon band away from the sun (on the Rouen world at a 10 deg sun the
  // observed regions of the lowest band read 0.6-0.8 of the model). false: the model alone.
  bool fill_band_residual = true;

  void Validate() const;  // throws rouen::Error
};

// The most sky detail cells a map may have (EnvOptions::sky_detail): 1 deg cells over the sky
// are 32400.
inline constexpr int64_t kMaxDetailCells = 1 << 20;

// The sun at the panoramas' time.
struct EnvSun {
  Eigen::Vector3d dir = Eigen::Vector3d::UnitZ();  // unit ENU, towards the sun
  double angular_radius_rad = 0;                   // pixels within the disc are skipped
  // Radiance x solid angle (RGB), for EnvOptions::lit_ground; zero leaves the ground as seen.
  Eigen::Vector3d irradiance = Eigen::Vector3d::Zero();
  // How roughly the ground reflects it (EnvironmentMap::ground_retro).
  double ground_retro = 0;
};

enum class EnvRegionSource : uint8_t {
  kObserved = 0,   // mean of panorama pixels
  kSkyModel = 1,   // above the horizon, never observed: sky model mean over the region
  kNeighbour = 2,  // below the horizon, never observed: nearest observed region
  kConstant = 3,   // set by hand (tests, defaults)
};

struct EnvironmentMap {
  int bands_below = 9, bands_above = 9, sectors = 24;
  // Heights of the layers (ENU z, metres; the panoramas' camera heights), increasing.
  std::vector<double> layer_z = {0.0};
  // Per layer, then per region: band-major from the nadir band upwards, sector from azimuth 0
  // eastwards.
  std::vector<Eigen::Vector3d> radiance;  // relative radiance, RGB
  std::vector<int> pixel_count;           // panorama pixels averaged (0 when filled)
  std::vector<EnvRegionSource> source;
  // How roughly the ground reflects (solve/retro.h; 0: Lambert), with which its shadow was read
  // as sunlit (EnvOptions::lit_ground) and is put back (GroundShadowRatio, the irradiance).
  double ground_retro = 0;
  // Above the horizon, each region split into detail x detail cells (EnvOptions::sky_detail),
  // and per cell the panoramas' residual against the sky model there, relative to the region's
  // (observed / model over the cell's pixels, divided by the same over the region's; 1 where no
  // pixel was seen). Pooled over the layers. Empty: 1 everywhere (the model's shape alone).
  // Cells are band-major from the horizon up, then by azimuth, as the regions.
  int detail = 1;
  std::vector<Eigen::Vector3f> sky_detail;
  // The panoramas' pixels this close to the sun were not averaged (EnvOptions::sun_exclusion_deg):
  // the shape takes the sky model no closer to the sun than this, radians.
  double sun_exclusion_rad = 2.0 * kDeg;

  int num_bands() const { return bands_below + bands_above; }
  int num_regions() const { return num_bands() * sectors; }
  int num_layers() const { return static_cast<int>(layer_z.size()); }
  int Region(const Eigen::Vector3d& dir) const;  // `dir` need not be unit
  int num_detail_cells() const { return bands_above * sectors * detail * detail; }
  // The detail cell of a direction above the horizon (`dir` need not be unit), -1 below it.
  int DetailCell(const Eigen::Vector3d& dir) const;
  // The region a detail cell belongs to.
  int RegionOfCell(int cell) const {
    const int row = cell / (sectors * detail), col = cell % (sectors * detail);
    return (bands_below + row / detail) * sectors + col / detail;
  }
  // Cell bounds in radians: elevation [lo, hi], azimuth [lo, hi].
  void CellBounds(int cell, double* el_lo, double* el_hi, double* az_lo, double* az_hi) const;
  // The lowest layer (the lowest panorama's height).
  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir) const { return radiance[Region(dir)]; }
  // Seen from height z: linear between the layers, clamped at the ends.
  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir, double z) const {
    return RegionRadiance(Region(dir), z);
  }
  // The same for a region found once (Region) and looked up under several maps of one layout.
  Eigen::Vector3d RegionRadiance(int region, double z) const;
  bool SameLayout(const EnvironmentMap& o) const {
    return bands_below == o.bands_below && bands_above == o.bands_above && sectors == o.sectors;
  }
  // Region bounds in radians: elevation [lo, hi], azimuth [lo, hi].
  void RegionBounds(int region, double* el_lo, double* el_hi, double* az_lo, double* az_hi) const;
  // Fraction of regions of the lowest layer that were observed.
  double ObservedFraction() const;
  // Irradiance on an unoccluded horizontal plane from the regions above the horizon (lowest
  // layer): sum of radiance x projected solid angle.
  Eigen::Vector3d HorizontalSkyIrradiance() const;
  // Throws rouen::Error when the sizes disagree or a radiance is negative or not finite.
  void Validate() const;

  // A map with one radiance above the horizon and another below (tests, fallbacks).
  static EnvironmentMap Constant(const EnvOptions& options, const Eigen::Vector3d& above,
                                 const Eigen::Vector3d& below);
  // The sky model averaged per region above the horizon, `ground` below.
  static EnvironmentMap FromSky(const EnvOptions& options, const SkyModel& sky,
                                const Eigen::Vector3d& ground);
};

// The radiance of each region above the horizon spread over it (EnvOptions::sky_detail): per
// detail cell, the sky model's mean over the cell times the cell's residual (sky_detail),
// divided by the region's solid-angle mean of the same, so that the shape averages to 1 over
// each region and the region keeps its measured mean. Built per lighting; ones below the
// horizon and everywhere when the map has detail 1.
class SkyShape {
 public:
  SkyShape(const EnvironmentMap& env, const SkyModel& sky);
  bool uniform() const { return shape_.empty(); }
  // The shape (per channel) at `dir` taken into region `region`'s cells (a part of a region seen
  // towards a direction just outside it, as its great-arc edges bulge): the nearest of its cells.
  Eigen::Vector3d InRegion(const Eigen::Vector3d& dir, int region) const;
  // The shape of detail cell `cell` (EnvironmentMap::DetailCell; -1, below the horizon: 1).
  Eigen::Vector3d OfCell(int cell) const {
    if (cell < 0 || shape_.empty()) return Eigen::Vector3d::Ones();
    return shape_[cell].cast<double>();
  }
  // Region `region` (above the horizon) wholly seen: row c is the integral over it of the shape
  // times w (sr), the region's own flux `region_flux` (eq. 20 of the polygon that stands for it)
  // where the shape is 1, so n . row_c is the cosine-weighted integral of a unit mean radiance.
  Eigen::Matrix3d Moment(int region, const Eigen::Vector3d& region_flux) const;

 private:
  const EnvironmentMap* env_;
  std::vector<Eigen::Vector3f> shape_;   // per detail cell
  std::vector<Eigen::Matrix3d> moment_;  // per region above the horizon: sum of shape x flux
  std::vector<Eigen::Vector3d> flux_;    // per region above the horizon: sum of the cells' flux
};

void to_json(nlohmann::json& j, const EnvironmentMap& m);
void from_json(const nlohmann::json& j, EnvironmentMap& m);  // validates

struct EnvSummary {
  int pixels_used = 0;
  int pixels_model = 0;          // rays that hit the model (building, plaza): skipped
  int pixels_sun = 0;            // within sun_exclusion_deg of the sun: skipped
  int pixels_invalid = 0;        // non-finite or negative: skipped
  int pixels_ground_shadow = 0;  // on the ground in the model's shadow: read as sunlit
  // Regions of all layers by source.
  int regions_observed = 0, regions_sky = 0, regions_neighbour = 0;
  double seconds = 0;
};

// One HDR landscape panorama (any projection) and where it was taken.
struct EnvPanorama {
  const Image* radiance = nullptr;  // kRadiance, >= 3 channels; not owned
  Intrinsics intrinsics;
  Pose pose;
  // A sky photo (fisheye or panorama from the mast): only its pixels above the horizon are
  // read, for the sky regions no landscape panorama saw (the building hides them from the
  // ground); it makes no layer.
  bool sky_only = false;
};

// §3.3: averages HDR panoramas over the regions, one layer per panorama height (see
// EnvOptions::layer_merge_m). Pixels whose ray from the panorama position hits the model are
// skipped (the model is lit by interreflection), as are pixels near the sun and invalid ones;
// ground in the model's shadow is read as sunlit (EnvOptions::lit_ground).
// In each layer, regions above the horizon no landscape panorama saw take the sky photos'
// (EnvPanorama::sky_only) mean there, else the sky model's mean over the region; below, the nearest
// observed region in the same band, else the nearest band with observations (towards the horizon
// first). Throws rouen::Error for no panorama or bad input.
EnvironmentMap BuildEnvironmentMap(const std::vector<EnvPanorama>& panoramas,
                                   const RayCaster& model, const EnvSun& sun, const SkyModel& sky,
                                   const EnvOptions& options, EnvSummary* summary = nullptr);

// Fills the regions below the horizon of one layer that no panorama saw (source not
// kObserved): the nearest observed sector in the band, else the nearest band with any
// observation (towards the horizon first); kNeighbour, or kConstant 0 when the layer saw nothing
// below the horizon. BuildEnvironmentMap fills its maps so, and a predicted map the same way.
void FillBelowHorizon(EnvironmentMap* m, int layer);

// Every layer's regions below the horizon set to zero radiance: the map's sky alone.
void ZeroBelowHorizon(EnvironmentMap* m);

// The shadowed/sunlit radiance ratio of horizontal ground of roughness `ground_retro`
// (solve/retro.h; 0: Lambert) under a sky of horizontal irradiance `e_sky`
// (EnvironmentMap::HorizontalSkyIrradiance) and a sun of irradiance `sun_e` (radiance x solid
// angle) from unit `sun_dir`, seen from unit direction `view` (ground to viewer), per channel:
//   e_sky A(view) / (e_sky A(view) + sun_e sin(el) D(sun, view)),
// D and A the sun's and sky's factors (RetroFactor, AmbientRetroFactor; 1 for Lambert). A
// rough ground seen with the sun behind is brighter sunlit, so its shadow is darker beside it.
Eigen::Vector3d GroundShadowRatio(double ground_retro, const Eigen::Vector3d& e_sky,
                                  const Eigen::Vector3d& sun_e, const Eigen::Vector3d& sun_dir,
                                  const Eigen::Vector3d& view);

// The level of the ground around the model (ENU z): its lowest vertex. The environment's lit
// ground and the irradiance's ground shadow both take the ground there.
double GroundLevel(const RayCaster& model);

}  // namespace rouen
