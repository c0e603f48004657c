#include "solve/albedo.h"

#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <string>
#include <unordered_map>

#include "core/angles.h"
#include "core/error.h"
#include "core/hash_random.h"
#include "core/stats.h"

namespace rouen {

namespace {

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// One equation of eqs. 11-12 for a point: y = pi I = rho_se e_se + rho_sun e_sun, per channel.
struct Equation {
  Eigen::Vector3d y, e_se, e_sun;
  double weight = 1;                                   // slot reliability (1 = full)
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();  // pi x Observation::measured
};

enum class Mode { kBoth, kSeOnly };

struct PointFit {
  Eigen::Vector3d rho_se = Eigen::Vector3d::Zero(), rho_sun = Eigen::Vector3d::Zero();
  bool clamped = false;
  std::vector<double> weights;
};

double RobustWeight(RobustLoss loss, double u, double huber_k) {
  const double a = std::abs(u);
  switch (loss) {
    case RobustLoss::kNone:
      return 1.0;
    case RobustLoss::kHuber:
      return a <= huber_k ? 1.0 : huber_k / a;
    case RobustLoss::kPaper: {
      // rho(u) = (1 - e^{-|u|/2}) / (1 + e^{-|u|/2}) = tanh(|u|/4); w = rho'(u) / u, with the
      // L1-like core capped at |u| = 1 and normalised to 1 there.
      const double sech = 1.0 / std::cosh(a / 4);
      return sech * sech / std::max(a, 1.0);
    }
  }
  return 1.0;
}

// Minimises x^T A x - 2 x^T b over x >= 0 (2 unknowns).
Eigen::Vector2d Nnls2(const Eigen::Matrix2d& A, const Eigen::Vector2d& b, bool* clamped) {
  const double det = A.determinant();
  const double scale = std::max(A(0, 0) * A(1, 1), 1e-300);
  if (det > 1e-12 * scale) {
    const Eigen::Vector2d x = A.inverse() * b;
    if (x.minCoeff() >= 0) return x;
  }
  auto cost = [&](const Eigen::Vector2d& x) { return x.dot(A * x) - 2 * x.dot(b); };
  Eigen::Vector2d best = Eigen::Vector2d::Zero();
  double best_cost = 0;
  for (int k = 0; k < 2; ++k) {
    if (A(k, k) <= 0) continue;
    Eigen::Vector2d x = Eigen::Vector2d::Zero();
    x[k] = std::max(0.0, b[k] / A(k, k));
    const double c = cost(x);
    if (c < best_cost) {
      best_cost = c;
      best = x;
    }
  }
  *clamped = true;
  return best;
}

// Eqs. 11-12 for one point by IRLS on relative residuals. `ratio` fixes rho_sun = ratio x
// rho_se in kSeOnly mode; with prior_weight > 0 it is a soft prior in kBoth mode.
PointFit FitPoint(const std::vector<Equation>& eqs, Mode mode, const Eigen::Vector3d& ratio,
                  double prior_weight, const AlbedoOptions& o) {
  const int n = static_cast<int>(eqs.size());
  PointFit fit;
  fit.weights.assign(n, 1.0);
  // Relative errors: sigma_k = pi I_k (of what the photo measured, where light was taken out of
  // I_k), floored at o.relative_error_floor x the channel mean.
  Eigen::Vector3d mean_y = Eigen::Vector3d::Zero(), mean_e = Eigen::Vector3d::Zero();
  for (const auto& q : eqs) {
    mean_y += q.y;
    mean_e += q.e_se + q.e_sun;
  }
  mean_y /= n;
  mean_e /= n;
  std::vector<Eigen::Vector3d> inv_sigma(n);
  for (int k = 0; k < n; ++k) {
    for (int c = 0; c < 3; ++c) {
      inv_sigma[k][c] =
          std::sqrt(eqs[k].weight) /
          std::max({eqs[k].y[c], eqs[k].measured[c], o.relative_error_floor * mean_y[c], 1e-30});
    }
  }
  const int unknowns = mode == Mode::kBoth ? 2 : 1;
  for (int it = 0; it < std::max(1, o.irls_iterations); ++it) {
    for (int c = 0; c < 3; ++c) {
      if (mode == Mode::kSeOnly) {
        double num = 0, den = 0;
        for (int k = 0; k < n; ++k) {
          const double w = fit.weights[k] * inv_sigma[k][c] * inv_sigma[k][c];
          const double x = eqs[k].e_se[c] + ratio[c] * eqs[k].e_sun[c];
          num += w * x * eqs[k].y[c];
          den += w * x * x;
        }
        const double a = den > 0 ? num / den : 0;
        fit.clamped = fit.clamped || a < 0;
        fit.rho_se[c] = std::max(0.0, a);
        fit.rho_sun[c] = ratio[c] * fit.rho_se[c];
        continue;
      }
      Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
      Eigen::Vector2d b = Eigen::Vector2d::Zero();
      double wsum = 0;
      for (int k = 0; k < n; ++k) {
        const double w = fit.weights[k] * inv_sigma[k][c] * inv_sigma[k][c];
        const Eigen::Vector2d x(eqs[k].e_se[c], eqs[k].e_sun[c]);
        A += w * x * x.transpose();
        b += w * x * eqs[k].y[c];
        wsum += fit.weights[k];
      }
      if (prior_weight > 0) {
        // Row (-ratio, 1) / rho_ref: a relative deviation from the block ratio.
        const double rho_ref = std::max(mean_y[c] / std::max(mean_e[c], 1e-300), 1e-6);
        const Eigen::Vector2d r(-ratio[c] / rho_ref, 1.0 / rho_ref);
        A += prior_weight * wsum * r * r.transpose();
      }
      bool clamped = false;
      const Eigen::Vector2d x = Nnls2(A, b, &clamped);
      fit.clamped = fit.clamped || clamped;
      fit.rho_se[c] = x[0];
      fit.rho_sun[c] = x[1];
    }
    if (o.loss == RobustLoss::kNone || n <= unknowns + 1) break;
    std::vector<double> z(n), az(n);
    for (int k = 0; k < n; ++k) {
      double s2 = 0;
      for (int c = 0; c < 3; ++c) {
        const double pred = fit.rho_se[c] * eqs[k].e_se[c] + fit.rho_sun[c] * eqs[k].e_sun[c];
        const double r = (eqs[k].y[c] - pred) * inv_sigma[k][c];
        s2 += r * r;
      }
      z[k] = std::sqrt(s2 / 3);
      az[k] = z[k];
    }
    const double scale = std::max(1.4826 * Median(az), o.min_scale);
    double change = 0;
    for (int k = 0; k < n; ++k) {
      const double w = RobustWeight(o.loss, z[k] / scale, o.huber_k);
      change = std::max(change, std::abs(w - fit.weights[k]));
      fit.weights[k] = w;
    }
    if (change < o.irls_tolerance) break;
  }
  return fit;
}

// Sunlit: the sun's irradiance (green) above `threshold` x the sky and environment's.
bool IsSunlit(const Eigen::Vector3d& e_sun, const Eigen::Vector3d& e_se, double threshold) {
  return e_sun[1] > threshold * std::max(e_se[1], 1e-300);
}

bool IsSunlit(const Equation& q, double threshold) { return IsSunlit(q.e_sun, q.e_se, threshold); }

// Never-observed points (category 0) filled from observed ones (category 1..3) of the same
// block: the inverse-square-distance mean of up to 6 within `radius` in the same plane, then of
// up to 6 within 4 x `radius` anywhere on the block. Which points fill which depends on the
// grid and the categories only, so the outer iterations make the plan once and apply it to
// each iteration's albedos.
struct FillPlan {
  double radius = -1;
  std::vector<uint8_t> category_in;   // the categories it was made for
  std::vector<uint8_t> category_out;  // the same with the filled points at 4
  std::vector<int> target;            // filled points
  std::vector<int> begin;             // per target, into source / weight (size target + 1)
  std::vector<int> source;
  std::vector<double> weight;  // normalised per target
};

// One pass: points of category 0 near observed ones within `radius` join the plan; with
// `plane_tolerance_m` > 0 only those of the same plane (normals within 2.6 deg, and each within
// that distance of the other's plane), else any of the same block.
void PlanFillPass(const SurfaceGrid& grid, double radius, double plane_tolerance_m,
                  const std::vector<uint8_t>& cat, FillPlan* plan) {
  constexpr double kSamePlaneCos = 0.999;
  constexpr int kMaxSources = 6;
  const int n = grid.size();
  const double R = radius;
  auto key = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(static_cast<int>(std::floor(p.x() / R)),
                           static_cast<int>(std::floor(p.y() / R)),
                           static_cast<int>(std::floor(p.z() / R)));
  };
  // A cell per block: a point looks only at its own block's points.
  auto hash = [](const Eigen::Vector3i& k, int block) {
    return (static_cast<int64_t>(k.x()) * 73856093) ^ (static_cast<int64_t>(k.y()) * 19349663) ^
           (static_cast<int64_t>(k.z()) * 83492791) ^ (static_cast<int64_t>(block) * 2654435761);
  };
  std::unordered_map<int64_t, std::vector<int>> cells;
  for (int i = 0; i < n; ++i) {
    const GridPoint& p = grid.points[i];
    if (cat[i] >= 1 && cat[i] <= 3) cells[hash(key(p.position), p.block)].push_back(i);
  }
  // Per point: its nearest sources (distance, index), found in parallel.
  std::vector<std::array<std::pair<double, int>, kMaxSources>> found(n);
  std::vector<uint8_t> count(n, 0);
  tbb::parallel_for(0, n, [&](int i) {
    if (cat[i] != 0) return;
    const GridPoint& p = grid.points[i];
    const Eigen::Vector3i k = key(p.position);
    std::vector<std::pair<double, int>> near;
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          auto it = cells.find(hash(k + Eigen::Vector3i(dx, dy, dz), p.block));
          if (it == cells.end()) continue;
          for (int j : it->second) {
            const GridPoint& q = grid.points[j];
            if (q.block != p.block) continue;
            if (plane_tolerance_m > 0 &&
                (q.normal.dot(p.normal) < kSamePlaneCos ||
                 std::abs(p.normal.dot(q.position - p.position)) > plane_tolerance_m)) {
              continue;
            }
            const double d = (q.position - p.position).norm();
            if (d <= R) near.emplace_back(d, j);
          }
        }
      }
    }
    const size_t m = std::min<size_t>(near.size(), kMaxSources);
    std::partial_sort(near.begin(), near.begin() + m, near.end());
    std::copy(near.begin(), near.begin() + m, found[i].begin());
    count[i] = static_cast<uint8_t>(m);
  });
  for (int i = 0; i < n; ++i) {
    if (count[i] == 0) continue;
    double wsum = 0;
    for (int a = 0; a < count[i]; ++a) wsum += 1.0 / (found[i][a].first * found[i][a].first + 1e-6);
    for (int a = 0; a < count[i]; ++a) {
      plan->source.push_back(found[i][a].second);
      plan->weight.push_back(1.0 / (found[i][a].first * found[i][a].first + 1e-6) / wsum);
    }
    plan->target.push_back(i);
    plan->begin.push_back(static_cast<int>(plan->source.size()));
    plan->category_out[i] = 4;
  }
}

FillPlan PlanFill(const SurfaceGrid& grid, double radius, double plane_tolerance_m,
                  const std::vector<uint8_t>& category) {
  FillPlan plan;
  plan.radius = radius;
  plan.category_in = category;
  plan.category_out = category;
  plan.begin.push_back(0);
  PlanFillPass(grid, radius, plane_tolerance_m, category, &plan);
  // The wider pass draws on observed points only, as the first: what it fills is what the
  // first left at 0.
  std::vector<uint8_t> rest = plan.category_out;
  PlanFillPass(grid, 4 * radius, 0, rest, &plan);
  return plan;
}

void ApplyFill(const FillPlan& plan, AlbedoResult* res) {
  for (size_t t = 0; t < plan.target.size(); ++t) {
    Eigen::Vector3d se = Eigen::Vector3d::Zero(), sun = Eigen::Vector3d::Zero();
    for (int k = plan.begin[t]; k < plan.begin[t + 1]; ++k) {
      se += plan.weight[k] * res->rho_se[plan.source[k]];
      sun += plan.weight[k] * res->rho_sun[plan.source[k]];
    }
    const int i = plan.target[t];
    res->rho_se[i] = se;
    res->rho_sun[i] = sun;
    res->flags[i] |= kAlbedoNoObservations | kAlbedoFilled;
  }
}

}  // namespace

void ObservationOptions::Validate() const {
  if (!(margin_px >= 0)) throw Error("ObservationOptions: margin_px must be >= 0");
  if (!(occlusion_tolerance >= 0 && occlusion_tolerance < 0.5)) {
    throw Error("ObservationOptions: occlusion_tolerance must be in [0, 0.5)");
  }
  if (!(min_cos_view >= 0 && min_cos_view < 1)) {
    throw Error("ObservationOptions: min_cos_view must be in [0, 1)");
  }
  if (!(plane_tolerance_m > 0)) throw Error("ObservationOptions: plane_tolerance_m must be > 0");
}

void AlbedoOptions::Validate() const {
  if (!(huber_k > 0)) throw Error("AlbedoOptions: huber_k must be > 0");
  if (!(min_scale > 0)) throw Error("AlbedoOptions: min_scale must be > 0");
  if (irls_iterations < 1) throw Error("AlbedoOptions: irls_iterations must be >= 1");
  if (!(irls_tolerance >= 0 && irls_tolerance < 1))
    throw Error("AlbedoOptions: irls_tolerance must be within [0, 1)");
  if (!(relative_error_floor >= 0 && relative_error_floor <= 1))
    throw Error("AlbedoOptions: relative_error_floor must be within [0, 1]");
  if (outer_iterations < 1) throw Error("AlbedoOptions: outer_iterations must be >= 1");
  if (!(outer_quantile > 0 && outer_quantile <= 1))
    throw Error("AlbedoOptions: outer_quantile must be within (0, 1]");
  if (!(outer_tolerance >= 0 && outer_tolerance < 1))
    throw Error("AlbedoOptions: outer_tolerance must be within [0, 1)");
  if (bounces < 1) throw Error("AlbedoOptions: bounces must be >= 1");
  if (!(sunlit_threshold > 0)) throw Error("AlbedoOptions: sunlit_threshold must be > 0");
  if (!(never_shadowed_prior >= 0)) throw Error("AlbedoOptions: never_shadowed_prior must be >= 0");
  if (!(ratio_prior >= 0)) throw Error("AlbedoOptions: ratio_prior must be >= 0");
  if (!(fill_radius_m >= 0)) throw Error("AlbedoOptions: fill_radius_m must be >= 0");
  if (!(retro_residual_cap > 0)) throw Error("AlbedoOptions: retro_residual_cap must be > 0");
  if (!(retro_min_gain >= 0)) throw Error("AlbedoOptions: retro_min_gain must be >= 0");
  sun_lobe.Validate();
  sky_lobe.Validate();
  if (retro_min_observations < 1) {
    throw Error("AlbedoOptions: retro_min_observations must be >= 1");
  }
  observation.Validate();
  irradiance.Validate();
}

std::string AlbedoSummary::BriefReport() const {
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "albedo: %d/%d points observed (%lld obs, %d filled from neighbours), "
                "sun-unobserved %d, never-shadowed %d, clamped %d, relative residual median "
                "%.2f%% p90 %.2f%%, downweighted %.1f%%, "
                "%d outer iterations, last change %.3f%%, %.2f s",
                points_observed, points, static_cast<long long>(observations),
                points_filled_neighbours, points_sun_unobserved, points_never_shadowed,
                points_clamped, 100 * residual_median_rel, 100 * residual_p90_rel,
                100 * downweighted_fraction, outer_iterations,
                change_per_iteration.empty() ? 0.0 : 100 * change_per_iteration.back(), seconds);
  return buf;
}

// App. B by ray casting, then a bilinear radiance sample per visible point and photo.
std::vector<Observation> CollectObservations(const SurfaceGrid& grid, const RayCaster& model,
                                             const std::vector<ArchitecturePhoto>& photos,
                                             const ObservationOptions& options,
                                             ObservationSummary* summary,
                                             const std::vector<Eigen::Vector3d>* sun_dirs) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  if (sun_dirs) {
    for (const auto& s : *sun_dirs) {
      if (!s.allFinite() || std::abs(s.norm() - 1) > 1e-3) {
        throw Error("observations: a sun direction is not a unit vector");
      }
    }
  }
  for (size_t p = 0; p < photos.size(); ++p) {
    const ArchitecturePhoto& ph = photos[p];
    const std::string name = ph.name.empty() ? "photo " + std::to_string(p) : ph.name;
    ph.intrinsics.Validate();
    if (ph.image.empty() || ph.image.channels < 3) {
      throw Error(name + ": empty image or fewer than 3 channels");
    }
    if (ph.image.width != ph.intrinsics.width || ph.image.height != ph.intrinsics.height) {
      throw Error(name + ": image is " + std::to_string(ph.image.width) + "x" +
                  std::to_string(ph.image.height) + " but the intrinsics say " +
                  std::to_string(ph.intrinsics.width) + "x" + std::to_string(ph.intrinsics.height));
    }
    if (ph.image.units != PixelUnits::kRadiance) {
      throw Error(name + ": architecture photos must hold radiance (HDR)");
    }
    if (!ph.mask.empty() &&
        ph.mask.size() != static_cast<size_t>(ph.image.width) * ph.image.height) {
      throw Error(name + ": mask has " + std::to_string(ph.mask.size()) + " entries, expected " +
                  std::to_string(static_cast<size_t>(ph.image.width) * ph.image.height));
    }
    if (ph.slot < 0) throw Error(name + ": negative slot index");
    if (sun_dirs && ph.slot >= static_cast<int>(sun_dirs->size())) {
      throw Error(name + ": slot " + std::to_string(ph.slot) + " has no sun direction");
    }
  }
  const int n = grid.size();
  std::vector<std::vector<Observation>> per_point(n);
  std::vector<int64_t> projected(n, 0), occluded(n, 0), invalid(n, 0), mixed(n, 0), edge(n, 0);
  const double offset = model.surface_offset();
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i < range.end(); ++i) {
      const GridPoint& gp = grid.points[i];
      for (size_t p = 0; p < photos.size(); ++p) {
        const ArchitecturePhoto& ph = photos[p];
        if (!ph.blocks.empty() &&
            !(gp.block >= 0 && gp.block < static_cast<int>(ph.blocks.size()) &&
              ph.blocks[gp.block]))
          continue;
        const Eigen::Vector3d to_cam = ph.pose.position - gp.position;
        const double dist = to_cam.norm();
        if (!(dist > 0) || gp.normal.dot(to_cam) < options.min_cos_view * dist) continue;
        const auto px = Project(ph.intrinsics, ph.pose.WorldToCamera(gp.position));
        if (!px) continue;
        const double x = px->x(), y = px->y(), m = options.margin_px;
        if (!(x >= m && y >= m && x <= ph.image.width - m && y <= ph.image.height - m)) continue;
        ++projected[i];
        const Eigen::Vector3d dir = -to_cam / dist;
        if (model.Occluded(ph.pose.position, dir, 0.0, dist * (1 - options.occlusion_tolerance))) {
          ++occluded[i];
          continue;
        }
        // The bilinear footprint: the four pixel centres around (x, y).
        const int x0 = std::clamp(static_cast<int>(std::floor(x - 0.5)), 0, ph.image.width - 1);
        const int y0 = std::clamp(static_cast<int>(std::floor(y - 0.5)), 0, ph.image.height - 1);
        const int x1 = std::min(x0 + 1, ph.image.width - 1);
        const int y1 = std::min(y0 + 1, ph.image.height - 1);
        bool ok = true;
        for (int yy : {y0, y1}) {
          for (int xx : {x0, x1}) {
            if (!ph.mask.empty() && ph.mask[static_cast<size_t>(yy) * ph.image.width + xx] == 0) {
              ok = false;
            }
            for (int c = 0; c < 3; ++c) {
              const float v = ph.image.at(xx, yy, c);
              ok = ok && std::isfinite(v) && v >= 0;
            }
          }
        }
        if (!ok) {
          ++invalid[i];
          continue;
        }
        // Footprint: a 3x3 lattice over the 2x2 pixel block (pixel corners, the outer ones
        // slightly inset). The bilinear sample needs the whole block on the point's plane (and
        // on one side of any shadow edge); failing that, the nearest pixel alone may qualify.
        bool use_nearest = false;
        if (options.check_footprint || sun_dirs) {
          bool on_plane[3][3];
          int lit[3][3];
          const Eigen::Vector3d* sun = sun_dirs ? &(*sun_dirs)[ph.slot] : nullptr;
          for (int b = 0; b < 3; ++b) {
            for (int a = 0; a < 3; ++a) {
              on_plane[b][a] = true;
              lit[b][a] = 0;
              // The middle lattice lines only matter for the nearest-pixel fallback.
              if ((a == 1 || b == 1) && !options.nearest_pixel_fallback) continue;
              const double xx = x0 + (a == 0 ? 0.05 : (a == 1 ? 1.0 : 1.95));
              const double yy = y0 + (b == 0 ? 0.05 : (b == 1 ? 1.0 : 1.95));
              const Eigen::Vector3d d =
                  (ph.pose.rotation * Unproject(ph.intrinsics, Eigen::Vector2d(xx, yy)))
                      .normalized();
              const RayHit h = model.Intersect(ph.pose.position, d, 0.0);
              on_plane[b][a] = h.hit && grid.triangle_n[h.triangle] > 0;
              if (!on_plane[b][a]) continue;
              const Eigen::Vector3d q = ph.pose.position + h.t * d;
              on_plane[b][a] =
                  std::abs(gp.normal.dot(q - gp.position)) <= options.plane_tolerance_m &&
                  grid.points[grid.triangle_first[h.triangle]].normal.dot(gp.normal) >= 0.999;
              if (sun) {
                lit[b][a] =
                    gp.normal.dot(*sun) > 0 && !model.Occluded(q + offset * gp.normal, *sun, 0.0);
              }
            }
          }
          // Is the footprint with lattice corners [a0, a0 + span] x [b0, b0 + span] clean?
          auto clean = [&](int a0, int b0, int span, bool* plane_ok) {
            bool plane = true;
            int n_lit = 0;
            for (int b : {b0, b0 + span}) {
              for (int a : {a0, a0 + span}) {
                plane = plane && on_plane[b][a];
                n_lit += lit[b][a];
              }
            }
            *plane_ok = plane || !options.check_footprint;
            return *plane_ok && (!sun || n_lit == 0 || n_lit == 4);
          };
          bool plane_ok = false;
          if (!clean(0, 0, 2, &plane_ok)) {
            // The pixel containing (x, y): x0 or x0 + 1, i.e. lattice columns [0, 1] or [1, 2].
            const int a0 = std::clamp(static_cast<int>(std::floor(x)) - x0, 0, 1);
            const int b0 = std::clamp(static_cast<int>(std::floor(y)) - y0, 0, 1);
            bool plane1 = false;
            if (!options.nearest_pixel_fallback || !clean(a0, b0, 1, &plane1)) {
              // Counted by the footprint that decided: shadow edge when it lay on the plane.
              const bool plane = options.nearest_pixel_fallback ? plane1 : plane_ok;
              ++(plane ? edge[i] : mixed[i]);
              continue;
            }
            use_nearest = true;
          }
        }
        Observation ob;
        ob.point = i;
        ob.slot = ph.slot;
        ob.photo = static_cast<int>(p);
        ob.view_dir = (to_cam / dist).cast<float>();
        for (int c = 0; c < 3; ++c) {
          ob.radiance[c] = use_nearest
                               ? ph.image.at(std::clamp(static_cast<int>(std::floor(x)), x0, x1),
                                             std::clamp(static_cast<int>(std::floor(y)), y0, y1), c)
                               : ph.image.Sample(x, y, c);
        }
        per_point[i].push_back(ob);
      }
    }
  });
  std::vector<Observation> out;
  ObservationSummary s;
  for (int i = 0; i < n; ++i) {
    s.projected += projected[i];
    s.occluded += occluded[i];
    s.invalid_pixels += invalid[i];
    s.mixed_footprint += mixed[i];
    s.shadow_edge += edge[i];
    s.points_observed += !per_point[i].empty();
    out.insert(out.end(), per_point[i].begin(), per_point[i].end());
  }
  s.observations = static_cast<int64_t>(out.size());
  s.seconds = Seconds(start);
  if (summary) *summary = s;
  return out;
}

// Eqs. 11-12 with per-slot weights (empty: all 1); defined below. `fill` (optional) keeps the
// neighbour fill's plan between calls on one grid.
static AlbedoResult SolveWeighted(const SurfaceGrid& grid,
                                  const std::vector<Observation>& observations,
                                  const std::vector<SlotIrradiance>& irradiance,
                                  const AlbedoOptions& options,
                                  const std::vector<double>& slot_weight, const SunShading* shading,
                                  FillPlan* fill = nullptr);

// Eqs. 11-12 per grid point with fixed irradiance.
AlbedoResult SolveAlbedoFixedIrradiance(const SurfaceGrid& grid,
                                        const std::vector<Observation>& observations,
                                        const std::vector<SlotIrradiance>& irradiance,
                                        const AlbedoOptions& options, const SunShading* shading) {
  return SolveWeighted(grid, observations, irradiance, options, {}, shading);
}

namespace {

// The factors on an observation's sun irradiance and its sky + environment irradiance: its
// block's RetroFactor and AmbientRetroFactor (both 1 without shading or for Lambert).
struct ShadingFactors {
  double sun = 1, se = 1;
};
ShadingFactors FactorsOf(const SurfaceGrid& grid, const Observation& ob, const SlotIrradiance& irr,
                         const SunShading* shading) {
  if (!shading) return {};
  const GridPoint& gp = grid.points[ob.point];
  const double retro = BlockRetro(shading->retro, gp.block);
  if (retro == 0) return {};
  const Eigen::Vector3d v = ob.view_dir.cast<double>();
  return {RetroFactor(retro, gp.normal, shading->sun_dirs[ob.slot], v),
          AmbientRetroFactor(retro, gp.normal, v, LightAt(irr.se_light, ob.point, gp.normal))};
}

// pi I of an observation as the solution `res` predicts it in channel c (eqs. 11-12), with the
// irradiances scaled by the observation's factors `f` (FactorsOf).
double Predicted(const AlbedoResult& res, const SlotIrradiance& irr, const Observation& ob,
                 const ShadingFactors& f, int c) {
  return res.rho_se[ob.point][c] * irr.se[ob.point][c] * f.se +
         res.rho_sun[ob.point][c] * irr.sun[ob.point][c] * f.sun;
}

// Per-slot weights from the residuals of a solution: (median over all slots / slot's median
// |relative residual|)^2, at most 1. A slot whose lighting model fits the photos worse than
// the others (e.g. a low sun, where the environment is least certain) counts less.
std::vector<double> SlotWeights(const SurfaceGrid& grid,
                                const std::vector<Observation>& observations,
                                const std::vector<SlotIrradiance>& irradiance,
                                const AlbedoResult& res, const SunShading* shading) {
  std::vector<std::vector<double>> per(irradiance.size());
  std::vector<double> all;
  for (const Observation& ob : observations) {
    if (res.flags[ob.point] & kAlbedoNoObservations) continue;
    const SlotIrradiance& irr = irradiance[ob.slot];
    const double y = kPi * ob.radiance[1];
    const double pred = Predicted(res, irr, ob, FactorsOf(grid, ob, irr, shading), 1);
    if (!(y > 0)) continue;
    const double r = std::abs(y - pred) / y;
    per[ob.slot].push_back(r);
    all.push_back(r);
  }
  const double m_all = Median(all);
  std::vector<double> w(irradiance.size(), 1.0);
  for (size_t s = 0; s < per.size(); ++s) {
    if (per[s].size() < 10 || !(m_all > 0)) continue;
    const double m = Median(per[s]);
    if (m > m_all) w[s] = (m_all / m) * (m_all / m);
  }
  return w;
}

}  // namespace

static AlbedoResult SolveWeighted(const SurfaceGrid& grid,
                                  const std::vector<Observation>& observations,
                                  const std::vector<SlotIrradiance>& irradiance,
                                  const AlbedoOptions& options,
                                  const std::vector<double>& slot_weight, const SunShading* shading,
                                  FillPlan* fill) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  // Polled per solve: the retro and lobe fits call this many times.
  ThrowIfCancelled(options.irradiance.cancel);
  const int n = grid.size();
  if (shading && shading->sun_dirs.size() < irradiance.size()) {
    throw Error("albedo: " + std::to_string(shading->sun_dirs.size()) + " sun directions for " +
                std::to_string(irradiance.size()) + " slots");
  }
  if (observations.empty()) throw Error("albedo: no observations of the model in any photo");
  for (size_t s = 0; s < irradiance.size(); ++s) {
    const SlotIrradiance& irr = irradiance[s];
    if (static_cast<int>(irr.sun.size()) != n || static_cast<int>(irr.se.size()) != n) {
      throw Error("albedo: irradiance of slot " + std::to_string(s) + " has " +
                  std::to_string(irr.sun.size()) + " points, the grid " + std::to_string(n));
    }
  }
  // Group by point (stable), validating indices.
  std::vector<int> order(observations.size());
  std::iota(order.begin(), order.end(), 0);
  for (const Observation& ob : observations) {
    if (ob.point < 0 || ob.point >= n) {
      throw Error("albedo: observation of grid point " + std::to_string(ob.point) +
                  " outside the grid (" + std::to_string(n) + " points)");
    }
    if (ob.slot < 0 || ob.slot >= static_cast<int>(irradiance.size())) {
      throw Error("albedo: observation in slot " + std::to_string(ob.slot) + " but only " +
                  std::to_string(irradiance.size()) + " slots have irradiance");
    }
    if (!ob.radiance.allFinite() || ob.radiance.minCoeff() < 0) {
      throw Error("albedo: observation of grid point " + std::to_string(ob.point) +
                  " has a negative or non-finite radiance");
    }
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return observations[a].point < observations[b].point; });
  std::vector<int> first(n + 1, 0);
  for (const Observation& ob : observations) ++first[ob.point + 1];
  for (int i = 0; i < n; ++i) first[i + 1] += first[i];

  std::vector<double> dark(irradiance.size(), 0.0);  // per slot: "no light" below this
  for (size_t s = 0; s < irradiance.size(); ++s) {
    for (size_t i = 0; i < irradiance[s].se.size() && i < irradiance[s].sun.size(); ++i)
      dark[s] = std::max(dark[s], (irradiance[s].se[i] + irradiance[s].sun[i]).maxCoeff());
    dark[s] *= 1e-9;
  }
  auto equations = [&](int i) {
    std::vector<Equation> eqs;
    for (int k = first[i]; k < first[i + 1]; ++k) {
      const Observation& ob = observations[order[k]];
      const SlotIrradiance& irr = irradiance[ob.slot];
      // A point that receives no light in this slot tells nothing about its albedo (less than
      // 1e-9 of the slot's brightest point is none: the exact irradiance of a point enclosed by
      // faces keeps rounding-level flux through their shared edges).
      if (!((irr.se[ob.point] + irr.sun[ob.point]).maxCoeff() > dark[ob.slot])) continue;
      const ShadingFactors f = FactorsOf(grid, ob, irr, shading);
      eqs.push_back({kPi * ob.radiance.cast<double>(), irr.se[ob.point] * f.se,
                     irr.sun[ob.point] * f.sun, slot_weight.empty() ? 1.0 : slot_weight[ob.slot],
                     kPi * ob.measured.cast<double>()});
    }
    return eqs;
  };

  AlbedoResult res;
  if (shading) res.retro = shading->retro;
  res.rho_sun.assign(n, Eigen::Vector3d::Zero());
  res.rho_se.assign(n, Eigen::Vector3d::Zero());
  res.observations.assign(n, 0);
  res.flags.assign(n, 0);
  std::vector<uint8_t> category(n, 0);  // 0 none, 1 good, 2 sun unobserved, 3 never shadowed
  for (int i = 0; i < n; ++i) {
    res.observations[i] = first[i + 1] - first[i];
    if (res.observations[i] == 0) continue;
    int sunlit = 0;
    const auto eqs = equations(i);
    if (eqs.empty()) continue;  // only observed when unlit: as if never observed
    for (const auto& q : eqs) sunlit += IsSunlit(q, options.sunlit_threshold);
    const int shadowed = static_cast<int>(eqs.size()) - sunlit;
    category[i] = sunlit == 0 ? 2 : (shadowed == 0 ? 3 : 1);
  }
  std::vector<std::vector<double>> weights(n);
  auto solve = [&](int i, Mode mode, const Eigen::Vector3d& ratio, double prior) {
    const PointFit fit = FitPoint(equations(i), mode, ratio, prior, options);
    res.rho_se[i] = fit.rho_se;
    res.rho_sun[i] = fit.rho_sun;
    if (fit.clamped) res.flags[i] |= kAlbedoClamped;
    weights[i] = fit.weights;
  };
  // Pass 1: points seen both sunlit and in shadow (eqs. 11 and 12 both present).
  tbb::parallel_for(0, n, [&](int i) {
    if (category[i] == 1) solve(i, Mode::kBoth, Eigen::Vector3d::Ones(), 0.0);
  });
  // Block ratios rho_sun / rho_se from those points (global median as a fallback, else 1).
  const int nblocks = [&] {
    int m = 0;
    for (const auto& p : grid.points) m = std::max(m, p.block + 1);
    return m;
  }();
  // Index block + 1 (block -1: triangles without a block); all_ratio pools every point.
  std::vector<std::array<std::vector<double>, 3>> block_ratio(nblocks + 1);
  std::array<std::vector<double>, 3> all_ratio;
  for (int i = 0; i < n; ++i) {
    if (category[i] != 1) continue;
    for (int c = 0; c < 3; ++c) {
      if (res.rho_se[i][c] > 1e-9) {
        const double r = res.rho_sun[i][c] / res.rho_se[i][c];
        block_ratio[grid.points[i].block + 1][c].push_back(r);
        all_ratio[c].push_back(r);
      }
    }
  }
  Eigen::Vector3d global_ratio = Eigen::Vector3d::Ones();
  for (int c = 0; c < 3; ++c) {
    if (!all_ratio[c].empty()) global_ratio[c] = Median(all_ratio[c]);
  }
  auto ratio_for = [&](int block) {
    Eigen::Vector3d r = global_ratio;
    for (int c = 0; c < 3; ++c) {
      const auto& v = block_ratio[block + 1][c];
      if (v.size() >= 3) r[c] = Median(v);
    }
    return r;
  };
  std::vector<Eigen::Vector3d> ratios(nblocks + 1);
  for (int b = -1; b < nblocks; ++b) ratios[b + 1] = ratio_for(b);
  // Pass 2: points lacking one of the two equations (and, with ratio_prior, all the others
  // again with the block ratio as a weak prior).
  tbb::parallel_for(0, n, [&](int i) {
    const Eigen::Vector3d& r = ratios[grid.points[i].block + 1];
    if (category[i] == 1 && options.ratio_prior > 0) {
      solve(i, Mode::kBoth, r, options.ratio_prior);
    } else if (category[i] == 2) {
      solve(i, Mode::kSeOnly, r, 0.0);
      res.flags[i] |= kAlbedoSunUnobserved;
    } else if (category[i] == 3) {
      solve(i, Mode::kBoth, r, options.never_shadowed_prior);
      res.flags[i] |= kAlbedoNeverShadowed;
    }
  });
  // Never-observed points: from the nearest observed points of the same face when close, then
  // of the same block (the paper's "fill in reflectance values from adjacent faces", §4.1).
  if (options.fill_radius_m > 0) {
    FillPlan local;
    FillPlan& plan = fill ? *fill : local;
    if (plan.radius != options.fill_radius_m || plan.category_in != category) {
      plan = PlanFill(grid, options.fill_radius_m, options.observation.plane_tolerance_m, category);
    }
    ApplyFill(plan, &res);
    category = plan.category_out;
  }
  // The rest: the block median, else the median of the blocks of its kind, else the global one.
  const auto kind_of = [&](int block) {
    return block >= 0 && block < static_cast<int>(options.block_kind.size())
               ? options.block_kind[block]
               : 0;
  };
  std::vector<std::array<std::vector<double>, 6>> block_vals(nblocks + 1);
  std::map<int, std::array<std::vector<double>, 6>> kind_vals;
  std::array<std::vector<double>, 6> all_vals;
  for (int i = 0; i < n; ++i) {
    if (category[i] == 0 || category[i] == 4) continue;
    auto& kind = kind_vals[kind_of(grid.points[i].block)];
    for (int c = 0; c < 3; ++c) {
      for (auto* vals : {&block_vals[grid.points[i].block + 1], &kind, &all_vals}) {
        (*vals)[c].push_back(res.rho_se[i][c]);
        (*vals)[c + 3].push_back(res.rho_sun[i][c]);
      }
    }
  }
  for (int b = -1; b < nblocks; ++b) {
    bool any = false;
    for (int i = 0; i < n && !any; ++i) any = category[i] == 0 && grid.points[i].block == b;
    if (!any) continue;
    const auto kind = kind_vals.find(kind_of(b));
    const auto& vals = !block_vals[b + 1][0].empty() ? block_vals[b + 1]
                       : kind != kind_vals.end()     ? kind->second
                                                     : all_vals;
    Eigen::Vector3d se, sun;
    for (int c = 0; c < 3; ++c) {
      se[c] = Median(vals[c]);
      sun[c] = Median(vals[c + 3]);
    }
    for (int i = 0; i < n; ++i) {
      if (category[i] != 0 || grid.points[i].block != b) continue;
      res.rho_se[i] = se;
      res.rho_sun[i] = sun;
      res.flags[i] |= kAlbedoNoObservations | kAlbedoFilled;
    }
  }
  // Summary: residuals over every observation.
  AlbedoSummary& s = res.summary;
  s.points = n;
  s.observations = static_cast<int64_t>(observations.size());
  std::vector<double> rel;
  rel.reserve(observations.size() * 3);
  int64_t down = 0;
  double sum2 = 0;
  for (int i = 0; i < n; ++i) {
    if (category[i] == 4) {
      ++s.points_filled_neighbours;
      category[i] = 0;
    }
    s.points_observed += category[i] != 0;
    s.points_sun_unobserved += category[i] == 2;
    s.points_never_shadowed += category[i] == 3;
    s.points_clamped += (res.flags[i] & kAlbedoClamped) != 0;
    if (category[i] == 0) continue;
    const auto eqs = equations(i);
    for (size_t k = 0; k < eqs.size(); ++k) {
      if (k < weights[i].size() && weights[i][k] < 0.5) ++down;
      for (int c = 0; c < 3; ++c) {
        if (!(eqs[k].y[c] > 0)) continue;  // no relative error of nothing (e.g. all highlight)
        const double pred = res.rho_se[i][c] * eqs[k].e_se[c] + res.rho_sun[i][c] * eqs[k].e_sun[c];
        const double r = (eqs[k].y[c] - pred) / eqs[k].y[c];
        rel.push_back(std::abs(r));
        sum2 += r * r;
      }
    }
  }
  s.residual_rms_rel = rel.empty() ? 0 : std::sqrt(sum2 / rel.size());
  s.residual_median_rel = Median(rel);
  s.residual_p90_rel = rel.empty() ? 0 : Quantile(rel, 0.9);
  s.downweighted_fraction = static_cast<double>(down) / observations.size();
  s.outer_iterations = 1;
  for (int i = 0; i < n; ++i) {
    if (!res.rho_se[i].allFinite() || !res.rho_sun[i].allFinite()) {
      throw Error("albedo: non-finite albedo at grid point " + std::to_string(i) +
                  " (degenerate irradiance?)");
    }
  }
  s.seconds = Seconds(start);
  return res;
}

namespace {

// Per block: the mean over its observed points' observations of the truncated |relative
// residual| per channel under `res`, and how many of the observations are sunlit.
struct BlockCosts {
  std::vector<double> cost;
  std::vector<int> sunlit;
};

BlockCosts CostsPerBlock(const SurfaceGrid& grid, const std::vector<Observation>& observations,
                         const std::vector<SlotIrradiance>& irradiance, const AlbedoResult& res,
                         const SunShading& shading, const AlbedoOptions& options, int nblocks) {
  BlockCosts bc;
  bc.cost.assign(nblocks, 0.0);
  bc.sunlit.assign(nblocks, 0);
  std::vector<double> weight(nblocks, 0.0);
  for (const Observation& ob : observations) {
    const int b = grid.points[ob.point].block;
    if (b < 0 || (res.flags[ob.point] & kAlbedoNoObservations)) continue;
    const SlotIrradiance& irr = irradiance[ob.slot];
    bc.sunlit[b] += IsSunlit(irr.sun[ob.point], irr.se[ob.point], options.sunlit_threshold);
    const ShadingFactors f = FactorsOf(grid, ob, irr, &shading);
    for (int c = 0; c < 3; ++c) {
      const double y = kPi * ob.radiance[c];
      if (!(y > 0)) continue;
      bc.cost[b] +=
          std::min(std::abs(y - Predicted(res, irr, ob, f, c)) / y, options.retro_residual_cap);
      weight[b] += 1;
    }
  }
  for (int b = 0; b < nblocks; ++b) bc.cost[b] = weight[b] > 0 ? bc.cost[b] / weight[b] : 0;
  return bc;
}

// Each block's retro parameter (solve/retro.h): the albedos are solved with every block at each
// candidate of a regular grid over [kRetroMin, kRetroMax] (0 among them), each block keeps its
// cheapest candidate, refined by a parabola through its neighbours when that lowers its cost.
// Blocks with too few sunlit observations stay at 0.
std::vector<double> FitRetro(const SurfaceGrid& grid, const std::vector<Observation>& observations,
                             const std::vector<SlotIrradiance>& irradiance,
                             const AlbedoOptions& options, const std::vector<double>& slot_weight,
                             const std::vector<Eigen::Vector3d>& sun_dirs, AlbedoSummary* summary) {
  int nblocks = 0;
  for (const auto& p : grid.points) nblocks = std::max(nblocks, p.block + 1);
  constexpr int kSteps = 8;  // candidates kRetroMin + k (kRetroMax - kRetroMin) / kSteps
  const double step = (kRetroMax - kRetroMin) / kSteps;
  SunShading shading{sun_dirs, {}};
  FillPlan fill;
  auto costs_at = [&](const std::vector<double>& retro) {
    shading.retro = retro;
    const AlbedoResult r =
        SolveWeighted(grid, observations, irradiance, options, slot_weight, &shading, &fill);
    return CostsPerBlock(grid, observations, irradiance, r, shading, options, nblocks);
  };
  std::vector<std::vector<double>> cost(kSteps + 1);
  std::vector<int> sunlit;
  for (int k = 0; k <= kSteps; ++k) {
    const BlockCosts bc = costs_at(std::vector<double>(nblocks, kRetroMin + k * step));
    cost[k] = bc.cost;
    sunlit = bc.sunlit;
  }
  const int k_zero = static_cast<int>(std::lround(-kRetroMin / step));
  std::vector<double> best(nblocks, 0.0), best_cost(nblocks), refined(nblocks, 0.0);
  for (int b = 0; b < nblocks; ++b) {
    best_cost[b] = cost[k_zero][b];
    if (sunlit[b] < options.retro_min_observations) continue;
    int kb = k_zero;
    for (int k = 0; k <= kSteps; ++k) {
      if (cost[k][b] < cost[kb][b]) kb = k;
    }
    best[b] = refined[b] = kRetroMin + kb * step;
    best_cost[b] = cost[kb][b];
    if (kb > 0 && kb < kSteps) {
      const double c0 = cost[kb - 1][b], c1 = cost[kb][b], c2 = cost[kb + 1][b];
      const double curvature = c0 - 2 * c1 + c2;
      if (curvature > 0) {
        refined[b] = best[b] + std::clamp(0.5 * step * (c0 - c2) / curvature, -step, step);
      }
    }
  }
  // The refinement's solve only when some block moved off its candidate.
  const BlockCosts fine = refined != best ? costs_at(refined) : BlockCosts{best_cost, sunlit};
  for (int b = 0; b < nblocks; ++b) {
    if (fine.cost[b] < best_cost[b]) {
      best[b] = refined[b];
      best_cost[b] = fine.cost[b];
    }
    // Lambert unless the fit explains the photos clearly better.
    if (cost[k_zero][b] - best_cost[b] < options.retro_min_gain) {
      best[b] = 0;
      best_cost[b] = cost[k_zero][b];
    }
  }
  // A block the photos saw too little to tell takes the median of the blocks they could tell
  // (the site's materials), not Lambert's law.
  std::vector<double> told;
  for (int b = 0; b < nblocks; ++b)
    if (sunlit[b] >= options.retro_min_observations) told.push_back(best[b]);
  if (!told.empty()) {
    const double site = Median(told);
    for (int b = 0; b < nblocks; ++b)
      if (sunlit[b] < options.retro_min_observations) best[b] = site;
  }
  if (summary) {
    summary->retro_cost_lambert = cost[k_zero];
    summary->retro_cost_fitted = best_cost;
  }
  return best;
}

// §4.2.2: each block's sun lobe from its sunlit observations' residual after the diffuse
// solution `res`, sigma the block's robust relative residual scale (at least min_scale) times
// the observed radiance.
std::vector<SpecularLobe> FitSunLobes(const SurfaceGrid& grid,
                                      const std::vector<Observation>& observations,
                                      const std::vector<SlotIrradiance>& irradiance,
                                      const AlbedoResult& res, const SunShading& shading,
                                      const AlbedoOptions& options, AlbedoSummary* summary,
                                      std::vector<std::vector<LobeSample>>* block_samples) {
  int nblocks = 0;
  for (const auto& p : grid.points) nblocks = std::max(nblocks, p.block + 1);
  std::vector<std::vector<double>> rel(nblocks);
  for (const Observation& ob : observations) {
    const int b = grid.points[ob.point].block;
    if (b < 0 || (res.flags[ob.point] & kAlbedoNoObservations)) continue;
    const double y = kPi * ob.radiance[1];
    if (!(y > 0)) continue;
    const double pred = Predicted(res, irradiance[ob.slot], ob,
                                  FactorsOf(grid, ob, irradiance[ob.slot], &shading), 1);
    rel[b].push_back(std::abs(y - pred) / y);
  }
  // Each block's robust scale of the diffuse fit's relative residuals (MAD), once per block.
  std::vector<double> block_scale(nblocks);
  for (int b = 0; b < nblocks; ++b)
    block_scale[b] = std::max(options.min_scale, 1.4826 * Median(rel[b]));
  std::vector<std::vector<LobeSample>> samples(nblocks);
  for (const Observation& ob : observations) {
    const GridPoint& gp = grid.points[ob.point];
    if (gp.block < 0 || (res.flags[ob.point] & kAlbedoNoObservations)) continue;
    const SlotIrradiance& irr = irradiance[ob.slot];
    if (!IsSunlit(irr.sun[ob.point], irr.se[ob.point], options.sunlit_threshold)) continue;
    const double scale = block_scale[gp.block];
    const ShadingFactors f = FactorsOf(grid, ob, irr, &shading);
    LobeSample s;
    s.normal = gp.normal;
    s.to_light = shading.sun_dirs[ob.slot];
    s.to_viewer = ob.view_dir.cast<double>();
    s.irradiance = irr.sun[ob.point];
    for (int c = 0; c < 3; ++c) {
      s.residual[c] = ob.radiance[c] - Predicted(res, irr, ob, f, c) / kPi;
      s.sigma[c] = scale * std::max<double>(ob.radiance[c], 1e-12);
    }
    samples[gp.block].push_back(s);
  }
  std::vector<SpecularLobe> lobes(nblocks);
  summary->lobe_samples.assign(nblocks, 0);
  summary->lobe_cost_zero.assign(nblocks, 0.0);
  summary->lobe_cost_fitted.assign(nblocks, 0.0);
  for (int b = 0; b < nblocks; ++b) {
    ThrowIfCancelled(options.irradiance.cancel);
    const LobeFit fit = FitSunLobe(samples[b], options.sun_lobe);
    lobes[b] = fit.lobe;
    summary->lobe_samples[b] = fit.samples;
    summary->lobe_cost_zero[b] = fit.cost_zero;
    summary->lobe_cost_fitted[b] = fit.cost;
  }
  *block_samples = std::move(samples);
  return lobes;
}

// The light of the sun lobes in observation `ob` (radiance).
Eigen::Vector3d SunLobeLight(const SurfaceGrid& grid, const std::vector<SpecularLobe>& lobes,
                             const SlotIrradiance& irr, const SunShading& shading,
                             const Observation& ob) {
  const GridPoint& gp = grid.points[ob.point];
  const SpecularLobe lobe = BlockLobe(lobes, gp.block);
  if (lobe.IsZero()) return Eigen::Vector3d::Zero();
  return lobe.Eval(gp.normal, shading.sun_dirs[ob.slot], ob.view_dir.cast<double>())
      .cwiseProduct(irr.sun[ob.point]);
}

// The sky and environment of grid point i at a slot, seen from `view`, as pieces (§4.2.1):
// the hemisphere cache's cosine-distributed directions and `mirror_count` more drawn about the
// view's mirror direction with `lobe`'s MirrorExponent, each weighed by MixtureWeight (a lobe of
// a few degrees falls between the cache's directions), bringing the radiance it meets: the
// escaped sky and environment, or the diffuse radiance of the grid point it hits.
std::vector<LightPiece> Pieces(const SurfaceGrid& grid, const HemisphereCache& cache,
                               const RayCaster& model, const Lighting& lighting,
                               const SlotIrradiance& irr, const AlbedoResult& res, int i,
                               const Eigen::Vector3d& view, const SpecularLobe& lobe,
                               int mirror_count) {
  const GridPoint& gp = grid.points[i];
  const Eigen::Vector3d m = 2 * view.dot(gp.normal) * gp.normal - view;
  const double e = lobe.MirrorExponent();
  auto radiance = [&](const Eigen::Vector3d& d, int hit) -> Eigen::Vector3d {
    if (hit == -1) return lighting.EscapedRadiance(d, gp.position.z());
    return (res.rho_sun[hit].cwiseProduct(irr.sun[hit]) +
            res.rho_se[hit].cwiseProduct(irr.se[hit])) /
           kPi;
  };
  std::vector<LightPiece> pieces;
  pieces.reserve(cache.directions + mirror_count);
  auto add = [&](const Eigen::Vector3d& d, int hit) {
    const double w = MixtureWeight(gp.normal, m, d, e, cache.directions, mirror_count);
    if (w > 0) pieces.push_back({d.cast<float>(), (w * radiance(d, hit)).cast<float>()});
  };
  for (int k = 0; k < cache.directions; ++k) {
    const int hit = cache.Hit(i, k);
    if (hit != -2) add(cache.Direction(gp, i, k), hit);
  }
  const int strata = static_cast<int>(std::ceil(std::sqrt(mirror_count)));
  uint64_t seed = MixHash(static_cast<uint64_t>(i));
  for (int c = 0; c < 3; ++c)
    seed = MixHash(seed ^ std::bit_cast<uint32_t>(static_cast<float>(view[c])));
  const Eigen::Vector3d origin = gp.position + model.surface_offset() * gp.normal;
  for (int k = 0; k < mirror_count; ++k) {
    const uint64_t h = MixHash(seed + static_cast<uint64_t>(k));
    const double u1 = ((k / strata) + HashUniformHigh(h)) / strata;
    const double u2 = ((k % strata) + HashUniformLow(h)) / strata;
    const Eigen::Vector3d d = DrawAboutAxis(m, e, u1, u2);
    if (!(d.dot(gp.normal) > 0)) continue;
    const RayHit h2 = model.Intersect(origin, d, 0.0);
    int hit = -1;
    if (h2.hit) {
      hit = grid.NearestPoint(h2.triangle, h2.u, h2.v);
      if (hit < 0 || grid.points[hit].normal.dot(d) >= 0) continue;  // a back face or no grid
    }
    add(d, hit);
  }
  return pieces;
}

// §4.2.1: the sky/environment lobe of each block with a sun lobe, from the residual of its
// observations after the diffuse albedos and the sun lobe.
// With the sky lobe taken from the sun's (SkyLobeOptions::Source::kSun), a sun lobe whose
// reflection of the sky the observations contradict is fitted again from `sun_samples` among
// the lobes they do not contradict (none when no lobe passes): *sun_lobes is updated.
std::vector<SpecularLobe> FitSkyLobes(const SurfaceGrid& grid, const HemisphereCache& cache,
                                      const RayCaster& model, const std::vector<Lighting>& slots,
                                      const std::vector<Observation>& observations,
                                      const std::vector<SlotIrradiance>& irradiance,
                                      const AlbedoResult& res, const SunShading& shading,
                                      const AlbedoOptions& options,
                                      const std::vector<std::vector<LobeSample>>& sun_samples,
                                      std::vector<SpecularLobe>* sun_lobes,
                                      AlbedoSummary* summary) {
  const int nblocks = static_cast<int>(res.sun_lobes.size());
  std::vector<SpecularLobe> lobes(nblocks);
  summary->sky_lobe_samples.assign(nblocks, 0);
  summary->sky_lobe_cost_zero.assign(nblocks, 0.0);
  summary->sky_lobe_cost_fitted.assign(nblocks, 0.0);
  for (int b = 0; b < nblocks; ++b) {
    if (res.sun_lobes[b].IsZero()) continue;
    ThrowIfCancelled(options.irradiance.cancel);
    std::vector<const Observation*> of_block;
    std::vector<double> rel;
    for (const Observation& ob : observations) {
      if (grid.points[ob.point].block != b || (res.flags[ob.point] & kAlbedoNoObservations))
        continue;
      of_block.push_back(&ob);
      const double y = kPi * ob.radiance[1];
      if (y > 0)
        rel.push_back(
            std::abs(y - Predicted(res, irradiance[ob.slot], ob,
                                   FactorsOf(grid, ob, irradiance[ob.slot], &shading), 1)) /
            y);
    }
    const double scale = std::max(options.min_scale, 1.4826 * Median(rel));
    const size_t keep =
        std::min(of_block.size(), static_cast<size_t>(options.sky_lobe.max_samples));
    std::vector<SkyLobeSample> samples(keep);
    tbb::parallel_for(size_t{0}, keep, [&](size_t k) {
      const Observation& ob = *of_block[(k * of_block.size()) / keep];
      const GridPoint& gp = grid.points[ob.point];
      const SlotIrradiance& irr = irradiance[ob.slot];
      SkyLobeSample& s = samples[k];
      s.normal = gp.normal;
      s.to_viewer = ob.view_dir.cast<double>();
      s.pieces = Pieces(grid, cache, model, slots[ob.slot], irr, res, ob.point, s.to_viewer,
                        res.sun_lobes[b], options.sky_lobe.mirror_samples);
      const ShadingFactors f = FactorsOf(grid, ob, irr, &shading);
      const Eigen::Vector3d sun_lobe = SunLobeLight(grid, res.sun_lobes, irr, shading, ob);
      for (int c = 0; c < 3; ++c) {
        s.residual[c] = ob.radiance[c] - Predicted(res, irr, ob, f, c) / kPi - sun_lobe[c];
        s.sigma[c] = scale * std::max<double>(ob.radiance[c], 1e-12);
        s.diffuse_se[c] = res.rho_se[ob.point][c] * irr.se[ob.point][c] * f.se / kPi;
      }
    });
    LobeFit fit = FitSkyLobe(samples, options.sky_lobe, res.sun_lobes[b]);
    if (options.sky_lobe.source == SkyLobeOptions::Source::kSun && !fit.kept &&
        b < static_cast<int>(sun_samples.size())) {
      // One material: the sun lobe that best explains the sunlit observations among those
      // whose reflection of the sky these observations do not contradict.
      const double limit = fit.cost_zero;
      const SkyLobeCosts costs(samples);
      const LobeFit sun = FitSunLobe(sun_samples[b], options.sun_lobe, [&](const SpecularLobe& l) {
        return costs.CostRefittingDiffuse(l) <= limit;
      });
      (*sun_lobes)[b] = sun.lobe;
      summary->lobe_cost_fitted[b] = sun.cost;
      if (sun.kept) fit = FitSkyLobe(samples, options.sky_lobe, sun.lobe);
    }
    lobes[b] = fit.lobe;
    summary->sky_lobe_samples[b] = fit.samples;
    summary->sky_lobe_cost_zero[b] = fit.cost_zero;
    summary->sky_lobe_cost_fitted[b] = fit.cost;
  }
  return lobes;
}

// A zero albedo in the outer iteration's steps in log rho: the step from this floor.
constexpr double kLogFloor = 1e-4;

// Aitken's extrapolation of the outer iteration, per point, channel and albedo in log rho: two
// steps in the same direction, the second lambda times the first (0 < lambda < 1), say the
// iteration contracts by lambda, so the rest of the way is the second step times
// lambda / (1 - lambda) (lambda at most kMaxRatio: at most 4 more steps). Every other iteration,
// after one not extrapolated, whose step measures lambda afresh.
void Extrapolate(const AlbedoResult& from, AlbedoResult* to,
                 std::vector<std::array<double, 6>>* last_step) {
  constexpr double kMaxRatio = 0.8;
  const size_t n = to->rho_sun.size();
  const bool extrapolate = !last_step->empty();
  std::vector<std::array<double, 6>> steps(extrapolate ? 0 : n);
  for (size_t i = 0; i < n; ++i) {
    if (to->observations[i] <= 0) continue;  // its steps stay 0: never extrapolated
    for (int a = 0; a < 2; ++a) {
      for (int c = 0; c < 3; ++c) {
        double& x = (a == 0 ? to->rho_sun[i] : to->rho_se[i])[c];
        const double b = (a == 0 ? from.rho_sun[i] : from.rho_se[i])[c];
        const double d = std::log(std::max(x, kLogFloor)) - std::log(std::max(b, kLogFloor));
        if (!extrapolate) {
          steps[i][3 * a + c] = d;
          continue;
        }
        const double d0 = (*last_step)[i][3 * a + c];
        if (!(d * d0 > 0 && std::abs(d) < std::abs(d0)) || x <= 0) continue;
        const double lambda = std::min(d / d0, kMaxRatio);
        x = std::exp(std::log(x) + d * lambda / (1 - lambda));
      }
    }
  }
  *last_step = std::move(steps);
}

}  // namespace

// §4.1: albedos, then the one-bounce interreflection from them, then albedos again.
AlbedoResult SolveAlbedo(const SurfaceGrid& grid, const HemisphereCache& cache,
                         const RayCaster& model, const std::vector<Lighting>& slots,
                         const std::vector<Observation>& observations, const AlbedoOptions& options,
                         std::vector<SlotIrradiance>* irradiance, const AlbedoResult* warm) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  if (slots.empty()) throw Error("albedo: no time-of-day slots");
  if (warm && (static_cast<int>(warm->rho_sun.size()) != grid.size() ||
               static_cast<int>(warm->rho_se.size()) != grid.size()))
    throw Error("albedo: the albedos to start from are not of this grid");
  // Polled by every albedo solve (SolveWeighted), each lobe fit's blocks, each bounce.
  const Cancellation* cancel = options.irradiance.cancel;
  // Every slot at once: the vector flux's per-point geometry is shared by all of them. Exact
  // where photographed; the points no photo sees only light the others (interreflection).
  std::vector<uint8_t> observed(grid.size(), 0);
  for (const Observation& ob : observations)
    if (ob.point >= 0 && ob.point < grid.size()) observed[ob.point] = 1;
  IrradianceOptions io = options.irradiance;
  if (!io.exact_points) io.exact_points = &observed;
  std::vector<SlotIrradiance> irr = ComputeIrradiance(grid, cache, model, slots, io);
  const std::vector<std::shared_ptr<const GroundBounce>> ground =
      GroundBouncesOf(slots, model, grid, cache);
  SunShading shading;
  for (const Lighting& l : slots) shading.sun_dirs.push_back(l.sun_dir.normalized());
  AlbedoSummary retro_summary;
  FillPlan fill;  // made once, again only if the observed points change
  AlbedoResult res =
      warm ? *warm : SolveWeighted(grid, observations, irr, options, {}, &shading, &fill);
  if (warm) shading.retro = warm->retro;
  if (!warm && options.fit_retro && options.outer_iterations == 1) {
    shading.retro =
        FitRetro(grid, observations, irr, options, {}, shading.sun_dirs, &retro_summary);
    res = SolveWeighted(grid, observations, irr, options, {}, &shading, &fill);
  }
  std::vector<double> changes;
  std::vector<double> slot_weight;
  // The outer iteration from `res` on the observations `obs`, the blocks' sun lobes sending
  // their glint with the bounce (AddInterreflection's sun_lobes); the retro is fitted at its
  // first iteration when `fit_retro`.
  auto iterate = [&](const std::vector<Observation>& obs, const std::vector<SpecularLobe>& lobes,
                     bool fit_retro) {
    // Per point, channel and albedo (sun, then sky + environment): the last outer step in log
    // rho, when it was not extrapolated (AlbedoOptions::outer_aitken).
    std::vector<std::array<double, 6>> last_step;
    for (int it = 1; it < options.outer_iterations; ++it) {
      // Per point, for Newton's step: the sum over the slots of k x the light bounced k times,
      // and of all the light.
      std::vector<Eigen::Vector3d> order_sum, light_sum, order;
      if (options.outer_newton) {
        order_sum.assign(grid.size(), Eigen::Vector3d::Zero());
        light_sum.assign(grid.size(), Eigen::Vector3d::Zero());
      }
      for (size_t k = 0; k < irr.size(); ++k) {
        AddInterreflection(grid, cache, res.rho_sun, res.rho_se, &irr[k], options.bounces,
                           shading.retro, shading.sun_dirs[k], cancel,
                           options.outer_newton ? &order : nullptr, ground[k].get(), lobes);
        if (!options.outer_newton) continue;
        for (int i = 0; i < grid.size(); ++i) {
          order_sum[i] += order[i];
          light_sum[i] += irr[k].sun[i] + irr[k].se[i];
        }
      }
      if (options.slot_weighting) slot_weight = SlotWeights(grid, obs, irr, res, &shading);
      // Once, with the first interreflection: later iterations change the bounce little.
      if (fit_retro && it == 1)
        shading.retro =
            FitRetro(grid, obs, irr, options, slot_weight, shading.sun_dirs, &retro_summary);
      AlbedoResult next = SolveWeighted(grid, obs, irr, options, slot_weight, &shading, &fill);
      // The step the new solve proposes, per observed point (relative, the largest over the
      // channels and both albedos), then the outer update (AlbedoOptions::outer_newton).
      std::vector<double> step;
      for (int i = 0; i < grid.size(); ++i) {
        double largest = 0;
        for (int c = 0; c < 3; ++c) {
          for (const auto& [a, b] : {std::pair{next.rho_sun[i][c], res.rho_sun[i][c]},
                                     std::pair{next.rho_se[i][c], res.rho_se[i][c]}}) {
            if (a + b > 0) largest = std::max(largest, std::abs(a - b) / (0.5 * (a + b)));
          }
        }
        if (next.observations[i] > 0) step.push_back(largest);
        if (!options.outer_newton) continue;
        for (int c = 0; c < 3; ++c) {
          // Newton's step on log rho for rho E(rho) = pi I: the solve's rho_new = pi I / E(rho)
          // overshoots by E's elasticity s to the albedos (s = sum_k k x light bounced k times,
          // over all the light), so the root lies 1 / (1 + s) of the way there in log rho.
          const double sc =
              light_sum[i][c] > 0 ? std::max(0.0, order_sum[i][c] / light_sum[i][c]) : 0.0;
          const double f = 1 / (1 + sc);
          for (auto [a, b] : {std::pair{&next.rho_sun[i][c], res.rho_sun[i][c]},
                              std::pair{&next.rho_se[i][c], res.rho_se[i][c]}}) {
            if (f < 1)
              *a = std::exp(
                  std::log(std::max(b, kLogFloor)) +
                  f * (std::log(std::max(*a, kLogFloor)) - std::log(std::max(b, kLogFloor))));
          }
        }
      }
      changes.push_back(step.empty() ? 0.0 : Quantile(step, options.outer_quantile));
      // Not at the last iteration: what the iteration returns is a solve's.
      const bool done = changes.back() < options.outer_tolerance;
      if (options.outer_aitken && !done && it + 1 < options.outer_iterations)
        Extrapolate(res, &next, &last_step);
      res = std::move(next);
      if (done) break;
    }
  };
  iterate(observations, warm ? warm->sun_lobes : std::vector<SpecularLobe>{}, options.fit_retro);
  if (options.sun_lobe.fit) {
    AlbedoSummary lobe_summary;
    std::vector<std::vector<LobeSample>> sun_samples;
    std::vector<SpecularLobe> sun_lobes =
        FitSunLobes(grid, observations, irr, res, shading, options, &lobe_summary, &sun_samples);
    std::vector<SpecularLobe> sky_lobes;
    auto any = [](const std::vector<SpecularLobe>& l) {
      return std::any_of(l.begin(), l.end(), [](const auto& x) { return !x.IsZero(); });
    };
    // What the lobes leave of each observation (a highlight the lobes over-explain leaves
    // nothing rather than negative light): the diffuse albedos' observations.
    auto diffuse_observations = [&] {
      std::vector<Observation> diffuse = observations;
      for (Observation& ob : diffuse) {
        Eigen::Vector3d lobe_light = SunLobeLight(grid, sun_lobes, irr[ob.slot], shading, ob);
        const GridPoint& gp = grid.points[ob.point];
        const SpecularLobe sky = BlockLobe(sky_lobes, gp.block);
        if (!sky.IsZero()) {
          for (const LightPiece& p :
               Pieces(grid, cache, model, slots[ob.slot], irr[ob.slot], res, ob.point,
                      ob.view_dir.cast<double>(), sky, options.sky_lobe.mirror_samples))
            lobe_light += sky.Eval(gp.normal, p.to_light.cast<double>(), ob.view_dir.cast<double>())
                              .cwiseProduct(p.irradiance.cast<double>());
        }
        ob.measured = ob.measured.cwiseMax(ob.radiance);
        ob.radiance = (ob.radiance - lobe_light.cast<float>()).cwiseMax(0.f);
      }
      return diffuse;
    };
    auto resolve = [&](const std::vector<Observation>& diffuse) {
      return SolveWeighted(grid, diffuse, irr, options, slot_weight, &shading, &fill);
    };
    // The light the lobes send on (AddInterreflection's sun_lobes: a roof's glint on the walls
    // across the street), from the albedos so far, for the albedos solved again.
    auto bounce = [&] {
      for (size_t k = 0; k < irr.size(); ++k)
        AddInterreflection(grid, cache, res.rho_sun, res.rho_se, &irr[k], options.bounces,
                           shading.retro, shading.sun_dirs[k], cancel, nullptr, ground[k].get(),
                           sun_lobes);
    };
    if (any(sun_lobes)) {
      // The outer iteration again with the glint in the bounce: the walls it lights take darker
      // albedos, which light their neighbours less (once, from the albedos so far, the glint's
      // light counted twice on the nave world's north wall: 4% too bright).
      const std::vector<Observation> diffuse = diffuse_observations();
      iterate(diffuse, sun_lobes, false);
      res = resolve(diffuse);
      res.sun_lobes = sun_lobes;
      if (options.sky_lobe.fit) {
        const std::vector<SpecularLobe> fitted = sun_lobes;
        sky_lobes = FitSkyLobes(grid, cache, model, slots, observations, irr, res, shading, options,
                                sun_samples, &sun_lobes, &lobe_summary);
        // The albedos again where the lobes changed: a sky lobe, or a sun lobe fitted again.
        bool changed = false;
        for (size_t b = 0; b < sun_lobes.size(); ++b) {
          const SpecularLobe &l = sun_lobes[b], &f = fitted[b];
          changed |= l.rho_s != f.rho_s || l.n != f.n || l.kappa != f.kappa || l.model != f.model;
        }
        if (changed) bounce();
        if (any(sky_lobes) || changed) res = resolve(diffuse_observations());
        res.sun_lobes = sun_lobes;
      }
    }
    res.sun_lobes = std::move(sun_lobes);
    res.sky_lobes = std::move(sky_lobes);
    res.summary.lobe_samples = lobe_summary.lobe_samples;
    res.summary.lobe_cost_zero = lobe_summary.lobe_cost_zero;
    res.summary.lobe_cost_fitted = lobe_summary.lobe_cost_fitted;
    res.summary.sky_lobe_samples = lobe_summary.sky_lobe_samples;
    res.summary.sky_lobe_cost_zero = lobe_summary.sky_lobe_cost_zero;
    res.summary.sky_lobe_cost_fitted = lobe_summary.sky_lobe_cost_fitted;
  }
  res.summary.change_per_iteration = changes;
  res.summary.retro_cost_lambert = retro_summary.retro_cost_lambert;
  res.summary.retro_cost_fitted = retro_summary.retro_cost_fitted;
  res.summary.outer_iterations = 1 + static_cast<int>(changes.size());
  res.summary.slot_weights =
      slot_weight.empty() ? std::vector<double>(slots.size(), 1.0) : slot_weight;
  if (irradiance) {
    // Hand back the irradiance with the interreflection from the returned albedos (ready for
    // rendering these slots).
    for (size_t k = 0; k < irr.size(); ++k) {
      AddInterreflection(grid, cache, res.rho_sun, res.rho_se, &irr[k], options.bounces,
                         shading.retro, shading.sun_dirs[k], cancel, nullptr, ground[k].get(),
                         res.sun_lobes);
    }
    *irradiance = std::move(irr);
  }
  res.summary.seconds = Seconds(start);
  return res;
}

}  // namespace rouen
