// Sky fit (Yu & Malik 1998 §3.2, eqs. 9-10): time of a 20k-sample, 3-channel fit per model,
// and accuracy of the 7-parameter, Perez-5 and best-CIE models on the simulator's physically
// based skies (capture/sim/atmosphere.h, the demo's atmosphere and site) at the demo's five
// times of day. Accuracy is scored like `rouen demo`'s sky_rel_error_*: |fit - truth| / truth
// per channel over 2000 even directions above 3 deg elevation, more than 3 deg from the sun.
// Then rouen against scipy (bench/sky_fit_scipy.py, the same samples and weights): the demo's
// skies clear and hazy, hazy skies with a low sun (turbidity 2.5-6, sun 5-30 deg), and the real
// sky-scanner scans of ../shared/data/sky-scans (also painted into a panorama and fitted from
// it, solid-angle weights against every pixel alike).
// ROUEN_SKY_BENCH_STUDY=1 adds an error study: fit error on noise-free truth per objective
// (eq. 10, relative, p-norms) for three atmospheres (visibility 35, 15, 80 km) with the tail
// broken down by slot, elevation, sun distance and channel; then the sampling error of the
// demo's own sky photo (noise-free render, sky pixels, ExtractSkySamples). ROUEN_SKY_BENCH_
// RANDOM=1 adds a 64-random-start run (does LM reach the global minimum?). ROUEN_SKY_BENCH_
// SCIPY_ONLY=1 runs the comparison with scipy alone (no accuracy table, no timing benchmarks).
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "bench/results.h"
#include "capture/sim/almanac.h"
#include "capture/sim/atmosphere.h"
#include "capture/sim/sim_world.h"
#include "core/angles.h"
#include "core/camera.h"
#include "core/image.h"
#include "core/solar.h"
#include "core/stats.h"
#include "core/text.h"
#include "core/time.h"
#include "solve/sky_fit.h"

namespace rouen {
namespace {

struct TruthSky {
  std::string label;
  double sun_elevation_deg = 0;
  Eigen::Vector3d sun;
  SkyTable table;
};

const char* const kSlotTimes[] = {"07:45", "10:30", "13:30", "16:00", "18:15"};

UtcTime SlotTime(const char* hm) {
  return ParseIso8601(std::string("2026-08-25T") + hm + ":00-07:00");
}

// The demo's five slots (rigs/sim.toml), Berkeley 2026-08-25, PDT, under `params`.
std::vector<TruthSky> Skies(const AtmosphereParams& params) {
  const Atmosphere atmosphere{params};
  const Site site;
  std::vector<TruthSky> out;
  for (const char* hm : kSlotTimes) {
    const AlmanacSun s = AlmanacSunPosition(SlotTime(hm), site);
    const Eigen::Vector3d toa = atmosphere.params().solar_toa / (s.distance_au * s.distance_au);
    TruthSky ts;
    ts.label = hm;
    ts.sun = s.DirectionEnu();
    ts.sun_elevation_deg = std::asin(ts.sun.z()) / kDeg;
    ts.table = SkyTable(atmosphere, site.height_m, ts.sun, toa);
    out.push_back(std::move(ts));
  }
  return out;
}

// The demo's five slots (rigs/sim.toml), Berkeley 2026-08-25, PDT.
std::vector<TruthSky> DemoSkies() {
  static const Atmosphere atmosphere{AtmosphereParams{}};
  const Site site;
  std::vector<TruthSky> out;
  for (const char* hm : {"07:45", "10:30", "13:30", "16:00", "18:15"}) {
    const UtcTime t = ParseIso8601(std::string("2026-08-25T") + hm + ":00-07:00");
    const AlmanacSun s = AlmanacSunPosition(t, site);
    const Eigen::Vector3d toa = atmosphere.params().solar_toa / (s.distance_au * s.distance_au);
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
    double norm_p = 2;
  };
  const Variant variants[] = {
      {"7-param, eq.10 weights", SkyModelKind::kSevenParam, SkyWeighting::kPaper},
      {"7-param, relative", SkyModelKind::kSevenParam, SkyWeighting::kRelative},
      {"7-param, relative L1", SkyModelKind::kSevenParam, SkyWeighting::kRelative, 1.0},
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
      o.norm_p = v.norm_p;
      SkyModel fit;
      const SkyFitSummary sum = FitSky(Samples(s, 20000, 7), s.sun, o, &fit);
      std::vector<double> err;
      AppendErrors(fit, s, &err);
      all.insert(all.end(), err.begin(), err.end());
      std::printf("  %.4f  %.4f", Quantile(err, 0.5), Quantile(err, 0.9));
      if (v.model == SkyModelKind::kCie) {
        std::printf(" T%-2d", sum.cie_type);
      } else {
        std::printf("    ");
      }
    }
    std::printf("  %.4f  %.4f\n", Quantile(all, 0.5), Quantile(all, 0.9));
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
        std::printf("  ch%d Lz %.4g a %.3f b %.3f c %.3f d %.3f e %.3f h %.3f\n", c, p.Lz, p.a, p.b,
                    p.c, p.d, p.e, p.h);
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
        std::printf(" %.3f(%+.3f)", Quantile(by_el[i], 0.5),
                    by_el[i].empty() ? 0.0 : sgn_el[i] / by_el[i].size());
      std::printf("\n  by sun distance (15 deg bands): ");
      for (const auto& v : by_sun) std::printf(" %.3f", Quantile(v, 0.5));
      std::printf("\n");
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Error study (ROUEN_SKY_BENCH_STUDY=1): where the demo's sky p90 comes from.

// One scored direction and channel.
struct ScoredError {
  int slot = 0, channel = 0;
  double elevation_deg = 0, sun_distance_deg = 0, rel = 0;  // rel: |fit - truth| / truth
};

std::vector<ScoredError> Score(const SkyModel& fit, const TruthSky& sky, int slot) {
  std::vector<ScoredError> out;
  for (const Eigen::Vector3d& d : ScoreDirections(sky.sun)) {
    const Eigen::Vector3d f = fit.Radiance(d), t = sky.table.Radiance(d);
    for (int c = 0; c < 3; ++c) {
      ScoredError e;
      e.slot = slot;
      e.channel = c;
      e.elevation_deg = std::asin(d.z()) / kDeg;
      e.sun_distance_deg = std::acos(std::clamp(d.dot(sky.sun), -1.0, 1.0)) / kDeg;
      e.rel = std::abs(f[c] - t[c]) / t[c];
      out.push_back(e);
    }
  }
  return out;
}

double P(const std::vector<ScoredError>& v, double q) {
  std::vector<double> r;
  for (const ScoredError& e : v) r.push_back(e.rel);
  return Quantile(r, q);
}

// Median / p90 of the pooled errors and the share of the pooled tail (errors above the
// pooled p90) per slot, elevation band, sun-distance band and channel.
void PrintBreakdown(const std::vector<ScoredError>& all, const std::vector<TruthSky>& skies) {
  const double t90 = P(all, 0.9);
  const double n_tail = 0.1 * all.size();
  auto row = [&](const char* name,
                 const std::vector<std::pair<std::string, std::function<bool(const ScoredError&)>>>&
                     cats) {
    std::printf("  %-16s", name);
    for (const auto& [label, in] : cats) {
      std::vector<ScoredError> sub;
      int tail = 0;
      for (const ScoredError& e : all) {
        if (!in(e)) continue;
        sub.push_back(e);
        if (e.rel > t90) ++tail;
      }
      std::printf("  %s: n %4.1f%% med %.4f p90 %.4f tail %4.1f%%", label.c_str(),
                  100.0 * sub.size() / all.size(), P(sub, 0.5), P(sub, 0.9), 100.0 * tail / n_tail);
    }
    std::printf("\n");
  };
  std::vector<std::pair<std::string, std::function<bool(const ScoredError&)>>> slots, el, sd, ch;
  for (size_t k = 0; k < skies.size(); ++k) {
    char b[32];
    std::snprintf(b, sizeof b, "%s(el%.0f)", skies[k].label.c_str(), skies[k].sun_elevation_deg);
    slots.push_back({b, [k](const ScoredError& e) { return e.slot == static_cast<int>(k); }});
  }
  const double el_edges[] = {3, 10, 20, 45, 90.1};
  for (int i = 0; i < 4; ++i) {
    const double lo = el_edges[i], hi = el_edges[i + 1];
    el.push_back(
        {"el " + std::to_string(static_cast<int>(lo)) + "-" + std::to_string(static_cast<int>(hi)),
         [lo, hi](const ScoredError& e) { return e.elevation_deg >= lo && e.elevation_deg < hi; }});
  }
  const double sd_edges[] = {3, 15, 40, 90, 180.1};
  for (int i = 0; i < 4; ++i) {
    const double lo = sd_edges[i], hi = sd_edges[i + 1];
    sd.push_back(
        {"sun " + std::to_string(static_cast<int>(lo)) + "-" + std::to_string(static_cast<int>(hi)),
         [lo, hi](const ScoredError& e) {
           return e.sun_distance_deg >= lo && e.sun_distance_deg < hi;
         }});
  }
  for (int c = 0; c < 3; ++c) {
    ch.push_back({std::string(1, "RGB"[c]), [c](const ScoredError& e) { return e.channel == c; }});
  }
  std::printf("  pooled median %.4f p90 %.4f (tail: errors above the pooled p90)\n", P(all, 0.5),
              t90);
  row("by slot", slots);
  row("by elevation", el);
  row("by sun distance", sd);
  row("by channel", ch);
}

struct StudyVariant {
  std::string name;
  SkyFitOptions options;
};

std::vector<StudyVariant> StudyVariants() {
  std::vector<StudyVariant> v;
  SkyFitOptions o;
  o.weighting = SkyWeighting::kPaper;
  v.push_back({"eq.10 (kPaper), p=2", o});
  o.weighting = SkyWeighting::kRelative;
  v.push_back({"relative, p=2", o});
  if (const char* d = std::getenv("ROUEN_SKY_BENCH_RANDOM"); d && *d == '1') {
    o.random_starts = 64;
    v.push_back({"relative, p=2, +64 random starts", o});
    o.random_starts = 0;
  }
  for (double p : {1.0, 1.5, 3.0, 4.0}) {
    o.norm_p = p;
    char b[64];
    std::snprintf(b, sizeof b, "relative, p=%g", p);
    v.push_back({b, o});
  }
  return v;
}

// Fit error: each variant fitted to noise-free truth (20k samples uniform in solid angle, as
// ExtractSkySamples draws), scored on the demo's directions, for three atmospheres.
void PrintFitStudy() {
  struct Atmo {
    const char* name;
    double visibility_km;
  };
  for (const Atmo& a :
       {Atmo{"demo atmosphere (visibility 35 km)", 35.0}, Atmo{"hazy (visibility 15 km)", 15.0},
        Atmo{"clear (visibility 80 km)", 80.0}}) {
    AtmosphereParams ap;
    ap.visibility_km = a.visibility_km;
    const std::vector<TruthSky> skies = Skies(ap);
    std::printf("\n== Fit error on noise-free truth, %s ==\n", a.name);
    std::printf("%-34s", "variant");
    for (const TruthSky& s : skies) std::printf("  %s med/p90  ", s.label.c_str());
    std::printf("  pooled med/p90   cost ratio (green, vs relative p=2)\n");
    std::vector<double> base_cost(skies.size(), 0);
    for (const StudyVariant& v : StudyVariants()) {
      std::printf("%-34s", v.name.c_str());
      std::vector<ScoredError> all;
      std::string ratios;
      for (size_t k = 0; k < skies.size(); ++k) {
        SkyModel fit;
        const SkyFitSummary sum =
            FitSky(Samples(skies[k], 20000, 7), skies[k].sun, v.options, &fit);
        const std::vector<ScoredError> e = Score(fit, skies[k], static_cast<int>(k));
        all.insert(all.end(), e.begin(), e.end());
        std::printf("  %.4f/%.4f", P(e, 0.5), P(e, 0.9));
        if (v.name == "relative, p=2") base_cost[k] = sum.channel[1].final_cost;
        if (v.name.find("random") != std::string::npos) {
          char b[32];
          std::snprintf(b, sizeof b, " %.4f", sum.channel[1].final_cost / base_cost[k]);
          ratios += b;
        }
      }
      std::printf("  %.4f/%.4f %s\n", P(all, 0.5), P(all, 0.9), ratios.c_str());
      if (v.name == "relative, p=2" || v.name == "relative, p=1") {
        PrintBreakdown(all, skies);
      }
    }
  }
}

// Sampling error: the sky photo the demo takes (SimWorld's 180-degree fisheye on the mast,
// rendered noise-free, sky pixels only), sampled by ExtractSkySamples and fitted; the same
// scoring. Its difference from the fit error above is the photo's coverage and pixel grid;
// the rest of the demo's error (response curve, noise, HDR merge) is calibration.
void PrintPhotoStudy() {
  SimWorldOptions wo;
  wo.quick = true;
  SimWorld world(wo);
  const SimView view = world.SkyView();
  std::printf("\n== Sampling error: the demo's sky photo (noise-free render, sky pixels) ==\n");
  for (double p : {2.0, 1.0}) {
    SkyFitOptions o;
    o.weighting = SkyWeighting::kRelative;
    o.norm_p = p;
    std::vector<ScoredError> all;
    std::vector<TruthSky> skies;
    std::printf("relative, p=%g:", p);
    for (size_t k = 0; k < std::size(kSlotTimes); ++k) {
      world.SetTime(SlotTime(kSlotTimes[k]));
      const Image img = world.RenderRadiance(view.intrinsics, view.pose);
      const Image ids = world.RenderBlockIds(view.intrinsics, view.pose);
      std::vector<uint8_t> mask(ids.data.size());
      for (size_t i = 0; i < mask.size(); ++i) mask[i] = ids.data[i] == -2.0f ? 1 : 0;
      const Eigen::Vector3d sun = world.TrueSunDirection();
      const std::vector<SkySample> samples =
          ExtractSkySamples(img, &mask, view.intrinsics, view.pose, sun, SkySampleOptions{});
      SkyModel fit;
      FitSky(samples, sun, o, &fit);
      // Score against the world's own truth (TruthSky with the world's table).
      TruthSky ts;
      ts.label = kSlotTimes[k];
      ts.sun = sun;
      ts.sun_elevation_deg = std::asin(sun.z()) / kDeg;
      std::vector<ScoredError> e;
      for (const Eigen::Vector3d& d : ScoreDirections(sun)) {
        const Eigen::Vector3d f = fit.Radiance(d), t = world.TrueSkyRadiance(d);
        for (int c = 0; c < 3; ++c) {
          ScoredError se;
          se.slot = static_cast<int>(k);
          se.channel = c;
          se.elevation_deg = std::asin(d.z()) / kDeg;
          se.sun_distance_deg = std::acos(std::clamp(d.dot(sun), -1.0, 1.0)) / kDeg;
          se.rel = std::abs(f[c] - t[c]) / t[c];
          e.push_back(se);
        }
      }
      all.insert(all.end(), e.begin(), e.end());
      skies.push_back(ts);
      std::printf("  %s %zu samples %.4f/%.4f", kSlotTimes[k], samples.size(), P(e, 0.5),
                  P(e, 0.9));
    }
    std::printf("  pooled %.4f/%.4f\n", P(all, 0.5), P(all, 0.9));
    PrintBreakdown(all, skies);
  }
}

// The peer: scipy.optimize.least_squares fitting the same model (bench/sky_fit_scipy.py).
std::string PeerPython() {
  // Debian's python3 (python3-scipy) first: a python3 earlier on PATH may lack scipy.
  for (const char* candidate : {"/usr/bin/python3", "python3"}) {
    const std::string probe = std::string(candidate) + " -c 'import scipy.optimize' 2>/dev/null";
    if (std::system(probe.c_str()) == 0) return candidate;
  }
  return "";
}

// One sky of a comparison: its samples (with their weights) and the directions and radiances
// both fits are scored at (|fit - truth| / truth per channel).
struct Case {
  std::string name;
  double sun_elevation_deg = 0;
  Eigen::Vector3d sun;
  std::vector<SkySample> samples;
  std::vector<Eigen::Vector3d> score_dirs, score_truth;
};

// The peer's fit of every case (the same samples and weights), and its wall time per case; an
// empty result when the peer is missing or did not answer every case (said on stdout).
struct PeerFit {
  SkyModel model;
  double seconds = 0;
  bool complete = true;
};
std::vector<PeerFit> RunPeer(const std::vector<Case>& cases) {
  namespace fs = std::filesystem;
  const std::string python = PeerPython();
  if (python.empty()) {
    std::printf(
        "\nsky fit vs scipy: skipped (no python3 with scipy: apt-get install python3-scipy)\n");
    return {};
  }
  const fs::path script = fs::path(ROUEN_SOURCE_DIR) / "bench" / "sky_fit_scipy.py";
  const fs::path input = fs::temp_directory_path() / "rouen_sky_bench_samples.txt";
  {
    std::ofstream out(input);
    out.precision(9);
    for (const Case& c : cases) {
      out << "sky " << c.name << " " << c.sun.x() << " " << c.sun.y() << " " << c.sun.z() << " "
          << c.samples.size() << "\n";
      for (const SkySample& k : c.samples)
        out << k.dir.x() << " " << k.dir.y() << " " << k.dir.z() << " " << k.radiance.x() << " "
            << k.radiance.y() << " " << k.radiance.z() << " " << k.weight << "\n";
    }
  }
  std::vector<nlohmann::json> peer;
  FILE* p = popen((python + " '" + script.string() + "' '" + input.string() + "'").c_str(), "r");
  if (p != nullptr) {
    char line[1 << 14];
    while (std::fgets(line, sizeof line, p)) peer.push_back(nlohmann::json::parse(line));
    pclose(p);
  }
  fs::remove(input);
  if (peer.size() != cases.size()) {
    std::printf("\nsky fit vs scipy: the peer answered %zu of %zu skies\n", peer.size(),
                cases.size());
    return {};
  }
  std::vector<PeerFit> out(cases.size());
  for (size_t k = 0; k < cases.size(); ++k) {
    out[k].model.sun_dir = cases[k].sun;
    out[k].seconds = peer[k]["seconds"].get<double>();
    for (int ch = 0; ch < 3; ++ch) {
      const nlohmann::json& q = peer[k]["channels"][ch];
      if (q.is_null()) {
        out[k].complete = false;
        continue;
      }
      SkyParams& sp = out[k].model.channel[ch];
      double* fields[] = {&sp.Lz, &sp.a, &sp.b, &sp.c, &sp.d, &sp.e, &sp.h};
      for (int i = 0; i < 7; ++i) *fields[i] = q[i].get<double>();
    }
  }
  return out;
}

std::vector<double> CaseErrors(const SkyModel& fit, const Case& c) {
  std::vector<double> err;
  for (size_t i = 0; i < c.score_dirs.size(); ++i) {
    const Eigen::Vector3d f = fit.Radiance(c.score_dirs[i]);
    for (int ch = 0; ch < 3; ++ch)
      err.push_back(std::abs(f[ch] - c.score_truth[i][ch]) / c.score_truth[i][ch]);
  }
  return err;
}

// One table: rouen (FitSky with `options`) and the peer on the same cases, median and p90 of
// the errors per sky and pooled, and how many skies rouen's median or p90 is more than 5 %
// above the peer's. Records the figures under `key` when it is not empty.
void CompareTable(const std::string& title, const std::vector<Case>& cases,
                  const std::vector<PeerFit>& peer, const SkyFitOptions& options,
                  const std::string& key, const std::string& set_note) {
  std::printf("\n%s\n%-16s %6s %7s  %10s %8s %8s  %10s %8s %8s  %8s\n", title.c_str(), "sky",
              "sun el", "samples", "rouen ms", "median", "p90", "scipy ms", "median", "p90",
              "x scipy");
  std::vector<double> ratios, rouen_all, scipy_all;
  int p90_worse = 0, median_worse = 0;
  for (size_t k = 0; k < cases.size(); ++k) {
    const Case& c = cases[k];
    SkyModel mine;
    const auto t0 = std::chrono::steady_clock::now();
    FitSky(c.samples, c.sun, options, &mine);
    const double t_rouen =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::vector<double> e_rouen = CaseErrors(mine, c), e_scipy = CaseErrors(peer[k].model, c);
    const double med_r = Quantile(e_rouen, 0.5), med_s = Quantile(e_scipy, 0.5);
    const double p90_r = Quantile(e_rouen, 0.9), p90_s = Quantile(e_scipy, 0.9);
    p90_worse += p90_r > p90_s * 1.05;
    median_worse += med_r > med_s * 1.05;
    ratios.push_back(peer[k].seconds / t_rouen);
    rouen_all.insert(rouen_all.end(), e_rouen.begin(), e_rouen.end());
    scipy_all.insert(scipy_all.end(), e_scipy.begin(), e_scipy.end());
    std::printf("%-16s %6.1f %7zu  %10.1f %8.4f %8.4f  %10.1f %8.4f %8.4f  %8.1f%s\n",
                c.name.c_str(), c.sun_elevation_deg, c.samples.size(), t_rouen * 1e3, med_r, p90_r,
                peer[k].seconds * 1e3, med_s, p90_s, peer[k].seconds / t_rouen,
                peer[k].complete ? "" : "  (scipy failed on a channel)");
  }
  const double ratio = Quantile(ratios, 0.5);
  std::printf(
      "pooled: rouen median %.4f p90 %.4f; scipy median %.4f p90 %.4f; rouen more than 5%% above "
      "scipy on %d of %zu skies at the median, %d at the p90; median speed ratio %.1fx\n",
      Quantile(rouen_all, 0.5), Quantile(rouen_all, 0.9), Quantile(scipy_all, 0.5),
      Quantile(scipy_all, 0.9), median_worse, cases.size(), p90_worse, ratio);
  if (key.empty()) return;
  const std::string n = std::to_string(cases.size());
  bench::Record(key + ".x_scipy", ratio, "ratio",
                "scipy least_squares (soft_l1, 16 starts) on the same samples and weights, median "
                "over " +
                    n + " " + set_note + ", wall time of the fit");
  bench::Record(key + ".rouen_rel_error_p90", Quantile(rouen_all, 0.9), "");
  bench::Record(key + ".rouen_rel_error_median", Quantile(rouen_all, 0.5), "");
  bench::Record(key + ".skies_rouen_p90_worse", p90_worse, "skies of " + n);
  bench::Record(key + ".skies_rouen_median_worse", median_worse, "skies of " + n);
  bench::Record(key + ".scipy_rel_error_p90", Quantile(scipy_all, 0.9), "");
  bench::Record(key + ".scipy_rel_error_median", Quantile(scipy_all, 0.5), "");
}

// A simulator sky as a comparison case: 20000 samples uniform in solid angle (weight 1 each),
// scored at the demo's directions.
Case SimCase(const std::string& name, const TruthSky& t) {
  Case c;
  c.name = name;
  c.sun = t.sun;
  c.sun_elevation_deg = t.sun_elevation_deg;
  c.samples = Samples(t, 20000, 13);
  c.score_dirs = ScoreDirections(t.sun);
  for (const Eigen::Vector3d& d : c.score_dirs) c.score_truth.push_back(t.table.Radiance(d));
  return c;
}

// Visibility (km) of the simulator's atmosphere with turbidity `t`: Linke's ratio (Preetham's
// and Hosek-Wilkie's turbidity) of the whole atmosphere's vertical optical depth at 550 nm to
// its molecules' alone, T = 1 + tau_Mie / tau_Rayleigh, each tau = sea-level extinction x scale
// height; the visibility is Koschmieder's 3.912 / total sea-level extinction.
double VisibilityKmForTurbidity(double t) {
  const AtmosphereParams p;
  const double beta_r = p.rayleigh_sea_level[1];
  const double beta_m = (t - 1) * beta_r * p.rayleigh_scale_m / p.mie_scale_m;
  return 3.912 / (beta_r + beta_m) / 1e3;
}

// Hazy skies with a low sun: turbidity 2.5, 4 and 6, sun 5, 10, 20 and 30 deg high at azimuth
// 240 (an afternoon), the demo's site height.
std::vector<Case> HazyLowSunCases() {
  std::vector<Case> out;
  for (const double t : {2.5, 4.0, 6.0}) {
    AtmosphereParams ap;
    ap.visibility_km = VisibilityKmForTurbidity(t);
    const Atmosphere atmosphere{ap};
    for (const double el : {5.0, 10.0, 20.0, 30.0}) {
      TruthSky ts;
      ts.sun = EnuFromAzEl(240, el).normalized();
      ts.sun_elevation_deg = el;
      ts.table = SkyTable(atmosphere, Site{}.height_m, ts.sun, ap.solar_toa);
      out.push_back(SimCase(Formatted("T%.1f_el%02.0f", t, el), ts));
    }
  }
  return out;
}

// The real scans of ../shared/data/sky-scans/kider2014-sept (README.md there): 81 directions
// each, fitted and scored at the same directions. Left out: sample 0 (idx 0, the scan's first
// position, reads 39-75 % of its neighbours: the scanner settling, not the sky) and, as the
// README advises, the directions within 12 deg of the sun. Weight 1 per direction.
std::vector<Case> RealScanCases() {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(ROUEN_SHARED_DIR) / "data" / "sky-scans" / "kider2014-sept";
  std::vector<Case> out;
  if (!fs::exists(dir / "skies.json")) {
    std::printf("\nreal sky scans: skipped (no %s)\n", dir.c_str());
    return out;
  }
  const nlohmann::json skies = nlohmann::json::parse(std::ifstream(dir / "skies.json"))["skies"];
  SkySampleOptions region;
  region.min_sun_distance_deg = 12;
  for (const nlohmann::json& s : skies) {
    Case c;
    c.name = s["file"].get<std::string>().substr(11, 4);  // HHMM
    c.sun_elevation_deg = s["sun_elevation_deg"].get<double>();
    c.sun = EnuFromAzEl(s["sun_azimuth_deg"].get<double>(), c.sun_elevation_deg).normalized();
    const std::vector<SkySample> all =
        ReadSkySamplesCsv((dir / s["file"].get<std::string>()).string());
    for (size_t i = 1; i < all.size(); ++i) {  // the file's first line is idx 0
      if (InSkyFitRegion(all[i].dir, c.sun, region)) c.samples.push_back(all[i]);
    }
    for (const SkySample& k : c.samples) {
      c.score_dirs.push_back(k.dir);
      c.score_truth.push_back(k.radiance);
    }
    out.push_back(std::move(c));
  }
  return out;
}

// The real scans painted into an equirect panorama (a disc of 2 deg around each direction,
// the rest masked out) and fitted through ExtractSkySamples, as `rouen sky fit --image --mask`
// fits them: solid-angle weights, and for contrast every pixel alike (weight 1), both scored at
// the scans' directions. The discs hold about the same solid angle, but near the zenith many
// more pixels.
void PaintedScans(const std::vector<Case>& scans) {
  if (scans.empty()) return;
  std::printf(
      "\nThe real scans painted into a 1024x512 equirect (2 deg discs, masked), fitted from the "
      "image: per direction\n%-16s  %8s %8s  %8s %8s  %8s %8s\n",
      "sky", "CSV med", "p90", "px/sr med", "p90", "px med", "p90");
  const Intrinsics k = Intrinsics::Equirect(1024, 512);
  const Pose pose = Pose::Level(Eigen::Vector3d::Zero(), 0, 0);
  std::vector<double> all_csv, all_sr, all_px;
  for (const Case& c : scans) {
    Image img(k.width, k.height, 3, PixelUnits::kRadiance, 0.f);
    std::vector<uint8_t> mask(static_cast<size_t>(k.width) * k.height, 0);
    for (int y = 0; y < k.height; ++y) {
      for (int x = 0; x < k.width; ++x) {
        const Eigen::Vector3d d =
            (pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
        for (const SkySample& s : c.samples) {
          if (d.dot(s.dir) < std::cos(2 * kDeg)) continue;
          for (int ch = 0; ch < 3; ++ch) img.at(x, y, ch) = static_cast<float>(s.radiance[ch]);
          mask[static_cast<size_t>(y) * k.width + x] = 1;
        }
      }
    }
    SkySampleOptions so;
    so.min_sun_distance_deg = 12;
    std::vector<SkySample> px = ExtractSkySamples(img, &mask, k, pose, c.sun, so);
    SkyModel csv_fit, sr_fit, px_fit;
    FitSky(c.samples, c.sun, SkyFitOptions{}, &csv_fit);
    FitSky(px, c.sun, SkyFitOptions{}, &sr_fit);
    for (SkySample& s : px) s.weight = 1;
    FitSky(px, c.sun, SkyFitOptions{}, &px_fit);
    const std::vector<double> e_csv = CaseErrors(csv_fit, c), e_sr = CaseErrors(sr_fit, c),
                              e_px = CaseErrors(px_fit, c);
    all_csv.insert(all_csv.end(), e_csv.begin(), e_csv.end());
    all_sr.insert(all_sr.end(), e_sr.begin(), e_sr.end());
    all_px.insert(all_px.end(), e_px.begin(), e_px.end());
    std::printf("%-16s  %8.4f %8.4f  %8.4f %8.4f  %8.4f %8.4f\n", c.name.c_str(),
                Quantile(e_csv, 0.5), Quantile(e_csv, 0.9), Quantile(e_sr, 0.5),
                Quantile(e_sr, 0.9), Quantile(e_px, 0.5), Quantile(e_px, 0.9));
  }
  std::printf("%-16s  %8.4f %8.4f  %8.4f %8.4f  %8.4f %8.4f\n", "pooled", Quantile(all_csv, 0.5),
              Quantile(all_csv, 0.9), Quantile(all_sr, 0.5), Quantile(all_sr, 0.9),
              Quantile(all_px, 0.5), Quantile(all_px, 0.9));
  bench::Record("sky_fit.painted_scans.solid_angle_rel_error_p90", Quantile(all_sr, 0.9), "");
  bench::Record("sky_fit.painted_scans.per_pixel_rel_error_p90", Quantile(all_px, 0.9), "");
}

// rouen against the peer on the same samples, scored against the truth: the demo's five skies
// at visibility 35 km and the same five times in haze (15 km), hazy skies with a low sun, and
// the real scans. Times are wall times of the fit alone (rouen: FitSky with the pipeline's
// options; scipy: the three channels' fits, measured inside Python, without its start-up and
// parsing).
void CompareWithScipy() {
  std::vector<Case> demo;
  AtmosphereParams hazy;
  hazy.visibility_km = 15;
  for (const auto& [label, params] :
       {std::pair<std::string, AtmosphereParams>{"clear", AtmosphereParams{}}, {"hazy", hazy}}) {
    for (const TruthSky& t : Skies(params)) demo.push_back(SimCase(label + "_" + t.label, t));
  }
  const std::vector<Case> low = HazyLowSunCases(), scans = RealScanCases();
  std::vector<Case> all = demo;
  all.insert(all.end(), low.begin(), low.end());
  all.insert(all.end(), scans.begin(), scans.end());
  const std::vector<PeerFit> peer = RunPeer(all);
  if (peer.empty()) return;
  const std::vector<PeerFit> peer_demo(peer.begin(), peer.begin() + demo.size());
  const std::vector<PeerFit> peer_low(peer.begin() + demo.size(),
                                      peer.begin() + demo.size() + low.size());
  const std::vector<PeerFit> peer_scans(peer.begin() + demo.size() + low.size(), peer.end());
  // rouen's default objective (relative L1 smoothed within SkyFitOptions::norm_eps), and scipy's:
  // soft_l1 with f_scale 0.01 is 2 (sqrt(1 + (r/0.01)^2) - 1), proportional to rouen's p = 1
  // objective sqrt(r^2 + eps^2) - eps with eps = 0.01, so both then seek the same minimum.
  SkyFitOptions same;
  same.norm_eps = 0.01;
  const std::string head =
      "Sky fit vs scipy least_squares (soft_l1, 16 starts) on the same samples";
  CompareTable(head + ", 20000 per sky, scored against the truth; rouen: its default objective",
               demo, peer_demo, SkyFitOptions{}, "sky_fit.default", "demo skies");
  CompareTable(head +
                   ", 20000 per sky, scored against the truth; rouen: scipy's objective "
                   "(norm_eps 0.01)",
               demo, peer_demo, same, "sky_fit.same_objective", "demo skies");
  CompareTable(head +
                   ": hazy skies with a low sun (turbidity T, sun elevation), 20000 samples "
                   "each, scored against the truth; rouen: its default objective",
               low, peer_low, SkyFitOptions{}, "sky_fit.hazy_low_sun", "hazy low-sun skies");
  if (!scans.empty()) {
    CompareTable(
        head +
            ": real sky-scanner scans (Kider et al. 2014, 2013-09-24, local time), "
            "fitted and scored at their directions (not sample 0, not within 12 deg of the "
            "sun); rouen: its default objective",
        scans, peer_scans, SkyFitOptions{}, "sky_fit.real_scans", "real scans");
  }
  PaintedScans(scans);
}

void BM_FitSky20k(benchmark::State& state, SkyModelKind kind, SkyWeighting weighting,
                  double norm_p) {
  static const std::vector<TruthSky> skies = DemoSkies();
  const TruthSky& sky = skies[2];  // 13:30, sun ~62 deg
  const std::vector<SkySample> samples = Samples(sky, 20000, 11);
  SkyFitOptions o;
  o.model = kind;
  o.weighting = weighting;
  o.norm_p = norm_p;
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
BENCHMARK_CAPTURE(BM_FitSky20k, seven_param, SkyModelKind::kSevenParam, SkyWeighting::kPaper, 2.0)
    ->Unit(benchmark::kMillisecond);
// The pipeline's fit (app/pipeline.cc): relative residuals, L1.
BENCHMARK_CAPTURE(BM_FitSky20k, seven_param_relative_l1, SkyModelKind::kSevenParam,
                  SkyWeighting::kRelative, 1.0)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FitSky20k, perez5, SkyModelKind::kPerez5, SkyWeighting::kPaper, 2.0)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FitSky20k, cie, SkyModelKind::kCie, SkyWeighting::kPaper, 2.0)
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  if (const char* d = std::getenv("ROUEN_SKY_BENCH_SCIPY_ONLY"); d && *d == '1') {
    rouen::CompareWithScipy();
    return 0;
  }
  rouen::PrintAccuracy();
  rouen::CompareWithScipy();
  if (const char* d = std::getenv("ROUEN_SKY_BENCH_DIAG"); d && *d == '1') {
    rouen::PrintDiagnostics();
  }
  if (const char* d = std::getenv("ROUEN_SKY_BENCH_STUDY"); d && *d == '1') {
    rouen::PrintFitStudy();
    rouen::PrintPhotoStudy();
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
