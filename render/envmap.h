// The lighting of one time (sun, sky, environment) as a latitude-longitude (equirectangular)
// radiance map that another renderer can light a scene with, and the irradiance such a map
// gives a plane.
//
// Orientation: Blender's Environment Texture (equirectangular) convention, checked by rendering
// in Blender 3.4 (tests/export_cli_test.cc): for a direction (x, y, z) in Blender's world (z up)
//   u = 0.5 - atan2(y, x) / (2 pi)  (0 at the image's left edge),
//   v = 0.5 + atan2(z, hypot(x, y)) / pi  (0 at its bottom edge: row 0 of the file is the zenith),
// with rouen's ENU frame taken as Blender's world as is (x east, y north, z up). So north is at a
// quarter of the width, east at the centre, south at three quarters, west at both edges; the
// compass azimuth A (from north through east) is at u = 0.25 + A / (2 pi).
#pragma once

#include <Eigen/Core>
#include <limits>

#include "core/image.h"
#include "solve/irradiance.h"

namespace rouen {

struct LatLongOptions {
  int width = 1024;  // pixels; the height is width / 2. Even, 8..16384.
  // Above the horizon: the sky model, supersampled (smooth, as `rouen render` draws the sky
  // behind the building), instead of the environment's regions spread by the sky's shape
  // (SkyShape), which are what rouen's irradiance integrates. Below the horizon: the regions.
  bool sky_model = false;
  int sky_samples = 4;  // per axis, per pixel, for the sky model
  // The height (ENU metres) the environment is seen from, between its layers
  // (EnvironmentMap::Radiance); NaN: the lowest layer's.
  double height_m = std::numeric_limits<double>::quiet_NaN();
  void Validate() const;  // throws rouen::Error naming the field
};

// Unit ENU direction through continuous pixel coordinates (pixel centres at integer + 0.5)
// of a width x height latitude-longitude map, and back.
Eigen::Vector3d LatLongDirection(int width, int height, double column, double row);
Eigen::Vector2d LatLongPixel(int width, int height, const Eigen::Vector3d& dir);
// Solid angle of a pixel of row `row` (sr).
double LatLongPixelSolidAngle(int width, int height, int row);

// The radiance arriving from every direction (RGB, the lighting's relative radiance units): each
// pixel the solid-angle mean of the environment's regions over it, each spread by the sky's
// shape at the middle of the part of the pixel it covers (or
// of the supersampled sky model, see LatLongOptions), plus the sun disc added on top of them
// (as the irradiance adds E_sun to the sky's) over the pixels it covers, each in proportion to
// the part of the disc it holds, the whole scaled so that the pixels carry exactly the sun's
// L_sun x Omega_sun: its irradiance is conserved. Throws rouen::Error for bad options or a
// lighting with non-finite or negative values.
Image BakeLatLong(const Lighting& lighting, const LatLongOptions& options = {});

// The irradiance a width x height latitude-longitude radiance map gives an unoccluded plane
// facing `normal`: sum over pixels of L times the pixel's integral of max(0, n.d) d omega
// (closed form for pixels wholly in front of the plane, subsampled for those it cuts).
Eigen::Vector3d LatLongIrradiance(const Image& map, const Eigen::Vector3d& normal);

// rouen's own irradiance on a small plane facing `normal` at height z with nothing around it:
// ComputeIrradiance (solve/irradiance.h) of a one-triangle model, the sky and environment by
// vector flux (App. A) with the regions' parallels followed closely, the sun's L Omega max(0,
// n.s); no ground shadow (nothing casts one).
Eigen::Vector3d UnoccludedIrradiance(const Lighting& lighting, const Eigen::Vector3d& normal,
                                     double z);

}  // namespace rouen
