// Fitting the seven-parameter sky model (Yu & Malik 1998 §3.2, eq. 9) to sky pixels of
// radiance images, per colour channel, by Levenberg-Marquardt on eq. 10.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "solve/sky_model.h"

namespace rouen {

struct SkySample {
  Eigen::Vector3d dir;       // unit, ENU, above the horizon
  Eigen::Vector3d radiance;  // per channel, > 0
  // How much of the sky the sample stands for in the fit's objective and error figures (> 0;
  // only ratios matter): the solid angle (sr) for image pixels, 1 for measured directions.
  double weight = 1;
};

struct SkySampleOptions {
  double min_elevation_deg = 3.0;     // skip the horizon (buildings, haze)
  double min_sun_distance_deg = 3.0;  // skip the sun and its immediate aureole
  int max_samples = 20000;            // spread evenly over the visible sky
  uint64_t seed = 1;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

// Whether a unit ENU direction is in the sky a fit uses: at least min_elevation_deg high and
// more than min_sun_distance_deg from the (unit) sun. The one rule for pixels and directions.
bool InSkyFitRegion(const Eigen::Vector3d& dir, const Eigen::Vector3d& sun,
                    const SkySampleOptions& options);

// Sky samples from one radiance image: pixels in the sky fit region (InSkyFitRegion), valid in
// `valid_mask` (width x height, nonzero = valid; may be null), with finite positive radiance in
// every channel. Every such pixel is a candidate; at most max_samples are kept, spread evenly
// over solid angle: equal-area cells in azimuth x sin(elevation) get equal shares (a cell with
// fewer candidates gives all of them, each weighing its pixel's solid angle); within a cell
// the share is drawn in proportion to solid angle, each draw weighing the cell's solid angle /
// its share. So the samples weigh the sky by solid angle whatever the projection's pixel
// density (an equirect's rows near the zenith hold many pixels per steradian) and however the
// cap thins them; a pixel drawn twice comes once with twice the weight. Concatenate the results
// of several photos to fit them together. Throws rouen::Error for a wrong image or mask.
std::vector<SkySample> ExtractSkySamples(const Image& hdr, const std::vector<uint8_t>* valid_mask,
                                         const Intrinsics& intrinsics, const Pose& pose,
                                         const Eigen::Vector3d& sun_dir,
                                         const SkySampleOptions& options);

// Measured sky directions from a CSV file as a sky scanner or a luminance meter records them:
// one direction per line, `azimuth_deg, elevation_deg, R, G, B` (azimuth from north through
// east, elevation in [0, 90], linear radiance per channel, finite and positive), or the same
// after a leading integer index (`idx, azimuth_deg, elevation_deg, R, G, B`); the field count
// is that of the first line with data, for every line. A first line whose first field is not a
// number is a header; blank lines and lines starting with '#' are skipped. Weight 1 each. Throws
// rouen::Error naming the file and line for a malformed line, a value that is not finite, a
// radiance that is not positive, an elevation outside [0, 90], a direction within 0.01 deg of
// an earlier line's, or a file without directions.
std::vector<SkySample> ReadSkySamplesCsv(const std::string& path);

// Which sky model FitSky fits. All three are stored as eq. 9 parameters (SkyParams).
enum class SkyModelKind {
  kSevenParam,  // eq. 9, the paper's revised model
  kPerez5,      // Perez et al. 1993 as the paper writes it: eq. 9 with h = 1
  kCie,         // best of the 15 CIE standard general skies (solve/sky_cie.h), Lz per channel
};
const char* SkyModelKindName(SkyModelKind kind);  // "7", "perez5", "cie"
// Accepts "7", "seven", "perez5", "cie"; throws rouen::Error naming the bad value.
SkyModelKind ParseSkyModelKind(const std::string& name);

enum class SkyWeighting {
  kPaper,     // eq. 10: sigma_i = y_i / log y_i (radiance normalised so log y_i >= log 2)
  kRelative,  // sigma_i = y_i: plain relative residuals
};

// The defaults are the one sky fit of rouen (rouen solve, rouen sky fit, the library): relative
// residuals and their L1 norm, which fit physically based skies better than the paper's eq. 10
// (weighting kPaper, norm_p 2; bench/sky_bench.cc measures both).
struct SkyFitOptions {
  SkyModelKind model = SkyModelKind::kSevenParam;
  SkyWeighting weighting = SkyWeighting::kRelative;
  int max_iterations = 200;  // Levenberg-Marquardt iterations per start
  // Fewest distinct directions (SkyCoverage) a fit accepts: 3 per parameter of the model
  // (7 for eq. 9). A least-squares fit of k parameters to n samples leaves an in-sample mean
  // squared error (n - k) / (n + k) of its error at the same directions' fresh measurements;
  // n >= 3k keeps that ratio at least 1/2, so the reported error understates the fit's by at
  // most a factor sqrt(2).
  int min_directions = 21;
  // The directions must be spread at least as much as a uniform cap of this radius (deg)
  // around their mean: 60 deg is half the hemisphere's solid angle. Eq. 9's gradation term
  // differs between zenith and horizon and its scattering terms between the sun and the far
  // sky; a fit to a smaller cap extrapolates them to the rest of the sky.
  double min_spread_deg = 60;
  // Try the eight starting shapes (CIE general skies, Perez-like); false: CIE clear only.
  bool multiple_starts = true;
  // Extra starting shapes drawn at random (seeded) over the range clear to hazy skies span,
  // screened with the others: a check that LM reaches the global minimum.
  int random_starts = 0;
  uint64_t seed = 1;
  // Exponent of the objective: minimise sum_i rho(r_i), r_i = (y_i - Ls_i) / sigma_i,
  // rho(r) = (r^2 + eps^2)^(p/2) - eps^p (|r|^p smoothed within eps of 0; eps = norm_eps, in
  // the units of r: relative error for kRelative). p = 2 is eq. 10's least squares (exact,
  // eps unused). p < 2 is robust: sky regions the model cannot follow (the last degrees above
  // the horizon, the inner aureole) pull the rest of the fit less; p > 2 weighs the largest
  // residuals more, which helps only where the largest residuals are noise rather than sky
  // the model cannot follow. From the screened least-squares optimum and each starting
  // shape: p < 2 by LM on squares reweighted at every step (iteratively reweighted least
  // squares, majorise-minimise: each kept step lowers the objective); p > 2 by LM on
  // sign(r_i) sqrt(rho(r_i)). final_cost is then
  // half sum rho(r_i). Costs several times a least-squares fit.
  // In [1, 16]. Not used by kCie.
  double norm_p = 1;
  // 5e-3 (0.5% relative error): on the sky bench's ten clear and hazy skies (sun 13-62 deg)
  // its median error is below scipy's soft_l1 fit (f_scale 0.01) on every sky and its 90th
  // percentile within 4% of scipy's on each and below it pooled; 1e-3 had the lower median
  // but a 90th percentile 5-8% above scipy's on three low-sun skies, 1e-2 is scipy's fit.
  double norm_eps = 5e-3;
  // Levenberg-Marquardt stops when a step lowers the objective by less than this, relative.
  // p < 2 converges linearly; 1e-7 leaves its minimum within a small fraction of the samples'
  // noise.
  double function_tolerance = 1e-7;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

// How much of the sky a set of samples covers. Directions: the occupied cells of an
// equal-area grid of the hemisphere (10 bands of sin(elevation) x 20 azimuths, 0.031 sr or
// about 10 x 10 deg each), but no more than the distinct radiance triples among the samples
// (an image painted from a few measured directions has many pixels, few measurements).
// spread_deg: the radius of the uniform cap whose mean resultant length (1 + cos r) / 2
// equals that of the occupied cells' directions (each cell once): 90 for the whole
// hemisphere or more even spreads, 0 for a single cell.
struct SkyCoverage {
  int directions = 0;
  double spread_deg = 0;
};
SkyCoverage MeasureSkyCoverage(const std::vector<SkySample>& samples);
// Empty when `coverage` meets options.min_directions and options.min_spread_deg, else what is
// missing and the rule, for an error message.
std::string SkyCoverageProblem(const SkyCoverage& coverage, const SkyFitOptions& options);

struct SkyChannelSummary {
  int iterations = 0;       // of the winning start (screening + refinement)
  int starts = 0;           // starting points tried
  double initial_cost = 0;  // eq. 10 on all samples where the final refinement began
  double final_cost = 0;    // eq. 10 (half the sum of squares, normalised radiance units)
  // |model - y| / y over the samples, each counted by its weight (solid angle)
  double rel_error_median = 0;
  double rel_error_p90 = 0;
  double rel_error_max = 0;
  double rel_error_mean = 0;
  double seconds = 0;
};

struct SkyFitSummary {
  SkyModelKind model = SkyModelKind::kSevenParam;
  int cie_type = 0;  // 1..15 when model == kCie
  int samples = 0;
  std::array<SkyChannelSummary, 3> channel;
  double seconds = 0;
};

// Fits eq. 9 per channel, minimising eq. 10 with sigma_i = y_i / log y_i. The radiance is first
// divided by half its minimum, so every log y is at least log 2 and the weights are positive
// and finite (the weight's unit dependence is fixed this way); Lz is scaled back. Parameters
// are bounded so the model stays finite and positive: a in [-3, 30] with 1 + a e^b > 0 (the
// zenith, where the gradation is smallest), b in [-10, -0.01], c in [0, 200],
// d in [-20, -0.01], e in [-0.9, 20], h in [0.3, 3], Lz > 0. Eight starting shapes (CIE
// general skies, Perez-like) are screened on ~2000 evenly thinned samples; the best two
// distinct minima (the second only if its cost is within 25 % of the best's) are refined on all
// samples and the lower cost wins.
// Each sample's term of the objective is multiplied by its weight (weights normalised to mean 1).
// Throws rouen::Error for samples covering too little of the sky (SkyCoverageProblem),
// non-positive or non-finite radiance or weight, directions that are not unit or below the
// horizon, or a bad sun direction.
// With options.norm_p != 2 the screened least-squares optimum and every starting shape are
// instead screened and refined so under the p-norm objective (see SkyFitOptions::norm_p); the
// per-channel relative-error figures in the summary are of that final fit.
// kPerez5 fits the same way with h fixed at 1. kCie tries the 15 CIE types, each with Lz per
// channel in closed form (weighted linear least squares with the chosen weights), and keeps
// the type of lowest total cost; the result is stored as eq. 9 parameters (CieAsSkyParams).
SkyFitSummary FitSky(const std::vector<SkySample>& samples, const Eigen::Vector3d& sun_dir,
                     const SkyFitOptions& options, SkyModel* out);

// Per-sample relative residuals (model - y) / y per channel, in the order of `samples`.
std::vector<Eigen::Vector3d> SkyRelativeResiduals(const SkyModel& model,
                                                  const std::vector<SkySample>& samples);

// Median, p90, max and mean of |residual| over the samples, per channel (each sample once).
struct SkyResidualStats {
  std::array<double, 3> median{}, p90{}, max{}, mean{};
};
SkyResidualStats SummarizeSkyResiduals(const std::vector<Eigen::Vector3d>& residuals);

}  // namespace rouen
