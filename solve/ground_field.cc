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
#include "core/hash_random.h"
#include "core/json_text.h"
#include "core/stats.h"
#include "solve/retro.h"

namespace rouen {
namespace {

const Eigen::Vector3d kUp = Eigen::Vector3d::UnitZ();

// Cosine-weighted direction k of n over the upper hemisphere: stratified, jittered within its
// stratum by a hash of `key` and k (one pattern for every spot would put the same error on
// every cell beside a wall).
Eigen::Vector3d CosineDirection(int k, int n, uint64_t key) {
  const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(n))));
  const uint64_t h = MixHash(MixHash(key) ^ static_cast<uint64_t>(k));
  const double u = (k % side + HashUniformHigh(h)) / side;
  const double v = ((k / side) % side + HashUniformLow(h)) / side;
  const double r = std::sqrt(u), phi = 2 * kPi * v;
  return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1 - u))};
}

// What lights level ground at q per unit albedo, seen from `to_viewer`, over pi:
// (E_sun sin(el) D + (E_sky V_sky + E_walls) A) / pi with the ground's rough diffuse reflection
// `retro` (the walls' light taken as ambient, like the sky's).
Eigen::Vector3d LightPerAlbedo(const GroundField& f, const Eigen::Vector3d& q, bool shaded,
                               const Eigen::Vector3d& sun_dir, const Eigen::Vector3d& sun_e,
                               const Eigen::Vector3d& sky_e, const Eigen::Vector3d& walls_e,
                               const Eigen::Vector3d& to_viewer, double retro) {
  // walls_e may take away the sky the walls hide beyond its mean (HiddenSkyExcess): the light
  // never goes below none.
  Eigen::Vector3d e = (sky_e * f.SkyVisibility(q) + walls_e).cwiseMax(0.0) *
                      AmbientRetroFactor(retro, kUp, to_viewer);
  if (!shaded && sun_dir.z() > 0)
    e += sun_e * (sun_dir.z() * RetroFactor(retro, kUp, sun_dir, to_viewer));
  return e / kPi;
}

// Whether ground point q lies in the model's shadow (or the sun is down).
bool InShadow(const RayCaster& model, const Eigen::Vector3d& q, const Eigen::Vector3d& sun_dir) {
  return sun_dir.z() <= 0 ||
         model.Occluded(q + Eigen::Vector3d(0, 0, model.surface_offset()), sun_dir, 0.0);
}

// One landscape panorama pixel whose ray meets the ground.
struct GroundPixel {
  int time = 0, panorama = 0;                   // indices into the times and that time's panoramas
  int cell = -1;                                // -1: beyond the field
  Eigen::Vector3f q = Eigen::Vector3f::Zero();  // where the ray meets the ground
  bool shaded = false;  // the model hides the sun from where the ray meets the ground
  Eigen::Vector3f radiance = Eigen::Vector3f::Zero();
  Eigen::Vector3f to_viewer = Eigen::Vector3f::UnitZ();  // from the ground to the panorama
  // The albedo the pixel reads with the ground's reflection `retro` and the walls' light on its
  // cell `walls_e`; NaN where nothing lights it.
  Eigen::Vector3d Albedo(const GroundField& f, const GroundFieldTime& t,
                         const Eigen::Vector3d& walls_e, double retro) const {
    const Eigen::Vector3d e = LightPerAlbedo(f, q.cast<double>(), shaded, t.sun_dir, t.sun_e,
                                             t.sky_e, walls_e, to_viewer.cast<double>(), retro);
    if (!(e.minCoeff() > 0)) return Eigen::Vector3d::Constant(std::nan(""));
    return radiance.cast<double>().cwiseQuotient(e);
  }
};

// Calls fn for every stride-th pixel (in x and y) of every time's landscape panoramas whose ray
// meets the ground before the model, in time order; counts the pixels the model hides in
// summary->pixels_model.
template <typename Fn>
void ForEachGroundPixel(const std::vector<GroundFieldTime>& times, const RayCaster& model,
                        const GroundField& f, int stride, GroundFieldSummary* summary, Fn fn) {
  const double offset = model.surface_offset();
  for (size_t ti = 0; ti < times.size(); ++ti) {
    const GroundFieldTime& t = times[ti];
    for (size_t pi = 0; pi < t.panoramas.size(); ++pi) {
      const EnvPanorama& p = t.panoramas[pi];
      if (p.sky_only || !p.radiance) continue;
      const Image& im = *p.radiance;
      const Eigen::Vector3d o = p.pose.position;
      if (!(o.z() > f.level_z)) continue;
      for (int y = stride / 2; y < im.height; y += stride) {
        for (int x = stride / 2; x < im.width; x += stride) {
          const Eigen::Vector3d d =
              p.pose.rotation * Unproject(p.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
          if (!(d.z() < -1e-3)) continue;
          const Eigen::Vector3f l(im.at(x, y, 0), im.at(x, y, 1), im.at(x, y, 2));
          if (!l.allFinite() || l.minCoeff() < 0) continue;
          const double dist = (o.z() - f.level_z) / -d.z();
          if (model.Occluded(o, d, 0.0, dist - offset)) {
            if (summary) ++summary->pixels_model;
            continue;
          }
          const Eigen::Vector3d q = o + dist * d;
          GroundPixel g;
          g.time = static_cast<int>(ti);
          g.panorama = static_cast<int>(pi);
          g.cell = f.Cell(q.x(), q.y());
          g.q = q.cast<float>();
          g.shaded = InShadow(model, q, t.sun_dir);
          g.radiance = l;
          g.to_viewer = (-d).cast<float>();
          fn(g);
        }
      }
    }
  }
}

// Every cell not `keep` takes the value of the nearest cell of `queue` (breadth-first over the
// 4-neighbours, through kept cells as through others); all stay as they are when `queue` is
// empty.
void FillFromNearest(int nx, int ny, std::vector<Eigen::Vector3f>* values,
                     const std::vector<uint8_t>& keep, std::deque<int> queue) {
  std::vector<int> source(values->size(), -1);
  for (int c : queue) source[c] = c;
  while (!queue.empty()) {
    const int c = queue.front();
    queue.pop_front();
    const int cx = c % nx, cy = c / nx;
    const int nb[4][2] = {{cx - 1, cy}, {cx + 1, cy}, {cx, cy - 1}, {cx, cy + 1}};
    for (const auto& [x, y] : nb) {
      if (x < 0 || y < 0 || x >= nx || y >= ny) continue;
      const int m = y * nx + x;
      if (source[m] >= 0) continue;
      source[m] = source[c];
      if (!keep[m]) (*values)[m] = (*values)[source[c]];
      queue.push_back(m);
    }
  }
}

// Per time and cell, what lights the cell beside the sun and the sky's mean: the walls'
// irradiance (GroundFieldTime::walls_e) less the excess of the sky they hide (HiddenSkyExcess,
// with GroundFieldTime::sky); empty per time where neither is given.
using CellLight = std::vector<std::vector<Eigen::Vector3d>>;

Eigen::Vector3d ExtraAt(const CellLight& extra, int time, int cell) {
  return cell < 0 || extra[time].empty() ? Eigen::Vector3d(Eigen::Vector3d::Zero())
                                         : extra[time][cell];
}

struct RetroConsistency {
  double retro = 0, cost_given = 0, cost = 0;
  int cells = 0;  // cells seen by two or more (time, panorama) pairs
};

// Beyond the paper: the ground's rough diffuse reflection from the panoramas themselves. A
// spot of ground seen at several times (the sun elsewhere) or from several panoramas (from
// elsewhere) has one albedo: the retro at which each cell's albedos from its (time, panorama)
// pairs agree best. The cost: the median over such cells of the RMS deviation of the pairs'
// log albedos from their mean (per channel, pairs of fewer than kMinPixels pixels left out);
// candidates over [kRetroMin, kRetroMax] in steps of 0.25, refined by a parabola. `given` is
// kept when fewer than kMinCells cells are seen twice.
RetroConsistency FitRetroByConsistency(std::vector<GroundPixel> sample, const GroundField& f,
                                       const std::vector<GroundFieldTime>& times,
                                       const CellLight& extra, double given) {
  constexpr int kMinPixels = 4, kMinCells = 20;
  int panoramas = 1;
  for (const GroundFieldTime& t : times)
    panoramas = std::max(panoramas, static_cast<int>(t.panoramas.size()));
  auto pair_of = [&](const GroundPixel& g) { return g.time * panoramas + g.panorama; };
  std::sort(sample.begin(), sample.end(), [&](const GroundPixel& a, const GroundPixel& b) {
    return a.cell != b.cell ? a.cell < b.cell : pair_of(a) < pair_of(b);
  });
  RetroConsistency out;
  auto cost_at = [&](double retro, int* cells) {
    std::vector<double> per_cell;
    std::vector<Eigen::Vector3d> logs;  // one cell's pairs
    size_t i = 0;
    while (i < sample.size()) {
      const int cell = sample[i].cell;
      logs.clear();
      while (i < sample.size() && sample[i].cell == cell) {
        const int pair = pair_of(sample[i]);
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        int count = 0;
        for (; i < sample.size() && sample[i].cell == cell && pair_of(sample[i]) == pair; ++i) {
          const GroundPixel& g = sample[i];
          const Eigen::Vector3d rho =
              g.Albedo(f, times[g.time], ExtraAt(extra, g.time, g.cell), retro);
          if (!rho.allFinite()) continue;
          sum += rho;
          ++count;
        }
        if (count >= kMinPixels && (sum / count).minCoeff() > 0)
          logs.push_back((sum / count).array().log().matrix());
      }
      if (logs.size() < 2) continue;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (const Eigen::Vector3d& v : logs) mean += v;
      mean /= static_cast<double>(logs.size());
      double ss = 0;
      for (const Eigen::Vector3d& v : logs) ss += (v - mean).squaredNorm() / 3;
      per_cell.push_back(std::sqrt(ss / static_cast<double>(logs.size())));
    }
    if (cells) *cells = static_cast<int>(per_cell.size());
    return per_cell.empty() ? 0.0 : Median(std::move(per_cell));
  };
  out.retro = given;
  out.cost_given = out.cost = cost_at(given, &out.cells);
  if (out.cells < kMinCells) return out;
  constexpr double kStep = 0.25;
  std::vector<double> grid, cost;
  for (double r = kRetroMin; r <= kRetroMax + 1e-9; r += kStep) {
    grid.push_back(r);
    cost.push_back(cost_at(r, nullptr));
  }
  const size_t best =
      static_cast<size_t>(std::min_element(cost.begin(), cost.end()) - cost.begin());
  double retro = grid[best], c = cost[best];
  if (const std::optional<double> r = ParabolaVertex(grid, cost, best, kStep)) {
    const double cr = cost_at(*r, nullptr);
    if (cr < c) {
      retro = *r;
      c = cr;
    }
  }
  if (c < out.cost) {
    out.retro = retro;
    out.cost = c;
  }
  return out;
}

}  // namespace

void GroundFieldOptions::Validate() const {
  auto bad = [](const std::string& s) { throw Error("ground field: " + s); };
  if (!(cell_m >= 0.05 && cell_m <= 100)) bad("cell_m must be within [0.05, 100] metres");
  if (!(radius_factor >= 0 && radius_factor <= 100)) bad("radius_factor must be within [0, 100]");
  if (!(min_radius_m >= 0 && min_radius_m <= 1e5)) bad("min_radius_m must be within [0, 1e5]");
  if (max_cells < 1) bad("max_cells must be positive");
  if (sky_rays < 1 || sky_rays > 4096) bad("sky_rays must be within [1, 4096]");
  if (!(open_sky >= 0 && open_sky <= 1)) bad("open_sky must be within [0, 1]");
}

int GroundField::Cell(double x, double y) const {
  const double fx = std::floor((x - x0) / cell_m), fy = std::floor((y - y0) / cell_m);
  if (!(fx >= 0 && fy >= 0 && fx < nx && fy < ny)) return -1;
  return static_cast<int>(fy) * nx + static_cast<int>(fx);
}

double GroundField::SkyVisibility(const Eigen::Vector3d& q) const {
  const double fx = (q.x() - x0) / cell_m - 0.5, fy = (q.y() - y0) / cell_m - 0.5;
  const double ix = std::floor(fx), iy = std::floor(fy);
  if (!(std::isfinite(ix) && std::isfinite(iy))) return 1;
  double sum = 0, weight = 0;
  for (int b = 0; b < 2; ++b) {
    for (int a = 0; a < 2; ++a) {
      const double w = (a ? fx - ix : 1 - (fx - ix)) * (b ? fy - iy : 1 - (fy - iy));
      const double cx = ix + a, cy = iy + b;
      // Beyond the cells the model leaves the whole sky; a cell under the model, none to count.
      const double v = cx < 0 || cy < 0 || cx >= nx || cy >= ny
                           ? 1.0
                           : sky_visibility[static_cast<size_t>(cy) * nx + static_cast<size_t>(cx)];
      if (!(v > 0)) continue;
      sum += w * v;
      weight += w;
    }
  }
  return weight > 0 ? sum / weight : 0;
}

Eigen::Vector3d GroundField::CellCentre(int cell) const {
  return {x0 + (cell % nx + 0.5) * cell_m, y0 + (cell / nx + 0.5) * cell_m, level_z};
}

float GroundWalls::SkyVisibility(int cell) const {
  return weight[cell] > 0 ? std::max(0.f, 1 - weight[cell] * (begin[cell + 1] - begin[cell])) : 0.f;
}

GroundWalls CastGroundWalls(const GroundField& f, const RayCaster& model, bool only_shaded) {
  const int rays = f.sky_rays;
  if (rays < 1 || rays > 4096) throw Error("ground field: sky_rays must be within [1, 4096]");
  const int n = f.nx * f.ny;
  if (only_shaded && f.sky_visibility.size() != static_cast<size_t>(n))
    throw Error("ground field: no sky visibility per cell to find the cells that see walls");
  const double offset = model.surface_offset();
  const int per_spot = std::max(1, rays / 4);
  GroundWalls w;
  w.weight.assign(n, 0.f);
  std::vector<std::vector<GroundWalls::Hit>> per_cell(n);
  tbb::parallel_for(0, n, [&](int c) {
    if (only_shaded && !(f.sky_visibility[c] < 1)) return;
    const Eigen::Vector3d centre = f.CellCentre(c) + Eigen::Vector3d(0, 0, offset);
    std::vector<GroundWalls::Hit> hits;
    int cast = 0;
    for (int j = 0; j < 4; ++j) {
      const Eigen::Vector3d q =
          centre + 0.25 * f.cell_m * Eigen::Vector3d(j % 2 ? 1 : -1, j / 2 ? 1 : -1, 0);
      const size_t before = hits.size();
      for (int k = 0; k < per_spot; ++k) {
        const Eigen::Vector3d d = CosineDirection(k, per_spot, 4 * static_cast<uint64_t>(c) + j);
        const RayHit h = model.Intersect(q, d, 0.0);
        if (!h.hit) continue;
        GroundWalls::Hit hit;
        hit.triangle = h.triangle;
        hit.u = static_cast<float>(h.u);
        hit.v = static_cast<float>(h.v);
        hit.position = (q + h.t * d).cast<float>();
        hit.from = q.cast<float>();
        hits.push_back(hit);
      }
      if (hits.size() - before == static_cast<size_t>(per_spot)) {  // under the model
        hits.resize(before);
        continue;
      }
      cast += per_spot;
    }
    w.weight[c] = cast > 0 ? 1.f / cast : 0.f;
    per_cell[c] = std::move(hits);
  });
  w.begin.assign(static_cast<size_t>(n) + 1, 0);
  for (int c = 0; c < n; ++c)
    w.begin[c + 1] = w.begin[c] + static_cast<int32_t>(per_cell[c].size());
  w.hits.reserve(w.begin[n]);
  for (int c = 0; c < n; ++c) w.hits.insert(w.hits.end(), per_cell[c].begin(), per_cell[c].end());
  return w;
}

void GroundField::Validate() const {
  const size_t n = static_cast<size_t>(nx) * static_cast<size_t>(ny);
  if (nx < 0 || ny < 0 || albedo.size() != n || observed.size() != n || sky_visibility.size() != n)
    throw Error("ground field: " + std::to_string(nx) + " x " + std::to_string(ny) + " cells but " +
                std::to_string(albedo.size()) + " albedos, " + std::to_string(observed.size()) +
                " flags, " + std::to_string(sky_visibility.size()) + " sky visibilities");
  if (!(cell_m > 0) || !std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(level_z))
    throw Error("ground field: bad cell size or origin");
  if (sky_rays < 1 || sky_rays > 4096)
    throw Error("ground field: sky_rays must be within [1, 4096]");
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

  int with_walls = 0;
  for (const GroundFieldTime& t : times) {
    if (t.walls_e.empty()) continue;
    if (t.walls_e.size() != static_cast<size_t>(n))
      throw Error("ground field: the walls' light is given for " +
                  std::to_string(t.walls_e.size()) + " cells of a field of " + std::to_string(n));
    ++with_walls;
  }
  if (with_walls != 0 && with_walls != static_cast<int>(times.size()))
    throw Error("ground field: the walls' light is given for some times and not others");
  f.walls = with_walls > 0;
  // The sky the model leaves each cell, once.
  f.sky_rays = options.sky_rays;
  const GroundWalls seen = CastGroundWalls(f, model, false);
  f.sky_visibility.resize(n);
  for (int c = 0; c < n; ++c) f.sky_visibility[c] = seen.SkyVisibility(c);
  CellLight extra(times.size());
  for (size_t ti = 0; ti < times.size(); ++ti) {
    const GroundFieldTime& t = times[ti];
    if (t.walls_e.empty() && !t.sky) continue;
    extra[ti] = HiddenSkyExcess(seen, t.sky, t.sky_e);
    extra[ti].resize(n, Eigen::Vector3d::Zero());
    for (int c = 0; c < n; ++c) {
      extra[ti][c] = -extra[ti][c];
      if (!t.walls_e.empty()) extra[ti][c] += t.walls_e[c].cast<double>();
    }
  }

  // The fit's retro from a sample of the sunlit pixels (at most kFitPixels of all), then per time
  // each cell's mean albedo over every pixel that fell in it, sunlit and shaded apart. A shaded
  // spot's light is the sky's and the walls' (without walls_e, the walls' light as it was then
  // stays in the albedo: in a street several times the albedo); the sun, where it reaches, is
  // known best: a cell keeps its sunlit albedos when some time saw it sunlit.
  GroundFieldSummary s;
  s.retro_given = retro;
  if (options.fit_retro) {
    int64_t below = 0;
    for (const GroundFieldTime& t : times)
      for (const EnvPanorama& p : t.panoramas)
        if (!p.sky_only && p.radiance) below += int64_t{p.radiance->width} * p.radiance->height / 2;
    constexpr int64_t kFitPixels = 1 << 20;
    const int stride = std::max<int>(
        1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(below) / kFitPixels))));
    std::vector<GroundPixel> sample;
    ForEachGroundPixel(times, model, f, stride, nullptr, [&](const GroundPixel& g) {
      if (g.cell >= 0 && !g.shaded) sample.push_back(g);
    });
    const RetroConsistency fit = FitRetroByConsistency(sample, f, times, extra, retro);
    f.retro = retro = fit.retro;
    s.retro_cost_given = fit.cost_given;
    s.retro_cost = fit.cost;
    s.retro_cells = fit.cells;
  }
  s.retro = f.retro;
  std::vector<std::vector<Eigen::Vector3f>> per_time(2 * n);  // 2 cell + shaded
  Eigen::Vector3d far_sum = Eigen::Vector3d::Zero();
  int64_t far_count = 0;
  std::vector<Eigen::Vector3d> sum(2 * n, Eigen::Vector3d::Zero());
  std::vector<int> count(2 * n, 0);
  auto close_time = [&] {
    for (int c = 0; c < 2 * n; ++c)
      if (count[c] > 0) per_time[c].push_back((sum[c] / count[c]).cast<float>());
    std::fill(sum.begin(), sum.end(), Eigen::Vector3d::Zero());
    std::fill(count.begin(), count.end(), 0);
  };
  int current = -1;
  ForEachGroundPixel(times, model, f, 1, &s, [&](const GroundPixel& g) {
    if (g.time != current) {
      if (current >= 0) close_time();
      current = g.time;
    }
    const Eigen::Vector3d rho = g.Albedo(f, times[g.time], ExtraAt(extra, g.time, g.cell), f.retro);
    if (!rho.allFinite()) return;
    if (g.cell < 0) {
      far_sum += rho;
      ++far_count;
      ++s.pixels_far;
      return;
    }
    sum[2 * g.cell + g.shaded] += rho;
    ++count[2 * g.cell + g.shaded];
    ++s.pixels_used;
  });
  close_time();
  if (s.pixels_used == 0)
    throw Error("ground field: no landscape panorama pixel meets the ground around the model");

  // Over the times, the median per channel (of the sunlit times where there are some).
  f.albedo.assign(n, Eigen::Vector3f::Zero());
  f.observed.assign(n, 0);
  std::deque<int> open, elsewhere;
  for (int c = 0; c < n; ++c) {
    const std::vector<Eigen::Vector3f>& v =
        per_time[2 * c].empty() ? per_time[2 * c + 1] : per_time[2 * c];
    if (v.empty()) continue;
    for (int ch = 0; ch < 3; ++ch) {
      std::vector<float> x;
      for (const Eigen::Vector3f& a : v) x.push_back(a[ch]);
      f.albedo[c][ch] = Median(std::move(x));
    }
    f.observed[c] = 1;
    (f.sky_visibility[c] >= options.open_sky ? open : elsewhere).push_back(c);
    ++s.cells_observed;
  }
  // Unobserved cells: the nearest observed one's, of the open ground where some was seen (its
  // light the field models best: beside a wall a cell's reading rests on the walls' light).
  FillFromNearest(f.nx, f.ny, &f.albedo, f.observed, open.empty() ? elsewhere : open);
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

std::vector<Eigen::Vector3d> HiddenSkyExcess(const GroundWalls& walls, const SkyByDirection& sky,
                                             const Eigen::Vector3d& sky_e) {
  if (!sky) return {};
  std::vector<Eigen::Vector3d> out(walls.weight.size(), Eigen::Vector3d::Zero());
  tbb::parallel_for(size_t{0}, out.size(), [&](size_t c) {
    for (int k = walls.begin[c]; k < walls.begin[c + 1]; ++k) {
      const GroundWalls::Hit& h = walls.hits[k];
      const Eigen::Vector3d d = (h.position - h.from).cast<double>().normalized();
      if (d.allFinite() && d.z() > 0) out[c] += walls.weight[c] * (kPi * sky(d) - sky_e);
    }
  });
  return out;
}

GroundLight::GroundLight(const GroundField& field, const RayCaster& model,
                         const Eigen::Vector3d& sun_dir, const Eigen::Vector3d& sun_e,
                         const Eigen::Vector3d& sky_e, std::vector<Eigen::Vector3d> hidden_excess)
    : field_(&field),
      model_(&model),
      sun_dir_(sun_dir),
      sun_e_(sun_e),
      sky_e_(sky_e),
      hidden_excess_(std::move(hidden_excess)) {}

Eigen::Vector3d GroundLight::Radiance(const Eigen::Vector3d& q,
                                      const Eigen::Vector3d& to_viewer) const {
  const GroundField& f = *field_;
  const int cell = f.Cell(q.x(), q.y());
  const Eigen::Vector3d hidden = cell >= 0 && static_cast<size_t>(cell) < hidden_excess_.size()
                                     ? hidden_excess_[cell]
                                     : Eigen::Vector3d::Zero();
  return f.Albedo(cell).cwiseProduct(LightPerAlbedo(f, q, InShadow(*model_, q, sun_dir_), sun_dir_,
                                                    sun_e_, sky_e_, -hidden, to_viewer, f.retro));
}

Eigen::Vector3d GroundLight::Arriving(const Eigen::Vector3d& origin,
                                      const Eigen::Vector3d& d) const {
  const double h = origin.z() - field_->level_z;
  if (!(d.z() < 0) || !(h > 0)) return Eigen::Vector3d::Zero();
  return Radiance(origin + (h / -d.z()) * d, -d);
}

void to_json(nlohmann::json& j, const GroundFieldOptions& o) {
  // The config's key: false, true or "with_surroundings".
  const nlohmann::json enabled = o.use == GroundFieldUse::kWithSurroundings
                                     ? nlohmann::json("with_surroundings")
                                     : nlohmann::json(o.use == GroundFieldUse::kAlways);
  j = {{"enabled", enabled},
       {"cell_m", o.cell_m},
       {"radius_factor", o.radius_factor},
       {"min_radius_m", o.min_radius_m},
       {"max_cells", o.max_cells},
       {"sky_rays", o.sky_rays},
       {"open_sky", o.open_sky},
       {"walls", o.walls},
       {"fit_retro", o.fit_retro}};
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
       {"sky_rays", f.sky_rays},
       {"walls", f.walls},
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
  f.nx = JsonGet<int>(j.at("nx"), "ground field: nx");
  f.ny = JsonGet<int>(j.at("ny"), "ground field: ny");
  f.retro = j.at("retro").get<double>();
  // Absent in scenes written before the walls lit the ground: the default they were cast with.
  f.sky_rays = j.contains("sky_rays") ? JsonGet<int>(j.at("sky_rays"), "ground field: sky_rays")
                                      : GroundFieldOptions{}.sky_rays;
  f.walls = j.contains("walls") && j.at("walls").get<bool>();
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
