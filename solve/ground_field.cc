#include "solve/ground_field.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/stats.h"
#include "solve/retro.h"

namespace rouen {
namespace {

const Eigen::Vector3d kUp = Eigen::Vector3d::UnitZ();

// Cosine-weighted direction k of n over the upper hemisphere (stratified, fixed).
Eigen::Vector3d CosineDirection(int k, int n) {
  const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(n))));
  const double u = (k % side + 0.5) / side, v = ((k / side) % side + 0.5) / side;
  const double r = std::sqrt(u), phi = 2 * kPi * v;
  return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1 - u))};
}

// What lights level ground at cell `cell` per unit albedo, seen from `to_viewer`, over pi:
// (E_sun sin(el) D + E_sky V_sky A) / pi with the ground's retro.
Eigen::Vector3d LightPerAlbedo(const GroundField& f, int cell, bool shaded,
                               const Eigen::Vector3d& sun_dir, const Eigen::Vector3d& sun_e,
                               const Eigen::Vector3d& sky_e, const Eigen::Vector3d& to_viewer) {
  const double vis = cell < 0 ? 1.0 : f.sky_visibility[cell];
  Eigen::Vector3d e = sky_e * (vis * AmbientRetroFactor(f.retro, kUp, to_viewer));
  if (!shaded && sun_dir.z() > 0)
    e += sun_e * (sun_dir.z() * RetroFactor(f.retro, kUp, sun_dir, to_viewer));
  return e / kPi;
}

}  // namespace

void GroundFieldOptions::Validate() const {
  auto bad = [](const std::string& s) { throw Error("ground field: " + s); };
  if (!(cell_m >= 0.05 && cell_m <= 100)) bad("cell_m must be within [0.05, 100] metres");
  if (!(radius_factor >= 0 && radius_factor <= 100)) bad("radius_factor must be within [0, 100]");
  if (!(min_radius_m >= 0 && min_radius_m <= 1e5)) bad("min_radius_m must be within [0, 1e5]");
  if (max_cells < 1) bad("max_cells must be positive");
  if (sky_rays < 1 || sky_rays > 4096) bad("sky_rays must be within [1, 4096]");
}

int GroundField::Cell(double x, double y) const {
  const double fx = std::floor((x - x0) / cell_m), fy = std::floor((y - y0) / cell_m);
  if (!(fx >= 0 && fy >= 0 && fx < nx && fy < ny)) return -1;
  return static_cast<int>(fy) * nx + static_cast<int>(fx);
}

Eigen::Vector3d GroundField::CellCentre(int cell) const {
  return {x0 + (cell % nx + 0.5) * cell_m, y0 + (cell / nx + 0.5) * cell_m, level_z};
}

void GroundField::Validate() const {
  const size_t n = static_cast<size_t>(nx) * static_cast<size_t>(ny);
  if (nx < 0 || ny < 0 || albedo.size() != n || observed.size() != n || sky_visibility.size() != n)
    throw Error("ground field: " + std::to_string(nx) + " x " + std::to_string(ny) + " cells but " +
                std::to_string(albedo.size()) + " albedos, " + std::to_string(observed.size()) +
                " flags, " + std::to_string(sky_visibility.size()) + " sky visibilities");
  if (!(cell_m > 0) || !std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(level_z))
    throw Error("ground field: bad cell size or origin");
  if (!(retro >= kRetroMin && retro <= kRetroMax))
    throw Error("ground field: retro must be within [" + std::to_string(kRetroMin) + ", " +
                std::to_string(kRetroMax) + "]");
  if (!far_albedo.allFinite() || far_albedo.minCoeff() < 0)
    throw Error("ground field: the far albedo must be finite and >= 0");
  for (size_t i = 0; i < n; ++i) {
    if (!albedo[i].allFinite() || albedo[i].minCoeff() < 0 || !(sky_visibility[i] >= 0) ||
        !(sky_visibility[i] <= 1))
      throw Error("ground field: cell " + std::to_string(i) +
                  " has an albedo or sky visibility that is negative or not finite");
  }
}

GroundField BuildGroundField(const std::vector<GroundFieldTime>& times, const RayCaster& model,
                             double retro, const GroundFieldOptions& options,
                             GroundFieldSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  if (!(retro >= kRetroMin && retro <= kRetroMax))
    throw Error("ground field: retro must be within [" + std::to_string(kRetroMin) + ", " +
                std::to_string(kRetroMax) + "]");
  GroundField f;
  f.retro = retro;
  f.cell_m = options.cell_m;
  f.level_z = GroundLevel(model);
  const Eigen::AlignedBox3d& box = model.bounds();
  const double height = std::max(0.0, box.max().z() - f.level_z);
  const double radius = std::max(options.min_radius_m, options.radius_factor * height);
  const double cells_x = std::ceil((box.max().x() - box.min().x() + 2 * radius) / f.cell_m);
  const double cells_y = std::ceil((box.max().y() - box.min().y() + 2 * radius) / f.cell_m);
  if (!(cells_x * cells_y <= static_cast<double>(options.max_cells)))
    throw Error("ground field: " + std::to_string(static_cast<int64_t>(cells_x * cells_y)) +
                " cells of " + std::to_string(f.cell_m) + " m exceed max_cells " +
                std::to_string(options.max_cells) + " (a larger cell_m or a smaller radius)");
  f.nx = std::max(1, static_cast<int>(cells_x));
  f.ny = std::max(1, static_cast<int>(cells_y));
  f.x0 = box.min().x() - radius;
  f.y0 = box.min().y() - radius;
  const int n = f.nx * f.ny;
  const double offset = model.surface_offset();

  // The sky the model leaves each cell (cosine-weighted), once.
  f.sky_visibility.assign(n, 1.f);
  tbb::parallel_for(0, n, [&](int c) {
    const Eigen::Vector3d q = f.CellCentre(c) + Eigen::Vector3d(0, 0, offset);
    int open = 0;
    for (int k = 0; k < options.sky_rays; ++k)
      open += !model.Occluded(q, CosineDirection(k, options.sky_rays), 0.0);
    f.sky_visibility[c] = static_cast<float>(open) / options.sky_rays;
  });

  // Per time, each cell's mean albedo over the pixels that fell in it.
  std::vector<std::vector<Eigen::Vector3f>> per_time(n);
  Eigen::Vector3d far_sum = Eigen::Vector3d::Zero();
  int64_t far_count = 0;
  GroundFieldSummary s;
  for (const GroundFieldTime& t : times) {
    std::vector<Eigen::Vector3d> sum(n, Eigen::Vector3d::Zero());
    std::vector<int> count(n, 0);
    for (const EnvPanorama& p : t.panoramas) {
      if (p.sky_only || !p.radiance) continue;
      const Image& im = *p.radiance;
      const Eigen::Vector3d o = p.pose.position;
      if (!(o.z() > f.level_z)) continue;
      for (int y = 0; y < im.height; ++y) {
        for (int x = 0; x < im.width; ++x) {
          const Eigen::Vector3d d =
              p.pose.rotation * Unproject(p.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
          if (!(d.z() < -1e-3)) continue;
          const Eigen::Vector3d l(im.at(x, y, 0), im.at(x, y, 1), im.at(x, y, 2));
          if (!l.allFinite() || l.minCoeff() < 0) continue;
          const double dist = (o.z() - f.level_z) / -d.z();
          if (model.Occluded(o, d, 0.0, dist - offset)) {
            ++s.pixels_model;
            continue;
          }
          const Eigen::Vector3d q = o + dist * d;
          const int cell = f.Cell(q.x(), q.y());
          const bool shaded = t.sun_dir.z() <= 0 ||
                              model.Occluded(q + Eigen::Vector3d(0, 0, offset), t.sun_dir, 0.0);
          const Eigen::Vector3d e =
              LightPerAlbedo(f, cell, shaded, t.sun_dir, t.sun_e, t.sky_e, -d);
          if (!(e.minCoeff() > 0)) continue;
          const Eigen::Vector3d rho = l.cwiseQuotient(e);
          if (cell < 0) {
            far_sum += rho;
            ++far_count;
            ++s.pixels_far;
            continue;
          }
          sum[cell] += rho;
          ++count[cell];
          ++s.pixels_used;
        }
      }
    }
    for (int c = 0; c < n; ++c)
      if (count[c] > 0) per_time[c].push_back((sum[c] / count[c]).cast<float>());
  }
  if (s.pixels_used == 0)
    throw Error("ground field: no landscape panorama pixel meets the ground around the model");

  // Over the times, the median per channel.
  f.albedo.assign(n, Eigen::Vector3f::Zero());
  f.observed.assign(n, 0);
  std::deque<int> queue;
  for (int c = 0; c < n; ++c) {
    std::vector<Eigen::Vector3f>& v = per_time[c];
    if (v.empty()) continue;
    for (int ch = 0; ch < 3; ++ch) {
      std::vector<float> x;
      for (const Eigen::Vector3f& a : v) x.push_back(a[ch]);
      f.albedo[c][ch] = Median(std::move(x));
    }
    f.observed[c] = 1;
    queue.push_back(c);
    ++s.cells_observed;
  }
  // Unobserved cells: the nearest observed one's (breadth-first over the 4-neighbours).
  std::vector<uint8_t> done(f.observed);
  while (!queue.empty()) {
    const int c = queue.front();
    queue.pop_front();
    const int cx = c % f.nx, cy = c / f.nx;
    const int nb[4][2] = {{cx - 1, cy}, {cx + 1, cy}, {cx, cy - 1}, {cx, cy + 1}};
    for (const auto& [x, y] : nb) {
      if (x < 0 || y < 0 || x >= f.nx || y >= f.ny) continue;
      const int m = y * f.nx + x;
      if (done[m]) continue;
      done[m] = 1;
      f.albedo[m] = f.albedo[c];
      queue.push_back(m);
    }
  }
  // Beyond the cells: the pixels that fell there, else the rim's median.
  if (far_count > 0) {
    f.far_albedo = far_sum / static_cast<double>(far_count);
  } else {
    std::vector<double> rim[3];
    for (int c = 0; c < n; ++c) {
      const int cx = c % f.nx, cy = c / f.nx;
      if (cx != 0 && cy != 0 && cx != f.nx - 1 && cy != f.ny - 1) continue;
      for (int ch = 0; ch < 3; ++ch) rim[ch].push_back(f.albedo[c][ch]);
    }
    for (int ch = 0; ch < 3; ++ch) f.far_albedo[ch] = Median(std::move(rim[ch]));
  }
  s.cells = n;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (summary) *summary = s;
  f.Validate();
  return f;
}

GroundLight::GroundLight(const GroundField& field, const RayCaster& model,
                         const Eigen::Vector3d& sun_dir, const Eigen::Vector3d& sun_e,
                         const Eigen::Vector3d& sky_e)
    : field_(&field), sun_dir_(sun_dir), sun_e_(sun_e), sky_e_(sky_e) {
  const int n = field.nx * field.ny;
  shadow_.assign(n, 0);
  if (sun_dir.z() <= 0) {
    std::fill(shadow_.begin(), shadow_.end(), 1);
    return;
  }
  const Eigen::Vector3d up(0, 0, model.surface_offset());
  tbb::parallel_for(0, n, [&](int c) {
    shadow_[c] = model.Occluded(field.CellCentre(c) + up, sun_dir, 0.0) ? 1 : 0;
  });
}

Eigen::Vector3d GroundLight::Radiance(const Eigen::Vector3d& q,
                                      const Eigen::Vector3d& to_viewer) const {
  const GroundField& f = *field_;
  const int cell = f.Cell(q.x(), q.y());
  const bool shaded = cell >= 0 ? shadow_[cell] != 0 : sun_dir_.z() <= 0;
  return f.Albedo(cell).cwiseProduct(
      LightPerAlbedo(f, cell, shaded, sun_dir_, sun_e_, sky_e_, to_viewer));
}

Eigen::Vector3d GroundLight::Arriving(const Eigen::Vector3d& origin,
                                      const Eigen::Vector3d& d) const {
  const double h = origin.z() - field_->level_z;
  if (!(d.z() < 0) || !(h > 0)) return Eigen::Vector3d::Zero();
  return Radiance(origin + (h / -d.z()) * d, -d);
}

void to_json(nlohmann::json& j, const GroundFieldOptions& o) {
  j = {{"enabled", o.enabled},
       {"cell_m", o.cell_m},
       {"radius_factor", o.radius_factor},
       {"min_radius_m", o.min_radius_m},
       {"max_cells", o.max_cells},
       {"sky_rays", o.sky_rays}};
}

void to_json(nlohmann::json& j, const GroundField& f) {
  std::vector<float> albedo, vis(f.sky_visibility);
  albedo.reserve(3 * f.albedo.size());
  for (const Eigen::Vector3f& a : f.albedo) albedo.insert(albedo.end(), {a.x(), a.y(), a.z()});
  j = {{"level_z", f.level_z},
       {"x0", f.x0},
       {"y0", f.y0},
       {"cell_m", f.cell_m},
       {"nx", f.nx},
       {"ny", f.ny},
       {"retro", f.retro},
       {"far_albedo", {f.far_albedo.x(), f.far_albedo.y(), f.far_albedo.z()}},
       {"albedo", albedo},
       {"observed", f.observed},
       {"sky_visibility", vis}};
}

void from_json(const nlohmann::json& j, GroundField& f) {
  if (!j.is_object()) throw Error("ground field: expected an object");
  f.level_z = j.at("level_z").get<double>();
  f.x0 = j.at("x0").get<double>();
  f.y0 = j.at("y0").get<double>();
  f.cell_m = j.at("cell_m").get<double>();
  f.nx = j.at("nx").get<int>();
  f.ny = j.at("ny").get<int>();
  f.retro = j.at("retro").get<double>();
  const std::vector<double> far = j.at("far_albedo").get<std::vector<double>>();
  if (far.size() != 3) throw Error("ground field: far_albedo must be RGB");
  f.far_albedo = {far[0], far[1], far[2]};
  const std::vector<float> albedo = j.at("albedo").get<std::vector<float>>();
  if (albedo.size() % 3 != 0) throw Error("ground field: albedo must be RGB triples");
  f.albedo.resize(albedo.size() / 3);
  for (size_t i = 0; i < f.albedo.size(); ++i)
    f.albedo[i] = {albedo[3 * i], albedo[3 * i + 1], albedo[3 * i + 2]};
  f.observed = j.at("observed").get<std::vector<uint8_t>>();
  f.sky_visibility = j.at("sky_visibility").get<std::vector<float>>();
  f.Validate();
}

}  // namespace rouen
