// End-to-end tests of `rouen calib envmap` and `rouen calib orient`: photos rendered from a
// known environment / sun through core/camera.h, written as EXR with lens and pose files.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
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
#include "core/time.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using rouen::cli_test::Q;
using rouen::cli_test::Result;
using rouen::cli_test::RunRouen;
using rouen::cli_test::TempDir;

Eigen::Vector3d Env(const Eigen::Vector3d& d) {
  return Eigen::Vector3d(1.5 + 0.5 * d.z() + 0.3 * d.x(), 1.2 + 0.4 * d.y(), 1.0 + 0.3 * d.z());
}

Pose Camera(double az, double el, double roll_deg) {
  Pose p = Pose::Level(Eigen::Vector3d::Zero(), az, el);
  p.rotation = p.rotation * Eigen::AngleAxisd(roll_deg * kDeg, Eigen::Vector3d::UnitZ());
  return p;
}

// Writes photo, lens and pose files for one camera; returns the list line.
std::string WritePhoto(const fs::path& dir, const std::string& name, const Intrinsics& k,
                       const Pose& pose) {
  Image img(k.width, k.height, 3, PixelUnits::kRadiance, 0.f);
  const double circle = std::min({k.cx, k.cy, k.width - k.cx, k.height - k.cy});
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector2d px(x + 0.5, y + 0.5);
      if (k.projection == Projection::kFisheye &&
          (px - Eigen::Vector2d(k.cx, k.cy)).norm() > circle) {
        continue;
      }
      const Eigen::Vector3d v = Env(pose.rotation * Unproject(k, px));
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(v[c]);
    }
  }
  WriteImage((dir / (name + ".exr")).string(), img, StoredType::kFloat);
  nlohmann::json lens = k, p = pose;
  WriteFileAtomic(dir / (name + ".lens.json"), lens.dump(2));
  WriteFileAtomic(dir / (name + ".pose.json"), p.dump(2));
  return name + ".exr " + name + ".lens.json " + name + ".pose.json\n";
}

TEST(CalibEnvmapCli, AssemblesAMapWithMaskAndSummary) {
  const fs::path dir = TempDir("ok");
  std::string list = "# image lens pose\n";
  list += WritePhoto(dir, "up", Intrinsics::FisheyeFov(200, 200, 185), Camera(0, 90, 0));
  list += WritePhoto(dir, "east", Intrinsics::PinholeFov(160, 120, 70), Camera(90, -5, 0));
  WriteFileAtomic(dir / "photos.txt", list);
  const Result r = RunRouen("calib envmap --list " + Q(dir / "photos.txt") + " --width 128 --out " +
                            Q(dir / "env.exr"));
  ASSERT_EQ(r.code, 0) << r.out;
  const Image env = ReadImage((dir / "env.exr").string());
  ASSERT_EQ(env.width, 128);
  ASSERT_EQ(env.height, 64);
  const Image mask = ReadImage((dir / "env.mask.png").string());
  const Image cov = ReadImage((dir / "env.coverage.exr").string());
  ASSERT_EQ(mask.width, 128);
  ASSERT_EQ(cov.height, 64);
  int seen = 0, unseen = 0;
  double max_err = 0;
  for (int y = 0; y < 64; ++y) {
    for (int x = 0; x < 128; ++x) {
      for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(env.at(x, y, c)));
      const bool m = mask.at(x, y, 0) > 127;
      ASSERT_EQ(m, cov.at(x, y, 0) > 0);
      if (!m) {
        ++unseen;
        EXPECT_EQ(env.at(x, y, 0), 0.f);
        continue;
      }
      ++seen;
      // Row 0 is the zenith; column x at azimuth (x+0.5)/W*360 from north through east.
      const Eigen::Vector3d d = EnuFromAzEl((x + 0.5) / 128 * 360, 90 - (y + 0.5) / 64 * 180);
      const Eigen::Vector3d t = Env(d);
      for (int c = 0; c < 3; ++c) max_err = std::max(max_err, std::abs(env.at(x, y, c) - t[c]));
    }
  }
  EXPECT_GT(seen, 2000);
  EXPECT_GT(unseen, 1000);
  // Bilinear interpolation over photo pixels of ~1 deg: 1.25 h^2 ~ 4e-4.
  EXPECT_LT(max_err, 1e-3);
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(dir / "env.json"));
  EXPECT_GT(j["coverage_fraction"].get<double>(), 0.5);
  EXPECT_LT(j["coverage_fraction"].get<double>(), 0.8);
  EXPECT_EQ(j["photos"].size(), 2u);
  fs::remove_all(dir);
}

TEST(CalibEnvmapCli, BadInputFailsClearly) {
  const fs::path dir = TempDir("bad");
  const std::string line =
      WritePhoto(dir, "a", Intrinsics::PinholeFov(80, 60, 60), Camera(0, 0, 0));
  WriteFileAtomic(dir / "two_words.txt", "a.exr a.lens.json\n");
  Result r =
      RunRouen("calib envmap --list " + Q(dir / "two_words.txt") + " --out " + Q(dir / "o.exr"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("two_words.txt:1: expected 'image.exr lens.json pose.json'"),
            std::string::npos)
      << r.out;
  WriteFileAtomic(dir / "missing.txt", "nothere.exr a.lens.json a.pose.json\n");
  r = RunRouen("calib envmap --list " + Q(dir / "missing.txt") + " --out " + Q(dir / "o.exr"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("nothere.exr"), std::string::npos) << r.out;
  nlohmann::json big = Intrinsics::PinholeFov(640, 480, 60);
  WriteFileAtomic(dir / "big.lens.json", big.dump());
  WriteFileAtomic(dir / "size.txt", "a.exr big.lens.json a.pose.json\n");
  r = RunRouen("calib envmap --list " + Q(dir / "size.txt") + " --out " + Q(dir / "o.exr"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("image is 80x60 but its lens is 640x480"), std::string::npos) << r.out;
  WriteFileAtomic(dir / "ok.txt", line);
  r = RunRouen("calib envmap --list " + Q(dir / "ok.txt") + " --width 63 --out " +
               Q(dir / "o.exr"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("width 63"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "o.exr"));
  fs::remove_all(dir);
}

TEST(CalibEnvmapCli, Help) {
  Result r = RunRouen("calib envmap --help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("--list"), std::string::npos);
  EXPECT_NE(r.out.find("row 0 zenith"), std::string::npos);
  r = RunRouen("calib orient --help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("--landmark"), std::string::npos);
}

// A sky photo with the sun where it stands at `time` over `site`.
void WriteSkyPhoto(const fs::path& path, const Intrinsics& k, const Pose& pose,
                   const SunPosition* sun) {
  Image img(k.width, k.height, 3, PixelUnits::kRadiance, 0.f);
  const Eigen::Vector3d s = sun ? sun->DirectionEnu() : Eigen::Vector3d::UnitZ();
  const double rad = sun ? sun->angular_radius_deg * kDeg : 0;
  const auto sp = Project(k, pose.rotation.transpose() * s);
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const bool near = sun && sp && (Eigen::Vector2d(x + 0.5, y + 0.5) - *sp).norm() < 10;
      const int sub = near ? 16 : 1;
      double v = 0;
      for (int j = 0; j < sub; ++j) {
        for (int i = 0; i < sub; ++i) {
          const Eigen::Vector3d d =
              pose.rotation * Unproject(k, {x + (i + 0.5) / sub, y + (j + 0.5) / sub});
          v += (sun && std::acos(std::min(1.0, d.dot(s))) < rad) ? 3e4 : 1.0 + 0.5 * (1 - d.z());
        }
      }
      v /= sub * sub;
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(v);
    }
  }
  WriteImage(path.string(), img, StoredType::kFloat);
}

TEST(CalibOrientCli, OrientsASkyPhotoFromTheSunAndALandmark) {
  const fs::path dir = TempDir("orient");
  const std::string time = "2026-08-25T13:30:00-07:00";
  const Site site{37.8722, -122.2578, 60};
  const SunPosition sun = ComputeSunPosition(ParseIso8601(time), site);
  const Intrinsics k = Intrinsics::PinholeFov(800, 600, 100);
  // Look towards the sun but lower, rolled by 4 deg.
  const Pose truth = Camera(sun.azimuth_deg + 10, sun.elevation_deg - 25, 4);
  WriteSkyPhoto(dir / "sky.exr", k, truth, &sun);
  nlohmann::json lens = k;
  WriteFileAtomic(dir / "lens.json", lens.dump());
  const double lm_az = sun.azimuth_deg + 25, lm_el = 2;
  const auto px = Project(k, truth.rotation.transpose() * EnuFromAzEl(lm_az, lm_el));
  ASSERT_TRUE(px.has_value());
  char lm[128];
  std::snprintf(lm, sizeof lm, "%.4f,%.4f,%.6f,%.6f", px->x(), px->y(), lm_az, lm_el);
  const std::string base = "calib orient --image " + Q(dir / "sky.exr") + " --lens " +
                           Q(dir / "lens.json") + " --time " + time +
                           " --site 37.8722,-122.2578,60 --out " + Q(dir / "pose.json");
  Result r = RunRouen(base + " --landmark " + lm);
  ASSERT_EQ(r.code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(dir / "pose.json"));
  const Pose got = j.get<Pose>();
  const double err =
      Eigen::AngleAxisd(Eigen::Matrix3d(got.rotation.transpose() * truth.rotation)).angle() / kDeg;
  // The centroid is good to ~1/16 px (16x16 render) at >= 335 px/rad: 0.011 deg; the landmark
  // (over 30 deg from the sun) multiplies that by at most 1 + 1/sin(30 deg) = 3: 0.033 deg.
  EXPECT_LT(err, 0.05) << r.out;
  EXPECT_TRUE(j.contains("orientation"));
  std::printf("calib orient: rotation error %.5f deg\n", err);

  // No second constraint, and a photo without a sun: clear errors.
  r = RunRouen(base);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("--landmark, --horizon or --level"), std::string::npos) << r.out;
  WriteSkyPhoto(dir / "nosun.exr", k, truth, nullptr);
  r = RunRouen("calib orient --image " + Q(dir / "nosun.exr") + " --lens " + Q(dir / "lens.json") +
               " --time " + time + " --site 37.8722,-122.2578,60 --level" + " --out " +
               Q(dir / "p2.json"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("no sun disc"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("nosun.exr"), std::string::npos) << r.out;
  r = RunRouen(base + " --landmark 1,2,3");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("expected 4 comma-separated numbers"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
