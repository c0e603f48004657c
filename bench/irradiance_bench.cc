// Direct sky + environment irradiance on the demo's building model (capture/sim: tower, plaza):
// the vector flux of clipped spherical polygons (App. A, solve/vector_flux.h) against
// brute-force Monte Carlo (stratified cosine directions, ray-cast visibility). Prints the
// vector flux's error against a converged Monte Carlo reference, the number of Monte Carlo
// samples (and time) needed to reach the same error, and the speed ratio.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <vector>

#include "capture/sim/sim_scene.h"
#include "core/mesh.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"
#include "solve/vector_flux.h"

namespace rouen {
namespace {

constexpr double kPi = 3.14159265358979323846;

// This thread's CPU time, seconds (the machine is shared: wall time would measure the load).
double CpuNow() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

struct World {
  Mesh mesh;
  SurfaceGrid grid;
  std::unique_ptr<RayCaster> rc;
  std::vector<int> sample;  // grid points studied
  World() {
    sim::TexelSizes sizes;
    mesh = sim::BuildScene(sizes).model;
    GridOptions go;  // as app/pipeline.cc
    go.spacing_m = 0.6;
    go.block_spacing_m["plaza"] = 1.5;
    grid = BuildSurfaceGrid(mesh, go);
    rc = std::make_unique<RayCaster>(mesh);
    const int n = 48;
    for (int k = 0; k < n; ++k) {
      sample.push_back(static_cast<int>((static_cast<int64_t>(k) * 7919 + 13) % grid.size()));
    }
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
// HemisphereCache pattern, its own seed).
Eigen::Vector3d MonteCarlo(const World& w, const Lighting& l, int i, int strata, uint64_t seed) {
  HemisphereCache c;
  c.strata = strata;
  c.directions = strata * strata;
  c.seed = seed;
  const GridPoint& p = w.grid.points[i];
  const Eigen::Vector3d o = p.position + w.rc->surface_offset() * p.normal;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int k = 0; k < c.directions; ++k) {
    const Eigen::Vector3d d = c.Direction(p, i, k);
    if (!w.rc->Occluded(o, d, 0.0)) sum += l.EscapedRadiance(d, p.position.z());
  }
  return sum * (kPi / c.directions);
}

struct VfContext {
  std::vector<SphericalPolygon> regions;
  VectorFluxOptions options;
};

Eigen::Vector3d VectorFluxAt(const World& w, const Lighting& l, const VfContext& ctx, int i,
                             FluxStats* st = nullptr) {
  const GridPoint& p = w.grid.points[i];
  const Eigen::Vector3d o = p.position + w.rc->surface_offset() * p.normal;
  const PointVisibility vis(w.mesh, o, p.normal, p.triangle);
  if (l.use_env) {
    return EnvironmentIrradianceVectorFlux(vis, l.env, p.position.z(), ctx.regions, nullptr,
                                           Eigen::Vector3d::Ones(), st);
  }
  return SkyIrradianceVectorFlux(vis, l.sky, ctx.options, st);
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
  VfContext ctx;
  ctx.regions = EnvironmentRegionPolygons(l.env, ctx.options);
  const int n = static_cast<int>(w.sample.size());
  std::printf("\n== %s: %d grid points of the demo model (%zu triangles, %d grid points) ==\n",
              use_env ? "environment map (the demo's path)" : "sky model, adaptive subdivision",
              n, w.mesh.triangles.size(), w.grid.size());
  // Reference: 1024^2 = 1048576 directions per point; its own error estimated from a
  // 512^2 run with another seed (Monte Carlo error ~ K^-1/2 here: the reference's is about
  // half the difference).
  const int ref_strata = 1024;
  std::vector<Eigen::Vector3d> ref(n), ref_q(n);
  double t0 = CpuNow();
  for (int k = 0; k < n; ++k) ref[k] = MonteCarlo(w, l, w.sample[k], ref_strata, 99);
  const double ref_s = CpuNow() - t0;
  for (int k = 0; k < n; ++k) ref_q[k] = MonteCarlo(w, l, w.sample[k], ref_strata / 2, 7);
  double ref_worst;
  const double ref_diff = MeanRelError(ref_q, ref, &ref_worst);
  std::printf("reference: %d MC directions/point, %.1f s CPU; a 262144-direction run differs "
              "by %.2e mean, %.2e max: reference error ~%.1e\n",
              ref_strata * ref_strata, ref_s, ref_diff, ref_worst, ref_diff / 2);
  // Vector flux (default options), and a much finer one (parallels followed by 64 arcs per
  // region, sky tolerance 0.01) for its own discretisation error (self-convergence).
  std::vector<Eigen::Vector3d> vf(n), vf_fine(n);
  FluxStats st;
  t0 = CpuNow();
  for (int k = 0; k < n; ++k) vf[k] = VectorFluxAt(w, l, ctx, w.sample[k], &st);
  const double vf_s = (CpuNow() - t0) / n;
  VfContext fine;
  fine.options.env_parallel_segments = 64;
  fine.options.sky_tolerance = 0.01;
  fine.regions = EnvironmentRegionPolygons(l.env, fine.options);
  for (int k = 0; k < n; ++k) vf_fine[k] = VectorFluxAt(w, l, fine, w.sample[k]);
  double vf_worst, fine_worst, self_worst;
  const double vf_err = MeanRelError(vf, ref, &vf_worst);
  const double fine_err = MeanRelError(vf_fine, ref, &fine_worst);
  const double self_err = MeanRelError(vf, vf_fine, &self_worst);
  std::printf("vector flux: vs reference mean rel error %.2e, max %.2e; %.3f ms CPU/point; %d "
              "occluders at the last point, %.1f patches/point\n",
              vf_err, vf_worst, vf_s * 1e3, st.occluders, static_cast<double>(st.patches) / n);
  std::printf("fine vector flux vs reference: mean %.2e, max %.2e; default vs fine "
              "(discretisation error): mean %.2e, max %.2e\n",
              fine_err, fine_worst, self_err, self_worst);
  // Monte Carlo convergence.
  std::vector<double> ks, errs, times;
  for (int strata : {8, 16, 32, 64, 128, 256}) {
    std::vector<Eigen::Vector3d> mc(n);
    t0 = CpuNow();
    for (int k = 0; k < n; ++k) mc[k] = MonteCarlo(w, l, w.sample[k], strata, 1);
    const double s = (CpuNow() - t0) / n;
    double worst;
    const double err = MeanRelError(mc, ref, &worst);
    ks.push_back(strata * strata);
    errs.push_back(err);
    times.push_back(s);
    std::printf("monte carlo K=%6d: mean rel error %.2e, max %.2e; %.3f ms/point\n",
                strata * strata, err, worst, s * 1e3);
  }
  // Samples Monte Carlo needs for a given mean error: log-log fit through the last two runs
  // (interpolated between runs when the error lies within them).
  const double t_per_sample = times.back() / ks.back();
  auto needed = [&](double target) {
    size_t j = 1;
    while (j + 1 < ks.size() && errs[j] > target) ++j;
    const double slope = std::log(errs[j] / errs[j - 1]) / std::log(ks[j] / ks[j - 1]);
    return std::max(ks[j] * std::pow(target / errs[j], 1 / slope), 1.0);
  };
  const double k1 = needed(vf_err);
  std::printf("monte carlo needs ~%.3g directions/point for the measured error %.2e "
              "(includes the reference's noise): %.2f ms CPU/point\n",
              k1, vf_err, k1 * t_per_sample * 1e3);
  std::printf("RATIO (conservative, measured error) monte carlo / vector flux CPU time: %.0fx "
              "(%s)\n",
              k1 * t_per_sample / vf_s, vf_err <= 0.005 ? "error <= 0.5%" : "ERROR ABOVE 0.5%");
  const double own = std::max(self_err, 1e-6);
  const double k2 = needed(own);
  std::printf("RATIO (at the vector flux's own discretisation error %.2e, extrapolated: "
              "~%.3g directions) monte carlo / vector flux CPU time: %.0fx\n",
              own, k2, k2 * t_per_sample / vf_s);
}

void BM_VectorFluxEnvironment(benchmark::State& state) {
  const World& w = TheWorld();
  const Lighting l = DemoLighting(true);
  VfContext ctx;
  ctx.regions = EnvironmentRegionPolygons(l.env, ctx.options);
  size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(VectorFluxAt(w, l, ctx, w.sample[k++ % w.sample.size()]));
  }
}
BENCHMARK(BM_VectorFluxEnvironment)->Unit(benchmark::kMicrosecond);

void BM_VectorFluxSky(benchmark::State& state) {
  const World& w = TheWorld();
  const Lighting l = DemoLighting(false);
  VfContext ctx;
  size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(VectorFluxAt(w, l, ctx, w.sample[k++ % w.sample.size()]));
  }
}
BENCHMARK(BM_VectorFluxSky)->Unit(benchmark::kMicrosecond);

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
BENCHMARK(BM_MonteCarlo)->Arg(16)->Arg(64)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  rouen::Study(true);
  rouen::Study(false);
  std::fflush(stdout);
  benchmark::RunSpecifiedBenchmarks();
  return 0;
}
