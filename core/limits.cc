#include "core/limits.h"

#include <cmath>
#include <cstdio>

#include "core/error.h"

namespace rouen {
namespace {

// "" when lo <= v <= hi, else "<what> <v><unit> is outside <lo>..<hi><unit><after>".
std::string OutsideOf(double v, double lo, double hi, const char* what, const char* unit,
                      const char* after = "") {
  if (v >= lo && v <= hi) return {};  // false for NaN
  return std::string(what) + " " + FormatNumber(v) + unit + " is outside " + FormatNumber(lo) +
         ".." + FormatNumber(hi) + unit + after;
}

}  // namespace

std::string FormatNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::string FormatCount(double n) {
  char buf[32];
  if (std::abs(n) < 1e15)
    std::snprintf(buf, sizeof buf, "%.0f", n);
  else
    std::snprintf(buf, sizeof buf, "%g", n);
  return buf;
}

std::string LatitudeProblem(double deg) {
  return OutsideOf(deg, -kMaxAbsLatitudeDeg, kMaxAbsLatitudeDeg, "latitude", " deg");
}

std::string LongitudeProblem(double deg) {
  return OutsideOf(deg, -kMaxAbsLongitudeDeg, kMaxAbsLongitudeDeg, "longitude", " deg",
                   " (east positive)");
}

std::string CoordinateProblem(double m) {
  return OutsideOf(m, -kMaxCoordinateM, kMaxCoordinateM, "coordinate", " m",
                   " of the site's east-north-up frame");
}

std::string HeightProblem(double m) {
  return OutsideOf(m, kMinHeightM, kMaxHeightM, "height", " m", " above the WGS84 ellipsoid");
}

std::string ExposureProblem(double seconds) {
  if (seconds <= 0) {
    return "exposure " + FormatNumber(seconds) + " s is not positive (the range is " +
           FormatNumber(kMinExposureS) + ".." + FormatNumber(kMaxExposureS) + " s)";
  }
  return OutsideOf(seconds, kMinExposureS, kMaxExposureS, "exposure", " s");
}

std::string NdDensityProblem(double density) {
  return OutsideOf(density, 0, kMaxNdDensity, "ND density", "");
}

void Require(const std::string& problem, const std::string& where) {
  if (!problem.empty()) throw Error(where + ": " + problem);
}

void CheckSite(const Site& site, const std::string& where) {
  Require(LatitudeProblem(site.lat_deg), where);
  Require(LongitudeProblem(site.lon_deg), where);
  Require(HeightProblem(site.height_m), where);
}

}  // namespace rouen
