// Environment radiance model (Yu & Malik 1998, §5.2): photometric stereo per region of the
// coarse environment map. Each landscape region is a Lambertian patch with an unknown normal
// and two pseudo-albedos (one for the sky's spectrum, one for the sun's), lit by the sun and
// the sky at several times of day; the recovered model predicts the environment map at a
// novel time from that time's sun and sky.
//
// Per region, channel c and time t (eq. 18, smooth in n.l; n not unit, one rho_sun fixed):
//   I_c(t) = k_sky_c E_sky_c(t, n/|n|) + k_sun_c E_sun_c(t) S(n, l(t)),
//   S(n, l) = n.l                                if n.l >= 0,
//             |n| (exp(alpha n.l / |n|) - 1) / alpha   otherwise,
// k = rho / pi (Lambertian: radiance = rho / pi x irradiance); E_sun = L_sun x sun solid angle
// (irradiance at normal incidence); rho_sun reported = pi k_sun |n|, normal = n / |n|.
// Units: radiance and irradiance in the lighting's relative units (irradiance = radiance x sr);
// albedos are dimensionless. Directions are unit ENU vectors.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/cancel.h"
#include "solve/environment.h"
#include "solve/sky_model.h"

namespace rouen {

// Sun and sky at one time (the inputs of a prediction).
struct EnvLighting {
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();      // unit ENU, towards the sun
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();  // mean disc radiance, RGB
  double sun_solid_angle_sr = 6.8e-5;
  SkyModel sky;
};

// One training time: the environment map built from that time's panoramas and its lighting.
struct EnvObservation {
  EnvironmentMap env;
  EnvLighting lighting;
};

// How E_sky is computed for a region.
enum class EnvSkyIrradiance : uint8_t {
  // The paper's eq. 16: the sky is an ambient source; E_sky is the magnitude of the total
  // flux from the sky (irradiance on an unoccluded horizontal plane), the same for all normals.
  kAmbient = 0,
  // Beyond the paper: irradiance from the sky model on an unoccluded plane with the region's
  // normal (upper hemisphere only), plus, when ground_albedo > 0, light from a flat Lambertian
  // ground lit by the sun and sky (the lower hemisphere).
  kPlane = 1,
};

struct EnvStereoOptions {
  double alpha = 1000;  // eq. 18's smoothing constant (large)
  // The rho_sun component held constant (eq. 17: it fixes the scale of the non-unit normal).
  int fixed_channel = 1;       // 0..2 (G)
  double fixed_rho_sun = 0.1;  // its value, as an albedo
  EnvSkyIrradiance sky_irradiance = EnvSkyIrradiance::kPlane;
  double ground_albedo = 0;  // kPlane only: albedo of the flat ground below the horizon
  int sky_quadrature = 12;   // kPlane: elevation rings (x 2 x as many azimuths) over the sky
  // Fewer training times than this: the photometric system is underdetermined (8 unknowns,
  // 3 equations per time) and every region takes the sky-only fallback.
  int min_times = 3;
  // Sky detection (above the horizon): a region whose observed radiance is within this
  // relative error of the sky model's mean over the region (every channel, mean over the times
  // where it was observed), or which the map filled from the sky model at every time, is sky
  // and is predicted by the novel time's sky model.
  double sky_match_tolerance = 0.15;
  // Above-horizon landscape regions get an extra unknown f in [0, 1], the fraction of the
  // region that is sky: + f x (sky model mean over the region).
  bool fit_sky_fraction = true;
  // Sky-only fallback (§5.2): a region whose weighted RMS relative residual exceeds this and
  // whose normal points away from the viewer (n . d > 0, d the region's direction from the
  // panorama; above the horizon, pointing away whatever the residual), or whose normal faces
  // the sun at no training time, keeps only rho_sky, with the fitted normal if it faces the
  // viewer, else the direction towards the viewer.
  double fallback_rel_error = 0.1;
  // Beyond the paper: a fit with an albedo above this (a normal the sun barely lit, whose
  // length ran away) also falls back to sky-only.
  double max_albedo = 1.5;
  // Residual sigma per sample: s x I + (1 - s) x (the region's mean radiance in the channel
  // over the times), s = sigma_relative in [0, 1]. s = 0 (default): residuals relative to the
  // region's mean; noise-free weights, so noise does not bias the fit. s -> 1: relative to each
  // sample (dark times weigh more, but a noisy I in its own weight biases the fit low).
  double sigma_relative = 0;
  // Optional smoothing between adjacent landscape regions of a layer (§5.2 "a smoothing term
  // between adjacent regions may also help"): weight on the difference of unit normals, in
  // units of the relative data residuals, with a Huber loss (edges survive) and never across
  // the horizon; all landscape regions are then refined together. 0: regions independent.
  // On the demo world it does not help (its landscape is mostly real edges); it does on a
  // noisy uniform ground.
  double smoothing_weight = 0;
  // Beyond the paper: regions below the horizon are mostly ground. `ground_retro` lets their
  // sunlight follow solve/retro.h's RetroFactor with the normal up and the view towards the
  // panorama (0: Lambert), so a rough ground seen at grazing angles keeps its brightness
  // pattern when the sun moves; `ground_normal_prior` pulls their unit normal towards up
  // (weight in units of the relative data residuals; 0: free), as four or five training suns
  // barely constrain the normal and a tilted one extrapolates badly to a low sun.
  double ground_retro = 0;
  double ground_normal_prior = 1;
  int max_iterations = 100;  // Levenberg-Marquardt, per start
  // 1..3 start normals: towards the viewer, up, level towards the viewer. The lowest cost
  // wins, but a normal facing the viewer beats any facing away (that side cannot be seen).
  int starts = 3;

  void Validate() const;  // throws rouen::Error naming the bad field
  bool operator==(const EnvStereoOptions&) const = default;
};

enum class EnvRegionKind : uint8_t {
  kSky = 0,         // above the horizon and explained by the sky model
  kLandscape = 1,   // full photometric model (sun + sky)
  kSkyOnly = 2,     // fallback: rho_sky only (never sunlit, or the fit failed)
  kUnobserved = 3,  // never observed nor filled (radiance 0 in every map): predicted 0
};

const char* EnvRegionKindName(EnvRegionKind kind);

struct EnvRegionFit {
  EnvRegionKind kind = EnvRegionKind::kUnobserved;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit ENU (the fallback's: fixed)
  Eigen::Vector3d rho_sky = Eigen::Vector3d::Zero();  // albedo for the sky's light
  Eigen::Vector3d rho_sun = Eigen::Vector3d::Zero();  // albedo for the sun's light
  double sky_fraction = 0;                            // f, above-horizon regions only
  double rel_rms = 0;    // RMS of (model - I) / sigma over times and channels
  int sunlit_times = 0;  // training times with normal . sun > 0
  // Below the horizon with ground_retro: unit direction from the region to the panorama.
  Eigen::Vector3d to_viewer = Eigen::Vector3d::Zero();
  int iterations = 0;  // of the winning start (plus smoothing refinement)
};

// Whether a sky-only fallback explains its region at all: an albedo within max_albedo and a
// relative residual within fallback_rel_error. One that does not (a partly hidden region, a
// haze band) extrapolates a surface that is not there to other suns.
bool SkyOnlyExplains(const EnvRegionFit& fit, const EnvStereoOptions& options);

struct EnvStereoSummary {
  int times = 0;
  int regions_sky = 0, regions_landscape = 0, regions_sky_only = 0, regions_unobserved = 0;
  int fallback_bad_fit = 0;      // sky-only because of the fit error + normal away from viewer
  int fallback_never_lit = 0;    // sky-only because no training sun lit the normal
  bool underdetermined = false;  // fewer than min_times: all landscape regions are sky-only
  double rel_rms_median = 0;     // over landscape regions
  double rel_rms_p90 = 0;
  double seconds = 0;
  std::string BriefReport() const;
};

struct EnvStereoResult {
  // The region grid and layers of the training maps.
  int bands_below = 9, bands_above = 9, sectors = 24;
  std::vector<double> layer_z = {0.0};
  std::vector<EnvRegionSource> source;  // the first training map's, per layer x region
  std::vector<EnvRegionFit> regions;    // per layer, then region (as EnvironmentMap)
  EnvStereoOptions options;             // as used (prediction uses the same E_sky)
  EnvStereoSummary summary;
};

// The ground's retro parameter that best explains the training times: SolveEnvStereo with
// ground_retro at each candidate (0 to kRetroMax in steps of 0.5; the search stops at 0.5
// when the cost rises there), the cost the median rel_rms of
// the landscape regions below the horizon; refined by a parabola through the best candidate's
// neighbours. The fit keeps 0 (Lambert) unless its cost is below (1 - min_gain) x the Lambertian
// cost.
// Every field but the summary's seconds, numbers kept exactly (a scene keeps the fit its solve
// made, SceneModel::env_stereo, and a prediction reads it back instead of fitting again); from_json
// validates and names the bad field.
void to_json(nlohmann::json& j, const EnvStereoResult& r);
void from_json(const nlohmann::json& j, EnvStereoResult& r);

// `fit` (made from the slots `fit_slots`, e.g. a scene's SceneModel::env_stereo) when it was made
// from exactly `slots` with `options`; else nullptr, and a prediction fits its own.
const EnvStereoResult* FitFor(const std::optional<EnvStereoResult>& fit,
                              const std::vector<int>& fit_slots, const std::vector<int>& slots,
                              const EnvStereoOptions& options);

struct GroundRetroFit {
  double retro = 0;
  EnvStereoResult result;                 // the fit with `retro`
  std::vector<double> candidates, costs;  // as evaluated (the refinement last)
  double cost_lambert = 0, cost = 0;
};
GroundRetroFit FitGroundRetro(const std::vector<EnvObservation>& per_time,
                              const EnvStereoOptions& options, const Cancellation* cancel = nullptr,
                              double min_gain = 0.1);

// §5.2: fits every region of every layer. All maps must share the grid and layer count.
// Throws rouen::Error for no observation, mismatched maps or bad lighting; Cancelled when
// `cancel` (polled per region) is requested.
EnvStereoResult SolveEnvStereo(const std::vector<EnvObservation>& per_time,
                               const EnvStereoOptions& options = {},
                               const Cancellation* cancel = nullptr);

// §5.2: the environment map at a novel time. Sky regions: the sky model's mean over the
// region; landscape: eq. 17 with the recovered normal and albedos (+ f x sky for mixed
// regions); sky-only: rho_sky E_sky. `source` is copied from the training maps, pixel counts
// are 0 (nothing was observed at the novel time). `sky_fill_samples` as in EnvOptions.
EnvironmentMap PredictEnvironment(const EnvStereoResult& result, const EnvLighting& lighting,
                                  int sky_fill_samples = 8);

// The radiance PredictEnvironment gives one fitted region under `lighting`; `sky_mean` is the
// sky model's mean over the region (used by sky regions and the sky fraction f).
Eigen::Vector3d PredictRegionRadiance(const EnvRegionFit& fit, const EnvStereoOptions& options,
                                      const EnvLighting& lighting, const Eigen::Vector3d& sky_mean);

// E_sky for a unit normal under `lighting` as the solver computes it (ambient or plane).
Eigen::Vector3d EnvSkyIrradianceAt(const EnvLighting& lighting, const EnvStereoOptions& options,
                                   const Eigen::Vector3d& normal);

}  // namespace rouen
