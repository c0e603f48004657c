// Direct sky + environment irradiance on the demo's building model (capture/sim: tower, plaza):
// the vector flux of clipped spherical polygons (App. A; solve/vector_flux.h,
// solve/vector_flux_cache.h) against brute-force Monte Carlo (stratified cosine directions,
// ray-cast visibility, the HemisphereCache pattern).
//
// Reference: a fine vector flux (every model face as occluder, 8-level sky tree, sky tolerance
// 0.005, environment parallels followed by 64 arcs per region), validated against 1024^2 =
// 1048576-direction Monte Carlo on a subset of the points (the difference is printed next to
// the Monte Carlo noise, estimated from two seeds). Errors of both methods are measured
// against it; its own error is far below theirs.
//
// Ratios printed, CPU time of one thread (the machine is shared), at equal mean relative error:
//  (i)  from scratch per point: vector flux including finding the occluders (every face in
//       front, exact culling; the Embree id buffer is measured separately), projection and
//       clipping, vs Monte Carlo including its ray casting;
//  (ii) visibility cached for both (the marginal cost of one more lighting): vector flux's
//       cached patches (a sum of dot products, plus the per-lighting sky-tree integration
//       shared by all the grid's points) vs Monte Carlo's cached escaped directions (radiance
//       look-ups only).
// The Monte Carlo sample count reaching the vector flux's error comes from a log-log fit of
// Monte Carlo's measured error against the reference over K = 64 .. 65536.
#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include "bench/results.h"
#include "capture/sim/sim_scene.h"
#include "core/angles.h"
#include "core/mesh.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"
#include "solve/vector_flux.h"
#include "solve/vector_flux_cache.h"

namespace rouen {
namespace {

// This thread's CPU time, seconds (the machine is shared: wall time would measure the load).
double CpuNow() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

// This process's CPU time over all threads, seconds (less sensitive than wall time to other
// programs on a shared machine).
double ProcessCpuNow() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

struct World {
  Mesh mesh;
  SurfaceGrid grid;
  std::unique_ptr<RayCaster> rc;
  std::unique_ptr<FaceAdjacency> adj;
  std::unique_ptr<OccluderFaces> faces;  // the occluders ComputeIrradiance uses
  std::vector<int> sample;               // grid points studied
  World() {
    sim::TexelSizes sizes;
    mesh = sim::BuildScene(sizes).model;
    GridOptions go;  // as app/pipeline.cc
    go.spacing_m = 0.6;
    go.block_spacing_m["plaza"] = 1.5;
    grid = BuildSurfaceGrid(mesh, go);
    rc = std::make_unique<RayCaster>(mesh);
    adj = std::make_unique<FaceAdjacency>(mesh);
    faces = std::make_unique<OccluderFaces>(mesh);
    const int n = 48;
    for (int k = 0; k < n; ++k) {
      sample.push_back(static_cast<int>((static_cast<int64_t>(k) * 7919 + 13) % grid.size()));
    }
  }
  Eigen::Vector3d Origin(int i) const {
    const GridPoint& p = grid.points[i];
    return p.position + rc->surface_offset() * p.normal;
  }
};

const World& TheWorld() {
  static const World w;
  return w;
}

// A clear afternoon sky (eq. 9 parameters of CIE-clear shape) and an environment map: the
// sky averaged per region above the horizon, landscape regions of varying radiance below.
Lighting DemoLighting(bool use_env) {
  Lighting l;
  SkyModel sky;
  sky.channel[0] = SkyParams{1.0, -1.0, -0.32, 10, -3, 0.45, 1};
  sky.channel[1] = SkyParams{1.2, -1.0, -0.4, 12, -3.2, 0.5, 1};
  sky.channel[2] = SkyParams{1.5, -1.0, -0.5, 8, -2.5, 0.3, 1};
  sky.sun_dir = Eigen::Vector3d(0.55, -0.45, 0.7).normalized();
  l.sky = sky;
  l.sun_dir = sky.sun_dir;
  l.sun_radiance.setZero();
  l.env = EnvironmentMap::FromSky(EnvOptions(), sky, Eigen::Vector3d(0.3, 0.25, 0.2));
  for (int r = 0; r < l.env.bands_below * l.env.sectors; ++r) {
    l.env.radiance[r] = Eigen::Vector3d(0.2 + 0.1 * std::sin(r), 0.25 + 0.08 * std::cos(0.7 * r),
                                        0.3 + 0.05 * (r % 5));
  }
  l.use_env = use_env;
  return l;
}

// Monte Carlo estimate at one point with K = strata^2 stratified cosine directions (the
// HemisphereCache pattern, its own seed): ray casting and radiance look-ups.
Eigen::Vector3d MonteCarlo(const World& w, const Lighting& l, int i, int strata, uint64_t seed) {
  HemisphereCache c;
  c.strata = strata;
  c.directions = strata * strata;
  c.seed = seed;
  const GridPoint& p = w.grid.points[i];
  const Eigen::Vector3d o = w.Origin(i);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int k = 0; k < c.directions; ++k) {
    const Eigen::Vector3d d = c.Direction(p, i, k);
    if (!w.rc->Occluded(o, d, 0.0)) sum += l.EscapedRadiance(d, p.position.z());
  }
  return sum * (kPi / c.directions);
}

// Monte Carlo with visibility cached: the escaped directions of one point (best case for
// Monte Carlo: the directions themselves are stored, not recomputed).
struct McCache {
  std::vector<Eigen::Vector3d> escaped;
  int directions = 0;
};
McCache BuildMcCache(const World& w, int i, int strata, uint64_t seed) {
  HemisphereCache c;
  c.strata = strata;
  c.directions = strata * strata;
  c.seed = seed;
  McCache m;
  m.directions = c.directions;
  const GridPoint& p = w.grid.points[i];
  const Eigen::Vector3d o = w.Origin(i);
  for (int k = 0; k < c.directions; ++k) {
    const Eigen::Vector3d d = c.Direction(p, i, k);
    if (!w.rc->Occluded(o, d, 0.0)) m.escaped.push_back(d);
  }
  return m;
}
Eigen::Vector3d EvalMcCache(const McCache& m, const Lighting& l, double z) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& d : m.escaped) sum += l.EscapedRadiance(d, z);
  return sum * (kPi / m.directions);
}

struct VfSetup {
  VectorFluxOptions options;
  OccluderSelectOptions select;
  bool all_faces = false;  // every face in front as occluder (no id buffer)
  std::unique_ptr<SkyPatchTree> tree;
  std::unique_ptr<EnvironmentRegions> regions;
  VfSetup(const Lighting& l, int levels, double tol, int segments, bool all) : all_faces(all) {
    options.sky_tolerance = tol;
    options.env_parallel_segments = segments;
    tree = std::make_unique<SkyPatchTree>(levels);
    regions = std::make_unique<EnvironmentRegions>(l.env, options);
  }
};

// What a point keeps between lightings: the sky tree's or the environment regions' weights.
struct VfCache {
  PointFluxCache sky;
  EnvironmentView env;
};

// The per-point, lighting-independent part from scratch.
VfCache VfGeometry(const World& w, const VfSetup& s, int i, bool use_env,
                   int* occluders = nullptr) {
  const GridPoint& p = w.grid.points[i];
  const Eigen::Vector3d o = w.Origin(i);
  VfCache c;
  auto run = [&](const PointVisibility& vis) {
    if (occluders) *occluders = vis.num_occluders();
    if (use_env) {
      SeeEnvironment(vis, *s.regions, false, &c.env);
    } else {
      CacheSky(vis, *s.tree, &c.sky);
    }
  };
  if (s.all_faces) {
    run(PointVisibility(*w.faces, o, p.normal, p.triangle));
  } else {
    const std::vector<int> cand =
        SelectOccluders(w.mesh, *w.rc, *w.adj, o, p.normal, p.triangle, s.select);
    run(PointVisibility(*w.faces, o, p.normal, p.triangle, &cand));
  }
  return c;
}

Eigen::Vector3d VfEval(const World& w, const VfCache& c, const Lighting& l,
                       const SkyTreeRadiance* sky, int i) {
  if (l.use_env) return EnvironmentIrradiance(c.env, l.env, w.grid.points[i].position.z());
  return EvaluateSky(c.sky, *sky);
}

double MeanRelError(const std::vector<Eigen::Vector3d>& e, const std::vector<Eigen::Vector3d>& ref,
                    double* worst = nullptr) {
  double sum = 0, wmax = 0;
  int n = 0;
  for (size_t k = 0; k < e.size(); ++k) {
    if (!(ref[k].norm() > 1e-9)) continue;
    const double r = (e[k] - ref[k]).norm() / ref[k].norm();
    sum += r;
    wmax = std::max(wmax, r);
    ++n;
  }
  if (worst) *worst = wmax;
  return n ? sum / n : 0;
}

void Study(bool use_env) {
  const World& w = TheWorld();
  const Lighting l = DemoLighting(use_env);
  const int n = static_cast<int>(w.sample.size());
  std::printf("\n== %s: %d grid points of the demo model (%zu triangles, %d grid points) ==\n",
              use_env ? "ENVIRONMENT MAP (the demo's path)" : "SKY MODEL (eq. 9), adaptive", n,
              w.mesh.triangles.size(), w.grid.size());

  // --- Reference: fine vector flux, validated against 1M-direction Monte Carlo.
  VfSetup fine(l, 8, 0.005, 64, true);
  double t0 = CpuNow();
  const SkyTreeRadiance fine_sky(*fine.tree, l.sky, fine.options);
  const double fine_tree_s = CpuNow() - t0;
  std::vector<Eigen::Vector3d> ref(n);
  tbb::parallel_for(0, n, [&](int k) {
    const VfCache c = VfGeometry(w, fine, w.sample[k], use_env);
    ref[k] = VfEval(w, c, l, &fine_sky, w.sample[k]);
  });
  const int nval = 12;
  std::vector<Eigen::Vector3d> mc_a(nval), mc_b(nval), ref_sub(ref.begin(), ref.begin() + nval);
  tbb::parallel_for(0, nval, [&](int k) {
    mc_a[k] = MonteCarlo(w, l, w.sample[k], 1024, 99);
    mc_b[k] = MonteCarlo(w, l, w.sample[k], 1024, 7);
  });
  double noise_worst, diff_worst;
  const double noise = MeanRelError(mc_a, mc_b, &noise_worst) / std::sqrt(2.0);
  std::vector<Eigen::Vector3d> mc_mean(nval);
  for (int k = 0; k < nval; ++k) mc_mean[k] = 0.5 * (mc_a[k] + mc_b[k]);
  const double diff = MeanRelError(mc_mean, ref_sub, &diff_worst);
  std::printf(
      "reference: fine vector flux (all faces, 8-level tree, tol 0.005, 64 arcs; sky "
      "tree %.2f s). Validation on %d points vs 2 x 1048576-direction Monte Carlo: "
      "mean rel diff %.2e (max %.2e); that Monte Carlo's own noise ~%.2e (1 run), "
      "%.2e (mean of 2)\n",
      fine_tree_s, nval, diff, diff_worst, noise, noise / std::sqrt(2.0));

  // --- Default vector flux (every face in front, exact culling), and the Embree id-buffer
  // occluder selection against it (same discretisation).
  VfSetup def(l, 6, 0.1, 4, true), def_sel(l, 6, 0.1, 4, false);
  t0 = CpuNow();
  const SkyTreeRadiance sky(*def.tree, l.sky, def.options);
  const double tree_s = CpuNow() - t0;
  std::vector<VfCache> caches(n);
  std::vector<Eigen::Vector3d> vf(n), vf_sel(n);
  int occ_sel = 0, occ_all = 0, entries = 0, partial = 0;
  t0 = CpuNow();
  for (int k = 0; k < n; ++k) {
    int o = 0;
    caches[k] = VfGeometry(w, def, w.sample[k], use_env, &o);
    occ_all += o;
  }
  const double geom_s = (CpuNow() - t0) / n;
  t0 = CpuNow();
  const int reps = 20;
  for (int r = 0; r < reps; ++r) {
    for (int k = 0; k < n; ++k) vf[k] = VfEval(w, caches[k], l, &sky, w.sample[k]);
  }
  const double eval_s = (CpuNow() - t0) / (n * reps);
  for (const auto& c : caches) {
    entries += static_cast<int>(c.sky.sky_node.size() + c.env.region.size());
    partial += c.sky.partial_nodes;
  }
  t0 = CpuNow();
  for (int k = 0; k < n; ++k) {
    int o = 0;
    const VfCache c = VfGeometry(w, def_sel, w.sample[k], use_env, &o);
    occ_sel += o;
    vf_sel[k] = VfEval(w, c, l, &sky, w.sample[k]);
  }
  const double geom_sel_s = (CpuNow() - t0) / n;
  double sel_worst;
  const double sel_err = MeanRelError(vf_sel, vf, &sel_worst);
  if (std::getenv("ROUEN_DEBUG_SELECT")) {  // diagnostics: the faces the id buffer missed
    for (int k = 0; k < n; ++k) {
      if (!(vf[k].norm() > 1e-9)) continue;
      const double r = (vf_sel[k] - vf[k]).norm() / vf[k].norm();
      if (r < 1e-4) continue;
      const int i = w.sample[k];
      const GridPoint& p = w.grid.points[i];
      const Eigen::Vector3d o = w.Origin(i);
      const std::vector<int> cand =
          SelectOccluders(w.mesh, *w.rc, *w.adj, o, p.normal, p.triangle, def_sel.select);
      std::printf("point %d tri %d pos %s n %s rel %.2e sel %zu\n", i, p.triangle,
                  std::to_string(p.position.x()).c_str(), std::to_string(p.normal.z()).c_str(), r,
                  cand.size());
      for (int t = 0; t < static_cast<int>(w.mesh.triangles.size()); ++t) {
        if (std::binary_search(cand.begin(), cand.end(), t) || t == p.triangle) continue;
        const PointVisibility one(w.mesh, o, p.normal, p.triangle, std::vector<int>{t});
        if (one.num_occluders() == 0) continue;
        // Visible part of this face given the selected ones.
        const PointVisibility sel(w.mesh, o, p.normal, p.triangle, cand);
        std::vector<SphericalPolygon> vis;
        sel.Clip(one.occluder(0).vertices, &vis);
        double pw = 0;
        for (const auto& q : vis) pw += p.normal.dot(VectorFlux(q));
        if (pw > 1e-5) {
          std::printf("  missed face %d block %d omega %.3e visible n.phi %.3e\n", t,
                      w.mesh.triangle_block[t], SolidAngle(one.occluder(0).vertices), pw);
        }
      }
    }
  }
  std::printf(
      "occluder selection (Embree id buffer %dx%d rays, silhouette pixels, +%d ring): "
      "%.1f occluders/point vs %.1f with every face in front (after exact culling); "
      "irradiance vs all faces: mean rel diff %.2e, max %.2e; geometry %.3f ms vs %.3f "
      "ms CPU/point (default: all faces)\n",
      def_sel.select.resolution, def_sel.select.resolution, def_sel.select.grow_rings,
      static_cast<double>(occ_sel) / n, static_cast<double>(occ_all) / n, sel_err, sel_worst,
      geom_sel_s * 1e3, geom_s * 1e3);
  double vf_worst;
  const double vf_err = MeanRelError(vf, ref, &vf_worst);
  const double tree_per_point = use_env ? 0 : tree_s / w.grid.size();
  std::printf("vector flux (default: %s): vs reference mean rel error %.2e, max %.2e (%s)\n",
              use_env ? "4 arcs per parallel" : "6-level tree, tol 0.1", vf_err, vf_worst,
              vf_err <= 0.005 ? "<= 0.5%" : "ABOVE 0.5%");
  std::printf(
      "  geometry (projection + culling + clipping) %.3f ms/point; evaluation %.2f "
      "us/point (%.0f cached entries, %.0f partly visible deepest nodes); per lighting "
      "%s%.2f ms for the whole grid = %.2f us/point amortised over %d points\n",
      geom_s * 1e3, eval_s * 1e6, static_cast<double>(entries) / n,
      static_cast<double>(partial) / n, use_env ? "(nothing) " : "sky tree ",
      use_env ? 0.0 : tree_s * 1e3, tree_per_point * 1e6, w.grid.size());

  // --- Monte Carlo convergence (vs the reference), from scratch and with visibility cached.
  std::vector<double> ks, errs, t_scratch, t_cached;
  for (int strata : {8, 16, 32, 64, 128, 256}) {
    std::vector<Eigen::Vector3d> mc(n);
    std::vector<McCache> mcc(n);
    t0 = CpuNow();
    for (int k = 0; k < n; ++k) mcc[k] = BuildMcCache(w, w.sample[k], strata, 1);
    const double build_s = (CpuNow() - t0) / n;
    t0 = CpuNow();
    for (int k = 0; k < n; ++k) {
      mc[k] = EvalMcCache(mcc[k], l, w.grid.points[w.sample[k]].position.z());
    }
    const double cached_s = (CpuNow() - t0) / n;
    double worst;
    const double err = MeanRelError(mc, ref, &worst);
    ks.push_back(strata * strata);
    errs.push_back(err);
    t_scratch.push_back(build_s + cached_s);
    t_cached.push_back(cached_s);
    std::printf(
        "monte carlo K=%6d: mean rel error %.2e, max %.2e; from scratch %.3f ms/point, "
        "cached %.3f ms/point\n",
        strata * strata, err, worst, (build_s + cached_s) * 1e3, cached_s * 1e3);
  }
  // log-log least-squares fit err = a K^slope over the runs.
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const int m = static_cast<int>(ks.size());
  for (int j = 0; j < m; ++j) {
    const double x = std::log(ks[j]), y = std::log(errs[j]);
    sx += x, sy += y, sxx += x * x, sxy += x * y;
  }
  const double slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
  const double icpt = (sy - slope * sx) / m;
  const double k_needed = std::exp((std::log(vf_err) - icpt) / slope);
  const double per_dir_scratch = t_scratch.back() / ks.back();
  const double per_dir_cached = t_cached.back() / ks.back();
  const double mc_scratch = k_needed * per_dir_scratch, mc_cached = k_needed * per_dir_cached;
  const double vf_scratch = geom_s + eval_s + tree_per_point;
  const double vf_cached = eval_s + tree_per_point;
  // A measured point further out: one 1048576-direction run on the validation points.
  double big_worst;
  const double big_err = MeanRelError(mc_a, ref_sub, &big_worst);
  const double big_k = 1024.0 * 1024.0;
  std::printf("monte carlo K=%.0f (the %d validation points): mean rel error %.2e, max %.2e\n",
              big_k, nval, big_err, big_worst);
  std::printf(
      "monte carlo error ~ K^%.2f (fit over K = 64..65536): reaching %.2e needs ~%.3g "
      "directions/point: %.1f ms from scratch, %.2f ms cached\n",
      slope, vf_err, k_needed, mc_scratch * 1e3, mc_cached * 1e3);
  const char* path = use_env ? "env" : "sky";
  std::printf(
      "RATIO (i)  from scratch, %s: monte carlo %.2f ms / vector flux %.3f ms = %.0fx "
      "at error %.2e (%s)\n",
      path, mc_scratch * 1e3, vf_scratch * 1e3, mc_scratch / vf_scratch, vf_err,
      vf_err <= 0.005 ? "<= 0.5%" : "ABOVE 0.5%");
  std::printf(
      "RATIO (ii) visibility cached (per lighting), %s: monte carlo %.2f ms / vector "
      "flux %.2f us = %.0fx at error %.2e\n",
      path, mc_cached * 1e3, vf_cached * 1e6, mc_cached / vf_cached, vf_err);
  const std::string key = std::string("irradiance.") + path;
  bench::Record(key + ".vector_flux_rel_error", vf_err, "");
  bench::Record(key + ".x_monte_carlo_from_scratch", mc_scratch / vf_scratch, "ratio",
                "Monte Carlo with ray-cast visibility at equal mean error (directions from a "
                "log-log fit of its measured error)");
  bench::Record(key + ".x_monte_carlo_cached", mc_cached / vf_cached, "ratio",
                "Monte Carlo with cached visibility at equal mean error");
  if (vf_err <= big_err) {
    // No extrapolation: Monte Carlo at 1048576 directions is measured to be still worse.
    std::printf(
        "RATIO lower bounds without extrapolation (monte carlo at K=1048576 still has "
        "%.2e > %.2e): (i) %.0fx, (ii) %.0fx\n",
        big_err, vf_err, big_k * per_dir_scratch / vf_scratch, big_k * per_dir_cached / vf_cached);
  }
}

// Task-level figure: ComputeIrradiance over the whole demo grid (as the albedo solve calls it
// once per time slot), Monte Carlo with the pipeline's 256-direction cache vs vector flux,
// environment map with the ground-shadow correction, wall time with TBB on this machine.
void DemoGridTiming() {
  const World& w = TheWorld();
  Lighting l = DemoLighting(true);
  l.sun_radiance = Eigen::Vector3d(2e4, 1.9e4, 1.8e4);
  HemisphereOptions ho;
  ho.directions = 256;
  auto t0 = std::chrono::steady_clock::now();
  const HemisphereCache cache = BuildHemisphereCache(w.grid, *w.rc, ho);
  auto secs = [](auto a) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count();
  };
  const double cache_s = secs(t0);
  IrradianceOptions mc;
  IrradianceOptions vf = mc;
  vf.method = IrradianceMethod::kVectorFlux;
  vf.mesh = &w.mesh;
  t0 = std::chrono::steady_clock::now();
  double c0 = ProcessCpuNow();
  const SlotIrradiance a = ComputeIrradiance(w.grid, cache, *w.rc, l, mc);
  const double mc_s = secs(t0), mc_cpu = ProcessCpuNow() - c0;
  t0 = std::chrono::steady_clock::now();
  c0 = ProcessCpuNow();
  const SlotIrradiance b = ComputeIrradiance(w.grid, cache, *w.rc, l, vf);
  const double vf_s = secs(t0), vf_cpu = ProcessCpuNow() - c0;
  double diff = 0;
  int count = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (!(b.direct_se[i].norm() > 1e-9)) continue;
    diff += (a.direct_se[i] - b.direct_se[i]).norm() / b.direct_se[i].norm();
    ++count;
  }
  IrradianceOptions mc_ns = mc, vf_ns = vf;
  mc_ns.ground_shadow = vf_ns.ground_shadow = false;
  t0 = std::chrono::steady_clock::now();
  ComputeIrradiance(w.grid, cache, *w.rc, l, mc_ns);
  const double mc_ns_s = secs(t0);
  t0 = std::chrono::steady_clock::now();
  ComputeIrradiance(w.grid, cache, *w.rc, l, vf_ns);
  const double vf_ns_s = secs(t0);
  std::printf(
      "\n== ComputeIrradiance on the whole demo grid (%d points, environment map, ground "
      "shadow), wall time with TBB ==\nhemisphere cache (256 directions, once per model) "
      "%.2f s; per slot: monte carlo %.2f s, vector flux %.2f s (ratio vf/mc %.2f); "
      "mean rel difference of direct E_se %.2e (the 256-direction noise)\n"
      "  CPU time of all threads: monte carlo %.2f s, vector flux %.2f s (ratio %.2f)\n",
      w.grid.size(), cache_s, mc_s, vf_s, vf_s / mc_s, count ? diff / count : 0.0, mc_cpu, vf_cpu,
      vf_cpu / mc_cpu);
  bench::Record("irradiance.demo_grid.monte_carlo_256_s", mc_s, "s");
  bench::Record("irradiance.demo_grid.vector_flux_s", vf_s, "s");
  bench::Record("irradiance.demo_grid.vector_flux_over_monte_carlo_256", vf_s / mc_s, "ratio",
                "the albedo solve's 256-direction Monte Carlo per slot (wall time, TBB)");
  std::printf(
      "without the ground-shadow correction: monte carlo %.2f s, vector flux %.2f s "
      "(ratio vf/mc %.2f)\n",
      mc_ns_s, vf_ns_s, vf_ns_s / mc_ns_s);
  // As the albedo solve calls it: every time slot in one call (five suns from morning to
  // evening), the vector flux's per-point geometry shared by all of them.
  std::vector<Lighting> day;
  for (int k = 0; k < 5; ++k) {
    const double az = (100 + 40 * k) * kPi / 180,
                 el = (25 + 25 * std::sin(kPi * k / 4)) * kPi / 180;
    Lighting d = l;
    d.sun_dir =
        Eigen::Vector3d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
    d.sky.sun_dir = d.sun_dir;
    day.push_back(d);
  }
  t0 = std::chrono::steady_clock::now();
  c0 = ProcessCpuNow();
  ComputeIrradiance(w.grid, cache, *w.rc, day, mc);
  const double mc5_s = secs(t0), mc5_cpu = ProcessCpuNow() - c0;
  t0 = std::chrono::steady_clock::now();
  c0 = ProcessCpuNow();
  ComputeIrradiance(w.grid, cache, *w.rc, day, vf);
  const double vf5_s = secs(t0), vf5_cpu = ProcessCpuNow() - c0;
  std::printf(
      "five slots in one call (the albedo solve): monte carlo %.2f s, vector flux %.2f s (ratio "
      "vf/mc %.2f)\n  CPU time of all threads: monte carlo %.2f s, vector flux %.2f s (ratio "
      "%.2f)\n",
      mc5_s, vf5_s, vf5_s / mc5_s, mc5_cpu, vf5_cpu, vf5_cpu / mc5_cpu);
  bench::Record("irradiance.demo_grid.five_slots.monte_carlo_256_s", mc5_s, "s");
  bench::Record("irradiance.demo_grid.five_slots.vector_flux_s", vf5_s, "s");
  bench::Record("irradiance.demo_grid.five_slots.vector_flux_over_monte_carlo_256", vf5_s / mc5_s,
                "ratio",
                "the 256-direction Monte Carlo for the same five slots in one call (wall time, "
                "TBB)");
  bench::Record("irradiance.demo_grid.five_slots.vector_flux_over_monte_carlo_256_cpu",
                vf5_cpu / mc5_cpu, "ratio",
                "the same, CPU time of all threads (less sensitive to a shared machine's load)");
  // What `rouen solve` pays for either method: the hemisphere cache (its "surface grid and
  // visibility" stage; both methods need it, for the interreflection) and one call for every
  // training slot (in "irradiance and pseudo-albedos"). Each later single-lighting call
  // (`rouen validate`, render) pays the vector flux's per-point geometry again.
  std::printf(
      "as the solve pays it (hemisphere cache + five slots in one call): monte carlo %.2f s, "
      "vector flux %.2f s (ratio vf/mc %.2f)\n",
      cache_s + mc5_s, cache_s + vf5_s, (cache_s + vf5_s) / (cache_s + mc5_s));
  bench::Record("irradiance.demo_grid.as_solve_pays.vector_flux_over_monte_carlo_256",
                (cache_s + vf5_s) / (cache_s + mc5_s), "ratio",
                "the solve's cost of either method: the 256-direction hemisphere cache (built "
                "for both: the interreflection uses it) plus five slots in one call (wall time, "
                "TBB)");
}

void BM_VectorFluxGeometryEnv(benchmark::State& state) {
  const World& w = TheWorld();
  const Lighting l = DemoLighting(true);
  const VfSetup s(l, 6, 0.1, 4, false);
  size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(VfGeometry(w, s, w.sample[k++ % w.sample.size()], true));
  }
}
BENCHMARK(BM_VectorFluxGeometryEnv)->Unit(benchmark::kMicrosecond);

void BM_VectorFluxGeometrySky(benchmark::State& state) {
  const World& w = TheWorld();
  const Lighting l = DemoLighting(false);
  const VfSetup s(l, 6, 0.1, 4, false);
  size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(VfGeometry(w, s, w.sample[k++ % w.sample.size()], false));
  }
}
BENCHMARK(BM_VectorFluxGeometrySky)->Unit(benchmark::kMicrosecond);

void BM_SkyTree(benchmark::State& state) {
  const Lighting l = DemoLighting(false);
  const SkyPatchTree tree(static_cast<int>(state.range(0)));
  const VectorFluxOptions o;
  for (auto _ : state) benchmark::DoNotOptimize(SkyTreeRadiance(tree, l.sky, o));
}
BENCHMARK(BM_SkyTree)->Arg(6)->Unit(benchmark::kMillisecond);

void BM_MonteCarlo(benchmark::State& state) {
  const World& w = TheWorld();
  const Lighting l = DemoLighting(true);
  const int strata = static_cast<int>(state.range(0));
  size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(MonteCarlo(w, l, w.sample[k++ % w.sample.size()], strata, 1));
  }
  state.counters["directions"] = strata * strata;
}
BENCHMARK(BM_MonteCarlo)->Arg(16)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  // --demo_grid_only: the whole-grid timing alone; --benchmarks_only: the Google Benchmarks
  // alone (no accuracy study, no whole-grid timing).
  bool demo_grid_only = false, benchmarks_only = false;
  for (int i = 1; i < argc; ++i) {
    demo_grid_only |= std::string(argv[i]) == "--demo_grid_only";
    benchmarks_only |= std::string(argv[i]) == "--benchmarks_only";
  }
  if (!demo_grid_only && !benchmarks_only) {
    rouen::Study(true);
    rouen::Study(false);
  }
  if (!benchmarks_only) rouen::DemoGridTiming();
  if (demo_grid_only) return 0;
  std::fflush(stdout);
  benchmark::RunSpecifiedBenchmarks();
  return 0;
}
