// Sky fit (Yu & Malik 1998 §3.2, eqs. 9-10): time of a 20k-sample, 3-channel fit per model,
// and accuracy of the 7-parameter, Perez-5 and best-CIE models on the simulator's physically
// based skies (capture/sim/atmosphere.h, the demo's atmosphere and site) at the demo's five
// times of day. Accuracy is scored like `rouen demo`'s sky_rel_error_*: |fit - truth| / truth
// per channel over 2000 even directions above 3 deg elevation, more than 3 deg from the sun.
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "capture/sim/almanac.h"
#include "capture/sim/atmosphere.h"
#include "core/solar.h"
#include "core/time.h"
#include "solve/sky_fit.h"

namespace rouen {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180;

struct TruthSky {
  std::string label;
  double sun_elevation_deg = 0;
  Eigen::Vector3d sun;
  SkyTable table;
};

// The demo's five slots (rigs/sim.toml), Berkeley 2026-08-25, PDT.
std::vector<TruthSky> DemoSkies() {
  static const Atmosphere atmosphere{AtmosphereParams{}};
  const Site site;
  std::vector<TruthSky> out;
  for (const char* hm : {"07:45", "10:30", "13:30", "16:00", "18:15"}) {
    const UtcTime t = ParseIso8601(std::string("2026-08-25T") + hm + ":00-07:00");
    const AlmanacSun s = AlmanacSunPosition(t, site);
    const Eigen::Vector3d toa =
        atmosphere.params().solar_toa / (s.distance_au * s.distance_au);
    TruthSky ts;
    ts.label = hm;
    ts.sun = s.DirectionEnu();
    ts.sun_elevation_deg = std::asin(ts.sun.z()) / kDeg;
    ts.table = SkyTable(atmosphere, site.height_m, ts.sun, toa);
    out.push_back(std::move(ts));
  }
  return out;
}

// Uniform in solid angle above 3 deg, more than 3 deg from the sun (as ExtractSkySamples).
std::vector<SkySample> Samples(const TruthSky& sky, int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  const double z0 = std::sin(3 * kDeg);
  std::vector<SkySample> out;
  while (static_cast<int>(out.size()) < n) {
    const double z = z0 + (1 - z0) * u(rng), phi = 2 * kPi * u(rng);
    const double r = std::sqrt(1 - z * z);
    const Eigen::Vector3d d(r * std::cos(phi), r * std::sin(phi), z);
    if (d.dot(sky.sun) > std::cos(3 * kDeg)) continue;
    out.push_back({d, sky.table.Radiance(d)});
  }
  return out;
}

// The demo's scoring directions (golden spiral).
std::vector<Eigen::Vector3d> ScoreDirections(const Eigen::Vector3d& sun) {
  std::vector<Eigen::Vector3d> out;
  const double golden = kPi * (3 - std::sqrt(5.0)), zmin = std::sin(3 * kDeg);
  for (int i = 0; i < 2000; ++i) {
    const double z = zmin + (1 - zmin) * (i + 0.5) / 2000, r = std::sqrt(1 - z * z);
    const Eigen::Vector3d d(r * std::cos(golden * i), r * std::sin(golden * i), z);
    if (d.dot(sun) <= std::cos(3 * kDeg)) out.push_back(d);
  }
  return out;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

void AppendErrors(const SkyModel& fit, const TruthSky& sky, std::vector<double>* err) {
  for (const Eigen::Vector3d& d : ScoreDirections(sky.sun)) {
    const Eigen::Vector3d f = fit.Radiance(d), t = sky.table.Radiance(d);
    for (int c = 0; c < 3; ++c) err->push_back(std::abs(f[c] - t[c]) / t[c]);
  }
}

void PrintAccuracy() {
  const std::vector<TruthSky> skies = DemoSkies();
  struct Variant {
    const char* name;
    SkyModelKind model;
    SkyWeighting weighting;
  };
  const Variant variants[] = {
      {"7-param, eq.10 weights", SkyModelKind::kSevenParam, SkyWeighting::kPaper},
      {"7-param, relative", SkyModelKind::kSevenParam, SkyWeighting::kRelative},
      {"Perez-5, eq.10 weights", SkyModelKind::kPerez5, SkyWeighting::kPaper},
      {"Perez-5, relative", SkyModelKind::kPerez5, SkyWeighting::kRelative},
      {"best CIE, eq.10 weights", SkyModelKind::kCie, SkyWeighting::kPaper},
      {"best CIE, relative", SkyModelKind::kCie, SkyWeighting::kRelative},
  };
  std::printf("\nSky fit accuracy on the simulator's noise-free skies (20000 samples each)\n");
  std::printf("relative error |fit - truth| / truth, 3 channels, demo scoring directions\n");
  std::printf("%-24s", "model");
  for (const TruthSky& s : skies) {
    std::printf("  %5s el %4.1f     ", s.label.c_str(), s.sun_elevation_deg);
  }
  std::printf("  all 5 (demo pooling)\n%-24s", "");
  for (size_t i = 0; i < skies.size(); ++i) std::printf("  median    p90     ");
  std::printf("  median    p90\n");
  for (const Variant& v : variants) {
    std::printf("%-24s", v.name);
    std::vector<double> all;
    for (const TruthSky& s : skies) {
      SkyFitOptions o;
      o.model = v.model;
      o.weighting = v.weighting;
      SkyModel fit;
      const SkyFitSummary sum = FitSky(Samples(s, 20000, 7), s.sun, o, &fit);
      std::vector<double> err;
      AppendErrors(fit, s, &err);
      all.insert(all.end(), err.begin(), err.end());
      std::printf("  %.4f  %.4f", Percentile(err, 0.5), Percentile(err, 0.9));
      if (v.model == SkyModelKind::kCie) {
        std::printf(" T%-2d", sum.cie_type);
      } else {
        std::printf("    ");
      }
    }
    std::printf("  %.4f  %.4f\n", Percentile(all, 0.5), Percentile(all, 0.9));
  }
  std::printf("\n");
}

// Where the 7-parameter fit misses: median |error| (green) by elevation and by angle from the
// sun, and the fitted parameters (set ROUEN_SKY_BENCH_DIAG=1).
void PrintDiagnostics() {
  const std::vector<TruthSky> skies = DemoSkies();
  for (const SkyWeighting wt : {SkyWeighting::kPaper, SkyWeighting::kRelative}) {
    for (size_t k : {size_t{0}, size_t{2}}) {
      const TruthSky& s = skies[k];
      SkyFitOptions o;
      o.weighting = wt;
      SkyModel fit;
      FitSky(Samples(s, 20000, 7), s.sun, o, &fit);
      std::printf("%s, sun el %.1f, %s weights\n", s.label.c_str(), s.sun_elevation_deg,
                  wt == SkyWeighting::kPaper ? "eq.10" : "relative");
      for (int c = 0; c < 3; ++c) {
        const SkyParams& p = fit.channel[c];
        std::printf("  ch%d Lz %.4g a %.3f b %.3f c %.3f d %.3f e %.3f h %.3f\n", c, p.Lz, p.a,
                    p.b, p.c, p.d, p.e, p.h);
      }
      std::vector<std::vector<double>> by_el(9), by_sun(12);
      std::vector<double> sgn_el(9, 0.0);
      for (const Eigen::Vector3d& d : ScoreDirections(s.sun)) {
        const double f = fit.Radiance(d)[1], t = s.table.Radiance(d)[1];
        const double el = std::asin(d.z()) / kDeg;
        const double g = std::acos(std::clamp(d.dot(s.sun), -1.0, 1.0)) / kDeg;
        by_el[std::min(8, static_cast<int>(el / 10))].push_back(std::abs(f / t - 1));
        sgn_el[std::min(8, static_cast<int>(el / 10))] += f / t - 1;
        by_sun[std::min(11, static_cast<int>(g / 15))].push_back(std::abs(f / t - 1));
      }
      std::printf("  by elevation (10 deg bands): ");
      for (int i = 0; i < 9; ++i)
        std::printf(" %.3f(%+.3f)", Percentile(by_el[i], 0.5),
                    by_el[i].empty() ? 0.0 : sgn_el[i] / by_el[i].size());
      std::printf("\n  by sun distance (15 deg bands): ");
      for (const auto& v : by_sun) std::printf(" %.3f", Percentile(v, 0.5));
      std::printf("\n");
    }
  }
}

void BM_FitSky20k(benchmark::State& state, SkyModelKind kind) {
  static const std::vector<TruthSky> skies = DemoSkies();
  const TruthSky& sky = skies[2];  // 13:30, sun ~62 deg
  const std::vector<SkySample> samples = Samples(sky, 20000, 11);
  SkyFitOptions o;
  o.model = kind;
  SkyFitSummary last;
  for (auto _ : state) {
    SkyModel fit;
    last = FitSky(samples, sky.sun, o, &fit);
    benchmark::DoNotOptimize(fit);
  }
  state.counters["median_g"] = last.channel[1].rel_error_median;
  state.counters["p90_g"] = last.channel[1].rel_error_p90;
  state.counters["iterations_g"] = last.channel[1].iterations;
}
BENCHMARK_CAPTURE(BM_FitSky20k, seven_param, SkyModelKind::kSevenParam)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FitSky20k, perez5, SkyModelKind::kPerez5)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FitSky20k, cie, SkyModelKind::kCie)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  rouen::PrintAccuracy();
  if (const char* d = std::getenv("ROUEN_SKY_BENCH_DIAG"); d && *d == '1') {
    rouen::PrintDiagnostics();
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
