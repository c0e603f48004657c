#include "core/solar.h"

#include <erfa.h>

#include <cmath>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/text.h"

namespace rouen {
namespace {

constexpr double kRadToDeg = 180.0 / kPi;
constexpr double kSunRadiusKm = 695700.0;     // IAU 2015 nominal solar radius
constexpr double kAuKm = 149597870.700;       // IAU 2012 astronomical unit
constexpr double kSpaSunRadiusDeg = 0.26667;  // NREL SPA's sun radius for its condition
constexpr double kSpaRefractionDeg = 0.5667;  // NREL SPA's refraction at the horizon

// NREL SPA (Reda & Andreas 2008, eq. 42): refraction correction in degrees for a true
// elevation e0 (degrees) at pressure P (mbar) and temperature T (deg C).
double SpaRefractionDeg(double e0_deg, double pressure_mbar, double temperature_c) {
  if (!(e0_deg >= -(kSpaSunRadiusDeg + kSpaRefractionDeg))) return 0.0;
  return (pressure_mbar / 1010.0) * (283.0 / (273.0 + temperature_c)) * 1.02 /
         (60.0 * std::tan((e0_deg + 10.3 / (e0_deg + 5.11)) * kDeg));
}

}  // namespace

Eigen::Vector3d SunPosition::DirectionEnu() const {
  return EnuFromAzEl(azimuth_deg, elevation_deg);
}

double SunPosition::SolidAngleSr() const {
  return 2.0 * kPi * (1.0 - std::cos(angular_radius_deg * kDeg));
}

SunPosition ComputeSunPosition(UtcTime t, const Site& site, const Weather& weather) {
  if (!std::isfinite(site.lat_deg) || !std::isfinite(site.lon_deg) ||
      !std::isfinite(site.height_m) || std::abs(site.lat_deg) > 90.0) {
    throw Error("solar position: invalid site (lat " + std::to_string(site.lat_deg) + ", lon " +
                std::to_string(site.lon_deg) + ", height " + std::to_string(site.height_m) + ")");
  }
  if (!std::isfinite(weather.pressure_mbar) || !std::isfinite(weather.temperature_c) ||
      weather.pressure_mbar < 0 || weather.temperature_c <= -273.0) {
    throw Error("solar position: invalid weather (pressure " +
                std::to_string(weather.pressure_mbar) + " mbar, temperature " +
                std::to_string(weather.temperature_c) + " C)");
  }
  const CivilTime c = ToCivil(t);
  double utc1 = 0, utc2 = 0;
  if (eraDtf2d("UTC", c.year, c.month, c.day, c.hour, c.minute, c.second, &utc1, &utc2) < 0) {
    throw Error("solar position: ERFA refused the date " + t.Iso8601());
  }
  eraASTROM astrom;
  double eo = 0;
  // Pressure 0: ERFA's refraction is off; SPA's formula is applied below.
  const int status =
      eraApco13(utc1, utc2, /*dut1=*/0.0, site.lon_deg * kDeg, site.lat_deg * kDeg, site.height_m,
                /*xp=*/0.0, /*yp=*/0.0,
                /*phpa=*/0.0, weather.temperature_c, /*rh=*/0.0, /*wl=*/0.55, &astrom, &eo);
  if (status < 0) throw Error("solar position: ERFA refused the date " + t.Iso8601());
  // Observer-to-Sun natural direction (astrom.eh is the Sun-to-observer unit vector).
  double pnat[3] = {-astrom.eh[0], -astrom.eh[1], -astrom.eh[2]};
  double ppr[3], pi[3];
  eraAb(pnat, astrom.v, astrom.em, astrom.bm1, ppr);  // annual aberration
  eraRxp(astrom.bpn, ppr, pi);                        // GCRS -> CIRS
  double ri = 0, di = 0;
  eraC2s(pi, &ri, &di);
  double aob = 0, zob = 0, hob = 0, dob = 0, rob = 0;
  eraAtioq(ri, di, &astrom, &aob, &zob, &hob, &dob, &rob);

  SunPosition s;
  double az = aob * kRadToDeg;
  az = std::fmod(az, 360.0);
  if (az < 0) az += 360.0;
  if (az >= 360.0) az -= 360.0;
  s.azimuth_deg = az;
  s.elevation_true_deg = 90.0 - zob * kRadToDeg;
  s.elevation_deg =
      s.elevation_true_deg +
      SpaRefractionDeg(s.elevation_true_deg, weather.pressure_mbar, weather.temperature_c);
  s.distance_au = astrom.em;
  s.angular_radius_deg = std::asin(kSunRadiusKm / (astrom.em * kAuKm)) * kRadToDeg;
  // ERFA gives NaN for sites far from the Earth's surface (a height of 1e15 m): never return it.
  if (!std::isfinite(s.azimuth_deg) || !std::isfinite(s.elevation_deg) ||
      !std::isfinite(s.angular_radius_deg)) {
    throw Error("solar position: no finite position for the site (lat " +
                std::to_string(site.lat_deg) + ", lon " + std::to_string(site.lon_deg) +
                ", height " + std::to_string(site.height_m) + " m)");
  }
  return s;
}

Eigen::Vector3d EnuFromAzEl(double azimuth_deg, double elevation_deg) {
  const double az = azimuth_deg * kDeg, el = elevation_deg * kDeg;
  return Eigen::Vector3d(std::sin(az) * std::cos(el), std::cos(az) * std::cos(el), std::sin(el));
}

void AzElFromEnu(const Eigen::Vector3d& d, double* azimuth_deg, double* elevation_deg) {
  const double n = d.norm();
  const double horiz = std::hypot(d.x(), d.y());
  double az = std::atan2(d.x(), d.y()) * kRadToDeg;
  if (az < 0) az += 360.0;
  if (az >= 360.0) az -= 360.0;
  if (azimuth_deg) *azimuth_deg = n > 0 ? az : 0.0;
  if (elevation_deg) *elevation_deg = n > 0 ? std::atan2(d.z(), horiz) * kRadToDeg : 0.0;
}

std::string SunDownProblem(UtcTime t, const Site& site) {
  const SunPosition sun = ComputeSunPosition(t, site);
  if (!sun.BelowHorizon()) return "";
  return Formatted("the sun is %.1f deg below the horizon at the site (%.5f, %.5f)",
                   -sun.elevation_deg, site.lat_deg, site.lon_deg);
}

}  // namespace rouen
