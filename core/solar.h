// Topocentric solar position (IAU SOFA routines through ERFA) and the sun's size for the date.
#pragma once

#include <Eigen/Core>
#include <string>

#include "core/time.h"

namespace rouen {

// A place on the WGS84 ellipsoid. Degrees, east-positive longitude, metres above ellipsoid.
struct Site {
  double lat_deg = 37.8722;
  double lon_deg = -122.2578;
  double height_m = 60.0;
};

// Conditions for atmospheric refraction (standard: 1010 mbar, 10 C).
struct Weather {
  double pressure_mbar = 1010.0;
  double temperature_c = 10.0;
};

struct SunPosition {
  double azimuth_deg = 0;         // from north, eastward, [0, 360)
  double elevation_deg = 0;       // refracted (apparent), SPA refraction formula
  double elevation_true_deg = 0;  // airless topocentric
  double distance_au = 1;         // observer-sun distance
  double angular_radius_deg = 0;  // apparent semi-diameter of the disc
  // Unit vector towards the sun in the site's local east-north-up frame (refracted).
  Eigen::Vector3d DirectionEnu() const;
  // Solid angle of the sun's disc, steradians.
  double SolidAngleSr() const;
  // True when the whole disc is below the (apparent) horizon: night or twilight.
  bool BelowHorizon() const { return elevation_deg + angular_radius_deg < 0; }
};

SunPosition ComputeSunPosition(UtcTime t, const Site& site, const Weather& weather = {});

// Empty while any of the sun's disc is above the horizon at `site` at `t`; else "the sun is
// 12.3 deg below the horizon at the site (lat, lon)", for messages that refuse a night slot.
std::string SunDownProblem(UtcTime t, const Site& site);

// Unit ENU vector from azimuth (from north, eastward) and elevation, both in degrees.
Eigen::Vector3d EnuFromAzEl(double azimuth_deg, double elevation_deg);
// Inverse: azimuth in [0, 360) and elevation in degrees.
void AzElFromEnu(const Eigen::Vector3d& d, double* azimuth_deg, double* elevation_deg);

}  // namespace rouen
