// The sun and sky at novel times (Yu & Malik 1998 §5.1) and under intermediate and overcast
// skies (§6.3):
//  - InterpolateSky: the three parts of eq. 9 -- Lz, the background Bg(xi) = 1 + a exp(b/cos xi)
//    and the scattering part Sa(gamma) = 1 + c exp(d gamma^h) + e cos^2 gamma -- averaged
//    separately with weights proportional to 1 / (angular distance between sun positions), then
//    refitted to seven parameters (never a pointwise blend of radiance, Fig. 8).
//  - Sunrise/sunset: per-channel extinction L_sun(m) = L0 exp(-beta m) fitted to measured sun
//    radiances against air mass (Kasten & Young 1989), applied to the sun and the aureole; the
//    mean beta dims the background and keeps its colour.
//  - Overcast: the CIE overcast sky (Moon & Spencer 1942), L = Lz (1 + 2 cos xi) / 3, with a user
//    colour; a blocked-sunlight fraction PBS blends it with a clear sky pointwise and dims the
//    sun by (1 - PBS).
// Radiances are in the caller's relative units (the sky fit's and the Lighting's).
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

#include "solve/sky_model.h"

namespace rouen {

// ---------------------------------------------------------------------------------------------
// Sky interpolation (§5.1).

// One recovered sky: the fitted model (its sun_dir is the sun position of that time) and,
// optionally, the measured sun radiance at that time (RGB; zero when unknown).
struct TimedSky {
  SkyModel sky;
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();
};

// How the inputs are combined for a new sun.
enum class SkyInterpMode {
  // §5.1 as written: each part averaged with weights 1 / (angular distance between suns).
  kAngularDistance,
  // Beyond the paper: eq. 9 describes the sky relative to the sun (xi, gamma), so its parts
  // depend on the sun's elevation, not its azimuth. Weights 1 / |elevation difference|, and each
  // part is a weighted power law in sin(elevation) (a straight line of log value against log
  // sin e), evaluated at the new elevation (clamped to max_extrapolation_deg beyond the inputs'
  // range); a power law in every part is one in the radiance, so a sun lower than every
  // input's gets a darker sky, darkening faster as it nears the horizon.
  kElevation,
  // As kElevation, but the zenith radiance Lz and the gradation part Bg follow straight lines of
  // log value against the sun's air mass (Beer-Lambert: the light they scatter down comes along
  // the sun's slant path); the scattering part Sa keeps its power law. The zenith's line is
  // followed to the new sun itself, past max_extrapolation_deg (where the other parts are held
  // and relight's sunset extinction dims them, not Lz again). The default: on the Blender
  // worlds the air-mass line through the four training skies' Lz predicts the held-out one (a
  // sun 3-13 deg below the lowest) within -4..+5.5%, the power law 2-21% too bright, and the
  // predicted sky above 30 deg is within -5..0% of the held-out panorama (kElevation: -5..+6%);
  // the held-out views' worst gain 0.4-2.3 dB (median errors 4.8% -> 2.5% and 2.2%), the others
  // move by -1.0..+1.2 dB.
  kAirMass,
};

struct SkyInterpOptions {
  SkyInterpMode mode = SkyInterpMode::kAirMass;
  // kElevation, kAirMass: how far beyond the inputs' elevations the line is followed (degrees).
  double max_extrapolation_deg = 10;
  // Equal-area grid on the upper hemisphere where the averaged parts are evaluated and
  // refitted: `grid_zenith` rings uniform in cos(xi) times `grid_azimuth` columns.
  int grid_zenith = 40;
  int grid_azimuth = 80;
  int max_iterations = 200;  // Levenberg-Marquardt iterations per part and channel
  // A sun closer than this to an input's sun (radians) takes that input alone (the inverse
  // distance weight is infinite there). Several coincident inputs share the weight equally.
  double coincident_rad = 1e-6;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct SkyPartFitSummary {
  int iterations = 0;
  double bg_rel_error_max = 0;  // |Bg_fit - Bg_avg| / Bg_avg over the grid
  double sa_rel_error_max = 0;  // |Sa_fit - Sa_avg| / Sa_avg over the grid
};

struct SkyInterpSummary {
  std::vector<double> weights;  // per input, summing to 1
  // The sun elevation (radians) the parts were estimated at: the new sun's, clamped to the
  // inputs' range (kAngularDistance) or to max_extrapolation_deg beyond it (kElevation).
  double evaluated_elevation_rad = 0;
  std::array<SkyPartFitSummary, 3> channel;
  // |L_fit - L_avg| / L_avg over the grid, L_avg = Lz_avg Bg_avg Sa_avg (all channels).
  double rel_error_median = 0;
  double rel_error_p90 = 0;
  double rel_error_max = 0;
  // Inverse-distance average of the inputs' sun radiances (zero when none was given) and of
  // their Kasten-Young air masses (an input sun below the horizon counts as on it, m ~ 37.9).
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();
  double reference_air_mass = 0;
  double seconds = 0;
};

// The inputs' weights for a sun at `sun_dir` (options.mode), summing to 1: 1 / angular distance
// between suns (§5.1) or 1 / elevation difference; an input within coincident_rad takes the
// weight alone (shared with any other such input).
// Throws rouen::Error for no inputs or a sun direction that is not finite and non-zero.
std::vector<double> SkyInterpWeights(const std::vector<TimedSky>& skies,
                                     const Eigen::Vector3d& sun_dir,
                                     const SkyInterpOptions& options);

// §5.1: the sky at a new sun position `sun_dir` (unit or not; ENU, towards the sun). Lz is the
// weighted average of the inputs' Lz; (a, b) are fitted to the weighted average of Bg over the
// grid's zenith angles and (c, d, e, h) to the weighted average of Sa over the grid's angles to
// the new sun, minimising relative residuals, started from the weighted average parameters
// (the parts are separable, so this is the least-squares refit of the product). When the new
// sun coincides with an input's, the result is that input's sky. Parameters stay within the
// bounds of FitSky. `summary` may be null.
// Throws rouen::Error for no inputs, non-finite parameters, a non-positive Bg or Sa part, a
// negative Lz, a bad sun direction or bad options.
SkyModel InterpolateSky(const std::vector<TimedSky>& skies, const Eigen::Vector3d& sun_dir,
                        const SkyInterpOptions& options, SkyInterpSummary* summary);

// Equal-area grid on the upper hemisphere: `rings` uniform in cos(xi), `columns` uniform in
// azimuth (from north through east), cell centres; ENU unit vectors.
std::vector<Eigen::Vector3d> HemisphereGrid(int rings, int columns);
// Irradiance on an unoccluded level plane from the sky model (upper hemisphere only):
// E = integral L cos(xi) d omega, by the midpoint rule on a 48 x 96 HemisphereGrid.
Eigen::Vector3d HorizontalIrradiance(const SkyModel& sky);

// ---------------------------------------------------------------------------------------------
// Sunrise and sunset (§5.1).

// Relative optical air mass for a sun at `elevation_rad` above the horizon (Kasten & Young
// 1989, Applied Optics 28(22):4735: m = 1 / (cos z + 0.50572 (96.07995 - z)^-1.6364), z the
// zenith angle in degrees); about 1 at the zenith and 38 at the horizon. Throws rouen::Error
// for a sun below the horizon or a non-finite elevation.
double KastenYoungAirMass(double elevation_rad);

// Elevation (radians) of an ENU direction (need not be unit; must be non-zero).
double ElevationOf(const Eigen::Vector3d& dir);

// One measurement of the sun: its direction (ENU, towards the sun, above the horizon) and its
// radiance (RGB, > 0, the units of the Lighting's sun_radiance).
struct SunObservation {
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d radiance = Eigen::Vector3d::Zero();
};

// L_sun(m) = L0 exp(-beta m) per channel (§5.1, with m the Kasten-Young air mass).
struct SunExtinction {
  Eigen::Vector3d L0 = Eigen::Vector3d::Zero();    // radiance outside the atmosphere
  Eigen::Vector3d beta = Eigen::Vector3d::Zero();  // per channel, per unit air mass
  double beta_mean = 0;                            // mean over the channels (the background's)
  int samples = 0;
  double rms_log_residual = 0;  // over samples and channels, natural log units
  double air_mass_min = 0, air_mass_max = 0;

  Eigen::Vector3d SunRadiance(double air_mass) const;  // L0 exp(-beta m)
};

// Fits (log L0, beta) per channel by linear least squares on log radiance against air mass.
// Throws rouen::Error for fewer than 2 distinct air masses (differing by at least 1e-3),
// non-positive or non-finite radiance, or a sun below the horizon; the message names the
// observation.
SunExtinction FitSunExtinction(const std::vector<SunObservation>& observations);

// Changes a sky seen with the sun at air mass `from_air_mass` to one seen through air mass
// `to_air_mass` (§5.1): with dm = to - from, Lz_c *= exp(-beta_mean dm) (the whole sky darkens,
// its background colour kept), and the aureole term c_c *= exp(-(beta_c - beta_mean) dm), so the
// aureole as a whole changes by exp(-beta_c dm), like the sun. The e cos^2 gamma term is taken
// as background. sun_dir is left unchanged. `dim_zenith` false: the sky's Lz was already
// predicted for to_air_mass (SkyInterpMode::kAirMass follows it there); only the aureole's colour
// changes.
SkyModel ApplyExtinction(const SkyModel& sky, const SunExtinction& extinction, double from_air_mass,
                         double to_air_mass, bool dim_zenith = true);

struct LowSunPrediction {
  SkyModel sky;                                            // sun_dir = the new sun
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();  // extinction.SunRadiance(air_mass)
  double air_mass = 0;                                     // of the new sun
  double reference_air_mass = 0;                           // weighted over the inputs
};

// A sunrise/sunset sky: InterpolateSky to `sun_dir` (shape), then ApplyExtinction from the
// inputs' weighted air mass (summary->reference_air_mass) to the new sun's air mass; the sun
// radiance from the extinction fit. Throws rouen::Error as InterpolateSky and for a sun below
// the horizon.
LowSunPrediction PredictLowSun(const std::vector<TimedSky>& skies, const SunExtinction& extinction,
                               const Eigen::Vector3d& sun_dir, const SkyInterpOptions& options,
                               SkyInterpSummary* summary);

// ---------------------------------------------------------------------------------------------
// Overcast and intermediate skies (§6.3).

// CIE standard overcast sky (Moon & Spencer 1942): L(xi) = Lz (1 + 2 cos xi) / 3 per channel;
// `zenith_radiance` carries the user's colour (usually near grey) and brightness.
struct OvercastSky {
  Eigen::Vector3d zenith_radiance = Eigen::Vector3d::Ones();

  // Radiance towards an ENU direction; below the horizon, the horizon value Lz/3.
  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir) const;
};

// Eq. 9 cannot reproduce (1 + 2 cos xi)/3 exactly (its background 1 + a exp(b / cos xi) is flat
// at the horizon). The approximation puts the model's sun at the zenith, so gamma = xi and all
// seven parameters shape one profile Lz Bg(xi) Sa(xi); they are fitted to the normalised
// profile by relative least squares over the hemisphere (uniform in cos xi, i.e. equal solid
// angle) from several starts. The returned SkyModel's sun_dir is therefore the zenith, not the
// real sun (whose radiance is zero under a full overcast).
struct OvercastFitSummary {
  double rel_error_rms = 0;  // over the hemisphere (equal solid angle)
  double rel_error_max = 0;
  // Irradiance of an unoccluded horizontal plane, approximation vs exact 7 pi Lz / 9, relative.
  double horizontal_irradiance_rel_error = 0;
};
SkyModel OvercastAsSkyModel(const OvercastSky& overcast, OvercastFitSummary* summary);

// The intermediate sky of §6.3 for a blocked-sunlight fraction pbs in [0, 1]: each sky
// direction's colour is (1 - pbs) L_clear + pbs L_overcast, and the sun is (1 - pbs) L_sun.
struct IntermediateSky {
  SkyModel clear;
  OvercastSky overcast;
  double pbs = 0;

  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir) const;  // exact blend
  Eigen::Vector3d SunRadiance(const Eigen::Vector3d& clear_sun_radiance) const;
};

// Throws rouen::Error unless pbs is in [0, 1], the clear sky's parameters are finite and the
// overcast colour is finite and non-negative.
IntermediateSky MakeIntermediateSky(const SkyModel& clear, const OvercastSky& overcast, double pbs);

struct IntermediateFitSummary {
  // |L_fit - L_blend| / L_blend over an equal-area hemisphere grid, all channels.
  double rel_error_median = 0;
  double rel_error_p90 = 0;
  double rel_error_max = 0;
  bool refitted = false;  // false: pbs was 0 (exact) or 1 (OvercastAsSkyModel)
};

// The blend as one seven-parameter SkyModel (what Lighting::sky holds), sun_dir = the clear
// sky's except for pbs = 1: pbs = 0 returns the clear sky, pbs = 1 OvercastAsSkyModel (sun_dir
// the zenith), otherwise the blend sampled on an equal-area grid (grid_zenith x grid_azimuth,
// >= 20 samples) and refitted with FitSky (an approximation: see the summary's errors).
SkyModel IntermediateAsSkyModel(const IntermediateSky& sky, int grid_zenith, int grid_azimuth,
                                IntermediateFitSummary* summary);

}  // namespace rouen
