#include "calib/envmap.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

// One photo prepared for lookups.
struct Prepared {
  const Image* img;
  Intrinsics k;
  Eigen::Matrix3d world_to_cam;
  double cos_max_field;  // rays further than this from the optical axis are not imaged
  double circle_px;      // fisheye: radius of the imaged circle (for feathering), else 0
  bool wrap_x;           // equirect photo: columns wrap around
};

// Bilinear sample of all channels at continuous pixel coordinates; false when a tap is
// negative or not finite.
bool SampleAll(const Prepared& p, double u, double v, float* out) {
  const Image& im = *p.img;
  const double fx = u - 0.5, fy = v - 0.5;
  int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  const double ax = fx - x0, ay = fy - y0;
  int x1 = x0 + 1, y1 = y0 + 1;
  if (p.wrap_x) {
    x0 = (x0 % im.width + im.width) % im.width;
    x1 = (x1 % im.width + im.width) % im.width;
  } else {
    x0 = std::clamp(x0, 0, im.width - 1);
    x1 = std::clamp(x1, 0, im.width - 1);
  }
  y0 = std::clamp(y0, 0, im.height - 1);
  y1 = std::clamp(y1, 0, im.height - 1);
  const float* t00 = &im.data[im.index(x0, y0)];
  const float* t10 = &im.data[im.index(x1, y0)];
  const float* t01 = &im.data[im.index(x0, y1)];
  const float* t11 = &im.data[im.index(x1, y1)];
  for (int c = 0; c < im.channels; ++c) {
    const float a = t00[c], b = t10[c], d = t01[c], e = t11[c];
    if (!(a >= 0 && b >= 0 && d >= 0 && e >= 0) || !std::isfinite(a + b + d + e)) return false;
    out[c] = static_cast<float>((1 - ay) * ((1 - ax) * a + ax * b) + ay * ((1 - ax) * d + ax * e));
  }
  return true;
}

// Weight of a photo's pixel: 1 inside, falling to a small floor at the frame edge.
double EdgeWeight(const Prepared& p, const Eigen::Vector2d& px, double feather) {
  if (feather <= 0 || p.wrap_x) return 1.0;
  const double half = 0.5 * std::min(p.k.width, p.k.height);
  double d = std::min({px.x(), p.k.width - px.x(), px.y(), p.k.height - px.y()});
  if (p.circle_px > 0) {
    d = std::min(d, p.circle_px - (px - Eigen::Vector2d(p.k.cx, p.k.cy)).norm());
  }
  return std::clamp(d / (feather * half), 1e-3, 1.0);
}

}  // namespace

void EnvmapOptions::Validate() const {
  if (width < 8 || width > 65536 || width % 2 != 0) {
    throw Error("envmap options: width " + std::to_string(width) +
                " must be even and between 8 and 65536");
  }
  if (supersample < 1 || supersample > 8) {
    throw Error("envmap options: supersample must be 1..8");
  }
  if (!(edge_feather >= 0 && edge_feather <= 1)) {
    throw Error("envmap options: edge_feather must be in [0, 1]");
  }
}

Eigen::Vector3d EnvmapDirection(int width, int height, double x, double y) {
  const double az = x / width * 2 * kPi;
  const double el = 0.5 * kPi - y / height * kPi;
  return Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
}

Eigen::Vector2d EnvmapPixel(int width, int height, const Eigen::Vector3d& d) {
  double az = std::atan2(d.x(), d.y());
  if (az < 0) az += 2 * kPi;
  const double el = std::asin(std::clamp(d.z() / d.norm(), -1.0, 1.0));
  double x = az / (2 * kPi) * width;
  if (x >= width) x -= width;
  return Eigen::Vector2d(x, (0.5 * kPi - el) / kPi * height);
}

EnvmapResult AssembleEnvmap(const std::vector<EnvmapPhoto>& photos, const EnvmapOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  o.Validate();
  if (photos.empty()) throw Error("envmap: no photos");
  std::vector<Prepared> prep;
  int channels = 0;
  for (size_t i = 0; i < photos.size(); ++i) {
    const EnvmapPhoto& ph = photos[i];
    const std::string name =
        "envmap: photo " + std::to_string(i + 1) + (ph.name.empty() ? "" : " (" + ph.name + ")");
    if (!ph.radiance || ph.radiance->empty()) throw Error(name + ": no image");
    const Image& im = *ph.radiance;
    if (im.units == PixelUnits::kDigital) {
      throw Error(name + ": an LDR image (digital numbers); merge it to HDR radiance first");
    }
    if (static_cast<size_t>(im.width) * im.height * im.channels != im.data.size()) {
      throw Error(name + ": image data does not match its size");
    }
    try {
      ph.intrinsics.Validate();
    } catch (const Error& e) {
      throw Error(name + ": " + e.what());
    }
    if (im.width != ph.intrinsics.width || im.height != ph.intrinsics.height) {
      throw Error(name + ": image is " + std::to_string(im.width) + "x" +
                  std::to_string(im.height) + " but its lens is " +
                  std::to_string(ph.intrinsics.width) + "x" + std::to_string(ph.intrinsics.height));
    }
    if (i == 0) channels = im.channels;
    if (im.channels != channels) {
      throw Error(name + ": " + std::to_string(im.channels) + " channels, but photo 1 has " +
                  std::to_string(channels));
    }
    const Eigen::Matrix3d& r = ph.pose.rotation;
    if (!r.allFinite() || (r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
        r.determinant() < 0) {
      throw Error(name + ": the pose's rotation is not a rotation");
    }
    if (!(ph.max_field_deg >= 0 && ph.max_field_deg <= 180)) {
      throw Error(name + ": max_field_deg must be in [0, 180]");
    }
    Prepared p{&im,  ph.intrinsics, r.transpose(),
               -2.0, 0.0,           ph.intrinsics.projection == Projection::kEquirect};
    const Intrinsics& k = ph.intrinsics;
    if (k.projection == Projection::kFisheye) {
      p.circle_px = std::min({k.cx, k.cy, k.width - k.cx, k.height - k.cy});
      if (!(p.circle_px > 0)) throw Error(name + ": the principal point is outside the image");
      // One pixel inside the circle, so that no bilinear tap reaches the dark outside.
      if (ph.max_field_deg == 0) {
        p.cos_max_field = Unproject(k, Eigen::Vector2d(k.cx + p.circle_px - 1, k.cy)).z();
      }
    }
    if (k.projection == Projection::kPinhole && ph.max_field_deg == 0) {
      // No ray further from the axis than the farthest corner is in the frame; this also keeps
      // out rays that a barrel distortion polynomial folds back into the image.
      double c = 1;
      for (double u : {0.0, 1.0 * k.width}) {
        for (double v : {0.0, 1.0 * k.height}) c = std::min(c, Unproject(k, {u, v}).z());
      }
      p.cos_max_field = c - 1e-9;
    }
    if (ph.max_field_deg > 0) p.cos_max_field = std::cos(ph.max_field_deg * kDeg);
    prep.push_back(p);
  }

  const int W = o.width, H = o.width / 2, S = o.supersample, np = static_cast<int>(prep.size());
  EnvmapResult res;
  res.radiance = Image(W, H, channels, PixelUnits::kRadiance, 0.f);
  res.coverage = Image(W, H, 1, PixelUnits::kOther, 0.f);
  std::vector<int64_t> row_counts(static_cast<size_t>(H) * np, 0);
  const double feather = o.edge_feather;
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
    std::vector<double> sum(channels);
    std::vector<float> val(channels);
    std::vector<char> seen(np);
    for (int y = rows.begin(); y < rows.end(); ++y) {
      for (int x = 0; x < W; ++x) {
        std::fill(sum.begin(), sum.end(), 0.0);
        std::fill(seen.begin(), seen.end(), 0);
        double wsum = 0;
        for (int sy = 0; sy < S; ++sy) {
          for (int sx = 0; sx < S; ++sx) {
            const Eigen::Vector3d d = EnvmapDirection(W, H, x + (sx + 0.5) / S, y + (sy + 0.5) / S);
            for (int i = 0; i < np; ++i) {
              const Prepared& p = prep[i];
              const Eigen::Vector3d dc = p.world_to_cam * d;
              if (dc.z() < p.cos_max_field) continue;
              const auto px = Project(p.k, dc);
              if (!px ||
                  !(px->x() >= 0 && px->x() < p.k.width && px->y() >= 0 && px->y() < p.k.height)) {
                continue;
              }
              if (!SampleAll(p, px->x(), px->y(), val.data())) continue;
              const double w = EdgeWeight(p, *px, feather);
              for (int c = 0; c < channels; ++c) sum[c] += w * val[c];
              wsum += w;
              seen[i] = 1;
            }
          }
        }
        int count = 0;
        for (int i = 0; i < np; ++i) {
          if (!seen[i]) continue;
          ++count;
          ++row_counts[static_cast<size_t>(y) * np + i];
        }
        res.coverage.at(x, y) = static_cast<float>(count);
        if (wsum > 0) {
          for (int c = 0; c < channels; ++c) {
            res.radiance.at(x, y, c) = static_cast<float>(sum[c] / wsum);
          }
        }
      }
    }
  });

  res.pixels_per_photo.assign(np, 0);
  double covered_sr = 0, sky_sr = 0;
  for (int y = 0; y < H; ++y) {
    for (int i = 0; i < np; ++i)
      res.pixels_per_photo[i] += row_counts[static_cast<size_t>(y) * np + i];
    const double el_top = 0.5 * kPi - y * kPi / H, el_bot = 0.5 * kPi - (y + 1) * kPi / H;
    const double pixel_sr = 2 * kPi / W * (std::sin(el_top) - std::sin(el_bot));
    int covered = 0;
    for (int x = 0; x < W; ++x) covered += res.coverage.at(x, y) > 0;
    res.pixels_covered += covered;
    covered_sr += covered * pixel_sr;
    if (y < H / 2) sky_sr += covered * pixel_sr;
  }
  res.coverage_fraction = covered_sr / (4 * kPi);
  res.sky_coverage_fraction = sky_sr / (2 * kPi);
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

nlohmann::json EnvmapSummaryJson(const EnvmapResult& r, const std::vector<EnvmapPhoto>& photos) {
  nlohmann::json per = nlohmann::json::array();
  for (size_t i = 0; i < photos.size() && i < r.pixels_per_photo.size(); ++i) {
    per.push_back({{"name", photos[i].name}, {"pixels", r.pixels_per_photo[i]}});
  }
  return nlohmann::json{
      {"width", r.radiance.width},
      {"height", r.radiance.height},
      {"channels", r.radiance.channels},
      {"photos", per},
      {"coverage_fraction", r.coverage_fraction},
      {"sky_coverage_fraction", r.sky_coverage_fraction},
      {"pixels_covered", r.pixels_covered},
      {"seconds", r.seconds},
      {"convention",
       "equirectangular ENU: row 0 zenith, last row nadir; column x at azimuth (x+0.5)/W*360 "
       "deg from north through east; coverage 0 = never seen (radiance 0)"}};
}

}  // namespace rouen
