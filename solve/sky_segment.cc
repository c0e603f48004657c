#include "solve/sky_segment.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/stats.h"

namespace rouen {
namespace {

// Angles between neighbouring pixels below this (deg) count as this much, so that the
// converging columns of an equirect image near the zenith do not turn noise into gradient.
constexpr double kMinNeighbourAngleDeg = 0.5;

}  // namespace

void SkySegmentOptions::Validate() const {
  auto bad = [](const std::string& what) { throw Error("SkySegmentOptions: " + what); };
  if (!std::isfinite(min_elevation_deg) || min_elevation_deg < -10 || min_elevation_deg >= 89)
    bad("min_elevation_deg must be in [-10, 89)");
  if (!std::isfinite(sun_exclusion_deg) || sun_exclusion_deg < 0 || sun_exclusion_deg > 90)
    bad("sun_exclusion_deg must be in [0, 90]");
  if (!std::isfinite(max_log_gradient_per_deg) || max_log_gradient_per_deg <= 0)
    bad("max_log_gradient_per_deg must be positive");
  if (!std::isfinite(min_relative_brightness) || min_relative_brightness < 0 ||
      min_relative_brightness > 1)
    bad("min_relative_brightness must be in [0, 1]");
  if (!std::isfinite(min_relative_blue_ratio) || min_relative_blue_ratio < 0 ||
      min_relative_blue_ratio > 1)
    bad("min_relative_blue_ratio must be in [0, 1]");
  if (!std::isfinite(seed_cone_deg) || seed_cone_deg <= 0 || seed_cone_deg > 90)
    bad("seed_cone_deg must be in (0, 90]");
}

std::vector<uint8_t> SegmentSky(const Image& hdr, const Intrinsics& intrinsics, const Pose& pose,
                                const Eigen::Vector3d& sun_dir, const SkySegmentOptions& options,
                                SkySegmentSummary* summary) {
  options.Validate();
  intrinsics.Validate();
  if (hdr.units != PixelUnits::kRadiance)
    throw Error("sky segmentation: the image is not a radiance image (kRadiance)");
  if (hdr.channels != 3) {
    throw Error("sky segmentation: the image must have 3 channels, has " +
                std::to_string(hdr.channels));
  }
  if (hdr.width != intrinsics.width || hdr.height != intrinsics.height) {
    throw Error("sky segmentation: image " + std::to_string(hdr.width) + "x" +
                std::to_string(hdr.height) + " does not match the intrinsics " +
                std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height));
  }
  const int w = hdr.width, h = hdr.height;
  const size_t np = static_cast<size_t>(w) * h;
  if (hdr.data.size() != np * 3)
    throw Error("sky segmentation: pixel buffer size does not match the image dimensions");
  const bool has_sun = sun_dir.allFinite() && sun_dir.norm() > 1e-9;
  const Eigen::Vector3d sun =
      has_sun ? Eigen::Vector3d(sun_dir.normalized()) : Eigen::Vector3d::Zero();
  const double z0 = std::sin(options.min_elevation_deg * kDeg);
  const double cos_sun = std::cos(options.sun_exclusion_deg * kDeg);
  const bool wrap = intrinsics.projection == Projection::kEquirect;

  // Per pixel: direction, log green, blue/red, basic validity.
  std::vector<Eigen::Vector3f> dirs(np);
  std::vector<float> log_g(np, 0.f);
  std::vector<uint8_t> ok(np, 0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      const Eigen::Vector3d d =
          (pose.rotation * Unproject(intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
      dirs[p] = d.cast<float>();
      bool good = d.allFinite() && d.z() >= z0 && !(has_sun && d.dot(sun) > cos_sun);
      for (int c = 0; c < 3 && good; ++c) {
        const float v = hdr.data[p * 3 + c];
        good = std::isfinite(v) && v > 0;
      }
      if (!good) continue;
      ok[p] = 1;
      log_g[p] = std::log(hdr.data[p * 3 + 1]);
    }
  }
  auto neighbours = [&](int x, int y, auto&& f) {
    const int nx[4] = {x - 1, x + 1, x, x};
    const int ny[4] = {y, y, y - 1, y + 1};
    for (int k = 0; k < 4; ++k) {
      int xx = nx[k];
      const int yy = ny[k];
      if (yy < 0 || yy >= h) continue;
      if (xx < 0 || xx >= w) {
        if (!wrap) continue;
        xx = (xx + w) % w;
      }
      f(static_cast<size_t>(yy) * w + xx);
    }
  };
  // Smoothness against every valid neighbour; a neighbour that is not valid (ground, outside
  // a fisheye circle) does not count against the pixel.
  std::vector<uint8_t> cand(np, 0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      if (!ok[p]) continue;
      bool smooth = true;
      neighbours(x, y, [&](size_t q) {
        if (!ok[q] || !smooth) return;
        const double cosang = std::clamp<double>(dirs[p].dot(dirs[q]), -1.0, 1.0);
        const double ang = std::max(std::acos(cosang) / kDeg, kMinNeighbourAngleDeg);
        if (std::abs(log_g[p] - log_g[q]) / ang > options.max_log_gradient_per_deg) smooth = false;
      });
      cand[p] = smooth;
    }
  }
  // Seeds: smooth candidates near the highest one.
  double top_z = -2;
  for (size_t p = 0; p < np; ++p)
    if (cand[p]) top_z = std::max<double>(top_z, dirs[p].z());
  if (top_z < -1) {
    throw Error("sky segmentation: no pixel looks like sky (none smooth above the horizon)");
  }
  const double top_el = std::asin(std::clamp(top_z, -1.0, 1.0));
  const double seed_z = std::sin(std::max(-0.5 * kPi, top_el - options.seed_cone_deg * kDeg));
  std::vector<size_t> seeds;
  std::vector<double> seed_g, seed_br;
  for (size_t p = 0; p < np; ++p) {
    if (!cand[p] || dirs[p].z() < seed_z) continue;
    seeds.push_back(p);
    seed_g.push_back(hdr.data[p * 3 + 1]);
    seed_br.push_back(hdr.data[p * 3 + 2] / hdr.data[p * 3 + 0]);
  }
  const double g_ref = Median(seed_g), br_ref = Median(seed_br);
  int n_cand = 0;
  for (size_t p = 0; p < np; ++p) {
    if (!cand[p]) continue;
    const double g = hdr.data[p * 3 + 1], br = hdr.data[p * 3 + 2] / hdr.data[p * 3 + 0];
    cand[p] = g >= options.min_relative_brightness * g_ref &&
              br >= options.min_relative_blue_ratio * br_ref;
    n_cand += cand[p];
  }
  // Flood fill from the seeds through 4-connected candidates.
  std::vector<uint8_t> mask(np, 0);
  std::deque<size_t> queue;
  int n_seeds = 0;
  for (size_t p : seeds) {
    if (!cand[p]) continue;
    mask[p] = 1;
    queue.push_back(p);
    ++n_seeds;
  }
  int n_sky = n_seeds;
  while (!queue.empty()) {
    const size_t p = queue.front();
    queue.pop_front();
    const int x = static_cast<int>(p % w), y = static_cast<int>(p / w);
    neighbours(x, y, [&](size_t q) {
      if (cand[q] && !mask[q]) {
        mask[q] = 1;
        ++n_sky;
        queue.push_back(q);
      }
    });
  }
  if (summary) {
    summary->sky_pixels = n_sky;
    summary->candidates = n_cand;
    summary->seeds = n_seeds;
  }
  return mask;
}

}  // namespace rouen
