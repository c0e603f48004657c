#include "calib/sky_orientation.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
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

std::string Fmt(const char* f, double a) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, a);
  return buf;
}

std::string Px(double x, double y) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "(%.1f, %.1f)", x, y);
  return buf;
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) / kDeg;
}

// Any unit vector perpendicular to `v`.
Eigen::Vector3d Perpendicular(const Eigen::Vector3d& v) {
  Eigen::Vector3d a = std::abs(v.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return v.cross(a).normalized();
}

// The sun's radius in pixels where the ray `ray` meets the image: mean distance of the
// projections of four rays `radius_rad` away from it.
double ProjectedRadiusPx(const Intrinsics& k, const Eigen::Vector3d& ray, double radius_rad) {
  const auto c = Project(k, ray);
  if (!c) return 0;
  const Eigen::Vector3d u = Perpendicular(ray), v = ray.cross(u);
  double sum = 0;
  int n = 0;
  for (int i = 0; i < 4; ++i) {
    const double a = i * 0.5 * kPi;
    const Eigen::Vector3d d =
        std::cos(radius_rad) * ray + std::sin(radius_rad) * (std::cos(a) * u + std::sin(a) * v);
    const auto p = Project(k, d);
    if (!p) continue;
    sum += (*p - *c).norm();
    ++n;
  }
  return n ? sum / n : 0;
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d ExpSo3(const Eigen::Vector3d& w) {
  const double t = w.norm();
  if (t < 1e-15) return Eigen::Matrix3d::Identity() + Skew(w);
  return Eigen::AngleAxisd(t, w / t).toRotationMatrix();
}

// Rotation frame from two non-parallel unit vectors: columns a, (a x b)^, a x (a x b)^.
Eigen::Matrix3d Triad(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  Eigen::Matrix3d m;
  const Eigen::Vector3d n = a.cross(b).normalized();
  m.col(0) = a;
  m.col(1) = n;
  m.col(2) = a.cross(n);
  return m;
}

struct DirConstraint {
  Eigen::Vector3d cam, world;
  double sigma_rad;
};
struct PlaneConstraint {  // world elevation of the camera ray `cam` is zero
  Eigen::Vector3d cam;
  double sigma_rad;
};

// Weighted squared residuals; also the normal equations when asked.
double Cost(const Eigen::Matrix3d& r, const std::vector<DirConstraint>& dirs,
            const std::vector<PlaneConstraint>& planes, Eigen::Matrix3d* jtj = nullptr,
            Eigen::Vector3d* jtr = nullptr) {
  double cost = 0;
  if (jtj) jtj->setZero();
  if (jtr) jtr->setZero();
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  for (const DirConstraint& d : dirs) {
    const Eigen::Vector3d v = r * d.cam;
    const Eigen::Vector3d res = (v - d.world) / d.sigma_rad;
    cost += res.squaredNorm();
    if (jtj) {
      const Eigen::Matrix3d j = -Skew(v) / d.sigma_rad;  // d(exp(w) v)/dw = -[v]x
      *jtj += j.transpose() * j;
      *jtr += j.transpose() * res;
    }
  }
  for (const PlaneConstraint& p : planes) {
    const Eigen::Vector3d v = r * p.cam;
    const double res = z.dot(v) / p.sigma_rad;
    cost += res * res;
    if (jtj) {
      const Eigen::Vector3d j = v.cross(z) / p.sigma_rad;
      *jtj += j * j.transpose();
      *jtr += j * res;
    }
  }
  return cost;
}

// Levenberg-Marquardt on R <- exp(w) R.
Eigen::Matrix3d Refine(Eigen::Matrix3d r, const std::vector<DirConstraint>& dirs,
                       const std::vector<PlaneConstraint>& planes) {
  double lambda = 1e-6;
  double cost = Cost(r, dirs, planes);
  for (int it = 0; it < 100; ++it) {
    Eigen::Matrix3d jtj;
    Eigen::Vector3d jtr;
    Cost(r, dirs, planes, &jtj, &jtr);
    bool improved = false;
    for (int tries = 0; tries < 20 && !improved; ++tries) {
      Eigen::Matrix3d a = jtj;
      a.diagonal() += lambda * (jtj.diagonal().array() + 1e-12).matrix();
      const Eigen::Vector3d step = -a.fullPivLu().solve(jtr);
      if (!step.allFinite()) break;
      const Eigen::Matrix3d cand = ExpSo3(step) * r;
      const double c = Cost(cand, dirs, planes);
      if (c <= cost) {
        improved = true;
        const bool converged = step.norm() < 1e-13 || cost - c < 1e-15 * (1 + cost);
        r = cand;
        cost = c;
        lambda = std::max(lambda * 0.1, 1e-12);
        if (converged) return r;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
  }
  return r;
}

}  // namespace

void SunDiscOptions::Validate() const {
  auto bad = [](const std::string& m) { throw Error("sun disc options: " + m); };
  if (!(sun_radius_deg > 0 && sun_radius_deg < 10)) bad("sun_radius_deg must be in (0, 10)");
  if (!(min_contrast > 1)) bad("min_contrast must be > 1");
  if (!(core_fraction > 0 && core_fraction < 1)) bad("core_fraction must be in (0, 1)");
  if (!(rim_fraction >= 0 && rim_fraction < core_fraction)) {
    bad("rim_fraction must be in [0, core_fraction)");
  }
  if (!(max_size_ratio >= 1)) bad("max_size_ratio must be >= 1");
  if (!std::isfinite(saturation)) bad("saturation must be finite");
  if (!(second_blob_fraction > 0 && second_blob_fraction <= 1)) {
    bad("second_blob_fraction must be in (0, 1]");
  }
}

void OrientOptions::Validate() const {
  auto bad = [](const std::string& m) { throw Error("orientation options: " + m); };
  if (!(level_sigma_deg > 0 && std::isfinite(level_sigma_deg))) bad("level_sigma_deg must be > 0");
  if (!(min_separation_deg >= 0 && min_separation_deg < 90)) {
    bad("min_separation_deg must be in [0, 90)");
  }
  if (!(max_residual_sigma > 0)) bad("max_residual_sigma must be > 0");
}

SunDisc DetectSunDisc(const Image& image, const Intrinsics& k, const SunDiscOptions& o,
                      const std::string& what) {
  o.Validate();
  k.Validate();
  if (image.empty() || image.channels < 1) throw Error(what + ": empty image");
  if (image.width != k.width || image.height != k.height) {
    throw Error(what + ": image is " + std::to_string(image.width) + "x" +
                std::to_string(image.height) + " but the lens is " + std::to_string(k.width) + "x" +
                std::to_string(k.height));
  }
  const int w = image.width, h = image.height, nc = image.channels;
  const size_t n = static_cast<size_t>(w) * h;
  // Luminance (Rec. 709 for RGB), non-finite and negative values as 0.
  std::vector<float> lum(n);
  std::vector<float> chmax(n);
  for (size_t i = 0; i < n; ++i) {
    const float* p = &image.data[i * nc];
    float l = nc >= 3 ? 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2] : p[0];
    float m = p[0];
    for (int c = 1; c < nc; ++c) m = std::max(m, p[c]);
    if (!std::isfinite(l) || l < 0) l = 0;
    lum[i] = l;
    chmax[i] = std::isfinite(m) ? m : 0;
  }
  const double saturation =
      o.saturation > 0
          ? o.saturation
          : (image.units == PixelUnits::kDigital ? 254.5 : std::numeric_limits<double>::infinity());
  // Global median from a subsample (at most ~1M values).
  std::vector<float> sub;
  const size_t stride = std::max<size_t>(1, n / 1000000);
  for (size_t i = 0; i < n; i += stride) sub.push_back(lum[i]);
  const double median = Median(std::move(sub));
  const size_t ipeak = std::max_element(lum.begin(), lum.end()) - lum.begin();
  const double peak = lum[ipeak];
  const int px = static_cast<int>(ipeak % w), py = static_cast<int>(ipeak / w);
  if (!(peak > 0) || !(peak > o.min_contrast * median)) {
    throw Error(what + ": no sun disc: the brightest pixel " + Px(px + 0.5, py + 0.5) + " is " +
                Fmt("%.3g", median > 0 ? peak / median : 0) + " times the median (need > " +
                Fmt("%.3g", o.min_contrast) + ")");
  }
  const Eigen::Vector3d ray0 = Unproject(k, Eigen::Vector2d(px + 0.5, py + 0.5));
  double r_exp = ProjectedRadiusPx(k, ray0, o.sun_radius_deg * kDeg);
  if (!(r_exp > 0)) {
    throw Error(what + ": the brightest pixel " + Px(px + 0.5, py + 0.5) +
                " is outside the lens's field of view");
  }
  // Core blob: 8-connected pixels above the core threshold around the peak.
  const double t_core = median + o.core_fraction * (peak - median);
  const double r_max = o.max_size_ratio * r_exp + 1.5;
  const size_t max_core = static_cast<size_t>(kPi * r_max * r_max) + 16;
  std::vector<uint8_t> in_core(n, 0);
  std::vector<size_t> stack = {ipeak}, core;
  in_core[ipeak] = 1;
  int x0 = px, x1 = px, y0 = py, y1 = py;
  bool clipped = false;
  while (!stack.empty()) {
    const size_t i = stack.back();
    stack.pop_back();
    core.push_back(i);
    const int x = static_cast<int>(i % w), y = static_cast<int>(i / w);
    x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    if (chmax[i] >= saturation) clipped = true;
    if (core.size() > 4 * max_core) break;  // clearly too large; stop flooding
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = x + dx, yy = y + dy;
        if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
        const size_t j = static_cast<size_t>(yy) * w + xx;
        if (in_core[j] || lum[j] < t_core) continue;
        in_core[j] = 1;
        stack.push_back(j);
      }
    }
  }
  const double r_eq = std::sqrt(core.size() / kPi);
  if (core.size() > max_core) {
    throw Error(what + ": the brightest blob at " + Px(px + 0.5, py + 0.5) + " has radius " +
                Fmt("%.1f", r_eq) + (core.size() > 4 * max_core ? "+" : "") +
                " px but the sun's disc is " + Fmt("%.2f", r_exp) +
                " px for this lens: flare or a clipped sun (use an ND frame or a shorter "
                "exposure)");
  }
  if (x0 == 0 || y0 == 0 || x1 == w - 1 || y1 == h - 1) {
    throw Error(what + ": the sun's disc at " + Px(px + 0.5, py + 0.5) +
                " touches the image edge; its centroid would be biased");
  }
  if (clipped) {
    throw Error(what + ": the sun's disc at " + Px(px + 0.5, py + 0.5) + " is clipped (values >= " +
                Fmt("%.4g", saturation) + "); use an ND frame or a shorter exposure");
  }
  if (r_exp > 3 && r_eq < 0.3 * r_exp) {
    throw Error(what + ": the brightest blob at " + Px(px + 0.5, py + 0.5) + " has radius " +
                Fmt("%.2f", r_eq) + " px, much smaller than the sun's " + Fmt("%.1f", r_exp) +
                " px (a hot pixel?)");
  }
  // Another comparable compact blob further away: ambiguous.
  {
    const double t2 = median + o.second_blob_fraction * (peak - median);
    const double far = std::max({4.0 * r_exp, 3.0 * r_eq, 5.0});
    const double cxp = 0.5 * (x0 + x1 + 1), cyp = 0.5 * (y0 + y1 + 1);
    for (size_t i = 0; i < n; ++i) {
      if (lum[i] < t2) continue;
      const double x = i % w + 0.5, y = static_cast<double>(i / w) + 0.5;
      if (std::hypot(x - cxp, y - cyp) > far + r_eq) {
        throw Error(what + ": two bright blobs, at " + Px(cxp, cyp) + " and " + Px(x, y) +
                    " (a reflection or a second light?); cannot tell which is the sun");
      }
    }
  }
  // Centroid window around the core and a background ring around it.
  const int m = static_cast<int>(std::ceil(r_exp)) + 3;
  const int wx0 = std::max(0, x0 - m), wx1 = std::min(w - 1, x1 + m);
  const int wy0 = std::max(0, y0 - m), wy1 = std::min(h - 1, y1 + m);
  const int rx0 = std::max(0, wx0 - 3), rx1 = std::min(w - 1, wx1 + 3);
  const int ry0 = std::max(0, wy0 - 3), ry1 = std::min(h - 1, wy1 + 3);
  std::vector<float> ring;
  for (int y = ry0; y <= ry1; ++y) {
    for (int x = rx0; x <= rx1; ++x) {
      if (x >= wx0 && x <= wx1 && y >= wy0 && y <= wy1) continue;
      ring.push_back(lum[static_cast<size_t>(y) * w + x]);
    }
  }
  const double bg = ring.empty() ? median : Median(ring);
  std::vector<float> dev;
  for (float v : ring) dev.push_back(std::abs(v - static_cast<float>(bg)));
  const double noise = 1.4826 * Median(dev);
  const double t_rim = bg + std::max(o.rim_fraction * (peak - bg), 4 * noise);
  double sw = 0, sx = 0, sy = 0;
  for (int y = wy0; y <= wy1; ++y) {
    for (int x = wx0; x <= wx1; ++x) {
      const double l = lum[static_cast<size_t>(y) * w + x];
      if (l <= t_rim) continue;
      const double wt = l - bg;
      sw += wt;
      sx += wt * (x + 0.5);
      sy += wt * (y + 0.5);
    }
  }
  SunDisc d;
  d.pixel = Eigen::Vector2d(sx / sw, sy / sw);
  double vx = 0, vy = 0;
  for (int y = wy0; y <= wy1; ++y) {
    for (int x = wx0; x <= wx1; ++x) {
      if (lum[static_cast<size_t>(y) * w + x] <= t_rim) continue;
      vx += std::pow(x + 0.5 - d.pixel.x(), 2);
      vy += std::pow(y + 0.5 - d.pixel.y(), 2);
    }
  }
  const double var = std::max(vx, vy) * noise * noise / (sw * sw);
  d.ray_cam = Unproject(k, d.pixel);
  d.peak = peak;
  d.background = bg;
  d.core_pixels = static_cast<int>(core.size());
  d.radius_px = r_eq;
  d.expected_radius_px = ProjectedRadiusPx(k, d.ray_cam, o.sun_radius_deg * kDeg);
  if (!(d.expected_radius_px > 0)) d.expected_radius_px = r_exp;
  d.sigma_px = std::sqrt(var + 0.02 * 0.02);
  d.sigma_deg = d.sigma_px * o.sun_radius_deg / d.expected_radius_px;
  return d;
}

double RotationAngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const Eigen::AngleAxisd aa(Eigen::Matrix3d(a.transpose() * b));
  return std::abs(aa.angle()) / kDeg;
}

SkyOrientation OrientFromSun(const Intrinsics& k, const Eigen::Vector3d& sun_ray_cam,
                             double sun_sigma_deg, const Eigen::Vector3d& sun_dir_world,
                             const std::vector<SkyLandmark>& landmarks,
                             const std::vector<HorizonPoint>& horizon, const OrientOptions& o) {
  o.Validate();
  k.Validate();
  if (!sun_ray_cam.allFinite() || !(sun_ray_cam.norm() > 0)) {
    throw Error("orientation: the sun's camera ray is not a direction");
  }
  if (!sun_dir_world.allFinite() || !(sun_dir_world.norm() > 0)) {
    throw Error("orientation: the sun's world direction is not a direction");
  }
  if (!(sun_sigma_deg > 0) || !std::isfinite(sun_sigma_deg)) {
    throw Error("orientation: the sun's sigma must be positive degrees");
  }
  if (landmarks.empty() && horizon.empty() && !o.level) {
    throw Error(
        "orientation: the sun alone leaves the roll about the sun axis free; give a landmark, "
        "horizon points or assume a level camera");
  }
  const Eigen::Vector3d cs = sun_ray_cam.normalized(), ws = sun_dir_world.normalized();
  std::vector<DirConstraint> dirs = {{cs, ws, sun_sigma_deg * kDeg}};
  for (size_t i = 0; i < landmarks.size(); ++i) {
    const SkyLandmark& l = landmarks[i];
    const std::string name = "orientation: landmark " + std::to_string(i + 1);
    if (!l.pixel.allFinite() || !l.world_dir.allFinite() || !(l.world_dir.norm() > 0)) {
      throw Error(name + ": pixel or world direction is not finite");
    }
    if (!(l.sigma_deg > 0)) throw Error(name + ": sigma must be positive degrees");
    const Eigen::Vector3d c = Unproject(k, l.pixel), wd = l.world_dir.normalized();
    const double sep_cam = AngleDeg(c, cs), sep_world = AngleDeg(wd, ws);
    const double sep = std::min({sep_cam, 180 - sep_cam, sep_world, 180 - sep_world});
    if (sep < o.min_separation_deg) {
      throw Error(name + " is " + Fmt("%.2f", std::min(sep_cam, sep_world)) +
                  " deg from the sun (or its opposite): nearly parallel to the sun axis, it "
                  "cannot fix the roll about it (need >= " +
                  Fmt("%.1f", o.min_separation_deg) + " deg)");
    }
    dirs.push_back({c, wd, l.sigma_deg * kDeg});
  }
  std::vector<PlaneConstraint> planes;
  for (size_t i = 0; i < horizon.size(); ++i) {
    if (!horizon[i].pixel.allFinite() || !(horizon[i].sigma_deg > 0)) {
      throw Error("orientation: horizon point " + std::to_string(i + 1) +
                  ": pixel not finite or sigma not positive");
    }
    planes.push_back({Unproject(k, horizon[i].pixel), horizon[i].sigma_deg * kDeg});
  }
  if (o.level) planes.push_back({Eigen::Vector3d::UnitX(), o.level_sigma_deg * kDeg});

  SkyOrientation out;
  Eigen::Matrix3d best;
  if (dirs.size() >= 2) {
    // Closed form: the sun exactly, the first landmark fixes the roll (TRIAD).
    best = Triad(ws, dirs[1].world) * Triad(cs, dirs[1].cam).transpose();
    best = Refine(best, dirs, planes);
  } else {
    // Horizon or level only: scan the roll about the sun axis, refine each local minimum.
    const Eigen::Matrix3d r0 = Eigen::Quaterniond::FromTwoVectors(cs, ws).toRotationMatrix();
    constexpr int kSteps = 720;
    std::vector<double> cost(kSteps);
    for (int i = 0; i < kSteps; ++i) {
      const Eigen::Matrix3d r = Eigen::AngleAxisd(2 * kPi * i / kSteps, ws).toRotationMatrix() * r0;
      cost[i] = Cost(r, dirs, planes);
    }
    struct Cand {
      Eigen::Matrix3d r;
      double cost;
    };
    std::vector<Cand> cands;
    for (int i = 0; i < kSteps; ++i) {
      const double a = cost[(i + kSteps - 1) % kSteps], b = cost[(i + 1) % kSteps];
      if (cost[i] <= a && cost[i] < b) {
        const Eigen::Matrix3d r = Refine(
            Eigen::AngleAxisd(2 * kPi * i / kSteps, ws).toRotationMatrix() * r0, dirs, planes);
        cands.push_back({r, Cost(r, dirs, planes)});
      }
    }
    if (cands.empty()) throw Error("orientation: no roll about the sun axis fits the horizon");
    std::sort(cands.begin(), cands.end(),
              [](const Cand& a, const Cand& b) { return a.cost < b.cost; });
    best = cands[0].r;
    // A second, clearly different solution that fits about as well: choose the upright one.
    for (size_t i = 1; i < cands.size(); ++i) {
      if (RotationAngleDeg(cands[i].r, cands[0].r) < 1.0) continue;
      if (cands[i].cost > 4 * cands[0].cost + 1) continue;
      out.had_mirror_solution = true;
      auto upright = [](const Eigen::Matrix3d& r) { return -r(2, 1) + r(2, 2); };
      if (upright(cands[i].r) > upright(best)) best = cands[i].r;
    }
  }
  // Uncertainty from the normal equations.
  Eigen::Matrix3d jtj;
  Eigen::Vector3d jtr;
  Cost(best, dirs, planes, &jtj, &jtr);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(jtj);
  const double min_eig = es.eigenvalues()(0);
  const double sigma_deg = min_eig > 0 ? 1 / std::sqrt(min_eig) / kDeg : 1e9;
  if (!(sigma_deg < 20)) {
    throw Error(
        "orientation: the constraints do not fix the roll about the sun axis (rotation "
        "uncertainty " +
        Fmt("%.3g", sigma_deg) + " deg); give a landmark or horizon points away from the sun");
  }
  out.pose.rotation = best;
  out.rotation_sigma_deg = sigma_deg;
  out.sun_residual_deg = AngleDeg(best * cs, ws);
  for (size_t i = 1; i < dirs.size(); ++i) {
    const double r = AngleDeg(best * dirs[i].cam, dirs[i].world);
    out.landmark_residual_deg.push_back(r);
    if (r * kDeg > o.max_residual_sigma * dirs[i].sigma_rad) {
      throw Error("orientation: landmark " + std::to_string(i) + " disagrees with the sun by " +
                  Fmt("%.2f", r) + " deg (sigma " + Fmt("%.2f", dirs[i].sigma_rad / kDeg) +
                  " deg): check its pixel and direction, the time and the site");
    }
  }
  for (size_t i = 0; i < planes.size(); ++i) {
    const double el = std::asin(std::clamp((best * planes[i].cam).z(), -1.0, 1.0)) / kDeg;
    const bool is_level = o.level && i + 1 == planes.size();
    if (is_level) {
      out.level_residual_deg = el;
    } else {
      out.horizon_residual_deg.push_back(el);
    }
    if (std::abs(el) * kDeg > o.max_residual_sigma * planes[i].sigma_rad) {
      throw Error(std::string("orientation: ") +
                  (is_level ? "the level assumption" : "horizon point " + std::to_string(i + 1)) +
                  " disagrees with the sun by " + Fmt("%.2f", el) + " deg (sigma " +
                  Fmt("%.2f", planes[i].sigma_rad / kDeg) + " deg)");
    }
  }
  if (out.sun_residual_deg * kDeg > o.max_residual_sigma * dirs[0].sigma_rad) {
    throw Error("orientation: the constraints disagree with the sun by " +
                Fmt("%.2f", out.sun_residual_deg) + " deg");
  }
  return out;
}

}  // namespace rouen
