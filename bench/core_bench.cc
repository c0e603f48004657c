// Speed of the pipeline's building blocks (Google Benchmark). Peer comparisons (OpenCV HDR,
// Monte Carlo irradiance) arrive with the issues that ask for them.
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "calib/hdr.h"
#include "core/angles.h"
#include "core/solar.h"
#include "solve/sky_fit.h"

namespace rouen {
namespace {

void BM_SunPosition(benchmark::State& state) {
  UtcTime t = ParseIso8601("2026-08-25T20:30:00Z");
  Site site;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ComputeSunPosition(t, site));
    t = t.PlusSeconds(1);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_SunPosition);

// A 4-frame bracket of a 1-megapixel radiance ramp through a gamma curve.
void BM_MergeHdr(benchmark::State& state) {
  const int w = 1024, h = 1024;
  ResponseCurve curve;
  for (int c = 0; c < 3; ++c) {
    curve.g[c].resize(256);
    for (int z = 0; z < 256; ++z) curve.g[c][z] = 2.2 * std::log((z + 0.5) / 128.0);
  }
  std::vector<double> exposures = {1.0 / 1000, 1.0 / 250, 1.0 / 60, 1.0 / 15};
  std::vector<Image> frames;
  for (double e : exposures) {
    Image im(w, h, 3, PixelUnits::kDigital);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) {
          double L = std::pow(10.0, 4.0 * x / w);
          double v = 128.0 * std::pow(L * e, 1 / 2.2);
          im.at(x, y, c) = static_cast<float>(std::clamp(std::round(v), 0.0, 255.0));
        }
    frames.push_back(std::move(im));
  }
  std::vector<const Image*> ptrs;
  for (const Image& f : frames) ptrs.push_back(&f);
  for (auto _ : state) benchmark::DoNotOptimize(MergeHdr(ptrs, exposures, curve, MergeOptions{}));
  state.counters["input_MP/s"] =
      benchmark::Counter(static_cast<double>(w) * h * frames.size() * 1e-6 * state.iterations(),
                         benchmark::Counter::kIsRate);
}
BENCHMARK(BM_MergeHdr)->Unit(benchmark::kMillisecond);

// Eq. 9 fitted to 20k samples of a CIE-like clear sky, 3 channels.
void BM_FitSky20k(benchmark::State& state) {
  Eigen::Vector3d sun = EnuFromAzEl(200, 40);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<SkySample> samples;
  while (samples.size() < 20000) {
    double z = u(rng), phi = 2 * kPi * u(rng), r = std::sqrt(1 - z * z);
    Eigen::Vector3d d(r * std::cos(phi), r * std::sin(phi), z);
    if (z < 0.05 || d.dot(sun) > std::cos(0.06)) continue;
    double xi = std::acos(z), gamma = std::acos(std::clamp(d.dot(sun), -1.0, 1.0));
    double base = (1 - std::exp(-0.32 / std::cos(xi))) *
                  (1 + 10 * std::exp(-3 * gamma) + 0.45 * std::cos(gamma) * std::cos(gamma));
    samples.push_back({d, Eigen::Vector3d(0.6, 1.0, 1.5) * base * (1 + 0.01 * (u(rng) - 0.5))});
  }
  for (auto _ : state) {
    SkyModel model;
    benchmark::DoNotOptimize(FitSky(samples, sun, SkyFitOptions{}, &model));
  }
}
BENCHMARK(BM_FitSky20k)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace rouen

BENCHMARK_MAIN();
