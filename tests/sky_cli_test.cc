// End-to-end tests of `rouen sky render` and `rouen sky fit`: draw a known sky, fit it back,
// and bad input.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/camera.h"
#include "core/files.h"
#include "core/image.h"
#include "core/solar.h"
#include "solve/sky_model.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using rouen::cli_test::Q;
using rouen::cli_test::Result;
using rouen::cli_test::RunRouen;
using rouen::cli_test::TempDir;

// A clear sky of eq. 9 (sun at azimuth 200, elevation 40), as `sky fit` would write it.
nlohmann::json KnownFit() {
  SkyModel m;
  m.sun_dir = EnuFromAzEl(200, 40);
  m.channel[0] = {0.8, -1.0, -0.40, 12.0, -3.2, 0.50, 0.9};
  m.channel[1] = {1.1, -1.0, -0.35, 9.0, -2.8, 0.45, 0.9};
  m.channel[2] = {1.9, -0.9, -0.30, 7.0, -2.5, 0.40, 0.85};
  return m;
}

TEST(SkyCli, RenderThenFitRecoversTheSky) {
  const fs::path dir = TempDir("roundtrip");
  WriteFileAtomic(dir / "known.json", KnownFit().dump());
  Result r = RunRouen("sky render " + Q(dir / "known.json") + " --out " + Q(dir / "sky.exr") +
                      " --width 256");
  ASSERT_EQ(r.code, 0) << r.out;
  const Image img = ReadImage((dir / "sky.exr").string());
  EXPECT_EQ(img.width, 256);
  EXPECT_EQ(img.height, 128);
  // Row 0 is the zenith: every column there shows (nearly) the zenith radiance.
  const SkyModel truth = KnownFit().get<SkyModel>();
  const double zenith = truth.Radiance(Eigen::Vector3d::UnitZ())[1];
  EXPECT_NEAR(img.at(10, 0, 1), zenith, 0.02 * zenith);
  // Column x looks at azimuth (x + 0.5) / W * 360: the sun's column (az 200) at elevation 40
  // (row (90 - 40) / 180 * H) is the brightest pixel above 30 degrees.
  int bx = 0, by = 0;
  for (int y = 0; y < 128 * 60 / 180; ++y)
    for (int x = 0; x < 256; ++x)
      if (img.at(x, y, 1) > img.at(bx, by, 1)) bx = x, by = y;
  EXPECT_NEAR((bx + 0.5) / 256 * 360, 200, 360.0 / 256 + 1e-9);
  EXPECT_NEAR(90 - (by + 0.5) / 128 * 180, 40, 180.0 / 128 + 1e-9);

  for (const char* model : {"7", "perez5", "cie"}) {
    const fs::path out = dir / (std::string("fit_") + model + ".json");
    r = RunRouen("sky fit --image " + Q(dir / "sky.exr") +
                 " --projection equirect --sun-azimuth 200 --sun-elevation 40 --model " + model +
                 " --out " + Q(out) + " --residuals " + Q(dir / "res.exr"));
    ASSERT_EQ(r.code, 0) << model << ": " << r.out;
    std::ifstream in(out);
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_EQ(j.at("model"), model);
    ASSERT_EQ(j.at("channels").size(), 3u);
    for (const char* key :
         {"Lz", "a", "b", "c", "d", "e", "h", "rel_error_median", "rel_error_p90"}) {
      EXPECT_TRUE(j["channels"][1].contains(key)) << key;
    }
    const double med = j.at("rel_error_median"), p90 = j.at("rel_error_p90");
    if (std::string(model) == "7") {
      // The image is eq. 9 itself (float EXR): the fit is exact to LM tolerance, and the
      // parameters come back.
      EXPECT_LT(p90, 0.005);
      for (int c = 0; c < 3; ++c) {
        const SkyParams& t = truth.channel[c];
        const nlohmann::json& f = j["channels"][c];
        EXPECT_NEAR(f.at("Lz").get<double>(), t.Lz, 0.02 * t.Lz) << c;
        EXPECT_NEAR(f.at("h").get<double>(), t.h, 0.05) << c;
        EXPECT_NEAR(f.at("d").get<double>(), t.d, 0.2) << c;
      }
    } else {
      // Perez-5 (h = 1) and CIE are different shapes: a fit, not exact, but bounded.
      EXPECT_LT(med, std::string(model) == "cie" ? 0.5 : 0.05) << model;
      EXPECT_LE(med, p90);
    }
    if (std::string(model) == "cie") {
      EXPECT_TRUE(j.contains("cie_type"));
    }
  }
  const Image res = ReadImage((dir / "res.exr").string());
  EXPECT_EQ(res.width, 256);
  // The fitted FIT.json renders too (sky render reads what sky fit writes).
  r = RunRouen("sky render " + Q(dir / "fit_7.json") + " --out " + Q(dir / "back.exr"));
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

TEST(SkyCli, MaskOverridesAndAzimuthOffsetRotates) {
  const fs::path dir = TempDir("mask");
  WriteFileAtomic(dir / "known.json", KnownFit().dump());
  // Rendered with the left edge at azimuth 90: the sun at 200 sits at column az 110.
  Result r = RunRouen("sky render " + Q(dir / "known.json") + " --out " + Q(dir / "sky.exr") +
                      " --width 128 --azimuth-offset 90");
  ASSERT_EQ(r.code, 0) << r.out;
  // A mask keeping only the upper left quarter.
  Image m(128, 64, 1, PixelUnits::kDigital, 0.f);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) m.at(x, y) = 255;
  WriteImage((dir / "mask.png").string(), m, StoredType::kUint8);
  r = RunRouen("sky fit --image " + Q(dir / "sky.exr") +
               " --projection equirect --sun-azimuth 200 --sun-elevation 40 --azimuth-offset 90"
               " --mask " +
               Q(dir / "mask.png") + " --out " + Q(dir / "fit.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  std::ifstream in(dir / "fit.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("mask"), "user");
  // At most the quarter of the panorama that the mask keeps (minus the horizon band).
  EXPECT_LE(j.at("fitted_pixels").get<int>(), 64 * 32);
  EXPECT_GT(j.at("fitted_pixels").get<int>(), 64 * 20);
  EXPECT_LT(j.at("rel_error_p90").get<double>(), 0.01);
  // Without the offset the sun would be in the wrong place: a clearly worse fit.
  r = RunRouen("sky fit --image " + Q(dir / "sky.exr") +
               " --projection equirect --sun-azimuth 200 --sun-elevation 40 --no-segment"
               " --out " +
               Q(dir / "wrong.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  std::ifstream in2(dir / "wrong.json");
  const nlohmann::json w = nlohmann::json::parse(in2);
  EXPECT_GT(w.at("rel_error_p90").get<double>(), 0.05);
  fs::remove_all(dir);
}

TEST(SkyCli, BadInputGivesClearErrors) {
  const fs::path dir = TempDir("bad");
  WriteFileAtomic(dir / "known.json", KnownFit().dump());
  ASSERT_EQ(RunRouen("sky render " + Q(dir / "known.json") + " --out " + Q(dir / "sky.exr") +
                     " --width 64")
                .code,
            0);
  const std::string base =
      "sky fit --image " + Q(dir / "sky.exr") + " --sun-azimuth 200 --out " + Q(dir / "f.json");
  auto expect_error = [](const Result& r, const std::string& what) {
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.out.find("rouen: error:"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(what), std::string::npos) << "expected '" << what << "' in: " << r.out;
  };
  expect_error(RunRouen("sky fit --image " + Q(dir / "missing.exr") +
                        " --projection equirect --sun-azimuth 0 --sun-elevation 30 --out " +
                        Q(dir / "f.json")),
               "missing.exr");
  expect_error(RunRouen(base + " --projection fisheye --sun-elevation 40"), "fisheye");
  expect_error(RunRouen(base + " --projection equirect --sun-elevation -10"), "-5");
  Image m(10, 10, 1, PixelUnits::kDigital, 255.f);
  WriteImage((dir / "small.png").string(), m, StoredType::kUint8);
  expect_error(
      RunRouen(base + " --projection equirect --sun-elevation 40 --mask " + Q(dir / "small.png")),
      "small.png");
  expect_error(RunRouen(base + " --projection equirect --sun-elevation 40 --model cie9"), "cie9");
  WriteFileAtomic(dir / "broken.json", "{\"channels\": [1, 2");
  expect_error(RunRouen("sky render " + Q(dir / "broken.json") + " --out " + Q(dir / "x.exr")),
               "broken.json");
  nlohmann::json no_h = KnownFit();
  no_h["channels"][2].erase("h");
  WriteFileAtomic(dir / "no_h.json", no_h.dump());
  expect_error(RunRouen("sky render " + Q(dir / "no_h.json") + " --out " + Q(dir / "x.exr")),
               "'h'");
  EXPECT_FALSE(fs::exists(dir / "f.json"));
  EXPECT_FALSE(fs::exists(dir / "x.exr"));
  fs::remove_all(dir);
}

// A sky scanner's 81 directions (rings at 12.1, 33.7, 53.4 and 71.9 deg and the zenith) of the
// known sky, as `idx, azimuth_deg, elevation_deg, R, G, B` lines.
std::string ScanCsv(const SkyModel& sky, int rings = 4) {
  std::string out = "idx,azimuth_deg,elevation_deg,R,G,B\n";
  const std::pair<double, int> ring[] = {{12.1151, 32}, {33.749, 24}, {53.3665, 16}, {71.9187, 8}};
  int idx = 0;
  for (int r = 0; r < rings; ++r) {
    for (int i = 0; i < ring[r].second; ++i) {
      const double az = 360.0 * i / ring[r].second;
      const Eigen::Vector3d l = sky.Radiance(EnuFromAzEl(az, ring[r].first).normalized());
      out += std::to_string(idx++) + "," + std::to_string(az) + "," +
             std::to_string(ring[r].first) + "," + std::to_string(l[0]) + "," +
             std::to_string(l[1]) + "," + std::to_string(l[2]) + "\n";
    }
  }
  const Eigen::Vector3d z = sky.Radiance(Eigen::Vector3d::UnitZ());
  out += std::to_string(idx) + ",0,90," + std::to_string(z[0]) + "," + std::to_string(z[1]) + "," +
         std::to_string(z[2]) + "\n";
  return out;
}

TEST(SkyCli, SamplesCsvFitsMeasuredDirections) {
  const fs::path dir = TempDir("csv");
  const SkyModel truth = KnownFit().get<SkyModel>();
  WriteFileAtomic(dir / "scan.csv", ScanCsv(truth));
  // The sun (azimuth 200, elevation 40) is 7.4 deg from the 33.7 deg ring's direction at
  // azimuth 195 and 10.1 deg from the one at 210: --sun-exclusion 8 leaves out the first.
  const Result r = RunRouen("sky fit --samples " + Q(dir / "scan.csv") +
                            " --sun-azimuth 200 --sun-elevation 40 --sun-exclusion 8 --out " +
                            Q(dir / "fit.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  std::ifstream in(dir / "fit.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("samples").get<int>(), 80);
  EXPECT_EQ(j.at("directions_left_out").get<int>(), 1);
  EXPECT_EQ(j.at("error_weighting"), "per direction");
  // The values are eq. 9 itself, printed to 6 significant digits (a relative error of at most
  // 5e-6 each): the fit is exact to that and to LM's tolerance.
  EXPECT_LT(j.at("rel_error_p90").get<double>(), 0.005);
  // The fit renders.
  EXPECT_EQ(RunRouen("sky render " + Q(dir / "fit.json") + " --out " + Q(dir / "s.exr")).code, 0);
  fs::remove_all(dir);
}

TEST(SkyCli, TooLittleSkyIsRefused) {
  const fs::path dir = TempDir("little");
  const SkyModel truth = KnownFit().get<SkyModel>();
  auto expect_error = [](const Result& r, const std::string& what) {
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.out.find(what), std::string::npos) << "expected '" << what << "' in: " << r.out;
  };
  // Three measured directions: fewer than 3 per parameter.
  std::string three = "azimuth_deg,elevation_deg,R,G,B\n";
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d l = truth.Radiance(EnuFromAzEl(120.0 * i, 30).normalized());
    three += std::to_string(120 * i) + ",30," + std::to_string(l[0]) + "," + std::to_string(l[1]) +
             "," + std::to_string(l[2]) + "\n";
  }
  WriteFileAtomic(dir / "three.csv", three);
  const std::string sun = " --sun-azimuth 200 --sun-elevation 40 --out " + Q(dir / "f.json");
  expect_error(RunRouen("sky fit --samples " + Q(dir / "three.csv") + sun), "need at least 21");
  // The same three painted into a panorama as discs of 5 deg: thousands of pixels, three
  // measurements; without a mask the automatic segmentation is pointed at.
  Image img(256, 128, 3, PixelUnits::kRadiance, 0.f);
  Image mask(256, 128, 1, PixelUnits::kDigital, 0.f);
  const Intrinsics k = Intrinsics::Equirect(256, 128);
  for (int y = 0; y < 128; ++y) {
    for (int x = 0; x < 256; ++x) {
      const Eigen::Vector3d d = Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      const Eigen::Vector3d enu(d.x(), d.z(), -d.y());  // a level equirect (Pose::Level, 0, 0)
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d m = EnuFromAzEl(120.0 * i, 30).normalized();
        if (enu.dot(m) < std::cos(5 * kDeg)) continue;
        const Eigen::Vector3d l = truth.Radiance(m);
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(l[c]);
        mask.at(x, y) = 255;
      }
    }
  }
  WriteImage((dir / "three.exr").string(), img, StoredType::kFloat);
  WriteImage((dir / "three.png").string(), mask, StoredType::kUint8);
  const std::string image = "sky fit --image " + Q(dir / "three.exr") + " --projection equirect";
  expect_error(RunRouen(image + " --mask " + Q(dir / "three.png") + sun), "distinct directions");
  expect_error(RunRouen(image + sun), "--mask");
  // Both inputs, or options of the other one.
  expect_error(RunRouen(image + " --samples " + Q(dir / "three.csv") + sun), "either --image");
  expect_error(RunRouen("sky fit --samples " + Q(dir / "three.csv") + " --mask " +
                        Q(dir / "three.png") + sun),
               "apply to --image");
  WriteFileAtomic(dir / "bad.csv", "10,20,1,1,1\n10,20,1,1\n");
  expect_error(RunRouen("sky fit --samples " + Q(dir / "bad.csv") + sun), "bad.csv:2:");
  EXPECT_FALSE(fs::exists(dir / "f.json"));
  fs::remove_all(dir);
}

// The 81 directions painted as 2-degree discs into a 1024-wide panorama with their mask:
// --max-samples 500 gives 500 samples over all of them (a pixel lattice used to find 44, most
// at the zenith), and the error figures count each disc by its solid angle, as the CSV of the
// same directions counts each direction once.
TEST(SkyCli, PaintedScanIsFittedPerDirection) {
  const fs::path dir = TempDir("painted");
  const SkyModel truth = KnownFit().get<SkyModel>();
  Image img(1024, 512, 3, PixelUnits::kRadiance, 0.f);
  Image mask(1024, 512, 1, PixelUnits::kDigital, 0.f);
  const Intrinsics k = Intrinsics::Equirect(1024, 512);
  std::vector<Eigen::Vector3d> dirs;
  const std::pair<double, int> ring[] = {{12.1151, 32}, {33.749, 24}, {53.3665, 16}, {71.9187, 8}};
  for (const auto& [el, n] : ring)
    for (int i = 0; i < n; ++i) dirs.push_back(EnuFromAzEl(360.0 * i / n, el).normalized());
  dirs.push_back(Eigen::Vector3d::UnitZ());
  for (int y = 0; y < 512; ++y) {
    for (int x = 0; x < 1024; ++x) {
      const Eigen::Vector3d d = Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      const Eigen::Vector3d enu(d.x(), d.z(), -d.y());
      for (const Eigen::Vector3d& m : dirs) {
        if (enu.dot(m) < std::cos(2 * kDeg)) continue;
        const Eigen::Vector3d l = truth.Radiance(m);
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(l[c]);
        mask.at(x, y) = 255;
      }
    }
  }
  WriteImage((dir / "scan.exr").string(), img, StoredType::kFloat);
  WriteImage((dir / "scan.png").string(), mask, StoredType::kUint8);
  const Result r = RunRouen("sky fit --image " + Q(dir / "scan.exr") +
                            " --projection equirect --mask " + Q(dir / "scan.png") +
                            " --sun-azimuth 200 --sun-elevation 40 --max-samples 500 --out " +
                            Q(dir / "fit.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  std::ifstream in(dir / "fit.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("samples").get<int>(), 500);
  EXPECT_EQ(j.at("error_weighting"), "solid angle");
  // Each disc is one value of eq. 9, the sky at its centre: the fit cannot follow the constant
  // discs, and the error stays small at the directions themselves.
  EXPECT_LT(j.at("rel_error_median").get<double>(), 0.05);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
