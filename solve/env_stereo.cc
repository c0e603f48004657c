#include "solve/env_stereo.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/cost_function.h>
#include <ceres/loss_function.h>
#include <ceres/problem.h>
#include <ceres/solver.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <type_traits>

#include "core/angles.h"
#include "core/error.h"
#include "core/json_text.h"
#include "core/stats.h"
#include "solve/retro.h"

namespace rouen {

namespace {

constexpr int kNumParams = 8;  // k_sky (3), two free k_sun, n (3)

// Eq. 18's smooth clamp of x = n.l for a unit normal: x when x >= 0, else (e^{alpha x} - 1) /
// alpha; and its derivative (1 at 0 from both sides).
inline double SoftCos(double x, double alpha, double* deriv) {
  if (x >= 0) {
    *deriv = 1;
    return x;
  }
  if (alpha * x < -40) {
    *deriv = 0;
    return -1 / alpha;
  }
  const double e = std::exp(alpha * x);
  *deriv = e;
  return (e - 1) / alpha;
}

// The sky of one time as a quadrature over the upper hemisphere: the directions (dx, dy, dz)
// and L x dOmega per channel (w0, w1, w2), by component for SkyIrradiance's whole-array sums.
struct SkyQuad {
  Eigen::ArrayXd dx, dy, dz, w0, w1, w2;
  Eigen::Vector3d horizontal = Eigen::Vector3d::Zero();  // E on an unoccluded level plane
  Eigen::Vector3d ground = Eigen::Vector3d::Zero();      // ground radiance (kPlane, albedo > 0)
};

SkyQuad MakeSkyQuad(const EnvLighting& l, const EnvStereoOptions& o) {
  SkyQuad q;
  const int ne = o.sky_quadrature, na = 2 * o.sky_quadrature;
  for (Eigen::ArrayXd* a : {&q.dx, &q.dy, &q.dz, &q.w0, &q.w1, &q.w2}) a->resize(ne * na);
  const double del = kPi / 2 / ne, daz = 2 * kPi / na;
  for (int i = 0; i < ne; ++i) {
    const double el = (i + 0.5) * del;
    // Exact solid angle of the ring cell.
    const double domega = daz * (std::sin((i + 1) * del) - std::sin(i * del));
    for (int j = 0; j < na; ++j) {
      const double az = (j + 0.5) * daz;
      const Eigen::Vector3d d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az),
                              std::sin(el));
      const Eigen::Vector3d w = l.sky.Radiance(d) * domega;
      const int k = i * na + j;
      q.dx[k] = d.x();
      q.dy[k] = d.y();
      q.dz[k] = d.z();
      q.w0[k] = w[0];
      q.w1[k] = w[1];
      q.w2[k] = w[2];
      q.horizontal += w * d.z();
    }
  }
  if (o.sky_irradiance == EnvSkyIrradiance::kPlane && o.ground_albedo > 0) {
    const Eigen::Vector3d sun_h =
        l.sun_radiance * l.sun_solid_angle_sr * std::max(0.0, l.sun_dir.normalized().z());
    q.ground = o.ground_albedo / kPi * (sun_h + q.horizontal);
  }
  return q;
}

// E_sky per channel for unit normal nh, and (optionally) its gradient d E_c / d nh (rows).
Eigen::Vector3d SkyIrradiance(const SkyQuad& q, const EnvStereoOptions& o,
                              const Eigen::Vector3d& nh, Eigen::Matrix3d* grad) {
  if (grad) grad->setZero();
  if (o.sky_irradiance == EnvSkyIrradiance::kAmbient) return q.horizontal;
  // SoftCos over every direction as whole-array operations: x where x >= 0 (slope 1), -1 / alpha
  // where alpha x < -40 (slope 0), and the exponential only in the narrow band between.
  thread_local Eigen::ArrayXd x, s, ds, wd;
  x = nh.x() * q.dx + nh.y() * q.dy + nh.z() * q.dz;
  const double far = -40 / o.alpha;
  s = x.max(0.0) - (x < far).cast<double>() / o.alpha;
  ds = (x >= 0).cast<double>();
  for (Eigen::Index k = 0; k < x.size(); ++k) {
    if (x[k] < 0 && x[k] >= far) s[k] = SoftCos(x[k], o.alpha, &ds[k]);
  }
  Eigen::Vector3d e((q.w0 * s).sum(), (q.w1 * s).sum(), (q.w2 * s).sum());
  if (grad) {
    const Eigen::ArrayXd* w[3] = {&q.w0, &q.w1, &q.w2};
    for (int c = 0; c < 3; ++c) {
      wd = *w[c] * ds;
      grad->row(c) << (wd * q.dx).sum(), (wd * q.dy).sum(), (wd * q.dz).sum();
    }
  }
  if (q.ground.any()) {
    // Flat Lambertian ground filling the lower hemisphere: E = L_g pi (1 - n_z) / 2.
    e += q.ground * kPi * (1 - nh.z()) / 2;
    if (grad) grad->col(2) -= q.ground * kPi / 2;
  }
  return e;
}

struct TimeData {
  const SkyQuad* quad = nullptr;
  Eigen::Vector3d I, inv_sigma, e_sun, sky_mean;
  Eigen::Vector3d l;  // unit sun direction
};

// Free parameter index of k_sun for each channel (-1: the fixed one).
std::array<int, 3> SunIndex(int fixed) {
  std::array<int, 3> idx{};
  int next = 3;
  for (int c = 0; c < 3; ++c) idx[c] = c == fixed ? -1 : next++;
  return idx;
}

// Eq. 18 residuals (model - I) / sigma for one region over all times, analytic Jacobians.
// Blocks: x (8) and, when with_fraction, f (1).
class RegionCost : public ceres::CostFunction {
 public:
  RegionCost(const std::vector<TimeData>* data, const EnvStereoOptions* o, bool with_fraction)
      : data_(data), o_(o), sun_idx_(SunIndex(o->fixed_channel)) {
    set_num_residuals(3 * static_cast<int>(data->size()));
    mutable_parameter_block_sizes()->push_back(kNumParams);
    if (with_fraction) mutable_parameter_block_sizes()->push_back(1);
    k_fix_ = o->fixed_rho_sun / kPi;
  }

  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const double* x = p[0];
    const bool with_f = parameter_block_sizes().size() > 1;
    const double f = with_f ? p[1][0] : 0.0;
    const Eigen::Vector3d n(x[5], x[6], x[7]);
    const double nn = std::max(n.norm(), 1e-12);
    const Eigen::Vector3d nh = n / nn;
    const Eigen::Matrix3d dnh_dn = (Eigen::Matrix3d::Identity() - nh * nh.transpose()) / nn;
    Eigen::Vector3d ksun;
    for (int c = 0; c < 3; ++c) ksun[c] = sun_idx_[c] < 0 ? k_fix_ : x[sun_idx_[c]];
    const double alpha = o_->alpha;
    for (size_t t = 0; t < data_->size(); ++t) {
      const TimeData& d = (*data_)[t];
      Eigen::Matrix3d gsky;
      const Eigen::Vector3d esky = SkyIrradiance(*d.quad, *o_, nh, jac ? &gsky : nullptr);
      // S(n, l) and dS/dn (eq. 18).
      const double u = nh.dot(d.l);
      double s;
      Eigen::Vector3d ds_dn;
      if (u >= 0) {
        s = n.dot(d.l);
        ds_dn = d.l;
      } else if (alpha * u < -40) {
        s = -nn / alpha;
        ds_dn = -nh / alpha;
      } else {
        const double e = std::exp(alpha * u);
        s = nn * (e - 1) / alpha;
        ds_dn = nh * (e - 1) / alpha + e * (d.l - u * nh);
      }
      for (int c = 0; c < 3; ++c) {
        const int i = 3 * static_cast<int>(t) + c;
        const double w = d.inv_sigma[c];
        const double m = x[c] * esky[c] + ksun[c] * d.e_sun[c] * s + f * d.sky_mean[c];
        residuals[i] = (m - d.I[c]) * w;
        if (!jac) continue;
        if (jac[0]) {
          double* J = jac[0] + i * kNumParams;
          std::fill(J, J + kNumParams, 0.0);
          J[c] = esky[c] * w;
          if (sun_idx_[c] >= 0) J[sun_idx_[c]] = d.e_sun[c] * s * w;
          const Eigen::RowVector3d gn =
              (x[c] * gsky.row(c) * dnh_dn + ksun[c] * d.e_sun[c] * ds_dn.transpose()) * w;
          J[5] = gn[0];
          J[6] = gn[1];
          J[7] = gn[2];
        }
        if (with_f && jac[1]) jac[1][i] = d.sky_mean[c] * w;
      }
    }
    return true;
  }

 private:
  const std::vector<TimeData>* data_;
  const EnvStereoOptions* o_;
  std::array<int, 3> sun_idx_;
  double k_fix_ = 0;
};

// Smoothing between adjacent regions: w (n_i / |n_i| - n_j / |n_j|).
struct SmoothCost {
  double w;
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    using std::sqrt;
    const T na = sqrt(a[5] * a[5] + a[6] * a[6] + a[7] * a[7]) + T(1e-12);
    const T nb = sqrt(b[5] * b[5] + b[6] * b[6] + b[7] * b[7]) + T(1e-12);
    for (int k = 0; k < 3; ++k) r[k] = T(w) * (a[5 + k] / na - b[5 + k] / nb);
    return true;
  }
};

Eigen::Vector3d RegionCentre(const EnvironmentMap& m, int region) {
  double el0, el1, az0, az1;
  m.RegionBounds(region, &el0, &el1, &az0, &az1);
  const double el = (el0 + el1) / 2, az = (az0 + az1) / 2;
  return Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
}

EnvOptions GridOptions(int bands_below, int bands_above, int sectors, int sky_fill_samples) {
  EnvOptions eo;
  eo.bands_below = bands_below;
  eo.bands_above = bands_above;
  eo.sectors = sectors;
  eo.sky_fill_samples = sky_fill_samples;
  return eo;
}

void CheckLighting(const EnvLighting& l, const std::string& what) {
  if (!l.sun_dir.allFinite() || std::abs(l.sun_dir.norm() - 1) > 1e-3) {
    throw Error(what + ": the sun direction is not a unit vector");
  }
  if (!l.sun_radiance.allFinite() || l.sun_radiance.minCoeff() < 0) {
    throw Error(what + ": the sun radiance is negative or not finite");
  }
  if (!(l.sun_solid_angle_sr > 0) || !std::isfinite(l.sun_solid_angle_sr)) {
    throw Error(what + ": the sun's solid angle must be > 0 sr");
  }
  const Eigen::Vector3d z = l.sky.Radiance(Eigen::Vector3d::UnitZ());
  if (!z.allFinite() || z.minCoeff() < 0) {
    throw Error(what + ": the sky model gives a negative or non-finite zenith radiance");
  }
}

// Sky-only fit for a fixed unit normal: k_sky per channel by weighted linear least squares.
void FitSkyOnly(const std::vector<TimeData>& data, const EnvStereoOptions& o,
                const Eigen::Vector3d& nh, EnvRegionFit* fit) {
  Eigen::Vector3d num = Eigen::Vector3d::Zero(), den = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> esky;
  for (const TimeData& d : data) {
    esky.push_back(SkyIrradiance(*d.quad, o, nh, nullptr));
    for (int c = 0; c < 3; ++c) {
      const double w2 = d.inv_sigma[c] * d.inv_sigma[c];
      num[c] += esky.back()[c] * d.I[c] * w2;
      den[c] += esky.back()[c] * esky.back()[c] * w2;
    }
  }
  Eigen::Vector3d k;
  for (int c = 0; c < 3; ++c) k[c] = den[c] > 0 ? std::max(0.0, num[c] / den[c]) : 0.0;
  double ss = 0;
  for (size_t t = 0; t < data.size(); ++t) {
    for (int c = 0; c < 3; ++c) {
      const double r = (k[c] * esky[t][c] - data[t].I[c]) * data[t].inv_sigma[c];
      ss += r * r;
    }
  }
  fit->kind = EnvRegionKind::kSkyOnly;
  fit->normal = nh;
  fit->rho_sky = kPi * k;
  fit->rho_sun.setZero();
  fit->sky_fraction = 0;
  fit->rel_rms = std::sqrt(ss / (3.0 * data.size()));
}

void SolverOptions(const EnvStereoOptions& o, ceres::Solver::Options* so) {
  so->minimizer_type = ceres::TRUST_REGION;
  so->trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so->linear_solver_type = ceres::DENSE_QR;
  so->max_num_iterations = o.max_iterations;
  so->function_tolerance = 1e-12;
  so->gradient_tolerance = 1e-14;
  so->parameter_tolerance = 1e-12;
  so->num_threads = 1;
  so->logging_type = ceres::SILENT;
  so->minimizer_progress_to_stdout = false;
}

// The fitted parameters of a landscape region (kept for the smoothing refinement).
struct RegionState {
  std::vector<TimeData> data;
  double x[kNumParams] = {0};
  double f = 0;
  bool with_fraction = false;
};

void StateToFit(const RegionState& s, const EnvStereoOptions& o, EnvRegionFit* fit) {
  const std::array<int, 3> idx = SunIndex(o.fixed_channel);
  const Eigen::Vector3d n(s.x[5], s.x[6], s.x[7]);
  const double nn = std::max(n.norm(), 1e-12);
  fit->kind = EnvRegionKind::kLandscape;
  fit->normal = n / nn;
  for (int c = 0; c < 3; ++c) {
    fit->rho_sky[c] = kPi * s.x[c];
    fit->rho_sun[c] = kPi * nn * (idx[c] < 0 ? o.fixed_rho_sun / kPi : s.x[idx[c]]);
  }
  fit->sky_fraction = s.with_fraction ? s.f : 0;
  fit->sunlit_times = 0;
  for (const TimeData& d : s.data) fit->sunlit_times += fit->normal.dot(d.l) > 0;
}

double Cost(const RegionState& s, const EnvStereoOptions& o) {
  RegionCost cost(&s.data, &o, s.with_fraction);
  std::vector<double> r(3 * s.data.size());
  const double* blocks[2] = {s.x, &s.f};
  cost.Evaluate(blocks, r.data(), nullptr);
  double ss = 0;
  for (double v : r) ss += v * v;
  return ss;
}

// The sun term's factor of a ground region (EnvStereoOptions::ground_retro); 1 elsewhere.
double GroundSunFactor(const EnvRegionFit& fit, const EnvStereoOptions& o,
                       const Eigen::Vector3d& sun) {
  if (o.ground_retro == 0 || fit.to_viewer.squaredNorm() == 0) return 1;
  return RetroFactor(o.ground_retro, Eigen::Vector3d::UnitZ(), sun, fit.to_viewer);
}

// Pulls a region's unit normal (parameters 5..7 of x, not unit) towards up.
struct NormalPrior {
  double weight;
  template <typename T>
  bool operator()(const T* x, T* r) const {
    const T n = ceres::sqrt(x[5] * x[5] + x[6] * x[6] + x[7] * x[7]) + T(1e-12);
    r[0] = weight * x[5] / n;
    r[1] = weight * x[6] / n;
    r[2] = weight * (x[7] / n - T(1));
    return true;
  }
};

Eigen::Vector3d PredictWithQuad(const EnvRegionFit& fit, const EnvStereoOptions& o,
                                const EnvLighting& l, const SkyQuad& q,
                                const Eigen::Vector3d& sky_mean) {
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  switch (fit.kind) {
    case EnvRegionKind::kSky:
      out = sky_mean;
      break;
    case EnvRegionKind::kUnobserved:
      break;
    case EnvRegionKind::kLandscape:
    case EnvRegionKind::kSkyOnly: {
      const Eigen::Vector3d esky = SkyIrradiance(q, o, fit.normal, nullptr);
      const Eigen::Vector3d s = l.sun_dir.normalized();
      const double cos_sun = std::max(0.0, fit.normal.dot(s)) * GroundSunFactor(fit, o, s);
      out = (fit.rho_sky.cwiseProduct(esky) +
             fit.rho_sun.cwiseProduct(l.sun_radiance) * l.sun_solid_angle_sr * cos_sun) /
                kPi +
            fit.sky_fraction * sky_mean;
      break;
    }
  }
  for (int c = 0; c < 3; ++c) {
    if (!std::isfinite(out[c]) || out[c] < 0) out[c] = 0;
  }
  return out;
}

}  // namespace

void EnvStereoOptions::Validate() const {
  if (!(alpha >= 10) || !std::isfinite(alpha)) {
    throw Error(
        "EnvStereoOptions: alpha must be a large positive constant (>= 10; the paper "
        "uses 1000)");
  }
  if (fixed_channel < 0 || fixed_channel > 2) {
    throw Error("EnvStereoOptions: fixed_channel must be 0, 1 or 2");
  }
  if (!(fixed_rho_sun > 0) || !std::isfinite(fixed_rho_sun)) {
    throw Error("EnvStereoOptions: fixed_rho_sun must be > 0");
  }
  if (!(ground_retro >= kRetroMin && ground_retro <= kRetroMax)) {
    throw Error("EnvStereoOptions: ground_retro must be in [" + std::to_string(kRetroMin) + ", " +
                std::to_string(kRetroMax) + "]");
  }
  if (!(ground_normal_prior >= 0) || !std::isfinite(ground_normal_prior)) {
    throw Error("EnvStereoOptions: ground_normal_prior must be >= 0");
  }
  if (!(ground_albedo >= 0 && ground_albedo <= 1)) {
    throw Error("EnvStereoOptions: ground_albedo must be in [0, 1]");
  }
  if (sky_quadrature < 2 || sky_quadrature > 200) {
    throw Error("EnvStereoOptions: sky_quadrature must be in 2..200");
  }
  if (min_times < 3) {
    throw Error("EnvStereoOptions: min_times must be >= 3 (8 unknowns, 3 equations per time)");
  }
  if (!(sky_match_tolerance >= 0) || !std::isfinite(sky_match_tolerance)) {
    throw Error("EnvStereoOptions: sky_match_tolerance must be >= 0");
  }
  if (!(fallback_rel_error > 0) || !std::isfinite(fallback_rel_error)) {
    throw Error("EnvStereoOptions: fallback_rel_error must be > 0");
  }
  if (!(sigma_relative >= 0 && sigma_relative <= 1)) {
    throw Error("EnvStereoOptions: sigma_relative must be in [0, 1]");
  }
  if (!(max_albedo > 0) || !std::isfinite(max_albedo)) {
    throw Error("EnvStereoOptions: max_albedo must be > 0");
  }
  if (!(smoothing_weight >= 0) || !std::isfinite(smoothing_weight)) {
    throw Error("EnvStereoOptions: smoothing_weight must be >= 0");
  }
  if (max_iterations < 1) throw Error("EnvStereoOptions: max_iterations must be >= 1");
  if (starts < 1 || starts > 3) throw Error("EnvStereoOptions: starts must be 1, 2 or 3");
}

bool SkyOnlyExplains(const EnvRegionFit& fit, const EnvStereoOptions& options) {
  return fit.rho_sky.maxCoeff() <= options.max_albedo && fit.rel_rms <= options.fallback_rel_error;
}

const char* EnvRegionKindName(EnvRegionKind kind) {
  switch (kind) {
    case EnvRegionKind::kSky:
      return "sky";
    case EnvRegionKind::kLandscape:
      return "landscape";
    case EnvRegionKind::kSkyOnly:
      return "sky_only";
    case EnvRegionKind::kUnobserved:
      return "unobserved";
  }
  return "?";
}

std::string EnvStereoSummary::BriefReport() const {
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "%d times; regions: %d landscape, %d sky-only (%d bad fit, %d never lit), %d sky, "
                "%d unobserved; rel. residual median %.4f p90 %.4f%s; %.2f s",
                times, regions_landscape, regions_sky_only, fallback_bad_fit, fallback_never_lit,
                regions_sky, regions_unobserved, rel_rms_median, rel_rms_p90,
                underdetermined ? " (underdetermined: sky-only)" : "", seconds);
  return buf;
}

Eigen::Vector3d EnvSkyIrradianceAt(const EnvLighting& lighting, const EnvStereoOptions& options,
                                   const Eigen::Vector3d& normal) {
  options.Validate();
  const SkyQuad q = MakeSkyQuad(lighting, options);
  return SkyIrradiance(q, options, normal.normalized(), nullptr);
}

// §5.2, eq. 18: per-region photometric stereo under the sun and the sky.
EnvStereoResult SolveEnvStereo(const std::vector<EnvObservation>& per_time,
                               const EnvStereoOptions& options, const Cancellation* cancel) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  if (per_time.empty()) throw Error("environment stereo: no observation given");
  const EnvironmentMap& m0 = per_time.front().env;
  for (size_t t = 0; t < per_time.size(); ++t) {
    const std::string what = "environment stereo: observation " + std::to_string(t);
    const EnvironmentMap& m = per_time[t].env;
    try {
      m.Validate();
    } catch (const Error& e) {
      throw Error(what + ": " + e.what());
    }
    if (m.bands_below != m0.bands_below || m.bands_above != m0.bands_above ||
        m.sectors != m0.sectors || m.num_layers() != m0.num_layers()) {
      throw Error(what + ": its environment map's regions or layers differ from observation 0's");
    }
    CheckLighting(per_time[t].lighting, what);
  }
  const int T = static_cast<int>(per_time.size());
  const int nreg = m0.num_regions(), L = m0.num_layers();
  const int first_above = m0.bands_below * m0.sectors;

  EnvStereoResult res;
  res.bands_below = m0.bands_below;
  res.bands_above = m0.bands_above;
  res.sectors = m0.sectors;
  res.layer_z = m0.layer_z;
  // Observed at any time (PredictEnvironment fills the others below the horizon).
  res.source = m0.source;
  for (size_t gi = 0; gi < res.source.size(); ++gi)
    for (const EnvObservation& o : per_time)
      if (o.env.source[gi] == EnvRegionSource::kObserved)
        res.source[gi] = EnvRegionSource::kObserved;
  res.options = options;
  res.regions.assign(static_cast<size_t>(nreg) * L, EnvRegionFit());
  res.summary.times = T;
  res.summary.underdetermined = T < options.min_times;

  std::vector<SkyQuad> quads;
  std::vector<EnvironmentMap> sky_means;  // per time: the sky model averaged per region
  const EnvOptions grid = GridOptions(m0.bands_below, m0.bands_above, m0.sectors, 8);
  for (const EnvObservation& o : per_time) {
    quads.push_back(MakeSkyQuad(o.lighting, options));
    sky_means.push_back(EnvironmentMap::FromSky(grid, o.lighting.sky, Eigen::Vector3d::Zero()));
  }

  const size_t total = res.regions.size();
  std::vector<RegionState> states(total);
  std::vector<int> fallback_reason(total, 0);  // 1 bad fit, 2 never lit
  tbb::parallel_for(size_t{0}, total, [&](size_t gi) {
    if (IsCancelled(cancel)) return;
    const int r = static_cast<int>(gi % nreg);
    const bool above = r >= first_above;
    EnvRegionFit& fit = res.regions[gi];
    RegionState& st = states[gi];
    // Data and classification.
    bool all_zero = true, all_sky_filled = above;
    double sky_err_sum = 0;
    int sky_err_n = 0;
    Eigen::Vector3d mean_I = Eigen::Vector3d::Zero();
    for (int t = 0; t < T; ++t) {
      const EnvironmentMap& m = per_time[t].env;
      const Eigen::Vector3d I = m.radiance[gi];
      all_zero = all_zero && I.isZero(0);
      mean_I += I / T;
      if (above) {
        all_sky_filled = all_sky_filled && m.source[gi] == EnvRegionSource::kSkyModel;
        if (m.source[gi] == EnvRegionSource::kObserved) {
          const Eigen::Vector3d S = sky_means[t].radiance[r];
          double e = 0;
          for (int c = 0; c < 3; ++c) {
            e = std::max(e, std::abs(I[c] - S[c]) / std::max(S[c], 1e-300));
          }
          sky_err_sum += e;
          ++sky_err_n;
        }
      }
    }
    if (above && (all_sky_filled ||
                  (sky_err_n > 0 && sky_err_sum / sky_err_n <= options.sky_match_tolerance))) {
      fit.kind = EnvRegionKind::kSky;
      fit.sky_fraction = 1;
      return;
    }
    // Below the horizon, a region no panorama saw at any time holds copies of its neighbours
    // (FillBelowHorizon): fitted, it would be their data seen from the wrong direction. It is
    // predicted as the maps fill it.
    if (all_zero || (!above && res.source[gi] != EnvRegionSource::kObserved)) {
      fit.kind = EnvRegionKind::kUnobserved;
      return;
    }
    st.with_fraction = above && options.fit_sky_fraction;
    if (!above && options.ground_retro != 0) fit.to_viewer = -RegionCentre(m0, r).normalized();
    for (int t = 0; t < T; ++t) {
      TimeData d;
      d.quad = &quads[t];
      d.I = per_time[t].env.radiance[gi];
      for (int c = 0; c < 3; ++c) {
        const double sigma =
            options.sigma_relative * d.I[c] + (1 - options.sigma_relative) * mean_I[c];
        d.inv_sigma[c] = sigma > 0 ? 1 / sigma : 0.0;
      }
      const EnvLighting& l = per_time[t].lighting;
      d.l = l.sun_dir.normalized();
      d.e_sun = l.sun_radiance * l.sun_solid_angle_sr * GroundSunFactor(fit, options, d.l);
      d.sky_mean = st.with_fraction ? sky_means[t].radiance[r] : Eigen::Vector3d::Zero();
      st.data.push_back(d);
    }
    const Eigen::Vector3d view = RegionCentre(m0, r);
    if (res.summary.underdetermined) {
      FitSkyOnly(st.data, options, -view, &fit);
      return;
    }
    // Start values (§5.2): rho_sky = mean radiance / mean sky flux magnitude, rho_sun = mean
    // radiance / mean sun irradiance; the fixed rho_sun component sets |n|.
    Eigen::Vector3d mean_esky = Eigen::Vector3d::Zero(), mean_esun = Eigen::Vector3d::Zero();
    for (const TimeData& d : st.data) {
      mean_esky += d.quad->horizontal / T;
      mean_esun += d.e_sun / T;
    }
    const int fc = options.fixed_channel;
    const double k_fix = options.fixed_rho_sun / kPi;
    Eigen::Vector3d ksky0, ksun0;
    for (int c = 0; c < 3; ++c) {
      ksky0[c] = mean_esky[c] > 0 ? mean_I[c] / mean_esky[c] : 0;
      ksun0[c] = mean_esun[c] > 0 ? mean_I[c] / mean_esun[c] : 0;
    }
    const double scale = ksun0[fc] > 0 ? ksun0[fc] / k_fix : 1.0;
    Eigen::Vector3d level(-view.x(), -view.y(), 0);
    if (level.norm() < 1e-6) level = Eigen::Vector3d::UnitY();
    const Eigen::Vector3d starts[3] = {-view, Eigen::Vector3d::UnitZ(), level.normalized()};
    const std::array<int, 3> idx = SunIndex(fc);
    ceres::Solver::Options so;
    SolverOptions(options, &so);
    // Solves `trial` from its values; with bound_sky, rho_sky within max_albedo.
    auto solve = [&](RegionState* trial, bool bound_sky) {
      ceres::Problem::Options po;
      po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
      ceres::Problem problem(po);
      auto* cost = new RegionCost(&trial->data, &options, trial->with_fraction);
      if (trial->with_fraction) {
        problem.AddResidualBlock(cost, nullptr, trial->x, &trial->f);
        problem.SetParameterLowerBound(&trial->f, 0, 0.0);
        problem.SetParameterUpperBound(&trial->f, 0, 1.0);
      } else {
        problem.AddResidualBlock(cost, nullptr, trial->x);
      }
      for (int k = 0; k < 5; ++k) problem.SetParameterLowerBound(trial->x, k, 0.0);
      if (bound_sky) {
        for (int k = 0; k < 3; ++k) {
          trial->x[k] = std::min(trial->x[k], options.max_albedo / kPi);
          problem.SetParameterUpperBound(trial->x, k, options.max_albedo / kPi);
        }
      }
      if (!above && options.ground_normal_prior > 0) {
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<NormalPrior, 3, kNumParams>(
                                     new NormalPrior{options.ground_normal_prior}),
                                 nullptr, trial->x);
      }
      ceres::Solver::Summary sum;
      ceres::Solve(so, &problem, &sum);
      return static_cast<int>(sum.iterations.size());
    };
    // The best start; a normal facing the viewer (n . d < 0: the patch is seen from its
    // front) is preferred over any that faces away.
    double best = std::numeric_limits<double>::infinity();
    bool best_facing = false;
    RegionState best_state;
    int best_iter = 0;
    for (int s = 0; s < options.starts; ++s) {
      RegionState trial;
      trial.data = st.data;
      trial.with_fraction = st.with_fraction;
      for (int c = 0; c < 3; ++c) {
        trial.x[c] = ksky0[c];
        if (idx[c] >= 0) trial.x[idx[c]] = ksun0[fc] > 0 ? ksun0[c] / scale : k_fix;
      }
      for (int k = 0; k < 3; ++k) trial.x[5 + k] = starts[s][k] * scale;
      trial.f = 0.5;
      const int iterations = solve(&trial, false);
      const double c = Cost(trial, options);
      const Eigen::Vector3d tn(trial.x[5], trial.x[6], trial.x[7]);
      const bool facing = tn.dot(view) < 0;
      if (std::isfinite(c) && ((facing && !best_facing) || (facing == best_facing && c < best))) {
        best_facing = facing;
        best = c;
        best_state = trial;
        best_iter = iterations;
      }
    }
    // A sky albedo past max_albedo (a channel the sky barely lights, following a few percent of
    // light from elsewhere: a wall's reflection on the ground) would make the region fall back
    // to sky-only; solved again from there with rho_sky bounded, it keeps a surface when that
    // still explains it.
    if (std::isfinite(best) &&
        kPi * Eigen::Vector3d(best_state.x[0], best_state.x[1], best_state.x[2]).maxCoeff() >
            options.max_albedo) {
      RegionState bounded = best_state;
      const int iterations = solve(&bounded, true);
      const double c = Cost(bounded, options);
      if (std::isfinite(c)) {
        best = c;
        best_state = bounded;
        best_iter += iterations;
      }
    }
    if (!std::isfinite(best)) {
      FitSkyOnly(st.data, options, -view, &fit);
      fallback_reason[gi] = 1;
      return;
    }
    std::copy(best_state.x, best_state.x + kNumParams, st.x);
    st.f = best_state.f;
    StateToFit(st, options, &fit);
    fit.iterations = best_iter;
    fit.rel_rms = std::sqrt(best / (3.0 * T));
    // Sky-only fallback (§5.2): a bad fit with a normal pointing away from the viewer, or a
    // normal no training sun lit (its solar term and direction are then unconstrained). Above
    // the horizon a normal pointing away is not kept however well it fits: the panorama could
    // not have seen that side (it is the glow next to a low sun that the smooth sky model
    // misses, fitted as a surface lit by that sun from behind).
    const bool away = fit.normal.dot(view) > 0;
    const bool implausible =
        std::max(fit.rho_sun.maxCoeff(), fit.rho_sky.maxCoeff()) > options.max_albedo * (1 + 1e-9);
    const Eigen::Vector3d fallback_normal = away ? Eigen::Vector3d(-view) : fit.normal;
    if (((fit.rel_rms > options.fallback_rel_error || above) && away) || implausible ||
        fit.sunlit_times == 0) {
      fallback_reason[gi] = fit.sunlit_times == 0 ? 2 : 1;
      FitSkyOnly(st.data, options, fallback_normal, &fit);
    }
  });
  ThrowIfCancelled(cancel);

  // Optional smoothing between adjacent landscape regions of a layer, all solved together.
  if (options.smoothing_weight > 0 && !res.summary.underdetermined) {
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    auto land = [&](size_t gi) { return res.regions[gi].kind == EnvRegionKind::kLandscape; };
    for (size_t gi = 0; gi < total; ++gi) {
      if (!land(gi)) continue;
      RegionState& st = states[gi];
      auto* cost = new RegionCost(&st.data, &options, st.with_fraction);
      if (st.with_fraction) {
        problem.AddResidualBlock(cost, nullptr, st.x, &st.f);
        problem.SetParameterLowerBound(&st.f, 0, 0.0);
        problem.SetParameterUpperBound(&st.f, 0, 1.0);
      } else {
        problem.AddResidualBlock(cost, nullptr, st.x);
      }
      for (int k = 0; k < 5; ++k) problem.SetParameterLowerBound(st.x, k, 0.0);
    }
    const int S = m0.sectors;
    for (size_t gi = 0; gi < total; ++gi) {
      if (!land(gi)) continue;
      const int r = static_cast<int>(gi % nreg);
      const size_t base = gi - r;
      const int band = r / S, sec = r % S;
      const size_t east = base + band * S + (sec + 1) % S;
      const size_t up = base + (band + 1) * S + sec;
      // Not across the horizon (ground below, skyline above: a real edge); a Huber loss
      // (linear beyond ~0.2 rad of normal difference) keeps other edges.
      const bool up_ok = band + 1 < m0.num_bands() && band + 1 != m0.bands_below;
      for (size_t gj : {east, up}) {
        if (gj == gi || (gj == up && !up_ok) || !land(gj)) continue;
        problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<SmoothCost, 3, kNumParams, kNumParams>(
                new SmoothCost{options.smoothing_weight}),
            new ceres::HuberLoss(0.2 * options.smoothing_weight), states[gi].x, states[gj].x);
      }
    }
    if (problem.NumResidualBlocks() > 0) {
      ceres::Solver::Options so;
      SolverOptions(options, &so);
      so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
      if (!ceres::IsSparseLinearAlgebraLibraryTypeAvailable(
              so.sparse_linear_algebra_library_type)) {
        so.linear_solver_type = ceres::CGNR;
      }
      so.num_threads = 2;
      ceres::Solver::Summary sum;
      ceres::Solve(so, &problem, &sum);
      for (size_t gi = 0; gi < total; ++gi) {
        if (!land(gi)) continue;
        EnvRegionFit& fit = res.regions[gi];
        const int iters = fit.iterations;
        StateToFit(states[gi], options, &fit);
        fit.iterations = iters + static_cast<int>(sum.iterations.size());
        fit.rel_rms = std::sqrt(Cost(states[gi], options) / (3.0 * T));
      }
    }
  }

  std::vector<double> rms;
  for (size_t gi = 0; gi < total; ++gi) {
    const EnvRegionFit& fit = res.regions[gi];
    switch (fit.kind) {
      case EnvRegionKind::kSky:
        ++res.summary.regions_sky;
        break;
      case EnvRegionKind::kLandscape:
        ++res.summary.regions_landscape;
        rms.push_back(fit.rel_rms);
        break;
      case EnvRegionKind::kSkyOnly:
        ++res.summary.regions_sky_only;
        break;
      case EnvRegionKind::kUnobserved:
        ++res.summary.regions_unobserved;
        break;
    }
    res.summary.fallback_bad_fit += fallback_reason[gi] == 1;
    res.summary.fallback_never_lit += fallback_reason[gi] == 2;
  }
  res.summary.rel_rms_median = Quantile(rms, 0.5);
  res.summary.rel_rms_p90 = Quantile(rms, 0.9);
  res.summary.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

void to_json(nlohmann::json& j, const EnvStereoResult& r) {
  const EnvStereoOptions& o = r.options;
  const EnvStereoSummary& s = r.summary;
  auto v3 = [](const Eigen::Vector3d& v) { return nlohmann::json::array({v[0], v[1], v[2]}); };
  nlohmann::json regions = nlohmann::json::array(), source = nlohmann::json::array();
  for (const EnvRegionFit& f : r.regions)
    regions.push_back({{"kind", static_cast<int>(f.kind)},
                       {"normal", v3(f.normal)},
                       {"rho_sky", v3(f.rho_sky)},
                       {"rho_sun", v3(f.rho_sun)},
                       {"sky_fraction", f.sky_fraction},
                       {"rel_rms", f.rel_rms},
                       {"sunlit_times", f.sunlit_times},
                       {"to_viewer", v3(f.to_viewer)},
                       {"iterations", f.iterations}});
  for (EnvRegionSource src : r.source) source.push_back(static_cast<int>(src));
  j = nlohmann::json{
      {"bands_below", r.bands_below},
      {"bands_above", r.bands_above},
      {"sectors", r.sectors},
      {"layer_z", r.layer_z},
      {"source", source},
      {"regions", regions},
      {"options",
       {{"alpha", o.alpha},
        {"fixed_channel", o.fixed_channel},
        {"fixed_rho_sun", o.fixed_rho_sun},
        {"sky_irradiance", static_cast<int>(o.sky_irradiance)},
        {"ground_albedo", o.ground_albedo},
        {"sky_quadrature", o.sky_quadrature},
        {"min_times", o.min_times},
        {"sky_match_tolerance", o.sky_match_tolerance},
        {"fit_sky_fraction", o.fit_sky_fraction},
        {"fallback_rel_error", o.fallback_rel_error},
        {"max_albedo", o.max_albedo},
        {"sigma_relative", o.sigma_relative},
        {"smoothing_weight", o.smoothing_weight},
        {"ground_retro", o.ground_retro},
        {"ground_normal_prior", o.ground_normal_prior},
        {"max_iterations", o.max_iterations},
        {"starts", o.starts}}},
      {"summary",
       {{"times", s.times},
        {"regions_sky", s.regions_sky},
        {"regions_landscape", s.regions_landscape},
        {"regions_sky_only", s.regions_sky_only},
        {"regions_unobserved", s.regions_unobserved},
        {"fallback_bad_fit", s.fallback_bad_fit},
        {"fallback_never_lit", s.fallback_never_lit},
        {"underdetermined", s.underdetermined},
        {"rel_rms_median", s.rel_rms_median},
        {"rel_rms_p90", s.rel_rms_p90}}}};  // not its seconds: a scene is the same each solve
}

void from_json(const nlohmann::json& j, EnvStereoResult& r) {
  r = EnvStereoResult();
  std::string field;  // the one being read, for the error
  try {
    auto get = [&](const nlohmann::json& obj, const char* key, auto* out) {
      field = key;
      *out = JsonGet<std::remove_pointer_t<decltype(out)>>(obj.at(key));
    };
    auto vec3 = [&](const nlohmann::json& obj, const char* key) {
      field = key;
      const nlohmann::json& a = obj.at(key);
      if (!a.is_array() || a.size() != 3) throw Error("not 3 numbers");
      const Eigen::Vector3d v(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
      if (!v.allFinite()) throw Error("not finite");
      return v;
    };
    get(j, "bands_below", &r.bands_below);
    get(j, "bands_above", &r.bands_above);
    get(j, "sectors", &r.sectors);
    get(j, "layer_z", &r.layer_z);
    field = "source";
    for (const auto& v : j.at("source")) {
      const int k = static_cast<int>(JsonInteger(v, 0, 3, "region source"));
      r.source.push_back(static_cast<EnvRegionSource>(k));
    }
    for (const auto& g : j.at("regions")) {
      EnvRegionFit f;
      int kind = 0;
      get(g, "kind", &kind);
      if (kind < 0 || kind > 3) throw Error("unknown region kind " + std::to_string(kind));
      f.kind = static_cast<EnvRegionKind>(kind);
      f.normal = vec3(g, "normal");
      f.rho_sky = vec3(g, "rho_sky");
      f.rho_sun = vec3(g, "rho_sun");
      get(g, "sky_fraction", &f.sky_fraction);
      get(g, "rel_rms", &f.rel_rms);
      get(g, "sunlit_times", &f.sunlit_times);
      f.to_viewer = vec3(g, "to_viewer");
      get(g, "iterations", &f.iterations);
      r.regions.push_back(f);
    }
    const nlohmann::json& o = j.at("options");
    EnvStereoOptions& op = r.options;
    get(o, "alpha", &op.alpha);
    get(o, "fixed_channel", &op.fixed_channel);
    get(o, "fixed_rho_sun", &op.fixed_rho_sun);
    int sky_irradiance = 0;
    get(o, "sky_irradiance", &sky_irradiance);
    if (sky_irradiance < 0 || sky_irradiance > 1) throw Error("must be 0 or 1");
    op.sky_irradiance = static_cast<EnvSkyIrradiance>(sky_irradiance);
    get(o, "ground_albedo", &op.ground_albedo);
    get(o, "sky_quadrature", &op.sky_quadrature);
    get(o, "min_times", &op.min_times);
    get(o, "sky_match_tolerance", &op.sky_match_tolerance);
    get(o, "fit_sky_fraction", &op.fit_sky_fraction);
    get(o, "fallback_rel_error", &op.fallback_rel_error);
    get(o, "max_albedo", &op.max_albedo);
    get(o, "sigma_relative", &op.sigma_relative);
    get(o, "smoothing_weight", &op.smoothing_weight);
    get(o, "ground_retro", &op.ground_retro);
    get(o, "ground_normal_prior", &op.ground_normal_prior);
    get(o, "max_iterations", &op.max_iterations);
    get(o, "starts", &op.starts);
    const nlohmann::json& s = j.at("summary");
    EnvStereoSummary& su = r.summary;
    get(s, "times", &su.times);
    get(s, "regions_sky", &su.regions_sky);
    get(s, "regions_landscape", &su.regions_landscape);
    get(s, "regions_sky_only", &su.regions_sky_only);
    get(s, "regions_unobserved", &su.regions_unobserved);
    get(s, "fallback_bad_fit", &su.fallback_bad_fit);
    get(s, "fallback_never_lit", &su.fallback_never_lit);
    get(s, "underdetermined", &su.underdetermined);
    get(s, "rel_rms_median", &su.rel_rms_median);
    get(s, "rel_rms_p90", &su.rel_rms_p90);
  } catch (const nlohmann::json::exception& e) {
    throw Error("environment stereo: " + field + ": " + e.what());
  } catch (const Error& e) {
    throw Error("environment stereo: " + field + ": " + e.what());
  }
  r.options.Validate();
  if (r.bands_below < 1 || r.bands_above < 1 || r.sectors < 1 || r.layer_z.empty())
    throw Error("environment stereo: bands, sectors and layers must be at least 1");
  const size_t n = r.layer_z.size() * static_cast<size_t>(r.bands_below + r.bands_above) *
                   static_cast<size_t>(r.sectors);
  if (r.regions.size() != n || r.source.size() != n)
    throw Error("environment stereo: " + std::to_string(r.regions.size()) + " regions and " +
                std::to_string(r.source.size()) + " sources for " + std::to_string(n) +
                " regions of its layers, bands and sectors");
}

const EnvStereoResult* FitFor(const std::optional<EnvStereoResult>& fit,
                              const std::vector<int>& fit_slots, const std::vector<int>& slots,
                              const EnvStereoOptions& options) {
  if (!fit || fit_slots != slots || !(fit->options == options)) return nullptr;
  return &*fit;
}

GroundRetroFit FitGroundRetro(const std::vector<EnvObservation>& per_time,
                              const EnvStereoOptions& options, const Cancellation* cancel,
                              double min_gain) {
  if (!(min_gain >= 0 && min_gain < 1)) throw Error("ground retro: min_gain must be in [0, 1)");
  GroundRetroFit out;
  std::vector<EnvStereoResult> fits;  // per candidate, as costed
  auto cost_at = [&](double retro) {
    EnvStereoOptions o = options;
    o.ground_retro = retro;
    fits.push_back(SolveEnvStereo(per_time, o, cancel));
    const EnvStereoResult& r = fits.back();
    const int first_above = r.bands_below * r.sectors;
    const int nreg = (r.bands_below + r.bands_above) * r.sectors;
    std::vector<double> rms;
    for (size_t gi = 0; gi < r.regions.size(); ++gi) {
      const bool below = static_cast<int>(gi % nreg) < first_above;
      if (below && r.regions[gi].kind == EnvRegionKind::kLandscape)
        rms.push_back(r.regions[gi].rel_rms);
    }
    const double c = rms.empty() ? 0.0 : Quantile(rms, 0.5);
    out.candidates.push_back(retro);
    out.costs.push_back(c);
    return c;
  };
  // Candidates 0, kStep, ..., kRetroMax: rough ground sends light back (retro > 0); a ground
  // darker than Lambert towards grazing views is not searched for.
  constexpr double kStep = 0.5;
  std::vector<double> grid, cost;
  for (double r = 0; r <= kRetroMax + 1e-9; r += kStep) {
    grid.push_back(r);
    cost.push_back(cost_at(r));
    // A cost that rises from the first step on: Lambert (the cost is taken as unimodal).
    if (grid.size() == 2 && cost[1] >= cost[0]) break;
  }
  size_t zero = 0, best = 0;
  for (size_t k = 0; k < grid.size(); ++k) {
    if (std::abs(grid[k]) < 1e-9) zero = k;
    if (cost[k] < cost[best]) best = k;
  }
  out.cost_lambert = cost[zero];
  out.retro = grid[best];
  out.cost = cost[best];
  if (const std::optional<double> r = ParabolaVertex(grid, cost, best, kStep)) {
    const double c = cost_at(*r);
    if (c < out.cost) {
      out.retro = *r;
      out.cost = c;
    }
  }
  if (!(out.cost < (1 - min_gain) * out.cost_lambert)) {
    out.retro = 0;
    out.cost = out.cost_lambert;
  }
  for (size_t k = 0; k < out.candidates.size(); ++k)
    if (out.candidates[k] == out.retro) out.result = std::move(fits[k]);
  return out;
}

Eigen::Vector3d PredictRegionRadiance(const EnvRegionFit& fit, const EnvStereoOptions& options,
                                      const EnvLighting& lighting,
                                      const Eigen::Vector3d& sky_mean) {
  if (fit.kind == EnvRegionKind::kSky) return sky_mean;
  if (fit.kind == EnvRegionKind::kUnobserved) return Eigen::Vector3d::Zero();
  options.Validate();
  const SkyQuad q = MakeSkyQuad(lighting, options);
  return PredictWithQuad(fit, options, lighting, q, sky_mean);
}

// §5.2: eq. 17 (the exact clamp) with the recovered normals and albedos at a novel time.
EnvironmentMap PredictEnvironment(const EnvStereoResult& result, const EnvLighting& lighting,
                                  int sky_fill_samples) {
  result.options.Validate();
  CheckLighting(lighting, "environment prediction");
  const EnvOptions grid =
      GridOptions(result.bands_below, result.bands_above, result.sectors, sky_fill_samples);
  grid.Validate();
  const EnvironmentMap sky = EnvironmentMap::FromSky(grid, lighting.sky, Eigen::Vector3d::Zero());
  const int nreg = sky.num_regions();
  const int L = static_cast<int>(result.layer_z.size());
  if (result.regions.size() != static_cast<size_t>(nreg) * L ||
      result.source.size() != result.regions.size()) {
    throw Error("environment prediction: the stereo result's regions do not match its grid");
  }
  const SkyQuad q = MakeSkyQuad(lighting, result.options);
  EnvironmentMap m;
  m.bands_below = result.bands_below;
  m.bands_above = result.bands_above;
  m.sectors = result.sectors;
  m.layer_z = result.layer_z;
  m.radiance.resize(result.regions.size());
  m.pixel_count.assign(result.regions.size(), 0);
  m.source = result.source;
  for (size_t gi = 0; gi < result.regions.size(); ++gi) {
    const int r = static_cast<int>(gi % nreg);
    m.radiance[gi] =
        PredictWithQuad(result.regions[gi], result.options, lighting, q, sky.radiance[r]);
  }
  for (int layer = 0; layer < L; ++layer) FillBelowHorizon(&m, layer);
  m.Validate();
  return m;
}

}  // namespace rouen
