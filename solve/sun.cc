#include "solve/sun.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
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

std::string Deg(double rad) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", rad / kDeg);
  return buf;
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
  // A disc smaller than a pixel lies within 0.71 pixel (half a diagonal) of some pixel centre.
  if (!std::isfinite(disc_min_pixels) || disc_min_pixels < 1 || disc_min_pixels > 100) {
    throw Error("SunOptions: disc_min_pixels must be in [1, 100], got " +
                std::to_string(disc_min_pixels));
  }
  if (!std::isfinite(annulus_inner_min_pixels) || !std::isfinite(annulus_outer_min_pixels) ||
      annulus_inner_min_pixels < 0 || annulus_outer_min_pixels < annulus_inner_min_pixels + 1 ||
      annulus_outer_min_pixels > 200) {
    throw Error(
        "SunOptions: need 0 <= annulus_inner_min_pixels and annulus_inner_min_pixels + 1 <= "
        "annulus_outer_min_pixels <= 200");
  }
  if (!std::isfinite(clip_radiance) || clip_radiance < 0) {
    throw Error("SunOptions: clip_radiance must be 0 (off) or positive, got " +
                std::to_string(clip_radiance));
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
  // Equirect columns wrap around (column -1 is column width - 1); other models have borders.
  const bool equirect = k.projection == Projection::kEquirect;
  auto wrap_x = [&](int x) { return equirect ? ((x % k.width) + k.width) % k.width : x; };
  // Work in the camera frame.
  const Eigen::Vector3d pred = (pose.rotation.transpose() * predicted_sun_dir_enu).normalized();
  // Pixel access: radiance (3 channels), validity, centre ray, solid angle.
  const double clip = options.clip_radiance;
  auto pixel_radiance = [&](int x, int y, bool* good) {
    const size_t p = static_cast<size_t>(y) * k.width + x;
    bool ok = !(valid_mask && !valid_mask->empty() && (*valid_mask)[p] == 0);
    Eigen::Vector3d v;
    for (int ch = 0; ch < 3; ++ch) {
      const double val = hdr.data[p * hdr.channels + (hdr.channels == 1 ? 0 : ch)];
      const bool finite = std::isfinite(val) && val >= 0;
      v[ch] = finite ? val : 0.0;
      // At the clip value itself (within float rounding), not merely near it: a float frame's
      // rim pixel may read 65499.5 (the next half below 65504 is 65472).
      ok = ok && finite && !(clip > 0 && std::abs(val - clip) <= 1e-6 * clip);
    }
    if (good) *good = ok;
    return v;
  };
  auto pixel_dir = [&](int x, int y) {
    return Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5)).normalized();
  };
  auto pixel_omega = [&](int x, int y) {
    if (equirect) {  // exact: a band of latitude times a range of azimuth
      const double el0 = 0.5 * kPi - y * kPi / k.height;
      const double el1 = 0.5 * kPi - (y + 1) * kPi / k.height;
      return 2 * kPi / k.width * (std::sin(el0) - std::sin(el1));
    }
    const Eigen::Vector3d a = Unproject(k, Eigen::Vector2d(x, y)).normalized();
    const Eigen::Vector3d b = Unproject(k, Eigen::Vector2d(x + 1, y)).normalized();
    const Eigen::Vector3d c = Unproject(k, Eigen::Vector2d(x + 1, y + 1)).normalized();
    const Eigen::Vector3d d = Unproject(k, Eigen::Vector2d(x, y + 1)).normalized();
    return TriangleSolidAngle(a, b, c) + TriangleSolidAngle(a, c, d);
  };
  // Angular sizes of a pixel's two sides near pixel coordinates `at` (x: across columns).
  auto pixel_sides = [&](const Eigen::Vector2d& at) {
    const Eigen::Vector2d c(std::clamp(at.x(), 1.0, k.width - 1.0),
                            std::clamp(at.y(), 1.0, k.height - 1.0));
    const double ax =
        Angle(Unproject(k, c - Eigen::Vector2d(0.5, 0)), Unproject(k, c + Eigen::Vector2d(0.5, 0)));
    const double ay =
        Angle(Unproject(k, c - Eigen::Vector2d(0, 0.5)), Unproject(k, c + Eigen::Vector2d(0, 0.5)));
    if (!(std::min(ax, ay) > 0) || !std::isfinite(ax) || !std::isfinite(ay)) {
      throw Error("sun: degenerate camera model near the sun");
    }
    return Eigen::Vector2d(ax, ay);
  };
  // The smaller side (lattice spacing, box sizes) and the larger one (window floors).
  auto pixel_angle = [&](const Eigen::Vector2d& at) { return pixel_sides(at).minCoeff(); };
  auto pixel_footprint = [&](const Eigen::Vector2d& at) { return pixel_sides(at).maxCoeff(); };
  auto project = [&](const Eigen::Vector3d& at, const char* what) {
    const auto px = Project(k, at);
    if (!px || !px->allFinite()) {
      throw Error(std::string("sun: ") + what + " is outside the camera's field of view");
    }
    return *px;
  };

  // Window radii (rad) around a camera-frame direction: disc, annulus inner and outer.
  struct Windows {
    double disc, inner, outer, pixel;
  };
  auto windows_at = [&](const Eigen::Vector3d& at) {
    Windows w;
    w.pixel = pixel_footprint(project(at, "the sun direction"));
    w.disc = std::max(options.disc_radius_factor * r_sun, options.disc_min_pixels * w.pixel);
    w.inner = std::max(options.annulus_inner_factor * r_sun,
                       w.disc + options.annulus_inner_min_pixels * w.pixel);
    w.outer = std::max(options.annulus_outer_factor * r_sun,
                       w.disc + options.annulus_outer_min_pixels * w.pixel);
    return w;
  };

  struct Box {
    int x0, y0, x1, y1;  // [x0, x1) x [y0, y1); equirect x wraps (wrap_x)
  };
  // Pixels whose centres may lie within `radius` (rad) of the camera-frame direction `at`.
  auto box_around = [&](const Eigen::Vector3d& at, double radius) {
    const Eigen::Vector2d px = project(at, "the sun direction");
    if (equirect) {
      // Rows of the elevation band, columns of the widest azimuth span within it (all of them
      // when the band reaches a pole).
      const double el = std::asin(std::clamp(-at.y() / at.norm(), -1.0, 1.0));
      const double top = el + radius, bottom = el - radius;
      Box b;
      b.y0 = std::max(0, static_cast<int>(std::floor((0.5 * kPi - top) / kPi * k.height)) - 1);
      b.y1 = std::min(k.height,
                      static_cast<int>(std::ceil((0.5 * kPi - bottom) / kPi * k.height)) + 1);
      const double max_abs_el = std::max(std::abs(top), std::abs(bottom));
      int half = k.width;
      if (max_abs_el < 0.5 * kPi) {
        const double s = std::sin(radius) / std::cos(max_abs_el);
        if (s < 1) half = static_cast<int>(std::ceil(std::asin(s) / (2 * kPi) * k.width)) + 2;
      }
      if (2 * half + 1 >= k.width) {
        b.x0 = 0;
        b.x1 = k.width;
      } else {
        const int cx = static_cast<int>(std::floor(px.x()));
        b.x0 = cx - half;
        b.x1 = cx + half + 1;
      }
      if (b.y0 >= b.y1) throw Error("sun: the sun is outside the image");
      return b;
    }
    const double half = std::min<double>(std::max(k.width, k.height),
                                         std::ceil(1.3 * radius / pixel_angle(px)) + 2);
    Box b{std::max(0, static_cast<int>(std::floor(px.x() - half))),
          std::max(0, static_cast<int>(std::floor(px.y() - half))),
          std::min(k.width, static_cast<int>(std::ceil(px.x() + half))),
          std::min(k.height, static_cast<int>(std::ceil(px.y() + half)))};
    if (b.x0 >= b.x1 || b.y0 >= b.y1) throw Error("sun: the sun is outside the image");
    return b;
  };

  // Start: the brightest 3x3 neighbourhood of a lattice (spacing at most a third of the
  // disc radius, so some lattice point falls on the disc) within the search radius.
  const Eigen::Vector2d pred_px = project(pred, "the predicted sun direction");
  const int step = std::max(1, static_cast<int>(r_sun / pixel_angle(pred_px) / 3));
  const Box sb = box_around(pred, search);
  const int lw = (sb.x1 - sb.x0 + step - 1) / step, lh = (sb.y1 - sb.y0 + step - 1) / step;
  std::vector<double> lum(static_cast<size_t>(lw) * lh, -1.0);  // -1: outside the search
  for (int j = 0; j < lh; ++j) {
    for (int i = 0; i < lw; ++i) {
      const int x = wrap_x(sb.x0 + i * step), y = sb.y0 + j * step;
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
        best_x = wrap_x(sb.x0 + i * step);
        best_y = sb.y0 + j * step;
      }
    }
  }
  if (best < 0) throw Error("sun: no pixel of the image lies within the search radius");

  // Background: per-channel median over the annulus, thinned to about 20000 pixels, and its
  // robust spread (1.4826 x median absolute deviation).
  Eigen::Vector3d bg = Eigen::Vector3d::Zero(), bg_spread = Eigen::Vector3d::Zero();
  int annulus_count = 0;
  auto background = [&](const Eigen::Vector3d& at, const Windows& w) {
    const Box b = box_around(at, w.outer);
    const double area = static_cast<double>(b.x1 - b.x0) * (b.y1 - b.y0);
    const int t = std::max(1, static_cast<int>(std::sqrt(area / 40000.0)));
    std::vector<double> ch[3];
    for (int y = b.y0; y < b.y1; y += t) {
      for (int xi = b.x0; xi < b.x1; xi += t) {
        const int x = wrap_x(xi);
        const double a = Angle(pixel_dir(x, y), at);
        if (a < w.inner || a > w.outer) continue;
        bool good = false;
        const Eigen::Vector3d v = pixel_radiance(x, y, &good);
        if (!good) continue;
        for (int c3 = 0; c3 < 3; ++c3) ch[c3].push_back(v[c3]);
      }
    }
    annulus_count = static_cast<int>(ch[0].size());
    if (annulus_count < 8) {
      throw Error("sun: only " + std::to_string(annulus_count) +
                  " valid background pixels in the annulus " + Deg(w.inner) + " to " +
                  Deg(w.outer) + " deg around the disc; is the sun at the image border?");
    }
    for (int c3 = 0; c3 < 3; ++c3) {
      bg[c3] = Median(ch[c3]);
      for (double& v : ch[c3]) v = std::abs(v - bg[c3]);
      bg_spread[c3] = 1.4826 * Median(ch[c3]);
    }
  };

  // Centroid of the background-subtracted brightness within the disc window, iterated.
  Eigen::Vector3d centre = pixel_dir(best_x, best_y);
  for (int it = 0; it < options.centroid_iterations; ++it) {
    const Windows w = windows_at(centre);
    background(centre, w);
    const double bg_lum = bg.mean();
    const Box b = box_around(centre, w.disc);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double total = 0;
    for (int y = b.y0; y < b.y1; ++y) {
      for (int xi = b.x0; xi < b.x1; ++xi) {
        const int x = wrap_x(xi);
        const Eigen::Vector3d d = pixel_dir(x, y);
        if (Angle(d, centre) > w.disc) continue;
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
  // The window is at least disc_min_pixels wide, so a disc smaller than a pixel, whose pixel
  // holds disc radiance x sun solid angle / pixel solid angle, adds up to the same energy.
  const Windows w = windows_at(centre);
  background(centre, w);
  SunMeasurement m;
  m.background = bg;
  m.annulus_pixels = annulus_count;
  m.window_radius_deg = w.disc / kDeg;
  m.pixel_deg = w.pixel / kDeg;
  Eigen::Vector3d integral = Eigen::Vector3d::Zero();
  double window_omega = 0;
  const Box b = box_around(centre, w.disc);
  for (int y = b.y0; y < b.y1; ++y) {
    for (int xi = b.x0; xi < b.x1; ++xi) {
      const int x = wrap_x(xi);
      if (Angle(pixel_dir(x, y), centre) > w.disc) continue;
      if (!equirect && (x == 0 || y == 0 || x == k.width - 1 || y == k.height - 1)) {
        throw Error("sun: the disc (window " + Deg(w.disc) + " deg) touches the image border");
      }
      bool good = false;
      const Eigen::Vector3d v = pixel_radiance(x, y, &good);
      const double omega = pixel_omega(x, y);
      integral += (v - bg) * omega;
      window_omega += omega;
      ++m.disc_pixels;
      if (!good) m.any_invalid = true;
    }
  }
  if (m.disc_pixels == 0) throw Error("sun: the disc covers no pixel centre");
  m.radiance = integral / sun_solid_angle_sr;
  for (int c = 0; c < 3; ++c) {
    m.radiance_uncertainty[c] = integral[c] > 0 ? bg_spread[c] * window_omega / integral[c]
                                                : std::numeric_limits<double>::infinity();
  }
  m.direction_enu = (pose.rotation * centre).normalized();
  m.offset_deg = Angle(m.direction_enu, predicted_sun_dir_enu.normalized()) / kDeg;
  if (!m.radiance.allFinite() || !m.direction_enu.allFinite()) {
    throw Error("sun: the measurement is not finite");
  }
  return m;
}

}  // namespace rouen
