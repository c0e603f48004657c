// What the sky fit is given: solid-angle weights of image samples, measured directions from a
// CSV, the coverage rule that refuses too little sky, and the fit on real scanned skies.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/image.h"
#include "core/solar.h"
#include "core/stats.h"
#include "solve/sky_fit.h"
#include "solve/sky_model.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

SkyModel ClearSky(const Eigen::Vector3d& sun) {
  SkyModel m;
  m.sun_dir = sun;
  m.channel[0] = {0.8, -1.0, -0.40, 12.0, -3.2, 0.50, 0.9};
  m.channel[1] = {1.1, -1.0, -0.35, 9.0, -2.8, 0.45, 0.9};
  m.channel[2] = {1.9, -0.9, -0.30, 7.0, -2.5, 0.40, 0.85};
  return m;
}

// A sky scanner's pattern (as the Kider et al. 2014 scans): rings of 32, 24, 16 and 8
// directions at 12.1, 33.7, 53.4 and 71.9 deg and the zenith.
std::vector<Eigen::Vector3d> ScannerDirections() {
  std::vector<Eigen::Vector3d> out;
  const std::pair<double, int> rings[] = {{12.1151, 32}, {33.749, 24}, {53.3665, 16}, {71.9187, 8}};
  for (const auto& [el, n] : rings) {
    for (int i = 0; i < n; ++i) out.push_back(EnuFromAzEl(360.0 * i / n, el).normalized());
  }
  out.push_back(Eigen::Vector3d::UnitZ());
  return out;
}

// An equirect panorama (row 0 the zenith) with a disc of `radius_deg` around each direction
// showing the sky there, and the mask of the discs.
struct Painted {
  Intrinsics k;
  Pose pose;
  Image img;
  std::vector<uint8_t> mask;
  std::vector<int> disc;  // per pixel: the disc's index, or -1
};
Painted Paint(const std::vector<Eigen::Vector3d>& dirs, const SkyModel& sky, int width,
              double radius_deg) {
  Painted p;
  p.k = Intrinsics::Equirect(width, width / 2);
  p.pose = Pose::Level(Eigen::Vector3d::Zero(), 0, 0);
  p.img = Image(p.k.width, p.k.height, 3, PixelUnits::kRadiance, 0.f);
  p.mask.assign(static_cast<size_t>(p.k.width) * p.k.height, 0);
  p.disc.assign(p.mask.size(), -1);
  const double cos_r = std::cos(radius_deg * kDeg);
  for (int y = 0; y < p.k.height; ++y) {
    for (int x = 0; x < p.k.width; ++x) {
      const Eigen::Vector3d d =
          (p.pose.rotation * Unproject(p.k, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
      for (size_t i = 0; i < dirs.size(); ++i) {
        if (d.dot(dirs[i]) < cos_r) continue;
        const Eigen::Vector3d l = sky.Radiance(dirs[i]);
        for (int c = 0; c < 3; ++c) p.img.at(x, y, c) = static_cast<float>(l[c]);
        const size_t px = static_cast<size_t>(y) * p.k.width + x;
        p.mask[px] = 1;
        p.disc[px] = static_cast<int>(i);
      }
    }
  }
  return p;
}

// Every pixel kept: each sample's weight is its pixel's solid angle, so a region's samples sum
// to its solid angle whatever the pixel density. Discs of radius r around the scanner's
// directions: the zenith disc holds many times the pixels of a disc at 12 deg, the same solid
// angle. The pixels whose centres fall in a disc differ from it by its boundary pixels: within
// sqrt(2) t / r relative (t the pixel's angular size), plus the pixel solid angle's t^2.
TEST(ExtractSkySamples, WeighsPixelsBySolidAngle) {
  const Eigen::Vector3d sun = EnuFromAzEl(100, 40).normalized();
  const std::vector<Eigen::Vector3d> dirs = ScannerDirections();
  const double r = 3;
  const Painted p = Paint(dirs, ClearSky(sun), 1024, r);
  SkySampleOptions o;
  o.min_sun_distance_deg = 0;
  o.max_samples = 1 << 30;
  const std::vector<SkySample> s = ExtractSkySamples(p.img, &p.mask, p.k, p.pose, sun, o);
  std::vector<double> weight(dirs.size(), 0);
  std::vector<int> count(dirs.size(), 0);
  for (const SkySample& q : s) {
    size_t best = 0;
    for (size_t i = 1; i < dirs.size(); ++i)
      if (q.dir.dot(dirs[i]) > q.dir.dot(dirs[best])) best = i;
    weight[best] += q.weight;
    ++count[best];
  }
  const double t = kPi / p.k.height;
  const double disc = 2 * kPi * (1 - std::cos(r * kDeg));
  for (size_t i = 0; i < dirs.size(); ++i) {
    EXPECT_NEAR(weight[i] / disc, 1, std::sqrt(2.0) * t / (r * kDeg) + t * t) << i;
  }
  // The zenith disc (the last direction) against one at 12 deg: several times the pixels.
  EXPECT_GT(count.back(), 4 * count[0]);
}

// Thinned to 500 samples, the painted discs are all represented (every pixel is a candidate;
// equal shares per equal-area cell), not only the zenith's, and the 500 are all returned.
TEST(ExtractSkySamples, MaxSamplesSpreadsOverSmallMaskedRegions) {
  const Eigen::Vector3d sun = EnuFromAzEl(100, 40).normalized();
  const std::vector<Eigen::Vector3d> dirs = ScannerDirections();
  const Painted p = Paint(dirs, ClearSky(sun), 1024, 2);
  SkySampleOptions o;
  o.min_sun_distance_deg = 0;
  o.max_samples = 500;
  const std::vector<SkySample> s = ExtractSkySamples(p.img, &p.mask, p.k, p.pose, sun, o);
  EXPECT_EQ(s.size(), 500u);
  std::set<size_t> seen;
  for (const SkySample& q : s) {
    size_t best = 0;
    for (size_t i = 1; i < dirs.size(); ++i)
      if (q.dir.dot(dirs[i]) > q.dir.dot(dirs[best])) best = i;
    seen.insert(best);
  }
  EXPECT_EQ(seen.size(), dirs.size());
}

// A weight of k is k copies of the sample: the same objective up to a constant factor, the
// same minimum. The two fits stop within function_tolerance (1e-7 relative) of it, which moves
// the model by a few 1e-4 of the samples' 1 % scatter: 1e-4 relative is far above that.
TEST(FitSky, WeightIsRepetition) {
  const Eigen::Vector3d sun = EnuFromAzEl(140, 35).normalized();
  const SkyModel truth = ClearSky(sun);
  std::mt19937_64 rng(4);
  std::normal_distribution<double> noise(0, 0.01);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<SkySample> weighted, repeated;
  for (int i = 0; i < 600; ++i) {
    const double z = 0.06 + 0.94 * u(rng), phi = 2 * kPi * u(rng), rr = std::sqrt(1 - z * z);
    const Eigen::Vector3d d(rr * std::cos(phi), rr * std::sin(phi), z);
    if (d.dot(sun) > std::cos(3 * kDeg)) continue;
    Eigen::Vector3d y = truth.Radiance(d);
    for (int c = 0; c < 3; ++c) y[c] *= 1 + noise(rng);
    const int k = d.z() > 0.7 ? 3 : 1;  // the zenith's samples weigh three times
    weighted.push_back({d, y, static_cast<double>(k)});
    for (int j = 0; j < k; ++j) repeated.push_back({d, y});
  }
  SkyModel a, b;
  FitSky(weighted, sun, SkyFitOptions{}, &a);
  FitSky(repeated, sun, SkyFitOptions{}, &b);
  for (const SkySample& s : weighted) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(a.Radiance(s.dir)[c] / b.Radiance(s.dir)[c], 1, 1e-4);
    }
  }
  // The summary's error figures count each sample by its weight: as the repeated set's.
  const SkyFitSummary sa = FitSky(weighted, sun, SkyFitOptions{}, &a);
  const SkyFitSummary sb = FitSky(repeated, sun, SkyFitOptions{}, &b);
  EXPECT_NEAR(sa.channel[1].rel_error_median, sb.channel[1].rel_error_median, 1e-4);
  EXPECT_NEAR(sa.channel[1].rel_error_p90, sb.channel[1].rel_error_p90, 1e-4);
}

// The coverage rule: 21 distinct directions (3 per parameter) spread at least as a 60 deg cap.
TEST(FitSky, RefusesTooLittleSky) {
  const Eigen::Vector3d sun = EnuFromAzEl(200, 30).normalized();
  const SkyModel sky = ClearSky(sun);
  auto samples_at = [&](const std::vector<Eigen::Vector3d>& dirs) {
    std::vector<SkySample> out;
    for (const Eigen::Vector3d& d : dirs) out.push_back({d, sky.Radiance(d)});
    return out;
  };
  // The whole hemisphere, evenly: the spread of a 90 deg cap (the grid's 10 bands shift the
  // cells' mean directions by under half a band, 0.05 in z: about 3 deg).
  std::vector<Eigen::Vector3d> even;
  for (int i = 0; i < 4000; ++i) {
    const double z = (i + 0.5) / 4000, rr = std::sqrt(1 - z * z), phi = 2.39996 * i;
    even.push_back(Eigen::Vector3d(rr * std::cos(phi), rr * std::sin(phi), z));
  }
  const SkyCoverage full = MeasureSkyCoverage(samples_at(even));
  EXPECT_EQ(full.directions, 200);
  EXPECT_NEAR(full.spread_deg, 90, 3);
  SkyModel fit;
  // 20 directions of the scanner's lowest ring, each in its own cell: one too few.
  std::vector<Eigen::Vector3d> twenty;
  for (int i = 0; i < 20; ++i) twenty.push_back(EnuFromAzEl(18.0 * i + 9, 12).normalized());
  EXPECT_EQ(MeasureSkyCoverage(samples_at(twenty)).directions, 20);
  try {
    FitSky(samples_at(twenty), sun, SkyFitOptions{}, &fit);
    ADD_FAILURE() << "20 directions accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("need at least 21"), std::string::npos) << e.what();
  }
  // Thousands of samples, but only within 30 deg of the zenith: too concentrated.
  std::vector<Eigen::Vector3d> cap;
  for (const Eigen::Vector3d& d : even)
    if (d.z() > std::cos(30 * kDeg)) cap.push_back(d);
  const SkyCoverage c = MeasureSkyCoverage(samples_at(cap));
  EXPECT_GE(c.directions, 21);
  EXPECT_LT(c.spread_deg, 35);
  try {
    FitSky(samples_at(cap), sun, SkyFitOptions{}, &fit);
    ADD_FAILURE() << "a 30 deg cap accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cap of radius"), std::string::npos) << e.what();
  }
  // Spread over the sky but three measurements (an image painted from three directions).
  std::vector<SkySample> three = samples_at(even);
  for (size_t i = 0; i < three.size(); ++i)
    three[i].radiance = Eigen::Vector3d::Constant(1 + i % 3);
  EXPECT_EQ(MeasureSkyCoverage(three).directions, 3);
  EXPECT_THROW(FitSky(three, sun, SkyFitOptions{}, &fit), Error);
  // The scanner's 81 directions are enough.
  EXPECT_NO_THROW(FitSky(samples_at(ScannerDirections()), sun, SkyFitOptions{}, &fit));
  SkyFitOptions bad;
  bad.min_spread_deg = 95;
  EXPECT_THROW(bad.Validate(), Error);
}

fs::path TempCsv(const std::string& name, const std::string& text) {
  const fs::path p = fs::temp_directory_path() / ("rouen_sky_csv_" + name + ".csv");
  std::ofstream(p) << text;
  return p;
}

TEST(ReadSkySamplesCsv, ReadsScannerAndMeterFiles) {
  // A scanner's file: header, index column.
  const fs::path a = TempCsv("idx",
                             "idx,azimuth_deg,elevation_deg,R,G,B\n0,0,12.1,1,2,3\n"
                             "\n# a comment\n1, 90 , 45,2,3,4\r\n2,180,90,3,4,5\n");
  const std::vector<SkySample> s = ReadSkySamplesCsv(a.string());
  ASSERT_EQ(s.size(), 3u);
  EXPECT_NEAR((s[0].dir - EnuFromAzEl(0, 12.1).normalized()).norm(), 0, 1e-12);
  EXPECT_NEAR((s[1].dir - EnuFromAzEl(90, 45).normalized()).norm(), 0, 1e-12);
  EXPECT_EQ(s[1].radiance, Eigen::Vector3d(2, 3, 4));
  EXPECT_EQ(s[2].weight, 1);
  // A luminance meter's: no header, five fields.
  const fs::path b = TempCsv("plain", "10,20,1,1,1\n200,60,0.5,0.6,0.7\n");
  EXPECT_EQ(ReadSkySamplesCsv(b.string()).size(), 2u);
  fs::remove(a);
  fs::remove(b);
}

TEST(ReadSkySamplesCsv, ErrorsNameFileAndLine) {
  const std::string head = "azimuth_deg,elevation_deg,R,G,B\n10,20,1,1,1\n";
  const std::pair<std::string, std::string> cases[] = {
      {"10,20,1,1\n", ":3: 4 comma-separated fields"},  // on the first data line: 2
      {"10,20,1,1,1,7\n", ":3: 6 fields"},
      {"10,x,1,1,1\n", ":3: elevation_deg 'x' is not a number"},
      {"10,20,nan,1,1\n", ":3: R is not finite"},
      {"10,20,1,-2,1\n", ":3: G -2 is not positive"},
      {"10,20,1,1,0\n", ":3: B 0 is not positive"},
      {"10,95,1,1,1\n", ":3: elevation_deg 95 is outside [0, 90]"},
      {"10,-1,1,1,1\n", ":3: elevation_deg -1 is outside [0, 90]"},
      {"370,20,1,1,1\n", ":3: the same direction as line 2"},
  };
  for (const auto& [line, what] : cases) {
    const fs::path p = TempCsv("bad", head + line);
    try {
      ReadSkySamplesCsv(p.string());
      ADD_FAILURE() << "accepted: " << line;
    } catch (const Error& e) {
      std::string expect = what;
      if (line == "10,20,1,1\n") expect = ":3: 4 fields, the first line has 5";
      EXPECT_NE(std::string(e.what()).find(p.string() + expect), std::string::npos)
          << e.what() << " / " << expect;
    }
    fs::remove(p);
  }
  // The zenith at any azimuth is one direction.
  const fs::path z = TempCsv("zenith", "0,90,1,1,1\n120,90,1,1,1\n");
  EXPECT_THROW(ReadSkySamplesCsv(z.string()), Error);
  const fs::path first = TempCsv("first", "1,2,3,4\n");
  try {
    ReadSkySamplesCsv(first.string());
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(":1: 4 comma-separated fields"), std::string::npos)
        << e.what();
  }
  const fs::path empty = TempCsv("empty", "azimuth_deg,elevation_deg,R,G,B\n");
  EXPECT_THROW(ReadSkySamplesCsv(empty.string()), Error);
  EXPECT_THROW(ReadSkySamplesCsv("/nonexistent/scan.csv"), Error);
  fs::remove(z);
  fs::remove(first);
  fs::remove(empty);
}

// The real scans (../shared/data/sky-scans/kider2014-sept): each fitted at its directions
// (sample 0, the scanner settling, and the directions within 12 deg of the sun left out, as
// its README advises). The README measures what eq. 9 can do on them: about 4 % median and
// 15-20 % at the 90th percentile on the hazy afternoon skies, whoever fits it. A fit that
// found eq. 9's optimum for the robust objective stays within those, scan by scan: median below
// 5 % and p90 below 20 %. And an image painted from a scan (a 2 deg disc per direction, the
// zenith's disc covering many more pixels) fitted through ExtractSkySamples with its solid-angle
// weights is no worse at the p90 of the five scans' errors than the same pixels weighted alike,
// the weighting the sky fit had before (scan by scan the two trade places on a few 1e-3).
TEST(FitSky, RealScannedSkies) {
  const fs::path dir = fs::path(ROUEN_SHARED_DIR) / "data" / "sky-scans" / "kider2014-sept";
  if (!fs::exists(dir / "skies.json")) {
    GTEST_SKIP() << "no real sky scans at " << dir << " (the shared data folder is absent)";
  }
  const nlohmann::json skies = nlohmann::json::parse(std::ifstream(dir / "skies.json"))["skies"];
  ASSERT_EQ(skies.size(), 5u);
  SkySampleOptions region;
  region.min_sun_distance_deg = 12;
  std::array<std::vector<double>, 2> pooled;  // solid angle, per pixel
  for (const nlohmann::json& s : skies) {
    const std::string name = s["file"].get<std::string>();
    const Eigen::Vector3d sun =
        EnuFromAzEl(s["sun_azimuth_deg"].get<double>(), s["sun_elevation_deg"].get<double>())
            .normalized();
    const std::vector<SkySample> all = ReadSkySamplesCsv((dir / name).string());
    ASSERT_EQ(all.size(), 81u) << name;
    std::vector<SkySample> used;
    for (size_t i = 1; i < all.size(); ++i)
      if (InSkyFitRegion(all[i].dir, sun, region)) used.push_back(all[i]);
    SkyModel fit;
    FitSky(used, sun, SkyFitOptions{}, &fit);
    std::vector<double> err;
    for (const SkySample& q : used) {
      const Eigen::Vector3d l = fit.Radiance(q.dir);
      for (int c = 0; c < 3; ++c) err.push_back(std::abs(l[c] / q.radiance[c] - 1));
    }
    EXPECT_LT(Quantile(err, 0.5), 0.05) << name;
    EXPECT_LT(Quantile(err, 0.9), 0.20) << name;

    std::vector<Eigen::Vector3d> dirs;
    for (const SkySample& q : used) dirs.push_back(q.dir);
    Painted p = Paint(dirs, ClearSky(sun), 512, 2);  // then each disc its scan's radiance
    for (size_t px = 0; px < p.disc.size(); ++px) {
      if (p.disc[px] < 0) continue;
      for (int c = 0; c < 3; ++c)
        p.img.data[px * 3 + c] = static_cast<float>(used[p.disc[px]].radiance[c]);
    }
    std::vector<SkySample> px = ExtractSkySamples(p.img, &p.mask, p.k, p.pose, sun, region);
    std::array<SkyModel, 2> fits;
    FitSky(px, sun, SkyFitOptions{}, &fits[0]);
    for (SkySample& q : px) q.weight = 1;
    FitSky(px, sun, SkyFitOptions{}, &fits[1]);
    for (int k = 0; k < 2; ++k) {
      std::vector<double> e;
      for (const SkySample& q : used) {
        const Eigen::Vector3d l = fits[k].Radiance(q.dir);
        for (int c = 0; c < 3; ++c) e.push_back(std::abs(l[c] / q.radiance[c] - 1));
      }
      pooled[k].insert(pooled[k].end(), e.begin(), e.end());
    }
  }
  EXPECT_LE(Quantile(pooled[0], 0.9), Quantile(pooled[1], 0.9));
}

}  // namespace
}  // namespace rouen
