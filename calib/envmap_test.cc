#include "calib/envmap.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/solar.h"

namespace rouen {
namespace {

using ::testing::HasSubstr;

// The analytic environment: smooth and positive. Along any unit-speed great circle its second
// derivative is at most about 5 per channel (linear terms: |b|; the products: <= 4 |coef|).
Eigen::Vector3d Env(const Eigen::Vector3d& d) {
  return Eigen::Vector3d(1.5 + 0.5 * d.z() + 0.3 * d.x(), 1.2 + 0.4 * d.y() + 0.2 * d.x() * d.y(),
                         1.0 + 0.3 * d.z() * d.z());
}

// A photo of the environment through core/camera.h (radiance at each pixel centre). Fisheye
// pixels outside the inscribed circle are black, as in a real photo.
Image Photograph(const Intrinsics& k, const Pose& pose) {
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
  return img;
}

Pose Camera(double az, double el, double roll_deg) {
  Pose p = Pose::Level(Eigen::Vector3d::Zero(), az, el);
  p.rotation = p.rotation * Eigen::AngleAxisd(roll_deg * kDeg, Eigen::Vector3d::UnitZ());
  return p;
}

// Largest angle between neighbouring pixel centres along x or y, radians (sampled).
double MaxPixelAngle(const Intrinsics& k) {
  double m = 0;
  for (int y = 1; y < k.height; y += 7) {
    for (int x = 1; x < k.width; x += 7) {
      const Eigen::Vector3d a = Unproject(k, {x + 0.5, y + 0.5});
      const Eigen::Vector3d b = Unproject(k, {x - 0.5, y + 0.5});
      const Eigen::Vector3d c = Unproject(k, {x + 0.5, y - 0.5});
      m = std::max({m, std::acos(std::min(1.0, a.dot(b))), std::acos(std::min(1.0, a.dot(c)))});
    }
  }
  return m;
}

struct Rig {
  std::vector<Intrinsics> lenses;
  std::vector<Pose> poses;
  std::vector<Image> images;
  std::vector<EnvmapPhoto> Photos() const {
    std::vector<EnvmapPhoto> out;
    for (size_t i = 0; i < images.size(); ++i) {
      out.push_back({&images[i], lenses[i], poses[i], 0, "photo" + std::to_string(i)});
    }
    return out;
  }
  void Add(const Intrinsics& k, const Pose& p) {
    lenses.push_back(k);
    poses.push_back(p);
    images.push_back(Photograph(k, p));
  }
};

// A fisheye looking up (non-square frame) and three pinholes around the horizon, one with
// barrel distortion.
Rig FourPhotos() {
  Rig r;
  r.Add(Intrinsics::FisheyeFov(400, 300, 185), Camera(20, 90, 0));
  r.Add(Intrinsics::PinholeFov(320, 240, 70), Camera(30, 0, 0));
  r.Add(Intrinsics::PinholeFov(320, 240, 70), Camera(95, -10, 5));
  Intrinsics d = Intrinsics::PinholeFov(320, 240, 70);
  d.k1 = -0.1;
  r.Add(d, Camera(250, 10, -3));
  return r;
}

// 1 = certainly seen by the photo, 0 = certainly not, -1 = within `margin` px of its edge.
int Sees(const Intrinsics& k, const Pose& pose, const Eigen::Vector3d& d, double margin) {
  const Eigen::Vector3d dc = pose.rotation.transpose() * d;
  const auto p = Project(k, dc);
  if (k.projection == Projection::kFisheye) {
    const double circle = std::min({k.cx, k.cy, k.width - k.cx, k.height - k.cy}) - 1;
    const double r = p ? (*p - Eigen::Vector2d(k.cx, k.cy)).norm() : 1e9;
    if (r < circle - margin) return 1;
    return r > circle + margin ? 0 : -1;
  }
  double corner = 1;  // cosine of the farthest corner's angle from the axis
  for (double u : {0.0, 1.0 * k.width}) {
    for (double v : {0.0, 1.0 * k.height}) corner = std::min(corner, Unproject(k, {u, v}).z());
  }
  if (dc.normalized().z() < corner - 0.01) return 0;
  if (!p) return -1;
  const double in = std::min({p->x(), k.width - p->x(), p->y(), k.height - p->y()});
  if (in > margin) return 1;
  return in < -margin ? 0 : -1;
}

TEST(Envmap, ConventionMatchesEquirectCameraAndCompass) {
  const int W = 64, H = 32;
  const Intrinsics eq = Intrinsics::Equirect(W, H);
  const Pose level = Pose::Level(Eigen::Vector3d::Zero(), 0, 0);
  for (double y : {0.5, 7.25, 16.0, 31.5}) {
    for (double x : {0.5, 13.7, 32.0, 63.5}) {
      const Eigen::Vector3d d = EnvmapDirection(W, H, x, y);
      EXPECT_LT((d - level.rotation * Unproject(eq, {x, y})).norm(), 1e-12);
      EXPECT_LT((EnvmapPixel(W, H, d) - Eigen::Vector2d(x, y)).norm(), 1e-9);
      double az, el;
      AzElFromEnu(d, &az, &el);
      EXPECT_NEAR(el, 90 - y / H * 180, 1e-9);
      if (std::abs(el) < 89) {
        EXPECT_NEAR(az, x / W * 360, 1e-9);
      }
    }
  }
  // Row 0 is the zenith, column W/4 looks east.
  EXPECT_GT(EnvmapDirection(W, H, 0.5, 0.0).z(), 0.999);
  EXPECT_GT(EnvmapDirection(W, H, W / 4.0, H / 2.0).x(), 0.999);
}

TEST(Envmap, FourCamerasMatchTheEnvironmentWhereCovered) {
  const Rig rig = FourPhotos();
  const std::vector<EnvmapPhoto> photos = rig.Photos();
  EnvmapOptions opt;
  opt.width = 512;
  const EnvmapResult r = AssembleEnvmap(photos, opt);
  ASSERT_EQ(r.radiance.width, 512);
  ASSERT_EQ(r.radiance.height, 256);
  ASSERT_EQ(r.coverage.channels, 1);
  // Bilinear interpolation error <= h^2 / 8 * (|f_uu| + |f_vv|) with h the photo's pixel angle
  // and |f''| <= 5: 1.25 h^2; plus float rounding.
  double h = 0;
  for (const Intrinsics& k : rig.lenses) h = std::max(h, MaxPixelAngle(k));
  const double tol = 1.25 * h * h + 1e-5;
  double max_err = 0;
  int64_t seen = 0, unseen = 0, checked = 0;
  for (int y = 0; y < r.radiance.height; ++y) {
    for (int x = 0; x < r.radiance.width; ++x) {
      const Eigen::Vector3d d = EnvmapDirection(512, 256, x + 0.5, y + 0.5);
      int expected = 0;
      bool certain = true;
      for (size_t i = 0; i < rig.images.size(); ++i) {
        const int s = Sees(rig.lenses[i], rig.poses[i], d, 2.0);
        if (s < 0) certain = false;
        expected += s > 0;
      }
      const float cov = r.coverage.at(x, y);
      for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(r.radiance.at(x, y, c)));
      if (!certain) continue;
      ++checked;
      ASSERT_EQ(cov, expected) << "pixel " << x << "," << y;
      if (expected == 0) {
        ++unseen;
        for (int c = 0; c < 3; ++c) EXPECT_EQ(r.radiance.at(x, y, c), 0.f);
        continue;
      }
      ++seen;
      const Eigen::Vector3d truth = Env(d);
      for (int c = 0; c < 3; ++c) {
        max_err = std::max(max_err, std::abs(r.radiance.at(x, y, c) - truth[c]));
      }
    }
  }
  EXPECT_GT(seen, 10000);
  EXPECT_GT(unseen, 1000);
  EXPECT_GT(checked, 0.95 * 512 * 256);
  EXPECT_LT(max_err, tol);
  EXPECT_GT(r.coverage_fraction, 0.5);
  EXPECT_LT(r.coverage_fraction, 1.0);
  for (int64_t n : r.pixels_per_photo) EXPECT_GT(n, 0);
  std::printf(
      "envmap 512x256 from 4 photos: max error %.2e (tolerance %.2e), coverage %.3f, "
      "%.3f s\n",
      max_err, tol, r.coverage_fraction, r.seconds);
  const nlohmann::json j = EnvmapSummaryJson(r, photos);
  EXPECT_EQ(j["photos"].size(), 4u);
  EXPECT_DOUBLE_EQ(j["coverage_fraction"].get<double>(), r.coverage_fraction);
}

TEST(Envmap, FisheyeCoverageIsItsSphericalCap) {
  Rig rig;
  rig.Add(Intrinsics::FisheyeFov(300, 300, 185), Camera(0, 90, 0));
  const Intrinsics& k = rig.lenses[0];
  EnvmapOptions opt;
  opt.width = 720;
  const EnvmapResult r = AssembleEnvmap(rig.Photos(), opt);
  // The cap up to one pixel inside the circle: 92.5 deg * (149 / 150).
  const double theta = std::acos(Unproject(k, {k.cx + 149, k.cy}).z());
  const double cap = (1 - std::cos(theta)) / 2;
  // The cap's rim falls inside one map row (pi / H of elevation).
  const double row = kPi / r.radiance.height;
  EXPECT_NEAR(r.coverage_fraction, cap, std::sin(theta) * row);
  EXPECT_DOUBLE_EQ(r.sky_coverage_fraction, 1.0);
}

TEST(Envmap, EquirectPhotoCoversEverythingAcrossTheSeam) {
  Rig rig;
  Pose tilted = Camera(123, 7, 11);
  rig.Add(Intrinsics::Equirect(720, 360), tilted);
  EnvmapOptions opt;
  opt.width = 256;
  opt.supersample = 2;
  const EnvmapResult r = AssembleEnvmap(rig.Photos(), opt);
  EXPECT_DOUBLE_EQ(r.coverage_fraction, 1.0);
  // Sub-samples average over a map pixel (1.4 deg): the box filter's error is about
  // (pixel angle)^2 / 24 * |f''| per axis; the bilinear lookup adds 1.25 h^2 (h = 0.5 deg).
  const double map_px = 2 * kPi / 256, h = 2 * kPi / 720;
  const double tol = 2 * map_px * map_px / 24 * 5 + 1.25 * h * h + 1e-5;
  double max_err = 0;
  for (int y = 4; y < r.radiance.height - 4; ++y) {  // the poles' pixels are not boxes
    for (int x = 0; x < r.radiance.width; ++x) {
      const Eigen::Vector3d truth = Env(EnvmapDirection(256, 128, x + 0.5, y + 0.5));
      for (int c = 0; c < 3; ++c) {
        max_err = std::max(max_err, std::abs(r.radiance.at(x, y, c) - truth[c]));
      }
    }
  }
  EXPECT_LT(max_err, tol);
}

TEST(Envmap, EdgeFeatherKeepsTheAverageAndTheCoverage) {
  const Rig rig = FourPhotos();
  EnvmapOptions opt;
  opt.width = 256;
  const EnvmapResult plain = AssembleEnvmap(rig.Photos(), opt);
  opt.edge_feather = 0.2;
  const EnvmapResult soft = AssembleEnvmap(rig.Photos(), opt);
  // Every photo shows the same environment, so the weights change nothing but rounding and the
  // interpolation error (each bounded as above).
  double h = 0;
  for (const Intrinsics& k : rig.lenses) h = std::max(h, MaxPixelAngle(k));
  for (size_t i = 0; i < plain.coverage.data.size(); ++i) {
    ASSERT_EQ(plain.coverage.data[i], soft.coverage.data[i]);
  }
  for (size_t i = 0; i < plain.radiance.data.size(); ++i) {
    ASSERT_NEAR(plain.radiance.data[i], soft.radiance.data[i], 2 * (1.25 * h * h + 1e-5));
  }
}

TEST(Envmap, InvalidPixelsAreSkipped) {
  Rig rig;
  rig.Add(Intrinsics::PinholeFov(160, 120, 60), Camera(0, 0, 0));
  rig.Add(Intrinsics::PinholeFov(160, 120, 60), Camera(0, 0, 0));
  // Photo 2 is NaN everywhere: the map must equal photo 1 alone, with coverage 1.
  for (float& v : rig.images[1].data) v = std::nanf("");
  EnvmapOptions opt;
  opt.width = 128;
  const EnvmapResult r = AssembleEnvmap(rig.Photos(), opt);
  EXPECT_EQ(r.pixels_per_photo[1], 0);
  EXPECT_GT(r.pixels_per_photo[0], 0);
  for (float v : r.radiance.data) ASSERT_TRUE(std::isfinite(v));
  for (float v : r.coverage.data) ASSERT_LE(v, 1.f);
}

TEST(Envmap, MismatchedInputsAreErrors) {
  Rig rig = FourPhotos();
  auto message = [](const std::vector<EnvmapPhoto>& photos, EnvmapOptions opt = {}) {
    opt.width = 64;
    try {
      AssembleEnvmap(photos, opt);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_THAT(message({}), HasSubstr("no photos"));
  std::vector<EnvmapPhoto> p = rig.Photos();
  p[1].intrinsics = Intrinsics::PinholeFov(640, 480, 70);
  EXPECT_THAT(message(p), HasSubstr("photo 2 (photo1): image is 320x240 but its lens is 640x480"));
  p = rig.Photos();
  Image gray(320, 240, 1, PixelUnits::kRadiance, 1.f);
  p[2].radiance = &gray;
  EXPECT_THAT(message(p), HasSubstr("1 channels, but photo 1 has 3"));
  p = rig.Photos();
  Image ldr = rig.images[1];
  ldr.units = PixelUnits::kDigital;
  p[1].radiance = &ldr;
  EXPECT_THAT(message(p), HasSubstr("LDR"));
  p = rig.Photos();
  p[3].pose.rotation(0, 0) = 2;
  EXPECT_THAT(message(p), HasSubstr("not a rotation"));
  p = rig.Photos();
  p[0].radiance = nullptr;
  EXPECT_THAT(message(p), HasSubstr("no image"));
  EnvmapOptions odd;
  odd.width = 63;
  EXPECT_THROW(AssembleEnvmap(rig.Photos(), odd), Error);
}

TEST(Envmap, Throughput) {
  const Rig rig = FourPhotos();
  EnvmapOptions opt;
  opt.width = 1024;
  const EnvmapResult r = AssembleEnvmap(rig.Photos(), opt);
  const double mp = 1024.0 * 512 / 1e6;
  std::printf(
      "envmap 1024x512 from 4 photos: %.3f s, %.1f output Mpx/s (%.1f photo lookups "
      "M/s)\n",
      r.seconds, mp / r.seconds, 4 * mp / r.seconds);
  EXPECT_GT(r.seconds, 0);
}

}  // namespace
}  // namespace rouen
