// Plausible ranges of the physical quantities users give rouen (options, list files, rigs,
// sessions): one rule each, so every reader accepts and refuses the same values. NaN and
// infinities are outside every range.
#pragma once

#include <string>

#include "core/solar.h"

namespace rouen {

// Latitude -90..90 deg, longitude -180..180 deg east.
inline constexpr double kMaxAbsLatitudeDeg = 90, kMaxAbsLongitudeDeg = 180;
// Height above the WGS84 ellipsoid: -500 m (the Dead Sea shore, -430 m, with room for the
// geoid's +-110 m) to 9000 m (above Everest, 8849 m).
inline constexpr double kMinHeightM = -500, kMaxHeightM = 9000;
// Exposure times: 1 ns to one day, seconds.
inline constexpr double kMinExposureS = 1e-9, kMaxExposureS = 86400;
// Optical density of an ND filter: 0 (none) to 10 (transmission 1e-10).
inline constexpr double kMaxNdDensity = 10;
// A position in the site's east-north-up frame (a camera, a model's vertex): within 100 km of
// its origin on each axis. Beyond, single-precision ray tracing (Embree) loses the building's
// detail, and far beyond it fails.
inline constexpr double kMaxCoordinateM = 1e5;

// Each returns "" when the value is within its range, else the problem, e.g. "height 1e+15
// m is outside -500..9000 m above the WGS84 ellipsoid".
std::string LatitudeProblem(double deg);
std::string LongitudeProblem(double deg);
std::string HeightProblem(double m);
std::string ExposureProblem(double seconds);
std::string NdDensityProblem(double density);
std::string CoordinateProblem(double m);

// Throws rouen::Error "<where>: <problem>" when `problem` is not empty.
void Require(const std::string& problem, const std::string& where);
// The site's latitude, longitude and height; `where` names its source (an option, a file
// and line, a table of a rig).
void CheckSite(const Site& site, const std::string& where);

// A number for messages: %g, so 1e15 stays 1e+15 and 0.5 stays 0.5.
std::string FormatNumber(double v);
// A count for messages (of frames, points, bytes), computed in floating point before it is
// known to fit an integer: whole digits up to 1e15, %g beyond (1e+303, never an overflow).
std::string FormatCount(double n);

}  // namespace rouen
