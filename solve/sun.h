// Sun radiance from a radiance image of the sun taken through neutral-density filters
// (Yu & Malik 1998 §3.1): integrate the disc, divide by the sun's solid angle.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

struct SunOptions {
  double search_radius_deg = 3.0;     // the disc is looked for this far from the prediction
  double disc_radius_factor = 1.6;    // integrate within this x the sun's angular radius (blur)
  double annulus_inner_factor = 2.5;  // background annulus, x the sun's angular radius
  double annulus_outer_factor = 4.0;
  int centroid_iterations = 8;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct SunMeasurement {
  Eigen::Vector3d radiance = Eigen::Vector3d::Zero();        // mean disc radiance per channel
  Eigen::Vector3d background = Eigen::Vector3d::Zero();      // annulus median, subtracted
  Eigen::Vector3d direction_enu = Eigen::Vector3d::UnitZ();  // disc centroid, unit ENU
  double offset_deg = 0;   // angle between the centroid and the predicted direction
  int disc_pixels = 0;     // pixels integrated
  int annulus_pixels = 0;  // pixels in the background estimate
  // Some pixel of the integration region was invalid in the mask (e.g. saturated in every
  // frame), non-finite or negative: the radiance is then a lower bound at best.
  bool any_invalid = false;
};

// `hdr` is a kRadiance image already divided by the ND transmission; `predicted_sun_dir_enu`
// comes from the solar position for the frame's time; `sun_solid_angle_sr` from the
// Earth-Sun distance. The disc is found near the prediction (brightest 3x3 neighbourhood within
// search_radius_deg), the sky background (median over an annulus) is subtracted per channel,
// and radiance x pixel solid angle (from the camera model, exact spherical quadrilaterals
// through the pixel corners) is summed within disc_radius_factor x the sun's angular radius
// around the iterated centroid; the sum divided by sun_solid_angle_sr is the mean disc
// radiance. `valid_mask` (width x height, nonzero = valid) may be null.
// Throws rouen::Error when the image or arguments are malformed, the predicted sun is not in
// the frame, the disc touches the image border, or no disc brighter than the sky is found.
SunMeasurement MeasureSun(const Image& hdr, const Intrinsics& intrinsics, const Pose& pose,
                          const Eigen::Vector3d& predicted_sun_dir_enu, double sun_solid_angle_sr,
                          const SunOptions& options,
                          const std::vector<uint8_t>* valid_mask = nullptr);

}  // namespace rouen
