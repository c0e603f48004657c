#include "solve/sky_fit.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <charconv>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <string_view>

#include "core/angles.h"
#include "core/error.h"
#include "core/solar.h"
#include "core/stats.h"
#include "core/text.h"
#include "solve/internal/sky_cost.h"
#include "solve/sky_cie.h"

namespace rouen {
namespace {

using internal::SkyCost;
using internal::SkyNormTransform;
using internal::SkyPoint;

// Bounds per parameter {Lz, a, b, c, d, e, h}; Lz's upper bound is open.
constexpr double kLower[7] = {1e-12, -3.0, -10.0, 0.0, -20.0, -0.9, 0.3};
constexpr double kUpper[7] = {
    std::numeric_limits<double>::infinity(), 30.0, -0.01, 200.0, -0.01, 20.0, 3.0};

// Starting shapes {a, b, c, d, e, h}: CIE general skies (NOTES.md groups) and Perez-like
// luminance skies of Preetham et al. for turbidity 3 and 6.
constexpr double kStarts[][6] = {
    {-1.0, -0.32, 10.0, -3.0, 0.45, 1.0},          // CIE clear, V.4 (type 12)
    {-1.0, -0.32, 16.0, -3.0, 0.30, 1.0},          // V.5
    {-1.0, -0.55, 5.0, -2.5, 0.30, 1.0},           // IV.3
    {0.0, -1.0, 2.0, -1.5, 0.15, 1.0},             // III.2
    {1.1, -0.8, 0.0, -1.0, 0.0, 1.0},              // II.1, overcast-like
    {-0.927, -0.639, 5.257, -2.215, 0.169, 1.0},   // Perez (Preetham) T = 3
    {-0.391, -1.705, 5.189, -1.853, -0.032, 1.0},  // Perez (Preetham) T = 6
    {-1.0, -0.32, 10.0, -3.0, 0.45, 0.6},          // clear with a wider aureole
};

// Screening: every start on about this many samples, for at most this many iterations, until
// an iteration gains less than kScreenTolerance relative; the best kRefined distinct minima
// (costs more than kSameMinimum apart, relative) continue on all samples, those after the
// first only if their cost is within kRefineWithin of its (relative).
constexpr size_t kScreenSamples = 2000;
constexpr int kScreenIterations = 60;
constexpr double kScreenTolerance = 1e-5;
constexpr size_t kRefined = 2;
constexpr double kSameMinimum = 1e-3;
constexpr double kRefineWithin = 0.25;
// Levenberg-Marquardt stops when a step is this small relative to the parameters.
constexpr double kParameterTolerance = 1e-10;

// The whole of `s` as a number (nan and inf included: the caller names them).
bool ParseFullDouble(const std::string& s, double* v) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return !s.empty() && r.ec == std::errc() && r.ptr == s.data() + s.size();
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

struct StartResult {
  double params[7] = {1, 0, -1, 0, -1, 0, 1};
  double initial_cost = 0, final_cost = std::numeric_limits<double>::infinity();
  int iterations = 0;
};

// Gradation factor 1 + a exp(b / cos xi) at the zenith, where it is smallest (b < 0).
double ZenithGradation(const double* p) { return SkyGradationFactor(p[1], p[2], 1.0); }

// The Gauss-Newton matrix and gradient of an objective at a point (over the first n parameters).
struct NormalEquations {
  Eigen::Matrix<double, 7, 7> h = Eigen::Matrix<double, 7, 7>::Zero();
  Eigen::Matrix<double, 7, 1> g = Eigen::Matrix<double, 7, 1>::Zero();
};

// Half the sum of squares of `cost`'s residuals at x (eq. 10; its p-norm transform for p > 2);
// with `irls`, half sum rho(r_i) of the p < 2 norm instead, its Gauss-Newton matrix being that of
// the weighted squares (rho is concave in r^2: they majorise it, so a step that lowers them
// lowers the objective, as iteratively reweighted least squares). Also writes the normal
// equations at x.
double Objective(const SkyCost& cost, const SkyNormTransform* irls, const double* x,
                 NormalEquations* ne) {
  const int n = cost.num_params();
  double h[49], g[7];
  const double f = cost.NormalEquations(x, irls, h, g);
  ne->h.setZero();
  ne->g.setZero();
  for (int k = 0; k < n; ++k) {
    ne->g[k] = g[k];
    for (int c = 0; c < n; ++c) ne->h(k, c) = h[k * n + c];
  }
  return f;
}

// Levenberg-Marquardt from `start` within the box bounds (`a_lower` replaces the lower bound
// of a): steps solve (H + mu diag H) delta = -g and are projected onto the box; a step is kept
// when it lowers the objective. Stops when a kept step lowers it by less than
// function_tolerance relative, when the projected gradient or the step vanishes, or after
// max_iterations steps.
StartResult Solve(const SkyCost& cost, const SkyNormTransform* irls, const double* start,
                  double a_lower, int max_iterations, double function_tolerance) {
  StartResult res;
  double* x = res.params;
  std::copy(start, start + 7, x);
  const int n = cost.num_params();
  if (n < 7) x[6] = 1;  // Perez 5: h fixed
  double lower[7], upper[7];
  for (int k = 0; k < 7; ++k) {
    lower[k] = k == 1 ? a_lower : kLower[k];
    upper[k] = kUpper[k];
    x[k] = std::clamp(x[k], lower[k], upper[k]);
  }
  NormalEquations ne, trial_ne;
  double f = Objective(cost, irls, x, &ne);
  res.initial_cost = f;
  res.final_cost = std::numeric_limits<double>::infinity();
  if (!std::isfinite(f)) return res;
  double mu = 1e-4, nu = 2;  // damping, as Ceres's initial trust region radius 1e4
  int it = 0;
  while (it < max_iterations) {
    ++it;
    // Projected gradient: zero at a (box-constrained) stationary point.
    double pg = 0;
    for (int k = 0; k < n; ++k) {
      pg = std::max(pg, std::abs(std::clamp(x[k] - ne.g[k], lower[k], upper[k]) - x[k]));
    }
    if (pg <= 1e-12) break;
    Eigen::MatrixXd a = ne.h.topLeftCorner(n, n);
    for (int k = 0; k < n; ++k) a(k, k) += mu * std::clamp(ne.h(k, k), 1e-6, 1e32);
    const Eigen::VectorXd delta = a.ldlt().solve(-ne.g.head(n));
    double trial[7];
    std::copy(x, x + 7, trial);
    Eigen::VectorXd step(n);
    for (int k = 0; k < n; ++k) {
      trial[k] = std::clamp(x[k] + delta[k], lower[k], upper[k]);
      step[k] = trial[k] - x[k];
    }
    double x_norm = 0;
    for (int k = 0; k < n; ++k) x_norm += x[k] * x[k];
    if (!step.allFinite() ||
        step.norm() <= kParameterTolerance * (std::sqrt(x_norm) + kParameterTolerance)) {
      break;
    }
    const double predicted =
        -(ne.g.head(n).dot(step) + 0.5 * step.dot(ne.h.topLeftCorner(n, n) * step));
    const double ft = Objective(cost, irls, trial, &trial_ne);
    if (std::isfinite(ft) && ft < f) {
      const double gain = f - ft;
      const double ratio = predicted > 0 ? gain / predicted : 1;
      std::copy(trial, trial + 7, x);
      std::swap(ne, trial_ne);
      f = ft;
      mu *= std::max(1.0 / 3, 1 - std::pow(2 * ratio - 1, 3));
      nu = 2;
      if (gain <= function_tolerance * (f + gain)) break;
    } else {
      mu *= nu;
      nu *= 2;
      if (mu > 1e32) break;
    }
  }
  res.iterations = it;
  res.final_cost = f;
  return res;
}

// One start: a lower bound of -3 on a lets the zenith darken more than a = -1 allows, but a
// result whose zenith gradation is not positive is refitted with a >= -0.999 (then
// exp(b / cos xi) < 1 keeps it positive everywhere).
StartResult RunStart(const SkyCost& cost, const SkyNormTransform* irls, const double* start,
                     int max_iterations, double function_tolerance) {
  StartResult r = Solve(cost, irls, start, kLower[1], max_iterations, function_tolerance);
  if (std::isfinite(r.final_cost) && ZenithGradation(r.params) < 1e-3) {
    const int used = r.iterations;
    const double initial = r.initial_cost;
    r = Solve(cost, irls, r.params, -0.999, max_iterations, function_tolerance);
    r.iterations += used;
    r.initial_cost = initial;
  }
  if (ZenithGradation(r.params) <= 0) r.final_cost = std::numeric_limits<double>::infinity();
  return r;
}

// The results of the best `count` distinct minima, best first: a result whose cost is within
// kSameMinimum (relative) of a better one's is taken for the same minimum; one whose cost is
// more than kRefineWithin above the best's is left out.
std::vector<StartResult> BestDistinct(std::vector<StartResult> results, size_t count) {
  std::sort(results.begin(), results.end(),
            [](const StartResult& x, const StartResult& y) { return x.final_cost < y.final_cost; });
  std::vector<StartResult> out;
  for (const StartResult& r : results) {
    if (out.size() == count || !std::isfinite(r.final_cost)) break;
    if (!out.empty() && r.final_cost > out.front().final_cost * (1 + kRefineWithin)) break;
    if (!out.empty() && r.final_cost <= out.back().final_cost * (1 + kSameMinimum)) continue;
    out.push_back(r);
  }
  return out;
}

// A start vector for a shape, with Lz in closed form (weighted linear least squares).
void MakeStart(const std::vector<SkyPoint>& points, const double shape[6], double* p) {
  p[0] = 1.0;
  for (int k = 0; k < 6; ++k) p[k + 1] = std::clamp(shape[k], kLower[k + 1], kUpper[k + 1]);
  double num = 0, den = 0;
  for (const SkyPoint& q : points) {
    const double f = internal::SkyModelAt(p, q, nullptr);
    num += q.w * q.s * q.s * q.y * f;
    den += q.w * q.s * q.s * f * f;
  }
  p[0] = den > 0 && num > 0 ? num / den : 1.0;
}

// Closed-form Lz for fixed shape parameters p[1..6] (weighted linear least squares); returns
// the eq. 10 cost and writes p[0].
double FitLzOnly(const std::vector<SkyPoint>& points, double* p) {
  p[0] = 1.0;
  double num = 0, den = 0;
  std::vector<double> f(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const SkyPoint& q = points[i];
    f[i] = internal::SkyModelAt(p, q, nullptr);
    num += q.w * q.s * q.s * q.y * f[i];
    den += q.w * q.s * q.s * f[i] * f[i];
  }
  p[0] = den > 0 && num > 0 ? num / den : 1.0;
  double cost = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const double r = points[i].s * (points[i].y - p[0] * f[i]);
    cost += 0.5 * points[i].w * r * r;
  }
  return std::isfinite(cost) ? cost : std::numeric_limits<double>::infinity();
}

}  // namespace

const char* SkyModelKindName(SkyModelKind kind) {
  switch (kind) {
    case SkyModelKind::kSevenParam:
      return "7";
    case SkyModelKind::kPerez5:
      return "perez5";
    case SkyModelKind::kCie:
      return "cie";
  }
  return "7";
}

SkyModelKind ParseSkyModelKind(const std::string& name) {
  if (name == "7" || name == "seven") return SkyModelKind::kSevenParam;
  if (name == "perez5") return SkyModelKind::kPerez5;
  if (name == "cie") return SkyModelKind::kCie;
  throw Error("sky model '" + name + "' is not one of 7, perez5, cie");
}

std::vector<Eigen::Vector3d> SkyRelativeResiduals(const SkyModel& model,
                                                  const std::vector<SkySample>& samples) {
  std::vector<Eigen::Vector3d> out(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) {
    const Eigen::Vector3d l = model.Radiance(samples[i].dir);
    for (int c = 0; c < 3; ++c) {
      const double y = samples[i].radiance[c];
      out[i][c] = y > 0 && std::isfinite(y) ? (l[c] - y) / y : 0.0;
    }
  }
  return out;
}

SkyResidualStats SummarizeSkyResiduals(const std::vector<Eigen::Vector3d>& residuals) {
  SkyResidualStats s;
  if (residuals.empty()) return s;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> a(residuals.size());
    double sum = 0;
    for (size_t i = 0; i < residuals.size(); ++i) {
      a[i] = std::abs(residuals[i][c]);
      sum += a[i];
    }
    s.median[c] = Quantile(a, 0.5);
    s.p90[c] = Quantile(a, 0.9);
    s.max[c] = *std::max_element(a.begin(), a.end());
    s.mean[c] = sum / a.size();
  }
  return s;
}

void SkySampleOptions::Validate() const {
  if (!std::isfinite(min_elevation_deg) || min_elevation_deg < 0 || min_elevation_deg >= 89) {
    throw Error("SkySampleOptions: min_elevation_deg must be in [0, 89), got " +
                std::to_string(min_elevation_deg));
  }
  if (!std::isfinite(min_sun_distance_deg) || min_sun_distance_deg < 0 ||
      min_sun_distance_deg > 90) {
    throw Error("SkySampleOptions: min_sun_distance_deg must be in [0, 90], got " +
                std::to_string(min_sun_distance_deg));
  }
  if (max_samples < 1) {
    throw Error("SkySampleOptions: max_samples must be positive, got " +
                std::to_string(max_samples));
  }
}

void SkyFitOptions::Validate() const {
  if (max_iterations < 1) {
    throw Error("SkyFitOptions: max_iterations must be positive, got " +
                std::to_string(max_iterations));
  }
  if (min_directions < 7) {
    throw Error("SkyFitOptions: min_directions must be at least 7 (the parameter count), got " +
                std::to_string(min_directions));
  }
  if (!std::isfinite(min_spread_deg) || min_spread_deg < 0 || min_spread_deg > 90) {
    throw Error("SkyFitOptions: min_spread_deg must be in [0, 90], got " +
                std::to_string(min_spread_deg));
  }
  if (!std::isfinite(function_tolerance) || function_tolerance <= 0) {
    throw Error("SkyFitOptions: function_tolerance must be positive");
  }
  if (!std::isfinite(norm_p) || norm_p < 1 || norm_p > 16) {
    throw Error("SkyFitOptions: norm_p must be in [1, 16], got " + std::to_string(norm_p));
  }
  if (!std::isfinite(norm_eps) || norm_eps <= 0 || norm_eps > 0.1) {
    throw Error("SkyFitOptions: norm_eps must be in (0, 0.1], got " + std::to_string(norm_eps));
  }
  if (random_starts < 0 || random_starts > 1000) {
    throw Error("SkyFitOptions: random_starts must be in [0, 1000], got " +
                std::to_string(random_starts));
  }
}

std::vector<SkySample> ExtractSkySamples(const Image& hdr, const std::vector<uint8_t>* valid_mask,
                                         const Intrinsics& intrinsics, const Pose& pose,
                                         const Eigen::Vector3d& sun_dir,
                                         const SkySampleOptions& options) {
  options.Validate();
  intrinsics.Validate();
  if (hdr.units != PixelUnits::kRadiance) {
    throw Error("sky samples: the image is not a radiance image (kRadiance)");
  }
  if (hdr.channels != 3 && hdr.channels != 1) {
    throw Error("sky samples: the image must have 1 or 3 channels, has " +
                std::to_string(hdr.channels));
  }
  if (hdr.width != intrinsics.width || hdr.height != intrinsics.height) {
    throw Error("sky samples: image " + std::to_string(hdr.width) + "x" +
                std::to_string(hdr.height) + " does not match the intrinsics " +
                std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height));
  }
  const size_t np = static_cast<size_t>(hdr.width) * hdr.height;
  if (hdr.data.size() != np * hdr.channels) {
    throw Error("sky samples: pixel buffer size does not match the image dimensions");
  }
  if (valid_mask && !valid_mask->empty() && valid_mask->size() != np) {
    throw Error("sky samples: valid mask has " + std::to_string(valid_mask->size()) +
                " entries, expected " + std::to_string(np));
  }
  if (!sun_dir.allFinite() || sun_dir.norm() < 1e-9) {
    throw Error("sky samples: the sun direction is not a direction");
  }
  const Eigen::Vector3d sun = sun_dir.normalized();
  const double z0 = std::sin(options.min_elevation_deg * kDeg);

  // Equal-area cells: azimuth x z (z = sin elevation is uniform in solid angle); about one
  // per sample, never more than there are pixels.
  const double cells = std::clamp(static_cast<double>(options.max_samples), 64.0,
                                  std::max(64.0, static_cast<double>(np)));
  const double step = std::sqrt(2 * kPi * (1 - z0) / cells);
  const int n_az = std::max(1, static_cast<int>(std::ceil(2 * kPi / step)));
  const int n_z = std::max(1, static_cast<int>(std::ceil((1 - z0) / step)));
  const size_t n_cells = static_cast<size_t>(n_az) * n_z;
  auto radiance_at = [&](size_t p, Eigen::Vector3d* rad) {
    bool ok = true;
    for (int c = 0; c < 3; ++c) {
      (*rad)[c] = hdr.data[p * hdr.channels + (hdr.channels == 1 ? 0 : c)];
      ok = ok && std::isfinite((*rad)[c]) && (*rad)[c] > 0;
    }
    return ok;
  };
  auto direction_at = [&](int x, int y) {
    return (pose.rotation * Unproject(intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
  };

  // Every pixel is a candidate (a lattice would miss small masked regions): its cell (or -1)
  // and its solid angle.
  std::vector<int32_t> cell_of(np, -1);
  std::vector<float> omega(np, 0.f);
  tbb::parallel_for(0, hdr.height, [&](int y) {
    for (int x = 0; x < hdr.width; ++x) {
      const size_t p = static_cast<size_t>(y) * hdr.width + x;
      Eigen::Vector3d rad;
      if ((valid_mask && !valid_mask->empty() && (*valid_mask)[p] == 0) || !radiance_at(p, &rad))
        continue;
      const Eigen::Vector3d d = direction_at(x, y);
      if (!d.allFinite() || !InSkyFitRegion(d, sun, options)) continue;
      double az = std::atan2(d.x(), d.y());
      if (az < 0) az += 2 * kPi;
      const int ia = std::min(n_az - 1, static_cast<int>(az / (2 * kPi) * n_az));
      const int iz = std::min(n_z - 1, static_cast<int>((d.z() - z0) / (1 - z0) * n_z));
      cell_of[p] = iz * n_az + ia;
      omega[p] = static_cast<float>(PixelSolidAngle(intrinsics, x, y));
    }
  });
  std::vector<size_t> count(n_cells, 0);
  std::vector<double> cell_omega(n_cells, 0);
  size_t total = 0;
  for (size_t p = 0; p < np; ++p) {
    if (cell_of[p] < 0) continue;
    ++count[static_cast<size_t>(cell_of[p])];
    cell_omega[static_cast<size_t>(cell_of[p])] += omega[p];
    ++total;
  }

  // Equal shares: every cell keeps min(count, level) samples, the level the largest whose sum
  // fits max_samples; the remainder one more each in cells with candidates left, in a random
  // cell order.
  std::mt19937_64 rng(options.seed);
  std::vector<size_t> occupied;
  for (size_t i = 0; i < n_cells; ++i) {
    if (count[i] > 0) occupied.push_back(i);
  }
  std::shuffle(occupied.begin(), occupied.end(), rng);
  const size_t want = std::min(total, static_cast<size_t>(options.max_samples));
  auto kept_at = [&](size_t level) {
    size_t sum = 0;
    for (size_t i : occupied) sum += std::min(count[i], level);
    return sum;
  };
  size_t lo = 0, hi = total == 0 ? 0 : *std::max_element(count.begin(), count.end());
  while (lo < hi) {  // the largest level with kept_at(level) <= want
    const size_t mid = (lo + hi + 1) / 2;
    if (kept_at(mid) <= want) {
      lo = mid;
    } else {
      hi = mid - 1;
    }
  }
  std::vector<size_t> quota(n_cells, 0);
  size_t extra = want - kept_at(lo);
  for (size_t i : occupied) {
    quota[i] = std::min(count[i], lo);
    if (extra > 0 && count[i] > lo) ++quota[i], --extra;
  }

  // A cell that keeps every candidate weighs each by its solid angle. Otherwise its quota is
  // drawn in proportion to solid angle, systematically in pixel order (thresholds at (j + u)
  // cell solid angle / quota, u random per cell), each draw standing for that share of the
  // cell's solid angle (a pixel drawn twice: twice the weight).
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> next(n_cells, 0), run(n_cells, 0);
  for (size_t i : occupied) next[i] = u(rng) * cell_omega[i] / static_cast<double>(quota[i]);
  std::vector<std::vector<SkySample>> bins(n_cells);
  for (int y = 0; y < hdr.height; ++y) {
    for (int x = 0; x < hdr.width; ++x) {
      const size_t p = static_cast<size_t>(y) * hdr.width + x;
      if (cell_of[p] < 0) continue;
      const size_t c = static_cast<size_t>(cell_of[p]);
      if (quota[c] == 0) continue;
      double weight = 0;
      if (quota[c] == count[c]) {
        weight = omega[p];
      } else {
        const double share = cell_omega[c] / static_cast<double>(quota[c]);
        run[c] += omega[p];
        while (next[c] < run[c]) {
          weight += share;
          next[c] += share;
        }
      }
      if (weight == 0) continue;
      SkySample s;
      s.dir = direction_at(x, y);
      radiance_at(p, &s.radiance);
      s.weight = weight;
      bins[c].push_back(s);
    }
  }

  // Round-robin over the cells (random order), so that any prefix is spread evenly too.
  std::vector<SkySample> out;
  out.reserve(want);
  for (size_t round = 0;; ++round) {
    bool any = false;
    for (size_t i : occupied) {
      if (round < bins[i].size()) {
        out.push_back(bins[i][round]);
        any = true;
      }
    }
    if (!any) break;
  }
  return out;
}

bool InSkyFitRegion(const Eigen::Vector3d& dir, const Eigen::Vector3d& sun,
                    const SkySampleOptions& options) {
  return dir.z() >= std::sin(options.min_elevation_deg * kDeg) &&
         dir.dot(sun) <= std::cos(options.min_sun_distance_deg * kDeg);
}

SkyCoverage MeasureSkyCoverage(const std::vector<SkySample>& samples) {
  constexpr int kBands = 10, kAzimuths = 20;
  std::vector<Eigen::Vector3d> cell_sum(kBands * kAzimuths, Eigen::Vector3d::Zero());
  for (const SkySample& s : samples) {
    double az = std::atan2(s.dir.x(), s.dir.y());
    if (az < 0) az += 2 * kPi;
    const int ia = std::min(kAzimuths - 1, static_cast<int>(az / (2 * kPi) * kAzimuths));
    const int iz = std::clamp(static_cast<int>(s.dir.z() * kBands), 0, kBands - 1);
    cell_sum[iz * kAzimuths + ia] += s.dir;
  }
  SkyCoverage out;
  Eigen::Vector3d resultant = Eigen::Vector3d::Zero();
  int cells = 0;
  for (const Eigen::Vector3d& v : cell_sum) {
    if (v.norm() == 0) continue;
    resultant += v.normalized();
    ++cells;
  }
  if (cells == 0) return out;
  // Mean resultant length R of a uniform cap of radius r: (1 + cos r) / 2.
  const double r = resultant.norm() / cells;
  out.spread_deg = std::acos(std::clamp(2 * r - 1, -1.0, 1.0)) / kDeg;
  std::vector<std::array<double, 3>> values;
  values.reserve(samples.size());
  for (const SkySample& s : samples)
    values.push_back({s.radiance[0], s.radiance[1], s.radiance[2]});
  std::sort(values.begin(), values.end());
  const int distinct = static_cast<int>(std::unique(values.begin(), values.end()) - values.begin());
  out.directions = std::min(cells, distinct);
  return out;
}

std::string SkyCoverageProblem(const SkyCoverage& coverage, const SkyFitOptions& options) {
  if (coverage.directions < options.min_directions) {
    return Formatted(
        "%d distinct directions, need at least %d: 3 per parameter of the model, so that the "
        "error the fit reports is at least 1/sqrt(2) of its error on fresh measurements "
        "(directions count once per 0.031 sr cell of the sky, about 10 x 10 deg, and once per "
        "distinct radiance)",
        coverage.directions, options.min_directions);
  }
  if (coverage.spread_deg < options.min_spread_deg) {
    return Formatted(
        "the directions cover too little of the sky: they are as concentrated as a cap of "
        "radius %.0f deg, need at least %.0f deg (half the hemisphere): a fit to a smaller part "
        "of the sky extrapolates eq. 9's zenith-to-horizon and sun-to-far-sky terms",
        coverage.spread_deg, options.min_spread_deg);
  }
  return "";
}

std::vector<SkySample> ReadSkySamplesCsv(const std::string& path) {
  const std::vector<std::string> lines = ReadTextLines(path, "a sky samples CSV");
  std::vector<SkySample> out;
  std::vector<int> line_of;
  size_t fields = 0;  // of the first line with data: 5, or 6 with a leading index
  bool first = true;
  for (size_t n = 0; n < lines.size(); ++n) {
    const std::string where = path + ":" + std::to_string(n + 1);
    const std::string line = Trimmed(lines[n]);
    if (line.empty() || line.front() == '#') continue;
    const std::vector<std::string> f = CsvFields(line);
    double v0 = 0;
    const bool header = first && !ParseFullDouble(f[0], &v0);
    first = false;
    if (header) continue;
    if (fields == 0) {
      if (f.size() != 5 && f.size() != 6) {
        throw Error(where + ": " + std::to_string(f.size()) +
                    " comma-separated fields; a sky sample is 'azimuth_deg, elevation_deg, R, "
                    "G, B', optionally after an index");
      }
      fields = f.size();
    } else if (f.size() != fields) {
      throw Error(where + ": " + std::to_string(f.size()) + " fields, the first line has " +
                  std::to_string(fields));
    }
    static const char* const kNames[] = {"azimuth_deg", "elevation_deg", "R", "G", "B"};
    const size_t off = fields - 5;
    if (off == 1) {
      double idx = 0;
      if (!ParseFullDouble(f[0], &idx) || idx < 0 || idx != std::floor(idx))
        throw Error(where + ": index '" + f[0] + "' is not a non-negative integer");
    }
    double v[5];
    for (int k = 0; k < 5; ++k) {
      const std::string& text = f[off + k];
      if (!ParseFullDouble(text, &v[k]))
        throw Error(where + ": " + kNames[k] + " '" + text + "' is not a number");
      if (!std::isfinite(v[k])) throw Error(where + ": " + kNames[k] + " is not finite");
    }
    if (v[1] < 0 || v[1] > 90)
      throw Error(where + ": elevation_deg " + f[off + 1] + " is outside [0, 90]");
    for (int k = 2; k < 5; ++k) {
      if (!(v[k] > 0))
        throw Error(where + ": " + kNames[k] + " " + f[off + k] +
                    " is not positive (the fit needs positive radiance in every channel)");
    }
    SkySample s;
    s.dir = EnuFromAzEl(v[0], v[1]).normalized();
    s.radiance = Eigen::Vector3d(v[2], v[3], v[4]);
    for (size_t i = 0; i < out.size(); ++i) {
      if (std::acos(std::clamp(out[i].dir.dot(s.dir), -1.0, 1.0)) < 0.01 * kDeg)
        throw Error(where + ": the same direction as line " + std::to_string(line_of[i]) +
                    " (within 0.01 deg)");
    }
    out.push_back(s);
    line_of.push_back(static_cast<int>(n + 1));
  }
  if (out.empty()) throw Error(path + ": no sky directions (azimuth_deg, elevation_deg, R, G, B)");
  return out;
}

SkyFitSummary FitSky(const std::vector<SkySample>& samples, const Eigen::Vector3d& sun_dir,
                     const SkyFitOptions& options, SkyModel* out) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  assert(out != nullptr);
  if (!sun_dir.allFinite() || sun_dir.norm() < 1e-9) {
    throw Error("sky fit: the sun direction is not a direction");
  }
  const Eigen::Vector3d sun = sun_dir.normalized();
  Eigen::Vector3d min_y = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  double weight_sum = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    const SkySample& s = samples[i];
    if (!s.dir.allFinite() || std::abs(s.dir.norm() - 1) > 1e-6) {
      throw Error("sky fit: sample " + std::to_string(i) + " direction is not a unit vector");
    }
    if (s.dir.z() < -1e-9) {
      throw Error("sky fit: sample " + std::to_string(i) + " lies below the horizon");
    }
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(s.radiance[c]) || s.radiance[c] <= 0) {
        throw Error("sky fit: sample " + std::to_string(i) + " channel " + std::to_string(c) +
                    " radiance " + std::to_string(s.radiance[c]) + " is not positive and finite");
      }
      min_y[c] = std::min(min_y[c], s.radiance[c]);
    }
    if (!std::isfinite(s.weight) || s.weight <= 0) {
      throw Error("sky fit: sample " + std::to_string(i) + " weight " + std::to_string(s.weight) +
                  " is not positive and finite");
    }
    weight_sum += s.weight;
  }
  if (const std::string problem = SkyCoverageProblem(MeasureSkyCoverage(samples), options);
      !problem.empty()) {
    throw Error("sky fit: " + problem);
  }
  // Weights normalised to mean 1: the objective keeps the scale of unweighted samples.
  const double weight_scale = static_cast<double>(samples.size()) / weight_sum;

  SkyFitSummary summary;
  summary.samples = static_cast<int>(samples.size());
  summary.model = options.model;
  SkyModel model;
  model.sun_dir = sun;
  const bool relative = options.weighting == SkyWeighting::kRelative;
  // Normalised radiance y' = y / (0.5 min y) >= 2, so log y' >= log 2 > 0 (eq. 10 weights).
  std::array<double, 3> ref{};
  std::array<std::vector<SkyPoint>, 3> points;
  for (int c = 0; c < 3; ++c) {
    ref[c] = 0.5 * min_y[c];
    points[c].reserve(samples.size());
    for (const SkySample& s : samples) {
      points[c].push_back(internal::MakeSkyPoint(s.dir, sun, s.radiance[c] / ref[c], relative,
                                                 s.weight * weight_scale));
    }
  }
  std::array<StartResult, 3> best;

  if (options.model == SkyModelKind::kCie) {
    // Every CIE type with a closed-form Lz per channel; the lowest total cost wins.
    const auto t0 = std::chrono::steady_clock::now();
    const double sun_zenith = std::acos(std::clamp(sun.z(), 0.0, 1.0));
    double best_total = std::numeric_limits<double>::infinity();
    for (int t = 1; t <= kNumCieSkyTypes; ++t) {
      const SkyParams q = CieAsSkyParams(CieStandardSky(t), sun_zenith, 1.0);
      std::array<StartResult, 3> trial;
      double total = 0;
      for (int c = 0; c < 3; ++c) {
        double* p = trial[c].params;
        const double shape[7] = {1, q.a, q.b, q.c, q.d, q.e, q.h};
        std::copy(shape, shape + 7, p);
        trial[c].final_cost = trial[c].initial_cost = FitLzOnly(points[c], p);
        total += trial[c].final_cost;
      }
      if (total < best_total) {
        best_total = total;
        best = trial;
        summary.cie_type = t;
      }
    }
    for (int c = 0; c < 3; ++c) {
      summary.channel[c].starts = kNumCieSkyTypes;
      summary.channel[c].seconds = Seconds(t0);
    }
  } else {
    const int n_fixed = options.multiple_starts ? static_cast<int>(std::size(kStarts)) : 1;
    const int n_starts = n_fixed + options.random_starts;
    // Random shapes over the range that clear to hazy skies span (the same for every channel).
    std::vector<std::array<double, 6>> shapes;
    for (int k = 0; k < n_fixed; ++k) {
      shapes.push_back({kStarts[k][0], kStarts[k][1], kStarts[k][2], kStarts[k][3], kStarts[k][4],
                        kStarts[k][5]});
    }
    std::mt19937_64 rng(options.seed);
    std::uniform_real_distribution<double> u(0, 1);
    for (int k = 0; k < options.random_starts; ++k) {
      const double a = -1.5 + 2.5 * u(rng), b = -2.0 + 1.9 * u(rng);
      const double c = std::exp(std::log(0.5) + (std::log(150.0) - std::log(0.5)) * u(rng));
      const double d = -8.0 + 7.5 * u(rng), e = -0.5 + 2.0 * u(rng), h = 0.5 + 1.0 * u(rng);
      shapes.push_back({a, b, c, d, e, h});
    }
    tbb::parallel_for(0, 3, [&](int c) {
      const auto t0 = std::chrono::steady_clock::now();
      const std::vector<SkyPoint>& pts = points[c];
      const bool fixed_h = options.model == SkyModelKind::kPerez5;
      // Every start on an evenly thinned subset, then the best distinct minima on all samples.
      const size_t stride = std::max<size_t>(1, pts.size() / kScreenSamples);
      const bool screen = stride > 1;
      std::vector<SkyPoint> subset;
      for (size_t i = 0; i < pts.size(); i += stride) subset.push_back(pts[i]);
      const SkyCost full_ls(pts, fixed_h), subset_ls(subset, fixed_h);
      // On the subset: kScreenIterations and kScreenTolerance; on all samples: the options'.
      const int screen_iterations = screen ? kScreenIterations : options.max_iterations;
      const double screen_tolerance = screen ? kScreenTolerance : options.function_tolerance;
      std::vector<StartResult> screened;
      for (int k = 0; k < n_starts; ++k) {
        double p0[7];
        MakeStart(subset, shapes[k].data(), p0);
        if (fixed_h) p0[6] = 1;
        screened.push_back(RunStart(screen ? subset_ls : full_ls, nullptr, p0, screen_iterations,
                                    screen_tolerance));
      }
      const std::vector<StartResult> ls = BestDistinct(std::move(screened), kRefined);
      StartResult b;
      if (!ls.empty() && options.norm_p == 2) {
        for (const StartResult& s : ls) {
          StartResult r = screen ? RunStart(full_ls, nullptr, s.params, options.max_iterations,
                                            options.function_tolerance)
                                 : s;
          if (screen) r.iterations += s.iterations;
          if (r.final_cost < b.final_cost) b = r;
        }
      } else if (!ls.empty()) {
        // The p-norm objective has its own local minima: it starts from the subset's
        // least-squares optimum and from every starting shape, each on the subset; the best
        // distinct minima continue on all samples. p < 2: the least-squares residuals
        // reweighted (Objective's irls); p > 2: the transformed residuals.
        const SkyNormTransform norm(options.norm_p, options.norm_eps);
        const bool irls = options.norm_p < 2;
        const SkyCost full_pn(irls ? std::vector<SkyPoint>{} : pts, fixed_h, options.norm_p,
                              options.norm_eps);
        const SkyCost subset_pn(irls ? std::vector<SkyPoint>{} : subset, fixed_h, options.norm_p,
                                options.norm_eps);
        const SkyCost& on_full = irls ? full_ls : full_pn;
        const SkyCost& on_subset =
            irls ? (screen ? subset_ls : full_ls) : (screen ? subset_pn : full_pn);
        const SkyNormTransform* weights = irls ? &norm : nullptr;
        std::vector<StartResult> cands;
        cands.push_back(
            RunStart(on_subset, weights, ls.front().params, screen_iterations, screen_tolerance));
        for (int k = 0; k < n_starts; ++k) {
          double p0[7];
          MakeStart(subset, shapes[k].data(), p0);
          if (fixed_h) p0[6] = 1;
          cands.push_back(RunStart(on_subset, weights, p0, screen_iterations, screen_tolerance));
        }
        for (const StartResult& s : BestDistinct(std::move(cands), kRefined)) {
          StartResult r = screen ? RunStart(on_full, weights, s.params, options.max_iterations,
                                            options.function_tolerance)
                                 : s;
          r.iterations += ls.front().iterations + (screen ? s.iterations : 0);
          if (r.final_cost < b.final_cost) b = r;
        }
      }
      best[c] = b;
      summary.channel[c].starts = n_starts;
      summary.channel[c].seconds = Seconds(t0);
    });
  }

  for (int c = 0; c < 3; ++c) {
    const StartResult& b = best[c];
    SkyChannelSummary& cs = summary.channel[c];
    cs.final_cost = b.final_cost;
    if (!std::isfinite(b.final_cost)) continue;  // reported below
    SkyParams& p = model.channel[c];
    p.Lz = b.params[0] * ref[c];
    p.a = b.params[1];
    p.b = b.params[2];
    p.c = b.params[3];
    p.d = b.params[4];
    p.e = b.params[5];
    p.h = b.params[6];
    std::vector<double> rel(points[c].size()), w(points[c].size());
    double sum = 0, wsum = 0;
    for (size_t i = 0; i < points[c].size(); ++i) {
      const double l = internal::SkyModelAt(b.params, points[c][i], nullptr);
      rel[i] = std::abs(l - points[c][i].y) / points[c][i].y;
      w[i] = points[c][i].w;
      sum += w[i] * rel[i];
      wsum += w[i];
    }
    cs.iterations = b.iterations;
    cs.initial_cost = b.initial_cost;
    cs.rel_error_median = WeightedQuantile(rel, w, 0.5);
    cs.rel_error_p90 = WeightedQuantile(rel, w, 0.9);
    cs.rel_error_max = *std::max_element(rel.begin(), rel.end());
    cs.rel_error_mean = sum / wsum;
  }

  for (int c = 0; c < 3; ++c) {
    const SkyParams& p = model.channel[c];
    for (double v : {p.Lz, p.a, p.b, p.c, p.d, p.e, p.h}) {
      if (!std::isfinite(v)) {
        throw Error("sky fit: channel " + std::to_string(c) +
                    " did not converge to a finite model");
      }
    }
    if (!std::isfinite(summary.channel[c].final_cost) || summary.channel[c].starts == 0) {
      throw Error("sky fit: channel " + std::to_string(c) + " failed from every starting point");
    }
  }
  *out = model;
  summary.seconds = Seconds(start);
  return summary;
}

}  // namespace rouen
