// Orientation of sky photographs from the sun (Yu & Malik 1998, §6: "exterior orientation is
// calibrated with a compass map or the solar position"). A sky photo without buildings is
// placed by its sun disc (an ND frame or an HDR image) plus one more constraint: a landmark of
// known direction, horizon points (world elevation 0) or the assumption of a level camera.
//
// Conventions: camera frame x right, y down, z forward (core/camera.h); world frame east-north-up;
// Pose::rotation maps camera rays to world directions.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

struct SunDiscOptions {
  // Apparent angular radius of the sun's disc, degrees (SunPosition::angular_radius_deg).
  double sun_radius_deg = 0.2666;
  // The peak must exceed the image's median luminance this many times (else: no sun).
  double min_contrast = 20.0;
  // Core of the blob: pixels above median + core_fraction * (peak - median).
  double core_fraction = 0.5;
  // Pixels of the centroid window above local background + this fraction of the peak height
  // take part in the centroid (catches the partly covered pixels at the disc's rim).
  double rim_fraction = 0.01;
  // The blob's equivalent radius may exceed the disc's expected radius by this factor plus
  // 1.5 px (pixelisation and lens blur) before it is refused as flare or a clipped sun.
  double max_size_ratio = 2.0;
  // Pixels at or above this value are clipped. <= 0: automatic (254.5 for kDigital images,
  // none for radiance images).
  double saturation = 0;
  // Another compact bright blob with a peak above this fraction of the sun's peak, further than
  // a few disc radii away, makes the detection ambiguous.
  double second_blob_fraction = 0.3;

  void Validate() const;  // throws rouen::Error
};

struct SunDisc {
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();     // sub-pixel centroid (pixel centres +0.5)
  Eigen::Vector3d ray_cam = Eigen::Vector3d::UnitZ();  // unit camera-frame ray through it
  double peak = 0;                                     // peak luminance (image units)
  double background = 0;                               // local background luminance around the disc
  int core_pixels = 0;                                 // pixels in the blob's core
  double radius_px = 0;                                // equivalent radius of the core, pixels
  double expected_radius_px = 0;  // the sun's radius projected at this place in the image
  // 1-sigma centroid uncertainty from the image noise around the disc, pixels (plus a 0.02 px
  // floor for pixelisation), and the same as an angle, degrees.
  double sigma_px = 0;
  double sigma_deg = 0;
};

// Finds the sun's disc: the brightest compact blob, its centroid weighted by radiance above the
// local background, sub-pixel. Throws rouen::Error (naming `what`) when there is no clear sun,
// when the blob is clipped or much larger than the sun's disc for this lens (flare, a
// saturated sun), when a second comparable blob exists, or when the image does not match the
// intrinsics.
SunDisc DetectSunDisc(const Image& image, const Intrinsics& intrinsics,
                      const SunDiscOptions& options = {}, const std::string& what = "image");

// A landmark: a pixel whose world direction is known (from azimuth/elevation, or a world point
// seen from the camera position: direction = (point - position).normalized()).
struct SkyLandmark {
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  Eigen::Vector3d world_dir = Eigen::Vector3d::UnitY();  // need not be unit
  double sigma_deg = 0.1;  // how well the pixel and the direction are known
};

// A pixel on the true horizon (world elevation 0).
struct HorizonPoint {
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  double sigma_deg = 0.1;
};

struct OrientOptions {
  // Assume the camera is level: its x axis (image rows) is horizontal.
  bool level = false;
  double level_sigma_deg = 0.5;
  // A landmark closer than this to the sun (on either side) cannot fix the roll about the sun
  // axis: rouen::Error.
  double min_separation_deg = 5.0;
  // A second constraint that disagrees with the sun by more than this many sigmas: rouen::Error.
  double max_residual_sigma = 10.0;

  void Validate() const;
};

struct SkyOrientation {
  Pose pose;  // rotation camera -> ENU; position zero (set by the caller)
  // Angle between the sun's camera ray mapped to the world and the sun's direction, degrees.
  double sun_residual_deg = 0;
  std::vector<double> landmark_residual_deg;  // same, per landmark
  std::vector<double> horizon_residual_deg;   // world elevation of each horizon ray, degrees
  double level_residual_deg = 0;              // elevation of the camera's x axis (level only)
  // 1-sigma uncertainty of the rotation (largest axis), from the constraints' sigmas, degrees.
  double rotation_sigma_deg = 0;
  // With only one horizon point or the level assumption, two rotations can fit about equally
  // well; then the one with the image upright and looking upwards is chosen and this is set.
  bool had_mirror_solution = false;
};

// Solves the camera rotation from the sun's camera ray and its world direction (ENU, unit,
// e.g. SunPosition::DirectionEnu()) plus at least one of: landmarks, horizon points, level.
// With one landmark the solution is closed form (the sun and the landmark directions), with
// more constraints a weighted least-squares refinement (Gauss-Newton on the rotation) follows.
// Throws rouen::Error when the constraints do not fix the roll about the sun axis or
// contradict each other.
SkyOrientation OrientFromSun(const Intrinsics& intrinsics, const Eigen::Vector3d& sun_ray_cam,
                             double sun_sigma_deg, const Eigen::Vector3d& sun_dir_world,
                             const std::vector<SkyLandmark>& landmarks,
                             const std::vector<HorizonPoint>& horizon,
                             const OrientOptions& options = {});

// Angle between two rotations, degrees.
double RotationAngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b);

}  // namespace rouen
