// Sun radiance from a radiance image of the sun taken through neutral-density filters
// (Yu & Malik 1998 §3.1): integrate the disc, divide by the sun's solid angle.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

// Each window radius is the larger of a multiple of the sun's angular radius (telephoto ND
// frames, where the disc spans many pixels and the blur scales with it) and a number of pixel
// footprints at the sun (panoramas and fisheye sky photos, where the disc may be smaller than
// a pixel). A pixel footprint is the angle across the longer side of the pixel at the sun,
// from the camera model (an equirect pixel narrows in azimuth towards the poles).
struct SunOptions {
  double search_radius_deg = 3.0;     // the disc is looked for this far from the prediction
  double disc_radius_factor = 1.6;    // integrate within this x the sun's angular radius (blur)
  double annulus_inner_factor = 2.5;  // background annulus, x the sun's angular radius
  double annulus_outer_factor = 4.0;
  double disc_min_pixels = 2.5;           // integrate within at least this many pixels
  double annulus_inner_min_pixels = 2.0;  // annulus from at least disc window + this many
  double annulus_outer_min_pixels = 6.0;  // to at least disc window + this many pixels
  // Pixels with a channel at this value (relative 1e-6: float rounding) are clipped, not
  // radiance: the largest half float, where a panorama stored as half EXR saturates (a float32
  // frame's values near it are radiance). 0 turns the test off.
  double clip_radiance = 65504.0;
  int centroid_iterations = 8;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct SunMeasurement {
  Eigen::Vector3d radiance = Eigen::Vector3d::Zero();        // mean disc radiance per channel
  Eigen::Vector3d background = Eigen::Vector3d::Zero();      // annulus median, subtracted
  Eigen::Vector3d direction_enu = Eigen::Vector3d::UnitZ();  // disc centroid, unit ENU
  // Relative uncertainty of `radiance` per channel: the background's robust spread over the
  // annulus (1.4826 x median absolute deviation) times the disc window's solid angle, divided
  // by the integrated disc energy; i.e. the error if the sky under the whole window were off by
  // one robust standard deviation (sky gradients, aureole, noise). Infinite if no energy.
  Eigen::Vector3d radiance_uncertainty = Eigen::Vector3d::Zero();
  double offset_deg = 0;         // angle between the centroid and the predicted direction
  double window_radius_deg = 0;  // radius of the disc window integrated
  double pixel_deg = 0;          // pixel footprint at the disc (longer side), degrees
  int disc_pixels = 0;           // pixels integrated
  int annulus_pixels = 0;        // pixels in the background estimate
  // Some pixel of the integration region was invalid in the mask (e.g. saturated in every
  // frame), non-finite, negative or at clip_radiance: the radiance is then a lower bound at best.
  bool any_invalid = false;
};

// `hdr` is a kRadiance image already divided by the ND transmission (or an unfiltered HDR
// panorama or sky photo whose disc is not clipped); `predicted_sun_dir_enu` comes from the
// solar position for the frame's time; `sun_solid_angle_sr` from the Earth-Sun distance. The
// disc is found near the prediction (brightest 3x3 neighbourhood within search_radius_deg), the
// sky background (median over an annulus) is subtracted per channel, and radiance x pixel solid
// angle (from the camera model: exact for equirect pixels, spherical quadrilaterals through the
// pixel corners otherwise) is summed over the pixels whose centres lie within the disc window
// around the iterated centroid; the sum divided by sun_solid_angle_sr is the mean disc
// radiance, whether the disc spans 30 pixels or a fraction of one. Equirect columns wrap
// around and its rows meet at the poles, so only pinhole and fisheye frames have borders.
// `valid_mask` (width x height, nonzero = valid) may be null.
// Throws rouen::Error when the image or arguments are malformed, the predicted sun is not in
// the frame, the disc touches the image border, or no disc brighter than the sky is found.
SunMeasurement MeasureSun(const Image& hdr, const Intrinsics& intrinsics, const Pose& pose,
                          const Eigen::Vector3d& predicted_sun_dir_enu, double sun_solid_angle_sr,
                          const SunOptions& options,
                          const std::vector<uint8_t>* valid_mask = nullptr);

}  // namespace rouen
