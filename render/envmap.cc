#include "render/envmap.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/error.h"
#include "core/mesh.h"
#include "solve/grid.h"
#include "solve/raycast.h"

namespace rouen {
namespace {

// Elevation (radians) of the horizontal line `row` (continuous; 0 the top edge).
double RowElevation(int height, double row) { return kPi / 2 - kPi * row / height; }
double ElevationRow(int height, double el) { return (kPi / 2 - el) / kPi * height; }

// Sorted cut points strictly inside (lo, hi), plus lo and hi.
std::vector<double> Cuts(double lo, double hi, const std::vector<double>& lines) {
  std::vector<double> c = {lo};
  for (double x : lines)
    if (x > lo + 1e-12 && x < hi - 1e-12) c.push_back(x);
  c.push_back(hi);
  std::sort(c.begin(), c.end());
  return c;
}

void CheckLighting(const Lighting& l) {
  if (!l.sun_dir.allFinite() || std::abs(l.sun_dir.norm() - 1) > 1e-3)
    throw Error("envmap: the sun direction is not a unit vector");
  if (!l.sun_radiance.allFinite() || l.sun_radiance.minCoeff() < 0 ||
      !(l.sun_solid_angle_sr >= 0 && l.sun_solid_angle_sr < 1))
    throw Error("envmap: the sun's radiance must be finite and >= 0, its solid angle in [0, 1) sr");
  if (l.use_env) l.env.Validate();
}

}  // namespace

void LatLongOptions::Validate() const {
  if (width < 8 || width > 16384 || width % 2 != 0)
    throw Error("envmap: the width must be even and within 8..16384 (got " + std::to_string(width) +
                ")");
  if (sky_samples < 1 || sky_samples > 64) throw Error("envmap: sky_samples must be within 1..64");
  if (std::isinf(height_m)) throw Error("envmap: the height must be finite");
}

Eigen::Vector3d LatLongDirection(int width, int height, double column, double row) {
  const double el = RowElevation(height, row);
  const double phi = kPi * (1 - 2 * column / width);  // from +x (east) towards +y (north)
  return Eigen::Vector3d(std::cos(el) * std::cos(phi), std::cos(el) * std::sin(phi), std::sin(el));
}

Eigen::Vector2d LatLongPixel(int width, int height, const Eigen::Vector3d& dir) {
  double u = 0.5 - std::atan2(dir.y(), dir.x()) / (2 * kPi);
  if (u >= 1) u -= 1;
  const double el = std::atan2(dir.z(), std::hypot(dir.x(), dir.y()));
  return Eigen::Vector2d(u * width, ElevationRow(height, el));
}

double LatLongPixelSolidAngle(int width, int height, int row) {
  return 2 * kPi / width *
         (std::sin(RowElevation(height, row)) - std::sin(RowElevation(height, row + 1)));
}

Image BakeLatLong(const Lighting& lighting, const LatLongOptions& options) {
  options.Validate();
  CheckLighting(lighting);
  const int w = options.width, h = options.width / 2;
  const EnvironmentMap& env = lighting.env;
  const bool regions = lighting.use_env;
  // The sky regions spread as the irradiance spreads them (EnvOptions::sky_detail).
  const SkyShape shape(env, lighting.sky);
  const double z =
      std::isnan(options.height_m) ? (regions ? env.layer_z.front() : 0.0) : options.height_m;
  // The region edges in pixel coordinates: sectors at compass azimuth k 2 pi / sectors (column
  // w (1/4 + k / sectors)), bands at the horizon and every (pi/2) / bands above and below it.
  std::vector<double> column_lines, row_lines = {ElevationRow(h, 0)};
  if (regions) {
    for (int k = -env.sectors; k <= 2 * env.sectors; ++k)
      column_lines.push_back(w * (0.25 + static_cast<double>(k) / env.sectors));
    for (int k = 1; k < env.bands_below; ++k)
      row_lines.push_back(ElevationRow(h, -kPi / 2 + k * (kPi / 2) / env.bands_below));
    for (int k = 1; k < env.bands_above; ++k)
      row_lines.push_back(ElevationRow(h, k * (kPi / 2) / env.bands_above));
  }
  const int ss = options.sky_samples;
  Image out(w, h, 3, PixelUnits::kRadiance, 0.f);
  for (int row = 0; row < h; ++row) {
    const std::vector<double> rows = Cuts(row, row + 1, row_lines);
    for (int col = 0; col < w; ++col) {
      const std::vector<double> cols = Cuts(col, col + 1, column_lines);
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      double weight = 0;
      for (size_t i = 0; i + 1 < rows.size(); ++i) {
        const double s_top = std::sin(RowElevation(h, rows[i]));
        const double s_bottom = std::sin(RowElevation(h, rows[i + 1]));
        const bool above = RowElevation(h, 0.5 * (rows[i] + rows[i + 1])) > 0;
        const bool smooth = above && (options.sky_model || !regions);
        for (size_t j = 0; j + 1 < cols.size(); ++j) {
          const double sr = (cols[j + 1] - cols[j]) * (s_top - s_bottom);  // x 2 pi / w
          Eigen::Vector3d l = Eigen::Vector3d::Zero();
          if (smooth) {
            // Equal solid angles: uniform in column and in sin(elevation).
            for (int a = 0; a < ss; ++a)
              for (int b = 0; b < ss; ++b) {
                const double el = std::asin(s_top + (a + 0.5) / ss * (s_bottom - s_top));
                const double c = cols[j] + (b + 0.5) / ss * (cols[j + 1] - cols[j]);
                l += lighting.sky.Radiance(LatLongDirection(w, h, c, ElevationRow(h, el)));
              }
            l /= ss * ss;
          } else if (regions) {
            // Wholly inside one region: its radiance at the centre, spread by the sky's shape.
            const Eigen::Vector3d d = LatLongDirection(w, h, 0.5 * (cols[j] + cols[j + 1]),
                                                       0.5 * (rows[i] + rows[i + 1]));
            const int r = env.Region(d);
            l = env.RegionRadiance(r, z).cwiseProduct(shape.InRegion(d, r));
          }
          sum += sr * l;
          weight += sr;
        }
      }
      const Eigen::Vector3d mean = sum / weight;
      for (int c = 0; c < 3; ++c) out.at(col, row, c) = static_cast<float>(mean[c]);
    }
  }

  // The sun disc: each candidate pixel's share of it by subsampling (equal solid angles),
  // scaled so that the shares sum to the disc's solid angle exactly.
  const double omega = lighting.sun_solid_angle_sr;
  if (omega > 0 && lighting.sun_radiance.maxCoeff() > 0) {
    const Eigen::Vector3d s = lighting.sun_dir.normalized();
    const double radius = lighting.SunAngularRadius(), cos_radius = std::cos(radius);
    const double el_s = std::asin(std::clamp(s.z(), -1.0, 1.0));
    const double pixel = kPi / h;  // a pixel's height (and at most its width) in radians
    const int n = std::clamp(static_cast<int>(std::ceil(8 * pixel / radius)), 16, 512);
    const int row0 = std::max(0, static_cast<int>(ElevationRow(h, el_s + radius + pixel)));
    const int row1 = std::min(h - 1, static_cast<int>(ElevationRow(h, el_s - radius - pixel)));
    const double cos_band = std::cos(std::min(kPi / 2, std::abs(el_s) + radius + pixel));
    const Eigen::Vector2d centre = LatLongPixel(w, h, s);
    const double half_columns =
        cos_band < 0.05 ? w : (radius + pixel) / cos_band / (2 * kPi) * w + 1;
    struct Share {
      int col, row;
      double sr;
    };
    std::vector<Share> shares;
    double total = 0;
    for (int row = row0; row <= row1; ++row) {
      const double s_top = std::sin(RowElevation(h, row)),
                   s_bottom = std::sin(RowElevation(h, row + 1));
      const int c0 =
          half_columns >= w / 2.0 ? 0 : static_cast<int>(std::floor(centre.x() - half_columns));
      const int c1 =
          half_columns >= w / 2.0 ? w - 1 : static_cast<int>(std::ceil(centre.x() + half_columns));
      for (int cc = c0; cc <= c1; ++cc) {
        const int col = ((cc % w) + w) % w;
        int inside = 0;
        for (int a = 0; a < n; ++a) {
          const double el = std::asin(s_top + (a + 0.5) / n * (s_bottom - s_top));
          for (int b = 0; b < n; ++b) {
            const Eigen::Vector3d d =
                LatLongDirection(w, h, col + (b + 0.5) / n, ElevationRow(h, el));
            inside += d.dot(s) >= cos_radius;
          }
        }
        if (inside == 0) continue;
        const double sr = LatLongPixelSolidAngle(w, h, row) * inside / (static_cast<double>(n) * n);
        shares.push_back({col, row, sr});
        total += sr;
      }
    }
    if (shares.empty()) {  // a disc far smaller than a subsample: all of it in its pixel
      shares.push_back({std::clamp(static_cast<int>(centre.x()), 0, w - 1),
                        std::clamp(static_cast<int>(centre.y()), 0, h - 1), 1.0});
      total = 1.0;
    }
    for (const Share& sh : shares) {
      const double fraction = omega * sh.sr / total / LatLongPixelSolidAngle(w, h, sh.row);
      for (int c = 0; c < 3; ++c)
        out.at(sh.col, sh.row, c) += static_cast<float>(lighting.sun_radiance[c] * fraction);
    }
  }
  for (float v : out.data)
    if (!std::isfinite(v) || v < 0)
      throw Error("envmap: a non-finite or negative radiance (check the scene's lighting)");
  return out;
}

Eigen::Vector3d LatLongIrradiance(const Image& map, const Eigen::Vector3d& normal) {
  const int w = map.width, h = map.height;
  if (w < 2 || h < 1 || w != 2 * h || map.channels < 3)
    throw Error("envmap: a latitude-longitude map is twice as wide as high, RGB");
  const Eigen::Vector3d n = normal.normalized();
  const double reach = kPi / h;  // no point of a pixel is farther than this from its centre
  constexpr int kSub = 16;
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  for (int row = 0; row < h; ++row) {
    const double eb = RowElevation(h, row), ea = RowElevation(h, row + 1);
    const double i2 = (eb - ea) / 2 + (std::sin(2 * eb) - std::sin(2 * ea)) / 4;  // cos^2
    const double i3 = (std::sin(eb) * std::sin(eb) - std::sin(ea) * std::sin(ea)) / 2;
    for (int col = 0; col < w; ++col) {
      const double centre = n.dot(LatLongDirection(w, h, col + 0.5, row + 0.5));
      if (centre <= -reach) continue;
      double flux;  // integral of max(0, n.d) over the pixel
      if (centre >= reach) {
        const double pa = kPi * (1 - 2.0 * (col + 1) / w), pb = kPi * (1 - 2.0 * col / w);
        flux = n.x() * (std::sin(pb) - std::sin(pa)) * i2 +
               n.y() * (std::cos(pa) - std::cos(pb)) * i2 + n.z() * (pb - pa) * i3;
      } else {
        double sum = 0;
        for (int a = 0; a < kSub; ++a) {
          const double el =
              std::asin(std::sin(eb) + (a + 0.5) / kSub * (std::sin(ea) - std::sin(eb)));
          for (int b = 0; b < kSub; ++b)
            sum += std::max(
                0.0, n.dot(LatLongDirection(w, h, col + (b + 0.5) / kSub, ElevationRow(h, el))));
        }
        flux = sum / (kSub * kSub) * LatLongPixelSolidAngle(w, h, row);
      }
      for (int c = 0; c < 3; ++c) e[c] += flux * map.at(col, row, c);
    }
  }
  return e;
}

Eigen::Vector3d UnoccludedIrradiance(const Lighting& lighting, const Eigen::Vector3d& normal,
                                     double z) {
  const Eigen::Vector3d n = normal.normalized();
  if (!n.allFinite()) throw Error("envmap: the plane's normal is not a direction");
  // A 10 cm triangle facing n whose one grid point (its centroid) is at (0, 0, z).
  Eigen::Vector3d t =
      std::abs(n.z()) < 0.9 ? Eigen::Vector3d::UnitZ().cross(n) : Eigen::Vector3d::UnitX().cross(n);
  t.normalize();
  const Eigen::Vector3d b = n.cross(t);
  const double e = 0.1;
  const Eigen::Vector3d corner = Eigen::Vector3d(0, 0, z) - e * (t + b) / 3;
  Mesh mesh;
  const int block = mesh.AddBlock("plane");
  mesh.vertices = {corner, corner + e * t, corner + e * b};
  mesh.AddTriangle(0, 1, 2, block);
  GridOptions go;
  go.spacing_m = 1.0;
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, go);
  const RayCaster caster(mesh);
  HemisphereOptions ho;
  ho.directions = 1;
  const HemisphereCache cache = BuildHemisphereCache(grid, caster, ho);
  IrradianceOptions io;
  io.method = IrradianceMethod::kVectorFlux;
  io.mesh = &mesh;
  io.ground_shadow = false;
  io.vector_flux.env_parallel_segments = 64;
  const SlotIrradiance irr = ComputeIrradiance(grid, cache, caster, lighting, io);
  if (irr.sun.size() != 1) throw Error("envmap: the test plane has no single grid point");
  return irr.sun[0] + irr.direct_se[0];
}

}  // namespace rouen
