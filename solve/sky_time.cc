#include "solve/sky_time.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "solve/sky_fit.h"

namespace rouen {
namespace {

// The parameter box of FitSky (solve/sky_fit.h), so interpolated skies stay in its domain.
constexpr double kALo = -3, kAHi = 30, kBLo = -10, kBHi = -0.01;
constexpr double kCLo = 0, kCHi = 200, kDLo = -20, kDHi = -0.01;
constexpr double kELo = -0.9, kEHi = 20, kHLo = 0.3, kHHi = 3;

std::string Num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", x);
  return buf;
}

Eigen::Vector3d UnitDirection(const Eigen::Vector3d& d, const std::string& what) {
  const double n = d.norm();
  if (!d.allFinite() || !(n > 1e-12)) throw Error(what + " is not a finite non-zero direction");
  return d / n;
}

bool FiniteParams(const SkyParams& p) {
  return std::isfinite(p.Lz) && std::isfinite(p.a) && std::isfinite(p.b) && std::isfinite(p.c) &&
         std::isfinite(p.d) && std::isfinite(p.e) && std::isfinite(p.h);
}

double AngleBetween(const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
  // atan2 form: accurate for small and large angles alike.
  return std::atan2(u.cross(v).norm(), u.dot(v));
}

struct Quantiles {
  double median = 0, p90 = 0, max = 0;
};

Quantiles QuantilesOf(std::vector<double> v) {
  Quantiles q;
  if (v.empty()) return q;
  std::sort(v.begin(), v.end());
  auto at = [&](double f) {
    const size_t k = std::min(v.size() - 1, static_cast<size_t>(f * (v.size() - 1) + 0.5));
    return v[k];
  };
  q.median = at(0.5);
  q.p90 = at(0.9);
  q.max = v.back();
  return q;
}

// Relative residual of the background part against a target value at 1/cos(xi).
struct BgResidual {
  double inv_cos, target;
  template <typename T>
  bool operator()(const T* ab, T* r) const {
    const T bg = SkyGradationFactor(ab[0], ab[1], inv_cos);
    if (!(bg > T(0))) return false;  // keeps the zenith gradation positive
    r[0] = bg / target - T(1);
    return true;
  }
};

// Relative residual of the scattering part: parameters {c, d, e, h}.
struct SaResidual {
  double log_gamma, cos2, target;
  template <typename T>
  bool operator()(const T* p, T* r) const {
    const T sa = SkyScatteringFactor(p[0], p[1], p[2], p[3], log_gamma, cos2);
    r[0] = sa / target - T(1);
    return true;
  }
};

// Overcast profile with the model's sun at the zenith (gamma = xi), parameters
// {K, a, b, c, d, e, h}: K Bg(xi) Sa(xi) against (1 + 2 cos xi)/3.
struct OvercastResidual {
  double inv_u, log_xi, cos2, target;
  template <typename T>
  bool operator()(const T* p, T* r) const {
    const T bg = SkyGradationFactor(p[1], p[2], inv_u);
    if (!(bg > T(0))) return false;
    const T sa = SkyScatteringFactor(p[3], p[4], p[5], p[6], log_xi, cos2);
    if (!(sa > T(0))) return false;
    r[0] = p[0] * bg * sa / target - T(1);
    return true;
  }
};

// Relative residual of eq. 9 at one direction: parameters {Lz, a, b, c, d, e, h}.
struct FullResidual {
  double inv_cos, log_gamma, cos2, target;
  template <typename T>
  bool operator()(const T* p, T* r) const {
    const T bg = SkyGradationFactor(p[1], p[2], inv_cos);
    if (!(bg > T(0))) return false;
    const T sa = SkyScatteringFactor(p[3], p[4], p[5], p[6], log_gamma, cos2);
    r[0] = p[0] * bg * sa / target - T(1);
    return true;
  }
};

ceres::Solver::Options SolverOptions(int max_iterations) {
  ceres::Solver::Options so;
  so.minimizer_type = ceres::TRUST_REGION;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = max_iterations;
  so.function_tolerance = 1e-14;
  so.gradient_tolerance = 1e-16;
  so.parameter_tolerance = 1e-12;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  return so;
}

SkyParams Params7(const double* p) {
  SkyParams q;
  q.Lz = p[0];
  q.a = p[1];
  q.b = p[2];
  q.c = p[3];
  q.d = p[4];
  q.e = p[5];
  q.h = p[6];
  return q;
}

int Iterations(const ceres::Solver::Summary& s) {
  return std::max(0, static_cast<int>(s.iterations.size()) - 1);
}

}  // namespace

std::vector<Eigen::Vector3d> HemisphereGrid(int rings, int columns) {
  std::vector<Eigen::Vector3d> dirs;
  dirs.reserve(static_cast<size_t>(rings) * columns);
  for (int i = 0; i < rings; ++i) {
    const double u = (i + 0.5) / rings;  // cos xi
    const double s = std::sqrt(std::max(0.0, 1 - u * u));
    for (int j = 0; j < columns; ++j) {
      const double phi = 2 * kPi * (j + 0.5) / columns;
      dirs.emplace_back(s * std::sin(phi), s * std::cos(phi), u);  // azimuth from north (y)
    }
  }
  return dirs;
}

Eigen::Vector3d HorizontalIrradiance(const SkyModel& sky) {
  constexpr int kRings = 48, kColumns = 96;
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& d : HemisphereGrid(kRings, kColumns)) e += sky.Radiance(d) * d.z();
  return e * (2 * kPi / (kRings * kColumns));  // d omega = d(cos xi) d(azimuth)
}

// ---------------------------------------------------------------------------------------------

void SkyInterpOptions::Validate() const {
  if (grid_zenith < 4 || grid_zenith > 2000)
    throw Error("sky interpolation: grid_zenith must be in [4, 2000], got " +
                std::to_string(grid_zenith));
  if (grid_azimuth < 4 || grid_azimuth > 4000)
    throw Error("sky interpolation: grid_azimuth must be in [4, 4000], got " +
                std::to_string(grid_azimuth));
  if (max_iterations < 1)
    throw Error("sky interpolation: max_iterations must be >= 1, got " +
                std::to_string(max_iterations));
  if (!(max_extrapolation_deg >= 0) || !(max_extrapolation_deg <= 90))
    throw Error("sky interpolation: max_extrapolation_deg must be in [0, 90], got " +
                Num(max_extrapolation_deg));
  if (!(coincident_rad >= 0) || !(coincident_rad < 0.1))
    throw Error("sky interpolation: coincident_rad must be in [0, 0.1) radians, got " +
                Num(coincident_rad));
}

namespace {

// Whether the mode weighs the inputs by elevation difference and follows each part's line.
bool ByElevation(SkyInterpMode mode) { return mode != SkyInterpMode::kAngularDistance; }

}  // namespace

std::vector<double> SkyInterpWeights(const std::vector<TimedSky>& skies,
                                     const Eigen::Vector3d& sun_dir,
                                     const SkyInterpOptions& options) {
  options.Validate();
  if (skies.empty()) throw Error("sky interpolation: no input skies");
  const Eigen::Vector3d s = UnitDirection(sun_dir, "sky interpolation: the new sun direction");
  std::vector<double> dist(skies.size());
  int coincident = 0;
  for (size_t j = 0; j < skies.size(); ++j) {
    const Eigen::Vector3d sj = UnitDirection(
        skies[j].sky.sun_dir, "sky interpolation: input " + std::to_string(j) + " sun direction");
    dist[j] = ByElevation(options.mode) ? std::abs(ElevationOf(s) - ElevationOf(sj))
                                        : AngleBetween(s, sj);
    if (dist[j] <= options.coincident_rad) ++coincident;
  }
  std::vector<double> w(skies.size(), 0.0);
  double total = 0;
  for (size_t j = 0; j < skies.size(); ++j) {
    // §5.1: weight proportional to the reciprocal of the distance between suns.
    if (coincident > 0) {
      w[j] = dist[j] <= options.coincident_rad ? 1.0 : 0.0;
    } else {
      w[j] = 1.0 / dist[j];
    }
    total += w[j];
  }
  for (double& x : w) x /= total;
  return w;
}

namespace {

// What a part's log is a straight line of (kElevation, kAirMass): log sin of the sun's elevation
// (a power law in sin e), or the sun's air mass (Beer-Lambert: kAirMass's zenith radiance and
// gradation part, whose light comes down the sun's slant path as the sun's own does).
enum class Abscissa : uint8_t { kLogSin, kAirMass };

// The estimate for the new sun of a positive part known at every input: the weighted mean
// (kAngularDistance), or the weighted least-squares line of log value against the inputs' sun
// elevations' abscissa evaluated at `at_rad` (kElevation, kAirMass; the weighted mean of the logs
// when the weighted inputs share one elevation).
class PartEstimate {
 public:
  PartEstimate(const std::vector<double>& w, const std::vector<double>& elevation, double at_rad,
               SkyInterpMode mode, Abscissa abscissa = Abscissa::kLogSin)
      : w_(w), mode_(mode) {
    if (!ByElevation(mode_)) return;
    // From 1 degree up: a power law in sin(elevation) is straight in log-log.
    auto x = [abscissa](double e) {
      return abscissa == Abscissa::kAirMass ? KastenYoungAirMass(std::max(e, kDeg))
                                            : std::log(std::sin(std::max(e, kDeg)));
    };
    double mean = 0;
    for (size_t j = 0; j < w.size(); ++j) mean += w[j] * x(elevation[j]);
    dx_.resize(w.size());
    double sxx = 0;
    for (size_t j = 0; j < w.size(); ++j) {
      dx_[j] = x(elevation[j]) - mean;
      sxx += w[j] * dx_[j] * dx_[j];
    }
    sxx_ = sxx;
    at_ = x(at_rad) - mean;
  }

  double operator()(const std::vector<double>& v) const {
    double m = 0;
    if (!ByElevation(mode_)) {
      for (size_t j = 0; j < v.size(); ++j) m += w_[j] * v[j];
      return m;
    }
    for (size_t j = 0; j < v.size(); ++j) m += w_[j] * std::log(v[j]);
    double sxy = 0;
    for (size_t j = 0; j < v.size(); ++j) sxy += w_[j] * dx_[j] * (std::log(v[j]) - m);
    // One elevation (to a thousandth of a degree squared): no slope to follow.
    const double slope = sxx_ > 1e-10 ? sxy / sxx_ : 0.0;
    return std::exp(m + slope * at_);
  }

 private:
  const std::vector<double>& w_;
  SkyInterpMode mode_;
  std::vector<double> dx_;
  double sxx_ = 0, at_ = 0;
};

}  // namespace

SkyModel InterpolateSky(const std::vector<TimedSky>& skies, const Eigen::Vector3d& sun_dir,
                        const SkyInterpOptions& options, SkyInterpSummary* summary) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<double> w = SkyInterpWeights(skies, sun_dir, options);
  const Eigen::Vector3d s = sun_dir.normalized();
  const size_t k = skies.size();
  std::vector<double> elevation(k);
  for (size_t j = 0; j < k; ++j) elevation[j] = ElevationOf(skies[j].sky.sun_dir);
  const auto [lowest, highest] = std::minmax_element(elevation.begin(), elevation.end());
  const double reach = ByElevation(options.mode) ? options.max_extrapolation_deg * kDeg : 0.0;
  const double at_elevation = std::clamp(ElevationOf(s), *lowest - reach, *highest + reach);
  const PartEstimate estimate(w, elevation, at_elevation, options.mode);
  // The zenith radiance's and the gradation's estimates: along the air mass in kAirMass, where
  // the zenith's line is followed to the new sun itself (the air mass is what dims it).
  const bool by_air_mass = options.mode == SkyInterpMode::kAirMass;
  const Abscissa dimming = by_air_mass ? Abscissa::kAirMass : Abscissa::kLogSin;
  const PartEstimate gradation(w, elevation, at_elevation, options.mode, dimming);
  const PartEstimate zenith(w, elevation,
                            by_air_mass ? std::max(0.0, ElevationOf(s)) : at_elevation,
                            options.mode, dimming);
  for (size_t j = 0; j < k; ++j) {
    for (int c = 0; c < 3; ++c) {
      const SkyParams& p = skies[j].sky.channel[c];
      if (!FiniteParams(p))
        throw Error("sky interpolation: input " + std::to_string(j) + " channel " +
                    std::to_string(c) + " has a non-finite parameter");
      if (p.Lz < 0)
        throw Error("sky interpolation: input " + std::to_string(j) + " channel " +
                    std::to_string(c) + " has negative Lz " + Num(p.Lz));
    }
  }

  // The grid for the new sun position (§5.1): xi per ring (plus the zenith, where a negative
  // gradation is smallest) and gamma per grid point.
  const int rings = options.grid_zenith, cols = options.grid_azimuth;
  const std::vector<Eigen::Vector3d> grid = HemisphereGrid(rings, cols);
  std::vector<double> ring_xi(rings + 1);
  for (int i = 0; i < rings; ++i) ring_xi[i] = std::acos((i + 0.5) / rings);
  ring_xi[rings] = 0;
  std::vector<double> gamma(grid.size());
  for (size_t i = 0; i < grid.size(); ++i) gamma[i] = AngleBetween(grid[i], s);

  SkyModel out;
  out.sun_dir = s;
  SkyInterpSummary sum;
  sum.weights = w;
  sum.evaluated_elevation_rad = at_elevation;
  std::vector<double> rel_errors;
  rel_errors.reserve(grid.size() * 3);
  for (int c = 0; c < 3; ++c) {
    // The three parts for the new sun (each input's value, then PartEstimate), and the
    // weighted average parameters as the refit's start.
    double start[6] = {0, 0, 0, 0, 0, 0};  // a, b, c, d, e, h
    std::vector<double> lz_in(k), bg_in((rings + 1) * k), sa_in(grid.size() * k);
    for (size_t j = 0; j < k; ++j) {
      const SkyParams& p = skies[j].sky.channel[c];
      lz_in[j] = p.Lz;
      const double pv[6] = {p.a, p.b, p.c, p.d, p.e, p.h};
      for (int q = 0; q < 6; ++q) start[q] += w[j] * pv[q];
      for (int i = 0; i <= rings; ++i) {
        const double bg = SkyBackground(p, ring_xi[i]);
        if (!(bg > 0))
          throw Error("sky interpolation: input " + std::to_string(j) + " channel " +
                      std::to_string(c) + " has a non-positive background part Bg at zenith " +
                      "angle " + Num(ring_xi[i] * 180 / kPi) + " deg");
        bg_in[i * k + j] = bg;
      }
      for (size_t i = 0; i < grid.size(); ++i) {
        const double sa = SkyScattering(p, gamma[i]);
        if (!(sa > 0))
          throw Error("sky interpolation: input " + std::to_string(j) + " channel " +
                      std::to_string(c) + " has a non-positive scattering part Sa at " +
                      Num(gamma[i] * 180 / kPi) + " deg from the sun");
        sa_in[i * k + j] = sa;
      }
    }
    // An input's Lz may be 0 (a black channel): the log line needs positive values.
    const bool lz_positive = *std::min_element(lz_in.begin(), lz_in.end()) > 0;
    const double lz = lz_positive ? zenith(lz_in)
                                  : PartEstimate(w, elevation, at_elevation,
                                                 SkyInterpMode::kAngularDistance)(lz_in);
    std::vector<double> bg_avg(rings + 1), sa_avg(grid.size()), values(k);
    for (int i = 0; i <= rings; ++i) {
      std::copy_n(bg_in.begin() + i * k, k, values.begin());
      bg_avg[i] = gradation(values);
    }
    for (size_t i = 0; i < grid.size(); ++i) {
      std::copy_n(sa_in.begin() + i * k, k, values.begin());
      sa_avg[i] = estimate(values);
    }

    // Refit Bg: {a, b}.
    double ab[2] = {std::clamp(start[0], kALo, kAHi), std::clamp(start[1], kBLo, kBHi)};
    if (!(SkyGradationFactor(ab[0], ab[1], 1.0) > 0)) ab[0] = std::max(ab[0], -0.999);
    ceres::Problem bg_problem;
    for (int i = 0; i <= rings; ++i) {
      const double inv_cos = SkyInvCosXi(ring_xi[i]);
      bg_problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<BgResidual, 1, 2>(new BgResidual{inv_cos, bg_avg[i]}),
          nullptr, ab);
    }
    bg_problem.SetParameterLowerBound(ab, 0, kALo);
    bg_problem.SetParameterUpperBound(ab, 0, kAHi);
    bg_problem.SetParameterLowerBound(ab, 1, kBLo);
    bg_problem.SetParameterUpperBound(ab, 1, kBHi);
    ceres::Solver::Summary bg_summary;
    ceres::Solve(SolverOptions(options.max_iterations), &bg_problem, &bg_summary);

    // Refit Sa: {c, d, e, h}.
    double cdeh[4] = {std::clamp(start[2], kCLo, kCHi), std::clamp(start[3], kDLo, kDHi),
                      std::clamp(start[4], kELo, kEHi), std::clamp(start[5], kHLo, kHHi)};
    ceres::Problem sa_problem;
    for (size_t i = 0; i < grid.size(); ++i) {
      const double g = std::max(gamma[i], 1e-6);
      const double cg = std::cos(gamma[i]);
      sa_problem.AddResidualBlock(new ceres::AutoDiffCostFunction<SaResidual, 1, 4>(
                                      new SaResidual{std::log(g), cg * cg, sa_avg[i]}),
                                  nullptr, cdeh);
    }
    const double lo[4] = {kCLo, kDLo, kELo, kHLo}, hi[4] = {kCHi, kDHi, kEHi, kHHi};
    for (int q = 0; q < 4; ++q) {
      sa_problem.SetParameterLowerBound(cdeh, q, lo[q]);
      sa_problem.SetParameterUpperBound(cdeh, q, hi[q]);
    }
    ceres::Solver::Summary sa_summary;
    ceres::Solve(SolverOptions(options.max_iterations), &sa_problem, &sa_summary);

    SkyParams& p = out.channel[c];
    p.Lz = lz;
    p.a = ab[0];
    p.b = ab[1];
    p.c = cdeh[0];
    p.d = cdeh[1];
    p.e = cdeh[2];
    p.h = cdeh[3];
    if (!FiniteParams(p))
      throw Error("sky interpolation: the refit of channel " + std::to_string(c) +
                  " did not converge to finite parameters");

    SkyPartFitSummary& cs = sum.channel[c];
    cs.iterations = Iterations(bg_summary) + Iterations(sa_summary);
    std::vector<double> bg_fit(rings + 1);
    for (int i = 0; i <= rings; ++i) {
      bg_fit[i] = SkyBackground(p, ring_xi[i]);
      cs.bg_rel_error_max = std::max(cs.bg_rel_error_max, std::abs(bg_fit[i] / bg_avg[i] - 1));
    }
    for (size_t i = 0; i < grid.size(); ++i) {
      const double sa_fit = SkyScattering(p, gamma[i]);
      cs.sa_rel_error_max = std::max(cs.sa_rel_error_max, std::abs(sa_fit / sa_avg[i] - 1));
      if (lz > 0) {
        const int ring = static_cast<int>(i) / cols;
        rel_errors.push_back(std::abs(bg_fit[ring] * sa_fit / (bg_avg[ring] * sa_avg[i]) - 1));
      }
    }
  }
  const Quantiles q = QuantilesOf(rel_errors);
  sum.rel_error_median = q.median;
  sum.rel_error_p90 = q.p90;
  sum.rel_error_max = q.max;

  // Sun radiance and air mass, averaged with the same weights.
  double wsun = 0;
  for (size_t j = 0; j < k; ++j) {
    const Eigen::Vector3d& r = skies[j].sun_radiance;
    if (r.allFinite() && r.norm() > 0) {
      sum.sun_radiance += w[j] * r;
      wsun += w[j];
    }
    const double elev = std::max(0.0, ElevationOf(skies[j].sky.sun_dir));
    sum.reference_air_mass += w[j] * KastenYoungAirMass(elev);
  }
  if (wsun > 0) {
    sum.sun_radiance /= wsun;
  } else {
    sum.sun_radiance.setZero();
  }
  sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (summary) *summary = std::move(sum);
  return out;
}

// ---------------------------------------------------------------------------------------------

double KastenYoungAirMass(double elevation_rad) {
  if (!std::isfinite(elevation_rad)) throw Error("air mass: the sun elevation is not finite");
  // A tolerance of 1e-9 rad lets a sun computed to sit on the horizon pass.
  if (elevation_rad < -1e-9)
    throw Error("air mass: the sun is below the horizon (elevation " +
                Num(elevation_rad * 180 / kPi) + " deg)");
  const double z_deg = 90.0 - std::clamp(elevation_rad, 0.0, kPi / 2) * 180.0 / kPi;
  // Kasten & Young 1989.
  return 1.0 / (std::cos(z_deg * kPi / 180.0) + 0.50572 * std::pow(96.07995 - z_deg, -1.6364));
}

double ElevationOf(const Eigen::Vector3d& dir) {
  return std::atan2(dir.z(), std::hypot(dir.x(), dir.y()));
}

Eigen::Vector3d SunExtinction::SunRadiance(double air_mass) const {
  return (L0.array() * (-beta.array() * air_mass).exp()).matrix();
}

SunExtinction FitSunExtinction(const std::vector<SunObservation>& observations) {
  const size_t n = observations.size();
  std::vector<double> m(n);
  for (size_t i = 0; i < n; ++i) {
    const SunObservation& o = observations[i];
    const std::string who = "sun extinction: observation " + std::to_string(i);
    const Eigen::Vector3d d = UnitDirection(o.sun_dir, who + " sun direction");
    if (!o.radiance.allFinite() || !(o.radiance.minCoeff() > 0))
      throw Error(who + " has a non-positive or non-finite radiance (" + Num(o.radiance[0]) + ", " +
                  Num(o.radiance[1]) + ", " + Num(o.radiance[2]) + ")");
    const double elev = ElevationOf(d);
    if (elev < 0)
      throw Error(who + " has the sun below the horizon (elevation " + Num(elev * 180 / kPi) +
                  " deg)");
    m[i] = KastenYoungAirMass(elev);
  }
  if (n < 2) throw Error("sun extinction: needs at least 2 observations, got " + std::to_string(n));
  const auto [mn, mx] = std::minmax_element(m.begin(), m.end());
  if (*mx - *mn < 1e-3)
    throw Error(
        "sun extinction: the observations need at least 2 distinct air masses (all are "
        "within 1e-3 of " +
        Num(*mn) + "); observe the sun at different elevations");

  SunExtinction ext;
  ext.samples = static_cast<int>(n);
  ext.air_mass_min = *mn;
  ext.air_mass_max = *mx;
  double mbar = 0;
  for (double x : m) mbar += x;
  mbar /= n;
  double sxx = 0;
  for (double x : m) sxx += (x - mbar) * (x - mbar);
  double ss = 0;
  for (int c = 0; c < 3; ++c) {
    // Linear least squares of log L = log L0 - beta m.
    double ybar = 0;
    for (size_t i = 0; i < n; ++i) ybar += std::log(observations[i].radiance[c]);
    ybar /= n;
    double sxy = 0;
    for (size_t i = 0; i < n; ++i)
      sxy += (m[i] - mbar) * (std::log(observations[i].radiance[c]) - ybar);
    const double slope = sxy / sxx;
    ext.beta[c] = -slope;
    const double log_l0 = ybar - slope * mbar;
    ext.L0[c] = std::exp(log_l0);
    for (size_t i = 0; i < n; ++i) {
      const double r = std::log(observations[i].radiance[c]) - (log_l0 + slope * m[i]);
      ss += r * r;
    }
  }
  ext.beta_mean = ext.beta.mean();
  ext.rms_log_residual = std::sqrt(ss / (3.0 * n));
  if (!ext.L0.allFinite() || !ext.beta.allFinite())
    throw Error("sun extinction: the fit is not finite (radiances out of range)");
  return ext;
}

SkyModel ApplyExtinction(const SkyModel& sky, const SunExtinction& extinction, double from_air_mass,
                         double to_air_mass, bool dim_zenith) {
  if (!std::isfinite(from_air_mass) || !std::isfinite(to_air_mass) || from_air_mass <= 0 ||
      to_air_mass <= 0)
    throw Error("sky extinction: air masses must be finite and positive, got " +
                Num(from_air_mass) + " and " + Num(to_air_mass));
  if (!extinction.beta.allFinite() || !std::isfinite(extinction.beta_mean))
    throw Error("sky extinction: the extinction coefficients are not finite");
  const double dm = to_air_mass - from_air_mass;
  SkyModel out = sky;
  for (int c = 0; c < 3; ++c) {
    // §5.1: the mean beta dims the background; the aureole follows the channel's beta.
    if (dim_zenith) out.channel[c].Lz *= std::exp(-extinction.beta_mean * dm);
    out.channel[c].c *= std::exp(-(extinction.beta[c] - extinction.beta_mean) * dm);
  }
  return out;
}

LowSunPrediction PredictLowSun(const std::vector<TimedSky>& skies, const SunExtinction& extinction,
                               const Eigen::Vector3d& sun_dir, const SkyInterpOptions& options,
                               SkyInterpSummary* summary) {
  const Eigen::Vector3d s = UnitDirection(sun_dir, "low sun: the sun direction");
  LowSunPrediction out;
  out.air_mass = KastenYoungAirMass(ElevationOf(s));
  SkyInterpSummary sum;
  const SkyModel shape = InterpolateSky(skies, s, options, &sum);
  out.reference_air_mass = sum.reference_air_mass;
  out.sky = ApplyExtinction(shape, extinction, out.reference_air_mass, out.air_mass);
  out.sun_radiance = extinction.SunRadiance(out.air_mass);
  if (!out.sun_radiance.allFinite())
    throw Error("low sun: the predicted sun radiance is not finite");
  if (summary) *summary = std::move(sum);
  return out;
}

// ---------------------------------------------------------------------------------------------

Eigen::Vector3d OvercastSky::Radiance(const Eigen::Vector3d& dir) const {
  const double n = dir.norm();
  if (!(n > 0) || !std::isfinite(n)) return Eigen::Vector3d::Zero();
  const double cos_xi = std::max(0.0, dir.z() / n);
  // CIE overcast sky (Moon & Spencer), §6.3.
  return zenith_radiance * ((1 + 2 * cos_xi) / 3);
}

SkyModel OvercastAsSkyModel(const OvercastSky& overcast, OvercastFitSummary* summary) {
  if (!overcast.zenith_radiance.allFinite() || overcast.zenith_radiance.minCoeff() < 0)
    throw Error("overcast sky: the zenith radiance must be finite and non-negative");
  // Profile fit of K Bg(xi) Sa(xi) (the model's sun at the zenith) to (1 + 2u)/3, u = cos xi
  // uniform in (0, 1] (equal solid angle), plus the zenith; several starts, the best kept.
  constexpr int kN = 200;
  const double starts[4][7] = {
      {1.0 / 3, 4.0, -0.7, 0.0, -1.0, 0.0, 1.0},    // CIE general sky type 1
      {1.0 / 3, 0.0, -1.0, 1.0, -1.0, 0.0, 1.0},    // aureole-only decay from the zenith
      {0.30, 2.0, -0.5, 2.0, -1.5, 0.15, 1.0},      // CIE-like mix
      {1.0 / 3, -0.5, -0.3, 2.0, -0.5, 0.5, 2.0}};  // broad, flat top
  const double lo[7] = {1e-6, kALo, kBLo, kCLo, kDLo, kELo, kHLo};
  const double hi[7] = {1e6, kAHi, kBHi, kCHi, kDHi, kEHi, kHHi};
  double best[7] = {0, 0, 0, 0, 0, 0, 0};
  double best_cost = std::numeric_limits<double>::infinity();
  for (const auto& start : starts) {
    double p[7];
    std::copy(start, start + 7, p);
    ceres::Problem problem;
    for (int i = 0; i <= kN; ++i) {
      const double u = i < kN ? (i + 0.5) / kN : 1.0;
      const double xi = std::acos(u);
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<OvercastResidual, 1, 7>(
              new OvercastResidual{SkyInvCosXi(xi), SkyLogGamma(xi), u * u, (1 + 2 * u) / 3}),
          nullptr, p);
    }
    for (int q = 0; q < 7; ++q) {
      problem.SetParameterLowerBound(p, q, lo[q]);
      problem.SetParameterUpperBound(p, q, hi[q]);
    }
    ceres::Solver::Summary s;
    ceres::Solve(SolverOptions(300), &problem, &s);
    bool finite = std::isfinite(s.final_cost);
    for (double x : p) finite = finite && std::isfinite(x);
    if (finite && s.final_cost < best_cost) {
      best_cost = s.final_cost;
      std::copy(p, p + 7, best);
    }
  }
  if (!std::isfinite(best_cost)) throw Error("overcast sky: the seven-parameter fit failed");

  SkyModel out;
  out.sun_dir = Eigen::Vector3d::UnitZ();  // gamma = xi: the "aureole" is a zenith brightening
  SkyParams unit;
  unit.Lz = best[0];
  unit.a = best[1];
  unit.b = best[2];
  unit.c = best[3];
  unit.d = best[4];
  unit.e = best[5];
  unit.h = best[6];
  for (int c = 0; c < 3; ++c) {
    out.channel[c] = unit;
    out.channel[c].Lz = unit.Lz * overcast.zenith_radiance[c];
  }
  if (summary) {
    OvercastFitSummary fs;
    double ss = 0, e_fit = 0;
    constexpr int kM = 20000;  // midpoint rule in u: smooth integrands
    for (int i = 0; i < kM; ++i) {
      const double u = (i + 0.5) / kM;
      const double xi = std::acos(u);
      const double model = SkyRadiance(unit, xi, xi);
      const double exact = (1 + 2 * u) / 3;
      const double r = model / exact - 1;
      ss += r * r;
      fs.rel_error_max = std::max(fs.rel_error_max, std::abs(r));
      e_fit += model * u;
    }
    fs.rel_error_rms = std::sqrt(ss / kM);
    e_fit *= 2 * kPi / kM;  // E = 2 pi int_0^1 L(u) u du, per unit overcast Lz
    fs.horizontal_irradiance_rel_error = e_fit / (7 * kPi / 9) - 1;
    *summary = fs;
  }
  return out;
}

Eigen::Vector3d IntermediateSky::Radiance(const Eigen::Vector3d& dir) const {
  // §6.3: linear interpolation between the clear and the overcast sky's colours.
  return (1 - pbs) * clear.Radiance(dir) + pbs * overcast.Radiance(dir);
}

Eigen::Vector3d IntermediateSky::SunRadiance(const Eigen::Vector3d& clear_sun_radiance) const {
  return (1 - pbs) * clear_sun_radiance;
}

IntermediateSky MakeIntermediateSky(const SkyModel& clear, const OvercastSky& overcast,
                                    double pbs) {
  if (!(pbs >= 0 && pbs <= 1))
    throw Error("intermediate sky: the blocked-sunlight fraction must be in [0, 1], got " +
                Num(pbs));
  for (int c = 0; c < 3; ++c) {
    if (!FiniteParams(clear.channel[c]))
      throw Error("intermediate sky: the clear sky's channel " + std::to_string(c) +
                  " has a non-finite parameter");
  }
  UnitDirection(clear.sun_dir, "intermediate sky: the clear sky's sun direction");
  if (!overcast.zenith_radiance.allFinite() || overcast.zenith_radiance.minCoeff() < 0)
    throw Error("intermediate sky: the overcast colour must be finite and non-negative");
  IntermediateSky s;
  s.clear = clear;
  s.overcast = overcast;
  s.pbs = pbs;
  return s;
}

SkyModel IntermediateAsSkyModel(const IntermediateSky& sky, int grid_zenith, int grid_azimuth,
                                IntermediateFitSummary* summary) {
  // Re-validate (the struct's fields are public).
  const IntermediateSky checked = MakeIntermediateSky(sky.clear, sky.overcast, sky.pbs);
  if (grid_zenith < 1 || grid_azimuth < 1 || grid_zenith * grid_azimuth < 20 ||
      grid_zenith > 2000 || grid_azimuth > 4000)
    throw Error("intermediate sky: the grid must have >= 20 points (got " +
                std::to_string(grid_zenith) + " x " + std::to_string(grid_azimuth) + ")");
  IntermediateFitSummary fs;
  SkyModel out;
  if (checked.pbs == 0) {
    out = checked.clear;
  } else if (checked.pbs == 1) {
    out = OvercastAsSkyModel(checked.overcast, nullptr);  // its sun_dir is the zenith
  } else {
    const std::vector<Eigen::Vector3d> grid = HemisphereGrid(grid_zenith, grid_azimuth);
    std::vector<SkySample> samples;
    samples.reserve(grid.size());
    for (const Eigen::Vector3d& d : grid) {
      const Eigen::Vector3d r = checked.Radiance(d);
      if (!r.allFinite() || !(r.minCoeff() > 0))
        throw Error(
            "intermediate sky: the blended sky is not positive in every channel (a "
            "channel with zero clear Lz and zero overcast colour cannot be fitted)");
      samples.push_back({d, r});
    }
    const Eigen::Vector3d sun = checked.clear.sun_dir.normalized();
    // The blend is noiseless and has no regions the model cannot follow: least squares with
    // eq. 10's weights, a start for the polish below.
    SkyFitOptions fo;
    fo.weighting = SkyWeighting::kPaper;
    fo.norm_p = 2;
    SkyModel fitsky;
    FitSky(samples, sun, fo, &fitsky);
    // Polish per channel by relative least squares (what the summary reports), from FitSky's
    // result and from the clear sky with Lz scaled to the blend at the zenith; the lower cost wins.
    out.sun_dir = sun;
    for (int c = 0; c < 3; ++c) {
      const SkyParams& f = fitsky.channel[c];
      SkyParams k = checked.clear.channel[c];
      const double zen = checked.Radiance(Eigen::Vector3d::UnitZ())[c];
      const double zen_clear = checked.clear.Radiance(Eigen::Vector3d::UnitZ())[c];
      if (zen_clear > 0) k.Lz *= zen / zen_clear;
      const double lo[7] = {0, kALo, kBLo, kCLo, kDLo, kELo, kHLo};
      const double hi[7] = {1e300, kAHi, kBHi, kCHi, kDHi, kEHi, kHHi};
      double best_cost = std::numeric_limits<double>::infinity();
      out.channel[c] = f;
      for (const SkyParams& st : {f, k}) {
        double p[7] = {st.Lz, st.a, st.b, st.c, st.d, st.e, st.h};
        for (int q = 0; q < 7; ++q) p[q] = std::clamp(p[q], lo[q], hi[q]);
        if (!(SkyGradationFactor(p[1], p[2], 1.0) > 0)) p[1] = std::max(p[1], -0.999);
        ceres::Problem problem;
        for (const SkySample& smp : samples) {
          const double g = std::max(AngleBetween(smp.dir, sun), 1e-6);
          const double cg = std::cos(g);
          problem.AddResidualBlock(
              new ceres::AutoDiffCostFunction<FullResidual, 1, 7>(new FullResidual{
                  1.0 / std::max(smp.dir.z(), 0.01), std::log(g), cg * cg, smp.radiance[c]}),
              nullptr, p);
        }
        for (int q = 0; q < 7; ++q) {
          problem.SetParameterLowerBound(p, q, lo[q]);
          problem.SetParameterUpperBound(p, q, hi[q]);
        }
        ceres::Solver::Summary sm;
        ceres::Solve(SolverOptions(200), &problem, &sm);
        bool finite = std::isfinite(sm.final_cost);
        for (double x : p) finite = finite && std::isfinite(x);
        if (finite && sm.final_cost < best_cost) {
          best_cost = sm.final_cost;
          out.channel[c] = Params7(p);
        }
      }
    }
    fs.refitted = true;
  }
  if (summary) {
    std::vector<double> errors;
    if (fs.refitted || checked.pbs == 1) {
      for (const Eigen::Vector3d& d : HemisphereGrid(grid_zenith, grid_azimuth)) {
        const Eigen::Vector3d exact = checked.Radiance(d);
        const Eigen::Vector3d fit = out.Radiance(d);
        for (int c = 0; c < 3; ++c)
          if (exact[c] > 0) errors.push_back(std::abs(fit[c] / exact[c] - 1));
      }
    }
    const Quantiles q = QuantilesOf(errors);
    fs.rel_error_median = q.median;
    fs.rel_error_p90 = q.p90;
    fs.rel_error_max = q.max;
    *summary = fs;
  }
  return out;
}

}  // namespace rouen
