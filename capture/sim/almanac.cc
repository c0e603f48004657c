#include "capture/sim/almanac.h"

#include <algorithm>
#include <cmath>

#include "core/angles.h"

namespace rouen {
namespace {

constexpr double kSunRadiusKm = 695700.0;  // IAU 2015 nominal solar radius
constexpr double kAuKm = 149597870.7;

double Wrap360(double deg) {
  double r = std::fmod(deg, 360.0);
  return r < 0 ? r + 360.0 : r;
}

Eigen::Vector3d FromAzEl(double az_deg, double el_deg) {
  const double az = az_deg * kDeg, el = el_deg * kDeg;
  return Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
}

// Bennett (1982): refraction R (arcmin) for an apparent altitude h (deg).
double BennettApparent(double h_app_deg) {
  const double h = std::max(h_app_deg, -1.0);
  return std::max(0.0, 1.0 / std::tan((h + 7.31 / (h + 4.4)) * kDeg));
}

}  // namespace

Eigen::Vector3d AlmanacSun::DirectionEnu() const { return FromAzEl(azimuth_deg, elevation_deg); }
Eigen::Vector3d AlmanacSun::TrueDirectionEnu() const {
  return FromAzEl(azimuth_deg, elevation_true_deg);
}

double BennettRefractionDeg(double true_elevation_deg, double pressure_mbar, double temperature_c) {
  if (true_elevation_deg < -2.0) return 0.0;
  const double scale = (pressure_mbar / 1010.0) * (283.0 / (273.0 + temperature_c));
  // Bennett's formula takes the apparent altitude: solve h_app - R(h_app) = h_true.
  double h_app = true_elevation_deg;
  for (int it = 0; it < 20; ++it) {
    const double r = scale * BennettApparent(h_app) / 60.0;
    const double next = true_elevation_deg + r;
    if (std::abs(next - h_app) < 1e-10) {
      h_app = next;
      break;
    }
    h_app = next;
  }
  return h_app - true_elevation_deg;
}

AlmanacSun AlmanacSunPosition(UtcTime t, const Site& site, double pressure_mbar,
                              double temperature_c) {
  // Astronomical Almanac, section C (low-precision formulas for the Sun).
  const double jd = t.UnixSeconds() / 86400.0 + 2440587.5;
  const double n = jd - 2451545.0;  // days from J2000.0 (UT ~ TT at this precision)
  const double mean_lon = Wrap360(280.460 + 0.9856474 * n);  // includes aberration
  const double g = Wrap360(357.528 + 0.9856003 * n) * kDeg;  // mean anomaly
  const double lambda = (mean_lon + 1.915 * std::sin(g) + 0.020 * std::sin(2 * g)) * kDeg;
  const double eps = (23.439 - 0.0000004 * n) * kDeg;
  const double ra = std::atan2(std::cos(eps) * std::sin(lambda), std::cos(lambda));
  const double dec = std::asin(std::sin(eps) * std::sin(lambda));
  const double dist = 1.00014 - 0.01671 * std::cos(g) - 0.00014 * std::cos(2 * g);

  // Greenwich mean sidereal time (hours) and the local hour angle.
  const double gmst_h = std::fmod(18.697374558 + 24.06570982441908 * n, 24.0);
  const double lst = (gmst_h * 15.0 + site.lon_deg) * kDeg;
  const double ha = lst - ra;
  const double lat = site.lat_deg * kDeg;

  const double sin_el =
      std::sin(lat) * std::sin(dec) + std::cos(lat) * std::cos(dec) * std::cos(ha);
  double el = std::asin(std::clamp(sin_el, -1.0, 1.0));
  const double az =
      std::atan2(-std::cos(dec) * std::sin(ha),
                 std::sin(dec) * std::cos(lat) - std::cos(dec) * std::cos(ha) * std::sin(lat));
  // Topocentric parallax in altitude (equatorial horizontal parallax 8.794 arcsec at 1 AU).
  el -= (8.794 / 3600.0) * kDeg / dist * std::cos(el);

  AlmanacSun s;
  s.azimuth_deg = Wrap360(az / kDeg);
  s.elevation_true_deg = el / kDeg;
  s.elevation_deg = s.elevation_true_deg +
                    BennettRefractionDeg(s.elevation_true_deg, pressure_mbar, temperature_c);
  s.distance_au = dist;
  s.angular_radius_deg = std::asin(kSunRadiusKm / (dist * kAuKm)) / kDeg;
  return s;
}

}  // namespace rouen
