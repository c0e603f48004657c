// Environment map assembly (Yu & Malik 1998, §3.3: "project every pixel into one of the
// spherical regions ... average the color of the pixels"): several HDR landscape/sky photos,
// each with intrinsics and pose, resampled into one equirectangular (lat-long) radiance image
// with per-pixel coverage counts; directions no photo saw are marked.
//
// Lat-long convention (shared with `rouen sky fit` and core/camera.h's kEquirect seen through
// Pose::Level(eye, 0, 0)): W x H with H = W / 2; row 0 at the zenith, the last row at the nadir;
// pixel (x, y) (centre at x + 0.5, y + 0.5) looks at azimuth (x + 0.5) / W * 360 deg from north
// through east and elevation 90 - (y + 0.5) / H * 180 deg. Directions are ENU; the photos'
// positions are ignored (the environment is taken to be at infinity).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

struct EnvmapPhoto {
  const Image* radiance = nullptr;  // kRadiance, not owned; same channel count for every photo
  Intrinsics intrinsics;            // size must equal the image's
  Pose pose;                        // rotation camera -> ENU
  // Largest angle from the optical axis that the lens images, degrees. 0: automatic (fisheye:
  // the circle inscribed in the frame; pinhole: the frame's edges).
  double max_field_deg = 0;
  std::string name;  // for messages
};

struct EnvmapOptions {
  int width = 1024;  // output width in pixels (even, >= 8); height = width / 2
  // Sub-samples per output pixel along each axis (box filter; > 1 when the map is finer than
  // or comparable to the photos' resolution is wasted, useful when it is much coarser).
  int supersample = 1;
  // Weights fall linearly from 1 to 0 over this fraction of each photo's half-size next to its
  // frame edge (or the fisheye's circle). 0: every photo weighs the same everywhere.
  double edge_feather = 0;

  void Validate() const;  // throws rouen::Error
};

struct EnvmapResult {
  Image radiance;  // W x H, the photos' channels, kRadiance; 0 where never seen
  Image coverage;  // W x H x 1, kOther: how many photos saw each pixel's direction (0: unseen)
  // Fraction of the sphere's solid angle seen by at least one photo, and the same for the
  // upper hemisphere.
  double coverage_fraction = 0;
  double sky_coverage_fraction = 0;
  int64_t pixels_covered = 0;
  std::vector<int64_t> pixels_per_photo;  // output pixels each photo contributed to
  double seconds = 0;
};

// World (ENU) unit direction of lat-long pixel coordinates (continuous; pixel centres +0.5).
Eigen::Vector3d EnvmapDirection(int width, int height, double x, double y);
// Lat-long pixel coordinates of a world direction (need not be unit); x in [0, W).
Eigen::Vector2d EnvmapPixel(int width, int height, const Eigen::Vector3d& dir);

// Resamples every photo into the lat-long map by inverse mapping (each output pixel looks each
// photo up through core/camera.h Project, bilinear), averaging with coverage counts. Photo
// pixels that are negative or not finite are skipped. Throws rouen::Error (naming the photo)
// for no photos, a missing image, a size that differs from the intrinsics, mismatched channel
// counts, LDR (kDigital) images or a rotation that is not a rotation.
EnvmapResult AssembleEnvmap(const std::vector<EnvmapPhoto>& photos, const EnvmapOptions& options);

// {"width", "height", "photos", "coverage_fraction", "sky_coverage_fraction", "pixels_covered",
//  "pixels_per_photo", "seconds", "convention"}.
nlohmann::json EnvmapSummaryJson(const EnvmapResult& result,
                                 const std::vector<EnvmapPhoto>& photos);

}  // namespace rouen
