// Automatic sky segmentation of a radiance photo or panorama (for the sky fit of §3.2: the
// paper fits sky pixels only, with buildings and trees masked out).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

struct SkySegmentOptions {
  // A pixel is a sky candidate when it looks above the horizon by at least this much (deg),
  double min_elevation_deg = 0.0;
  // is at least this far from the sun (deg; the disc and the saturated aureole are excluded),
  double sun_exclusion_deg = 3.0;
  // is smooth: |ln L - ln L_neighbour| of its 4-neighbours (green channel) at most this much,
  // per degree of angle between the two pixels' directions (a clear or overcast sky changes
  // by well under 0.1 per degree outside the aureole; edges and textures change faster),
  double max_log_gradient_per_deg = 0.15;
  // is bright: luminance at least this fraction of the median of the seed pixels,
  double min_relative_brightness = 0.15;
  // and has a blue/red ratio at least this fraction of the seeds' median ratio.
  double min_relative_blue_ratio = 0.6;
  // Seeds: candidates within this angle (deg) of the highest candidate direction. The mask is
  // the set of candidates 4-connected to a seed.
  double seed_cone_deg = 10.0;

  void Validate() const;  // throws rouen::Error naming the bad field
};

struct SkySegmentSummary {
  int sky_pixels = 0;
  int candidates = 0;  // pixels passing the per-pixel tests (before connectivity)
  int seeds = 0;
};

// Sky mask (width x height, 1 = sky, 0 = not) of a radiance image seen through
// intrinsics/pose; `sun_dir` (unit ENU) may be zero when no sun should be excluded. Throws
// rouen::Error for a non-radiance image, a size mismatch, or an image with no sky candidate.
std::vector<uint8_t> SegmentSky(const Image& hdr, const Intrinsics& intrinsics, const Pose& pose,
                                const Eigen::Vector3d& sun_dir, const SkySegmentOptions& options,
                                SkySegmentSummary* summary = nullptr);

}  // namespace rouen
