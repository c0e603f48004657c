// Diffuse pseudo-albedos per grid point and channel (Yu & Malik 1998, §4.1, eqs. 11-12):
// one for the sun's spectrum (rho_sun) and one for the sky and environment (rho_se), from
// radiance observed in HDR architecture photos at several times of day:
//   pi I_k = rho_se E_se,k + rho_sun E_sun,k   for every observation k of a point.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"
#include "solve/retro.h"
#include "solve/specular.h"

namespace rouen {

// An HDR photo of the architecture with known camera and time-of-day slot.
struct ArchitecturePhoto {
  Image image;  // kRadiance, >= 3 channels
  Intrinsics intrinsics;
  Pose pose;
  int slot = 0;               // index into the per-slot lighting / irradiance
  std::vector<uint8_t> mask;  // empty: all valid; else width*height, nonzero = valid pixel
  std::string name;           // for messages
  // The blocks this photo observes: empty, every one; else per block, nonzero = observed (a
  // landscape panorama reads the surroundings only). Points of no block (-1) never are.
  std::vector<uint8_t> blocks;
};

struct Observation {
  int point = 0;
  int slot = 0;
  int photo = 0;
  Eigen::Vector3f radiance = Eigen::Vector3f::Zero();   // I, relative radiance
  Eigen::Vector3f view_dir = Eigen::Vector3f::UnitZ();  // unit ENU, from the point to the camera
  // What the photo measured when `radiance` is what is left of it once light is taken out (the
  // specular lobes'): the albedo fit's relative error is of the larger, the photo's error being
  // of what it measured. Zero: `radiance` is what was measured.
  Eigen::Vector3f measured = Eigen::Vector3f::Zero();
};

struct ObservationOptions {
  double margin_px = 2;                // the projection must lie this far inside the image
  double occlusion_tolerance = 0.005;  // visibility ray stops this fraction short of the point
  double min_cos_view = 0.05;          // skip views more grazing than this (cos of angle)
  // The bilinear footprint (2x2 pixels) must see the point's own plane at all four corners:
  // no silhouette, occluding edge or other face mixes into the sample.
  bool check_footprint = true;
  // When the 2x2 footprint fails, use the nearest pixel alone if its own corners pass (more
  // points observed near edges, but noisier there: off by default).
  bool nearest_pixel_fallback = false;
  // How far from a point's plane a corner's hit may be and still be on it; the albedo fill
  // (AlbedoOptions::fill_radius_m) takes the same plane test for its neighbours.
  double plane_tolerance_m = 0.05;
  void Validate() const;
};

struct ObservationSummary {
  int64_t projected = 0;        // point-photo pairs in front of the camera and in the image
  int64_t occluded = 0;         // of those, hidden by the model (App. B)
  int64_t mixed_footprint = 0;  // footprint crosses an edge of the face (check_footprint)
  int64_t shadow_edge = 0;      // footprint crosses a cast-shadow edge (sun_dirs given)
  int64_t invalid_pixels = 0;   // masked or non-finite
  int64_t observations = 0;
  int points_observed = 0;
  double seconds = 0;
};

// App. B visibility by ray casting: for every photo and grid point, project, check the image
// bounds (margin), that the face looks at the camera and that the ray from the camera reaches
// the point; then take the bilinear radiance. With `sun_dirs` (unit ENU per slot), samples
// whose footprint straddles a cast-shadow edge are dropped too (the grid point's single sun
// visibility would not describe them). Sorted by point, then photo.
std::vector<Observation> CollectObservations(
    const SurfaceGrid& grid, const RayCaster& model, const std::vector<ArchitecturePhoto>& photos,
    const ObservationOptions& options = {}, ObservationSummary* summary = nullptr,
    const std::vector<Eigen::Vector3d>* sun_dirs = nullptr);

enum class RobustLoss {
  kNone,
  kHuber,  // weight min(1, k / |z|)
  kPaper,  // the paper's rho(z) = (1 - e^{-|z|/2}) / (1 + e^{-|z|/2}) as IRLS weights
};

// Per-point flags (bits).
enum AlbedoFlag : uint8_t {
  kAlbedoNoObservations = 1,  // never seen while lit: filled from neighbours or the block
  kAlbedoSunUnobserved = 2,   // never sunlit when seen: rho_sun = rho_se x block ratio
  kAlbedoNeverShadowed = 4,   // never in shadow when seen: eq. 11 missing, weak ratio prior used
  kAlbedoClamped = 8,         // the rho >= 0 constraint was active in some channel
  kAlbedoFilled = 16,         // value not from this point's own data
};

struct AlbedoOptions {
  RobustLoss loss = RobustLoss::kHuber;
  double huber_k = 1.345;   // in units of the robust scale
  double min_scale = 0.01;  // floor on the relative residual scale (1%)
  int irls_iterations = 8;
  // The reweighting stops early once no observation's robust weight changes by more than this.
  double irls_tolerance = 1e-4;
  // Each observation's error is relative, sigma = pi I, but at least this fraction of the
  // point's mean pi I in the channel (a nearly black observation would otherwise weigh
  // without bound).
  double relative_error_floor = 0.05;
  // §4.1: albedo -> interreflection -> albedo ..., at most this many times, stopping once the
  // albedos have settled: the outer_quantile of the points' relative change (largest over the
  // channels and both albedos, over the observed points) below outer_tolerance (0: always
  // outer_iterations). A mean hides the few points that converge slowest: on the tower world
  // the belfry's open storey, lit 70% by its own walls, still moved 10% after 8 iterations
  // while the mean change was 0.5%.
  int outer_iterations = 40;
  double outer_tolerance = 0.0025;
  double outer_quantile = 0.99;
  // Each outer iteration takes Newton's step on log rho for rho E(rho) = pi I, E's growth with
  // the albedos measured by the interreflection itself (AddInterreflection's bounce order): the
  // plain update (the albedo that explains the photos under the last bounce) overshoots where the
  // bounce carries much of the light -- an albedo too high brightens its neighbours' bounce, so
  // their next albedo is too low -- and diverges where E grows faster than rho (a deep well's
  // walls, a belfry's open storey with eight bounces). false: the paper's plain update.
  bool outer_newton = true;
  // Beyond the paper: every other outer iteration extrapolates each point's albedos by
  // Aitken's rule from its last two steps (in log rho, where they go the same way and shrink),
  // as far as the iteration's own rate of contraction says it would go. Newton's step assumes
  // every albedo around a point changes as its own does; where only the point's own is off, it
  // steps too short, and the nave world's walls crept 0.54 of the way per iteration.
  bool outer_aitken = true;
  // Radiosity passes in each interreflection update: 1 is the paper's one-bounce reflection;
  // Cycles' worlds carry 8 diffuse bounces, and light bounced 3-8 times is 10% of a narrow
  // street's north wall (the nave world) and of the belfry's open storey (the tower world).
  int bounces = 8;
  // An observation counts as sunlit when E_sun > sunlit_threshold x E_se (green).
  double sunlit_threshold = 0.05;
  // Weight of the prior rho_sun = ratio x rho_se (the block's ratio from its points seen both
  // sunlit and shadowed) for never-shadowed points, against their photos' relative residuals
  // squared, summed (0 disables). At 1 a ratio off by 10% costs what every photo off by 10%
  // costs: the photos still fix the sum rho_sun E_sun + rho_se E_se they see (to their noise),
  // the prior the split eq. 11's missing shadow would have fixed. At 0.1 the split drifted with
  // small errors of E (a slate roof's rho_se 28-47% low in blue on the nave world).
  double never_shadowed_prior = 1.0;
  // The same prior for points seen both sunlit and shadowed (0: none; their own data decide).
  // Small errors in E_se otherwise split unevenly between the two albedos.
  double ratio_prior = 0.1;
  // Never-observed points take the inverse-distance mean of up to 6 observed points of the same
  // block and plane within this radius, else of the same block within 4x the radius (0: off);
  // beyond that, the block median.
  double fill_radius_m = 3.0;
  // The kind of each block (by index; blocks beyond the vector are kind 0): a block no photo saw
  // takes the median albedos of the observed blocks of its kind, else of every observed block
  // (the session solve makes trees kind 1: a crown no panorama saw takes the trees' dark green,
  // not the walls' albedo).
  std::vector<int> block_kind;
  // Beyond the paper: from the second outer iteration on, each time-of-day slot is weighted by
  // (median relative residual of all slots / its own)^2, at most 1, so a slot whose lighting
  // model fits worse (typically a low sun) pulls the albedos less.
  bool slot_weighting = true;
  // Beyond the paper: fit each block's retro parameter (solve/retro.h: how much more of a
  // grazing sun a rough surface sends back than Lambert's law says) from its observations;
  // false keeps every block Lambertian (retro 0), as the paper's eq. 13 does.
  bool fit_retro = true;
  // A block's retro is fitted only from at least this many sunlit observations; else the median
  // of the blocks that have them (0 when none has).
  int retro_min_observations = 200;
  // The fit's cost: |relative residual| per observation and channel, truncated here (robust).
  double retro_residual_cap = 0.25;
  // A block keeps a non-zero retro only when it lowers that cost (the block's mean truncated
  // |relative residual|) by at least this much; below it Lambert explains the photos as well.
  double retro_min_gain = 0.002;
  // §4.2.2: each block's sun specular lobe (eq. 13) fitted to what the diffuse albedos leave
  // of its sunlit observations, then the albedos solved again without the lobe's light.
  SunLobeOptions sun_lobe;
  // §4.2.1: the sky/environment lobe (eq. 14) of each block that has a sun lobe (a surface
  // glossy for the sky is glossy for the sun, whose highlight the photos show far more
  // clearly), then the albedos once more without either lobe's light.
  SkyLobeOptions sky_lobe;
  ObservationOptions observation;
  // The direct sky and environment term by App. A's vector flux (exact; the solve gives it the
  // model mesh) unless set otherwise: Monte Carlo's 256 directions leave 2.9% noise per point.
  IrradianceOptions irradiance = [] {
    IrradianceOptions o;
    o.method = IrradianceMethod::kVectorFlux;
    return o;
  }();

  void Validate() const;  // throws rouen::Error
};

struct AlbedoSummary {
  int points = 0;
  int points_observed = 0;
  int points_sun_unobserved = 0;
  int points_never_shadowed = 0;
  int points_clamped = 0;
  int points_filled_neighbours = 0;  // never observed, filled from observed neighbours
  int64_t observations = 0;
  int outer_iterations = 0;  // run (at most AlbedoOptions::outer_iterations)
  // At each outer iteration after the first: the change the new solve proposed, the
  // AlbedoOptions::outer_quantile of the observed points' relative change.
  std::vector<double> change_per_iteration;
  // Relative residual (pi I - model) / (pi I) over all observations: its rms (a few nearly
  // black observations can make it any size, e.g. 32,554% on the nave world, median 1.6%), its
  // median and 90th percentile in absolute value (what the summary line reports).
  double residual_rms_rel = 0;
  double residual_median_rel = 0;
  double residual_p90_rel = 0;
  double downweighted_fraction = 0;  // observations with robust weight < 0.5
  std::vector<double> slot_weights;  // per slot, as used in the last solve (SolveAlbedo)
  // Per block: the relative residual cost (truncated |relative residual|, mean over the
  // block's observations) with retro 0 and with the fitted retro (SolveAlbedo, fit_retro).
  std::vector<double> retro_cost_lambert, retro_cost_fitted;
  // Per block: the sun lobe fit's samples and eq. 15's cost without and with the fitted lobe.
  std::vector<int> lobe_samples;
  std::vector<double> lobe_cost_zero, lobe_cost_fitted;
  // The same for the sky/environment lobes (eq. 14's cost); blocks without a sun lobe: 0.
  std::vector<int> sky_lobe_samples;
  std::vector<double> sky_lobe_cost_zero, sky_lobe_cost_fitted;
  double seconds = 0;
  std::string BriefReport() const;
};

struct AlbedoResult {
  std::vector<Eigen::Vector3d> rho_sun, rho_se;  // per grid point, RGB
  std::vector<int> observations;                 // per grid point
  std::vector<uint8_t> flags;                    // AlbedoFlag bits per grid point
  std::vector<double> retro;  // per block (solve/retro.h); empty or 0: Lambertian sun term
  // Per block (§4.2.2); empty or zero: no specular reflection of the sun.
  std::vector<SpecularLobe> sun_lobes;
  // Per block (§4.2.1): reflection of the sky and environment (empty or zero: none).
  std::vector<SpecularLobe> sky_lobes;
  AlbedoSummary summary;
};

// Eqs. 11-12 per point with fixed irradiance (irradiance[slot] per slot); IRLS, rho >= 0.
// Never-observed points are filled with their block's median. With `shading`, each
// observation's sun irradiance is scaled by its block's RetroFactor (the returned `retro`).
AlbedoResult SolveAlbedoFixedIrradiance(const SurfaceGrid& grid,
                                        const std::vector<Observation>& observations,
                                        const std::vector<SlotIrradiance>& irradiance,
                                        const AlbedoOptions& options = {},
                                        const SunShading* shading = nullptr);

// §4.1 with the outer iteration: irradiance without bounce -> albedos -> irradiance with the
// one-bounce interreflection from the current albedos -> albedos ... `irradiance` receives
// the per-slot irradiance with the interreflection from the returned albedos. With
// options.fit_retro, the first outer iteration with the interreflection (or the only one) also
// fits every block's retro parameter: the albedos are solved for candidates over
// [kRetroMin, kRetroMax] and each block keeps the one with the least truncated relative
// residual, refined by a parabola. Then, with options.sun_lobe.fit, every block's sun lobe
// (§4.2.2); when some block has one, the outer iteration again from the observations less the
// lobes' light with the lobes' glint in the bounce (AddInterreflection's sun_lobes), its
// sky/environment lobe (§4.2.1, options.sky_lobe.fit) and the albedos once more. The direct sky
// and environment term is options.irradiance's method at every observed point; points no
// observation sees (their albedos filled from neighbours) take Monte Carlo's for the light they
// pass on, unless options.irradiance.exact_points says otherwise. With `warm` (a solve of these
// photos on this grid under other light: the ground field read again), the outer iteration
// starts from its albedos, retros and sun lobes instead of a solve without the interreflection,
// so that the first bounce, and the retro fitted with it, see albedos near the answer.
AlbedoResult SolveAlbedo(const SurfaceGrid& grid, const HemisphereCache& cache,
                         const RayCaster& model, const std::vector<Lighting>& slots,
                         const std::vector<Observation>& observations,
                         const AlbedoOptions& options = {},
                         std::vector<SlotIrradiance>* irradiance = nullptr,
                         const AlbedoResult* warm = nullptr);

}  // namespace rouen
