#include "capture/sim/atmosphere.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kTableH = 128;    // altitude samples (sqrt spacing)
constexpr int kTableT = 256;    // zenith-cosine samples (sqrt spacing above the horizon)
constexpr int kSkyElev = 150;   // sky table rows: elevation = 90 deg * (i / (n-1))^1.5
constexpr int kSkyAz = 181;     // sky table columns: 1 deg steps of azimuth relative to the sun
constexpr int kQuadElev = 180;  // quadrature: 0.5 deg cells
constexpr int kQuadAz = 720;

double RayleighPhase(double c) { return 3.0 / (16.0 * kPi) * (1.0 + c * c); }

// Cornette-Shanks phase function (normalised over the sphere).
double MiePhase(double c, double g) {
  const double g2 = g * g;
  const double denom = (2.0 + g2) * std::pow(1.0 + g2 - 2.0 * g * c, 1.5);
  return 3.0 / (8.0 * kPi) * (1.0 - g2) * (1.0 + c * c) / denom;
}

// A direction's elevation (rad, clamped to [0, pi/2]) and azimuth (rad from north through east).
Eigen::Vector2d ElevationAzimuth(const Eigen::Vector3d& dir) {
  return Eigen::Vector2d(std::asin(std::clamp(dir.z() / dir.norm(), 0.0, 1.0)),
                         std::atan2(dir.x(), dir.y()));
}

double HorizonMu(double r, double earth_radius) {
  const double q = earth_radius / r;
  return -std::sqrt(std::max(0.0, 1.0 - q * q));
}

}  // namespace

void AtmosphereParams::Validate() const {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw Error("atmosphere parameters: " + what);
  };
  check(earth_radius_m > 1e6 && std::isfinite(earth_radius_m), "earth_radius_m must be > 1e6");
  check(top_altitude_m > 1e4 && top_altitude_m < 2e5, "top_altitude_m must be in (1e4, 2e5)");
  check(rayleigh_scale_m > 0 && mie_scale_m > 0, "scale heights must be positive");
  check((rayleigh_sea_level.array() > 0).all() && rayleigh_sea_level.allFinite(),
        "Rayleigh coefficients must be positive");
  check((wavelength_nm.array() > 0).all(), "wavelengths must be positive");
  check(visibility_km > 0 && 3.912 / (visibility_km * 1e3) > rayleigh_sea_level[1],
        "visibility_km must be positive and below the Rayleigh-only limit (~290 km)");
  check(mie_albedo > 0 && mie_albedo <= 1, "mie_albedo must be in (0, 1]");
  check(mie_g > -1 && mie_g < 1, "mie_g must be in (-1, 1)");
  check(multiple_scattering >= 0 && multiple_scattering <= 2,
        "multiple_scattering must be in [0, 2]");
  check((solar_toa.array() > 0).all() && solar_toa.allFinite(), "solar_toa must be positive");
}

Eigen::Vector3d AtmosphereParams::MieExtinction() const {
  // Koschmieder: total extinction at 550 nm = 3.912 / V; the aerosol part scales by Angstrom.
  const double mie550 = 3.912 / (visibility_km * 1e3) - rayleigh_sea_level[1];
  Eigen::Vector3d out;
  for (int c = 0; c < 3; ++c) out[c] = mie550 * std::pow(wavelength_nm[c] / 550.0, -angstrom);
  return out;
}

Atmosphere::Atmosphere(const AtmosphereParams& params) : p_(params) {
  p_.Validate();
  mie_ext_ = p_.MieExtinction();
  mie_sca_ = mie_ext_ * p_.mie_albedo;
  nh_ = kTableH;
  nt_ = kTableT;
  table_.assign(static_cast<size_t>(nh_) * nt_, Eigen::Vector2f::Zero());
  tbb::parallel_for(0, nh_, [&](int i) {
    const double uh = static_cast<double>(i) / (nh_ - 1);
    const double h = uh * uh * p_.top_altitude_m;
    const double mu_h = HorizonMu(p_.earth_radius_m + h, p_.earth_radius_m);
    for (int j = 0; j < nt_; ++j) {
      const double t = static_cast<double>(j) / (nt_ - 1);
      // Slightly above the horizon at t = 0 so the tangent ray is finite.
      const double mu = std::min(1.0, mu_h + (1.0 - mu_h) * t * t + 1e-12);
      table_[static_cast<size_t>(i) * nt_ + j] = DensityIntegralsExact(h, mu).cast<float>();
    }
  });
}

Eigen::Vector2d Atmosphere::DensityIntegralsExact(double h, double mu) const {
  const double big_r = p_.earth_radius_m;
  const double r = big_r + std::max(h, 0.0);
  const double rt = big_r + p_.top_altitude_m;
  if (mu < HorizonMu(r, big_r)) return Eigen::Vector2d(kInf, kInf);
  const double disc = r * r * (mu * mu - 1.0) + rt * rt;
  const double length = -r * mu + std::sqrt(std::max(0.0, disc));
  const double s_p = std::clamp(-r * mu, 0.0, length);  // closest approach to the centre
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  auto add = [&](double s, double ds) {
    const double rs = std::sqrt(std::max(0.0, r * r + s * s + 2.0 * r * mu * s));
    const double hs = rs - big_r;
    sum[0] += std::exp(-hs / p_.rayleigh_scale_m) * ds;
    sum[1] += std::exp(-hs / p_.mie_scale_m) * ds;
  };
  constexpr int n = 160;
  // Before the closest approach, samples dense near it; after it, dense near it again.
  if (s_p > 0) {
    for (int k = 0; k < n; ++k) {
      const double x = (k + 0.5) / n;
      add(s_p * (1.0 - (1.0 - x) * (1.0 - x)), 2.0 * s_p * (1.0 - x) / n);
    }
  }
  const double rest = length - s_p;
  for (int k = 0; k < n; ++k) {
    const double x = (k + 0.5) / n;
    add(s_p + rest * x * x, 2.0 * rest * x / n);
  }
  return sum;
}

Eigen::Vector3d Atmosphere::OpticalDepthExact(double h, double mu) const {
  const Eigen::Vector2d d = DensityIntegralsExact(h, mu);
  if (!std::isfinite(d[0])) return Eigen::Vector3d::Constant(kInf);
  return p_.rayleigh_sea_level * d[0] + mie_ext_ * d[1];
}

Atmosphere::Altitude Atmosphere::AltitudeSlot(double h) const {
  h = std::clamp(h, 0.0, p_.top_altitude_m);
  Altitude alt;
  alt.mu_h = HorizonMu(p_.earth_radius_m + h, p_.earth_radius_m);
  const double fh = std::sqrt(h / p_.top_altitude_m) * (nh_ - 1);
  alt.i0 = std::min(static_cast<int>(fh), nh_ - 2);
  alt.a = fh - alt.i0;
  return alt;
}

Eigen::Vector3d Atmosphere::OpticalDepth(double h, double mu) const {
  const Altitude alt = AltitudeSlot(h);
  if (mu < alt.mu_h) return Eigen::Vector3d::Constant(kInf);
  const double ft = std::sqrt(std::clamp((mu - alt.mu_h) / (1.0 - alt.mu_h), 0.0, 1.0)) * (nt_ - 1);
  const int j0 = std::min(static_cast<int>(ft), nt_ - 2);
  const double a = alt.a, b = ft - j0;
  const int i0 = alt.i0;
  auto at = [&](int i, int j) { return table_[static_cast<size_t>(i) * nt_ + j].cast<double>(); };
  const Eigen::Vector2d d = (1 - a) * ((1 - b) * at(i0, j0) + b * at(i0, j0 + 1)) +
                            a * ((1 - b) * at(i0 + 1, j0) + b * at(i0 + 1, j0 + 1));
  return p_.rayleigh_sea_level * d[0] + mie_ext_ * d[1];
}

Eigen::Vector3d Atmosphere::TransmittanceAt(const Altitude& alt, double mu) const {
  if (mu < alt.mu_h) return Eigen::Vector3d::Zero();
  const double ft = std::sqrt(std::clamp((mu - alt.mu_h) / (1.0 - alt.mu_h), 0.0, 1.0)) * (nt_ - 1);
  const int j0 = std::min(static_cast<int>(ft), nt_ - 2);
  const double a = alt.a, b = ft - j0;
  const size_t r0 = static_cast<size_t>(alt.i0) * nt_ + j0, r1 = r0 + nt_;
  const Eigen::Vector2f d = static_cast<float>((1 - a) * (1 - b)) * table_[r0] +
                            static_cast<float>((1 - a) * b) * table_[r0 + 1] +
                            static_cast<float>(a * (1 - b)) * table_[r1] +
                            static_cast<float>(a * b) * table_[r1 + 1];
  const Eigen::Vector3d tau = p_.rayleigh_sea_level * d[0] + mie_ext_ * d[1];
  return (-tau).array().exp();
}

Eigen::Vector3d Atmosphere::Transmittance(double h, double mu) const {
  const Eigen::Vector3d tau = OpticalDepth(h, mu);
  if (!std::isfinite(tau[0])) return Eigen::Vector3d::Zero();
  return (-tau).array().exp();
}

Atmosphere::Scatter Atmosphere::SingleScatter(double h_obs, const Eigen::Vector3d& view_in,
                                              const Eigen::Vector3d& sun,
                                              const Eigen::Vector3d& sun_toa, int steps) const {
  Eigen::Vector3d view = view_in;
  if (view.z() < 0) {
    view.z() = 0;
    if (view.squaredNorm() == 0) view = Eigen::Vector3d::UnitX();
  }
  view.normalize();
  const double big_r = p_.earth_radius_m;
  const double r0 = big_r + std::max(h_obs, 0.0);
  const double rt = big_r + p_.top_altitude_m;
  const double mu = view.z();
  const double length = -r0 * mu + std::sqrt(std::max(0.0, r0 * r0 * (mu * mu - 1.0) + rt * rt));
  const double cos_gamma = view.dot(sun);
  const double pr = RayleighPhase(cos_gamma);
  const double pm = MiePhase(cos_gamma, p_.mie_g);
  const Eigen::Vector3d origin(0, 0, r0);

  Scatter out;
  Eigen::Vector3d tau_view = Eigen::Vector3d::Zero();
  for (int k = 0; k < steps; ++k) {
    const double x = (k + 0.5) / steps;
    const double s = length * x * x;
    const double ds = 2.0 * length * x / steps;
    const Eigen::Vector3d p = origin + s * view;
    const double r = p.norm();
    const double h = r - big_r;
    const double rho_r = std::exp(-h / p_.rayleigh_scale_m);
    const double rho_m = std::exp(-h / p_.mie_scale_m);
    const Eigen::Vector3d ext = p_.rayleigh_sea_level * rho_r + mie_ext_ * rho_m;
    const Eigen::Vector3d sca = p_.rayleigh_sea_level * rho_r + mie_sca_ * rho_m;
    const Eigen::Vector3d tau_here = tau_view + 0.5 * ext * ds;  // observer -> sample
    tau_view += ext * ds;
    out.scatter_depth += sca * ds;
    const Eigen::Vector3d t_sun = Transmittance(h, p.dot(sun) / r);
    if (t_sun[0] == 0.0 && t_sun[2] == 0.0) continue;
    const Eigen::Vector3d phase_sca =
        p_.rayleigh_sea_level * (rho_r * pr) + mie_sca_ * (rho_m * pm);
    out.radiance += ((-tau_here).array().exp() * t_sun.array() * phase_sca.array()).matrix() * ds;
  }
  out.radiance = out.radiance.cwiseProduct(sun_toa);
  return out;
}

void Atmosphere::SingleScatterRow(double h_obs, double el, double sun_el,
                                  const Eigen::Vector3d& sun_toa, int n, Scatter* out,
                                  int steps) const {
  el = std::clamp(el, 0.0, 0.5 * kPi);
  const double big_r = p_.earth_radius_m;
  const double r0 = big_r + std::max(h_obs, 0.0);
  const double rt = big_r + p_.top_altitude_m;
  const double ce = std::cos(el), se = std::sin(el);
  const double cs = std::cos(sun_el), ss = std::sin(sun_el);
  const double length = -r0 * se + std::sqrt(std::max(0.0, r0 * r0 * (se * se - 1.0) + rt * rt));
  // View-path quantities shared by the whole row (they do not depend on azimuth).
  struct Step {
    double horiz, vert, r, ds;
    Altitude alt;
    Eigen::Vector3d t_view, sca_r, sca_m;
  };
  std::vector<Step> st(steps);
  Eigen::Vector3d tau = Eigen::Vector3d::Zero(), depth = Eigen::Vector3d::Zero();
  for (int k = 0; k < steps; ++k) {
    const double x = (k + 0.5) / steps;
    const double s = length * x * x, ds = 2.0 * length * x / steps;
    Step& q = st[k];
    q.horiz = s * ce;
    q.vert = r0 + s * se;
    q.r = std::hypot(q.horiz, q.vert);
    q.ds = ds;
    const double h = q.r - big_r;
    q.alt = AltitudeSlot(h);
    const double rho_r = std::exp(-h / p_.rayleigh_scale_m);
    const double rho_m = std::exp(-h / p_.mie_scale_m);
    const Eigen::Vector3d ext = p_.rayleigh_sea_level * rho_r + mie_ext_ * rho_m;
    q.t_view = (-(tau + 0.5 * ext * ds)).array().exp();
    tau += ext * ds;
    q.sca_r = p_.rayleigh_sea_level * (rho_r * ds);
    q.sca_m = mie_sca_ * (rho_m * ds);
    depth += q.sca_r + q.sca_m;
  }
  for (int j = 0; j < n; ++j) {
    const double cphi = std::cos(kPi * j / (n - 1));
    const double cos_gamma = ce * cphi * cs + se * ss;
    const double pr = RayleighPhase(cos_gamma), pm = MiePhase(cos_gamma, p_.mie_g);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const Step& q : st) {
      const double mu_s = (q.horiz * cphi * cs + q.vert * ss) / q.r;
      if (mu_s < q.alt.mu_h) continue;
      const Eigen::Vector3d t_sun = TransmittanceAt(q.alt, mu_s);
      sum += (q.t_view.array() * t_sun.array() * (q.sca_r * pr + q.sca_m * pm).array()).matrix();
    }
    out[j].radiance = sum.cwiseProduct(sun_toa);
    out[j].scatter_depth = depth;
  }
}

SkyTable::SkyTable(const Atmosphere& atmosphere, double observer_altitude_m,
                   const Eigen::Vector3d& sun_dir, const Eigen::Vector3d& sun_toa)
    : ne_(kSkyElev), na_(kSkyAz), sun_dir_(sun_dir.normalized()) {
  sun_az_ = std::atan2(sun_dir_.x(), sun_dir_.y());
  const double sun_el = std::asin(std::clamp(sun_dir_.z(), -1.0, 1.0));
  std::vector<Eigen::Vector3f> single(static_cast<size_t>(ne_) * na_);
  std::vector<Eigen::Vector3f> depth(single.size());
  tbb::parallel_for(0, ne_, [&](int i) {
    const double el = 0.5 * kPi * std::pow(static_cast<double>(i) / (ne_ - 1), 1.5);
    std::vector<Atmosphere::Scatter> row(na_);
    atmosphere.SingleScatterRow(observer_altitude_m, el, sun_el, sun_toa, na_, row.data());
    for (int j = 0; j < na_; ++j) {
      single[static_cast<size_t>(i) * na_ + j] = row[j].radiance.cast<float>();
      depth[static_cast<size_t>(i) * na_ + j] = row[j].scatter_depth.cast<float>();
    }
  });

  auto build_quadrature = [&](const std::vector<Eigen::Vector3f>& table) {
    quad_dir_.resize(static_cast<size_t>(kQuadElev) * kQuadAz);
    quad_w_.resize(quad_dir_.size());
    const double de = 0.5 * kPi / kQuadElev, da = 2 * kPi / kQuadAz;
    tbb::parallel_for(0, kQuadElev, [&](int i) {
      const double el = (i + 0.5) * de;
      for (int j = 0; j < kQuadAz; ++j) {
        const double az = (j + 0.5) * da;
        const Eigen::Vector3d d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az),
                                std::sin(el));
        double dphi = std::abs(std::remainder(az - sun_az_, 2 * kPi));
        const size_t q = static_cast<size_t>(i) * kQuadAz + j;
        quad_dir_[q] = d.cast<float>();
        quad_w_[q] = (Lookup(table, el, dphi) * (std::cos(el) * de * da)).cast<float>();
      }
    });
  };
  // Multiple scattering (documented approximation): isotropic source = mean single-scattered
  // radiance E_h / pi, seen through the view path's scattering depth.
  build_quadrature(single);
  const Eigen::Vector3d e_h_single = PlaneIrradiance(Eigen::Vector3d::UnitZ());
  const double f = atmosphere.params().multiple_scattering;
  radiance_.resize(single.size());
  for (size_t q = 0; q < single.size(); ++q) {
    const Eigen::Array3d open = 1.0 - (-depth[q].cast<double>()).array().exp();
    const Eigen::Vector3d ms = (f / kPi) * (e_h_single.array() * open).matrix();
    radiance_[q] = (single[q].cast<double>() + ms).cast<float>();
  }
  build_quadrature(radiance_);
  horizontal_ = PlaneIrradiance(Eigen::Vector3d::UnitZ());
  if (!horizontal_.allFinite()) throw Error("sky table: non-finite sky irradiance");
}

Eigen::Vector3d SkyTable::Lookup(const std::vector<Eigen::Vector3f>& t, double el,
                                 double dphi) const {
  el = std::clamp(el, 0.0, 0.5 * kPi);
  dphi = std::clamp(dphi, 0.0, kPi);
  const double fe = std::pow(el / (0.5 * kPi), 2.0 / 3.0) * (ne_ - 1);
  const double fa = dphi / kPi * (na_ - 1);
  const int i0 = std::min(static_cast<int>(fe), ne_ - 2);
  const int j0 = std::min(static_cast<int>(fa), na_ - 2);
  const double a = fe - i0, b = fa - j0;
  auto at = [&](int i, int j) { return t[static_cast<size_t>(i) * na_ + j].cast<double>(); };
  return (1 - a) * ((1 - b) * at(i0, j0) + b * at(i0, j0 + 1)) +
         a * ((1 - b) * at(i0 + 1, j0) + b * at(i0 + 1, j0 + 1));
}

SkyAngles SkyAngles::Of(const Eigen::Vector3d& dir) {
  const Eigen::Vector2d a = ElevationAzimuth(dir);
  return {static_cast<float>(a[0]), static_cast<float>(a[1])};
}

Eigen::Vector3d SkyTable::RadianceAt(double el, double az) const {
  if (radiance_.empty()) return Eigen::Vector3d::Zero();
  const double dphi = std::abs(std::remainder(az - sun_az_, 2 * kPi));
  return Lookup(radiance_, el, dphi);
}

Eigen::Vector3d SkyTable::Radiance(const Eigen::Vector3d& dir) const {
  if (!(dir.norm() > 0)) return Eigen::Vector3d::Zero();
  const Eigen::Vector2d a = ElevationAzimuth(dir);
  return RadianceAt(a[0], a[1]);
}

Eigen::Vector3d SkyTable::Radiance(const SkyAngles& angles) const {
  return RadianceAt(angles.elevation, angles.azimuth);
}

Eigen::Vector3d SkyTable::PlaneIrradiance(const Eigen::Vector3d& n) const {
  const Eigen::Vector3f nf = n.normalized().cast<float>();
  double s0 = 0, s1 = 0, s2 = 0;
  for (size_t q = 0; q < quad_dir_.size(); ++q) {
    const float c = nf.dot(quad_dir_[q]);
    if (c <= 0) continue;
    s0 += c * quad_w_[q][0];
    s1 += c * quad_w_[q][1];
    s2 += c * quad_w_[q][2];
  }
  return Eigen::Vector3d(s0, s1, s2);
}

}  // namespace rouen
