#include "solve/sun.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/stats.h"

namespace rouen {
namespace {

double Angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  // atan2 form: accurate for the tiny angles of a sun disc.
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// Solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom & Strackee).
double TriangleSolidAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& c) {
  const double num = std::abs(a.dot(b.cross(c)));
  const double den = 1 + a.dot(b) + b.dot(c) + c.dot(a);
  return 2 * std::atan2(num, den);
}

}  // namespace

void SunOptions::Validate() const {
  if (!std::isfinite(search_radius_deg) || search_radius_deg <= 0 || search_radius_deg > 45) {
    throw Error("SunOptions: search_radius_deg must be in (0, 45], got " +
                std::to_string(search_radius_deg));
  }
  if (!std::isfinite(disc_radius_factor) || disc_radius_factor < 1 || disc_radius_factor > 10) {
    throw Error("SunOptions: disc_radius_factor must be in [1, 10], got " +
                std::to_string(disc_radius_factor));
  }
  if (!std::isfinite(annulus_inner_factor) || !std::isfinite(annulus_outer_factor) ||
      annulus_inner_factor < disc_radius_factor || annulus_outer_factor <= annulus_inner_factor ||
      annulus_outer_factor > 50) {
    throw Error(
        "SunOptions: need disc_radius_factor <= annulus_inner_factor < "
        "annulus_outer_factor <= 50");
  }
  if (centroid_iterations < 1) throw Error("SunOptions: centroid_iterations must be positive");
}

SunMeasurement MeasureSun(const Image& hdr, const Intrinsics& k, const Pose& pose,
                          const Eigen::Vector3d& predicted_sun_dir_enu, double sun_solid_angle_sr,
                          const SunOptions& options, const std::vector<uint8_t>* valid_mask) {
  options.Validate();
  k.Validate();
  if (hdr.units != PixelUnits::kRadiance) {
    throw Error("sun: the image is not a radiance image (kRadiance)");
  }
  if (hdr.channels != 1 && hdr.channels != 3) {
    throw Error("sun: the image must have 1 or 3 channels, has " + std::to_string(hdr.channels));
  }
  if (hdr.width != k.width || hdr.height != k.height) {
    throw Error("sun: image " + std::to_string(hdr.width) + "x" + std::to_string(hdr.height) +
                " does not match the intrinsics " + std::to_string(k.width) + "x" +
                std::to_string(k.height));
  }
  const size_t np = static_cast<size_t>(hdr.width) * hdr.height;
  if (hdr.data.size() != np * hdr.channels) {
    throw Error("sun: pixel buffer size does not match the image dimensions");
  }
  if (valid_mask && !valid_mask->empty() && valid_mask->size() != np) {
    throw Error("sun: valid mask has " + std::to_string(valid_mask->size()) +
                " entries, expected " + std::to_string(np));
  }
  if (!std::isfinite(sun_solid_angle_sr) || sun_solid_angle_sr <= 0 || sun_solid_angle_sr > 0.1) {
    throw Error("sun: solid angle " + std::to_string(sun_solid_angle_sr) +
                " sr is not a sun's (expected about 6.8e-5)");
  }
  if (!predicted_sun_dir_enu.allFinite() || predicted_sun_dir_enu.norm() < 1e-9) {
    throw Error("sun: the predicted sun direction is not a direction");
  }

  const double r_sun = std::acos(1 - sun_solid_angle_sr / (2 * kPi));  // angular radius, rad
  const double search = options.search_radius_deg * kDeg;
  const double disc = options.disc_radius_factor * r_sun;
  const double inner = options.annulus_inner_factor * r_sun;
  const double outer = options.annulus_outer_factor * r_sun;
  // Work in the camera frame.
  const Eigen::Vector3d pred = (pose.rotation.transpose() * predicted_sun_dir_enu).normalized();
  // Pixel access: radiance (3 channels), validity, centre ray, solid angle.
  auto pixel_radiance = [&](int x, int y, bool* good) {
    const size_t p = static_cast<size_t>(y) * k.width + x;
    bool ok = !(valid_mask && !valid_mask->empty() && (*valid_mask)[p] == 0);
    Eigen::Vector3d v;
    for (int ch = 0; ch < 3; ++ch) {
      const double val = hdr.data[p * hdr.channels + (hdr.channels == 1 ? 0 : ch)];
      const bool finite = std::isfinite(val) && val >= 0;
      v[ch] = finite ? val : 0.0;
      ok = ok && finite;
    }
    if (good) *good = ok;
    return v;
  };
  auto pixel_dir = [&](int x, int y) {
    return Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5)).normalized();
  };
  auto pixel_omega = [&](int x, int y) {
    const Eigen::Vector3d a = Unproject(k, Eigen::Vector2d(x, y)).normalized();
    const Eigen::Vector3d b = Unproject(k, Eigen::Vector2d(x + 1, y)).normalized();
    const Eigen::Vector3d c = Unproject(k, Eigen::Vector2d(x + 1, y + 1)).normalized();
    const Eigen::Vector3d d = Unproject(k, Eigen::Vector2d(x, y + 1)).normalized();
    return TriangleSolidAngle(a, b, c) + TriangleSolidAngle(a, c, d);
  };
  // Angular size of a pixel near pixel coordinates `at` (the smaller of the two axes).
  auto pixel_angle = [&](const Eigen::Vector2d& at) {
    const Eigen::Vector2d c(std::clamp(at.x(), 1.0, k.width - 1.0),
                            std::clamp(at.y(), 1.0, k.height - 1.0));
    const double ax =
        Angle(Unproject(k, c - Eigen::Vector2d(0.5, 0)), Unproject(k, c + Eigen::Vector2d(0.5, 0)));
    const double ay =
        Angle(Unproject(k, c - Eigen::Vector2d(0, 0.5)), Unproject(k, c + Eigen::Vector2d(0, 0.5)));
    const double a = std::min(ax, ay);
    if (!(a > 0) || !std::isfinite(a)) throw Error("sun: degenerate camera model near the sun");
    return a;
  };
  struct Box {
    int x0, y0, x1, y1;  // [x0, x1) x [y0, y1)
  };
  // Pixels within `radius` (rad) of the camera-frame direction `at`, with margin.
  auto box_around = [&](const Eigen::Vector3d& at, double radius) {
    const auto px = Project(k, at);
    if (!px || !px->allFinite()) {
      throw Error("sun: the sun direction is outside the camera's field of view");
    }
    const double half = std::min<double>(std::max(k.width, k.height),
                                         std::ceil(1.3 * radius / pixel_angle(*px)) + 2);
    Box b{std::max(0, static_cast<int>(std::floor(px->x() - half))),
          std::max(0, static_cast<int>(std::floor(px->y() - half))),
          std::min(k.width, static_cast<int>(std::ceil(px->x() + half))),
          std::min(k.height, static_cast<int>(std::ceil(px->y() + half)))};
    if (b.x0 >= b.x1 || b.y0 >= b.y1) throw Error("sun: the sun is outside the image");
    return b;
  };

  // Start: the brightest 3x3 neighbourhood of a lattice (spacing at most a third of the
  // disc radius, so some lattice point falls on the disc) within the search radius.
  const auto pred_px = Project(k, pred);
  if (!pred_px || !pred_px->allFinite()) {
    throw Error("sun: the predicted sun direction is outside the camera's field of view");
  }
  const int step = std::max(1, static_cast<int>(r_sun / pixel_angle(*pred_px) / 3));
  const Box sb = box_around(pred, search);
  const int lw = (sb.x1 - sb.x0 + step - 1) / step, lh = (sb.y1 - sb.y0 + step - 1) / step;
  std::vector<double> lum(static_cast<size_t>(lw) * lh, -1.0);  // -1: outside the search
  for (int j = 0; j < lh; ++j) {
    for (int i = 0; i < lw; ++i) {
      const int x = sb.x0 + i * step, y = sb.y0 + j * step;
      if (Angle(pixel_dir(x, y), pred) > search) continue;
      lum[static_cast<size_t>(j) * lw + i] = pixel_radiance(x, y, nullptr).mean();
    }
  }
  double best = -1;
  int best_x = 0, best_y = 0;
  for (int j = 0; j < lh; ++j) {
    for (int i = 0; i < lw; ++i) {
      if (lum[static_cast<size_t>(j) * lw + i] < 0) continue;
      double sum = 0;
      for (int dj = -1; dj <= 1; ++dj) {
        for (int di = -1; di <= 1; ++di) {
          const int ii = std::clamp(i + di, 0, lw - 1), jj = std::clamp(j + dj, 0, lh - 1);
          sum += std::max(0.0, lum[static_cast<size_t>(jj) * lw + ii]);
        }
      }
      if (sum > best) {
        best = sum;
        best_x = sb.x0 + i * step;
        best_y = sb.y0 + j * step;
      }
    }
  }
  if (best < 0) throw Error("sun: no pixel of the image lies within the search radius");

  // Background: per-channel median over the annulus, thinned to about 20000 pixels.
  Eigen::Vector3d bg = Eigen::Vector3d::Zero();
  int annulus_count = 0;
  auto background = [&](const Eigen::Vector3d& at) {
    const Box b = box_around(at, outer);
    const double area = static_cast<double>(b.x1 - b.x0) * (b.y1 - b.y0);
    const int t = std::max(1, static_cast<int>(std::sqrt(area / 40000.0)));
    std::vector<double> ch[3];
    for (int y = b.y0; y < b.y1; y += t) {
      for (int x = b.x0; x < b.x1; x += t) {
        const double a = Angle(pixel_dir(x, y), at);
        if (a < inner || a > outer) continue;
        bool good = false;
        const Eigen::Vector3d v = pixel_radiance(x, y, &good);
        if (!good) continue;
        for (int c3 = 0; c3 < 3; ++c3) ch[c3].push_back(v[c3]);
      }
    }
    annulus_count = static_cast<int>(ch[0].size());
    if (annulus_count < 8) {
      throw Error("sun: only " + std::to_string(annulus_count) +
                  " background pixels around the disc; is the sun at the image border?");
    }
    for (int c3 = 0; c3 < 3; ++c3) bg[c3] = Median(ch[c3]);
  };

  // Centroid of the background-subtracted brightness within the disc radius, iterated.
  Eigen::Vector3d centre = pixel_dir(best_x, best_y);
  for (int it = 0; it < options.centroid_iterations; ++it) {
    background(centre);
    const double bg_lum = bg.mean();
    const Box b = box_around(centre, disc);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double total = 0;
    for (int y = b.y0; y < b.y1; ++y) {
      for (int x = b.x0; x < b.x1; ++x) {
        const Eigen::Vector3d d = pixel_dir(x, y);
        if (Angle(d, centre) > disc) continue;
        const double wt = (pixel_radiance(x, y, nullptr).mean() - bg_lum) * pixel_omega(x, y);
        sum += wt * d;
        total += wt;
      }
    }
    if (!(total > 0) || !(sum.norm() > 0)) {
      throw Error("sun: no disc brighter than the sky near the predicted direction");
    }
    const Eigen::Vector3d next = sum.normalized();
    const double moved = Angle(next, centre);
    centre = next;
    if (moved < 1e-9) break;
  }
  if (Angle(centre, pred) > search + r_sun) {
    throw Error("sun: the disc found lies outside the search radius");
  }

  // §3.1: integrate radiance x solid angle over the disc, divide by the sun's solid angle.
  background(centre);
  SunMeasurement m;
  m.background = bg;
  m.annulus_pixels = annulus_count;
  Eigen::Vector3d integral = Eigen::Vector3d::Zero();
  const Box b = box_around(centre, disc);
  for (int y = b.y0; y < b.y1; ++y) {
    for (int x = b.x0; x < b.x1; ++x) {
      if (Angle(pixel_dir(x, y), centre) > disc) continue;
      if (x == 0 || y == 0 || x == k.width - 1 || y == k.height - 1) {
        throw Error("sun: the disc touches the image border");
      }
      bool good = false;
      const Eigen::Vector3d v = pixel_radiance(x, y, &good);
      integral += (v - bg) * pixel_omega(x, y);
      ++m.disc_pixels;
      if (!good) m.any_invalid = true;
    }
  }
  if (m.disc_pixels == 0) throw Error("sun: the disc covers no pixel centre");
  m.radiance = integral / sun_solid_angle_sr;
  m.direction_enu = (pose.rotation * centre).normalized();
  m.offset_deg = Angle(m.direction_enu, predicted_sun_dir_enu.normalized()) / kDeg;
  if (!m.radiance.allFinite() || !m.direction_enu.allFinite()) {
    throw Error("sun: the measurement is not finite");
  }
  return m;
}

}  // namespace rouen
