// The simulated world's own sun: the Astronomical Almanac's low-precision solar coordinates
// (about 0.01 degrees, 1950-2050) with local sidereal time, independent of core/solar.h.
#pragma once

#include <Eigen/Core>

#include "core/solar.h"
#include "core/time.h"

namespace rouen {

struct AlmanacSun {
  double azimuth_deg = 0;         // from north, eastward, [0, 360)
  double elevation_deg = 0;       // apparent (refracted, Bennett's formula)
  double elevation_true_deg = 0;  // airless, topocentric
  double distance_au = 1;         // Earth-Sun distance
  double angular_radius_deg = 0;  // semi-diameter of the disc
  // Unit ENU vector towards the apparent sun.
  Eigen::Vector3d DirectionEnu() const;
  // Unit ENU vector towards the airless (unrefracted) sun.
  Eigen::Vector3d TrueDirectionEnu() const;
};

// Solar position for a site (only lat/lon are used; the ~0.0024 deg parallax is applied).
// Refraction uses Bennett's formula scaled by pressure (mbar) and temperature (C).
AlmanacSun AlmanacSunPosition(UtcTime t, const Site& site, double pressure_mbar = 1010.0,
                              double temperature_c = 10.0);

// Bennett's refraction (degrees) for a true elevation in degrees (inverted by iteration).
double BennettRefractionDeg(double true_elevation_deg, double pressure_mbar, double temperature_c);

}  // namespace rouen
