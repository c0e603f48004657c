#include "calib/sky_orientation.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>

#include "core/angles.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/solar.h"

namespace rouen {
namespace {

using ::testing::HasSubstr;

constexpr double kSunRadiusDeg = 0.265;  // 0.53 deg disc
constexpr double kSunRadiance = 5e4;     // relative to a sky of about 1

// The sky: a smooth gradient, brighter towards the horizon and the east, 0 below the horizon.
Eigen::Vector3d SkyRadiance(const Eigen::Vector3d& d) {
  if (d.z() < 0) return Eigen::Vector3d(0.2, 0.2, 0.2);
  const double g = 1.0 + 0.5 * (1 - d.z()) + 0.2 * d.x();
  return Eigen::Vector3d(0.6 * g, 0.8 * g, 1.2 * g);
}

struct SunSpec {
  Eigen::Vector3d dir;
  double radius_deg = kSunRadiusDeg;
  double radiance = kSunRadiance;
};

// Renders a sky photo through core/camera.h: each pixel the mean of 16x16 sub-pixel rays near a
// sun disc (so partly covered rim pixels are right), the pixel centre elsewhere. Fisheye pixels
// outside the image circle stay 0.
Image RenderSky(const Intrinsics& k, const Pose& pose, const std::vector<SunSpec>& suns,
                double noise_rel = 0, uint64_t seed = 1) {
  Image img(k.width, k.height, 3, PixelUnits::kRadiance);
  const double circle = 0.5 * std::min(k.width, k.height);
  std::vector<Eigen::Vector2d> centres;
  std::vector<double> radii;
  for (const SunSpec& s : suns) {
    const auto p = Project(k, pose.rotation.transpose() * s.dir);
    centres.push_back(p ? *p : Eigen::Vector2d(-1e9, -1e9));
    // Generous pixel radius: the disc radius at the image centre scale times 3, plus 3 px.
    radii.push_back(3 * s.radius_deg * kDeg * k.fx + 3);
  }
  auto radiance = [&](const Eigen::Vector2d& px) -> Eigen::Vector3d {
    const Eigen::Vector3d d = pose.rotation * Unproject(k, px);
    for (const SunSpec& s : suns) {
      if (std::acos(std::clamp(d.dot(s.dir), -1.0, 1.0)) < s.radius_deg * kDeg) {
        return Eigen::Vector3d(s.radiance, s.radiance, 0.9 * s.radiance);
      }
    }
    return SkyRadiance(d);
  };
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector2d c(x + 0.5, y + 0.5);
      if (k.projection == Projection::kFisheye && (c - Eigen::Vector2d(k.cx, k.cy)).norm() > circle)
        continue;
      bool near = false;
      for (size_t i = 0; i < suns.size(); ++i) near = near || (c - centres[i]).norm() < radii[i];
      Eigen::Vector3d v = Eigen::Vector3d::Zero();
      if (near) {
        constexpr int kSub = 16;
        for (int j = 0; j < kSub; ++j) {
          for (int i = 0; i < kSub; ++i) {
            v += radiance(Eigen::Vector2d(x + (i + 0.5) / kSub, y + (j + 0.5) / kSub));
          }
        }
        v /= kSub * kSub;
      } else {
        v = radiance(c);
      }
      for (int ch = 0; ch < 3; ++ch) img.at(x, y, ch) = static_cast<float>(v[ch]);
    }
  }
  if (noise_rel > 0) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> n(0, 1);
    for (float& v : img.data) v = static_cast<float>(std::max(0.0, v * (1 + noise_rel * n(rng))));
  }
  return img;
}

// A camera rotation from azimuth/elevation of the forward axis and a roll about it, degrees.
Pose Camera(double az, double el, double roll_deg) {
  Pose p = Pose::Level(Eigen::Vector3d::Zero(), az, el);
  p.rotation = p.rotation * Eigen::AngleAxisd(roll_deg * kDeg, Eigen::Vector3d::UnitZ());
  return p;
}

// The centroid error bound of the renderer: 16x16 sub-sampling puts each rim pixel's coverage
// within about 1/16 of its true value; summed over the rim (2 pi r pixels at distance r) against
// the disc's area (pi r^2) this moves the centroid by well under 1/16 px. Plus 4 sigma of noise.
double CentroidTolerancePx(const SunDisc& d) { return 1.0 / 16 + 4 * d.sigma_px; }

// Rotation error allowed for a sun direction error `sun_err_rad` when the second direction is
// `sep_deg` from the sun: the roll about the sun axis moves by up to sun_err / sin(sep).
double RotationToleranceDeg(double sun_err_rad, double sep_deg) {
  return (sun_err_rad * (1 + 1 / std::sin(sep_deg * kDeg))) / kDeg + 1e-6;
}

TEST(SunDisc, PinholeCentroidIsSubPixel) {
  const Intrinsics k = Intrinsics::PinholeFov(640, 480, 60);
  const Pose pose = Camera(140, 30, 4);
  const Eigen::Vector3d sun = EnuFromAzEl(147.3, 36.1);
  const Image img = RenderSky(k, pose, {{sun}});
  const SunDisc d = DetectSunDisc(img, k, {});
  const Eigen::Vector2d truth = *Project(k, pose.rotation.transpose() * sun);
  EXPECT_LT((d.pixel - truth).norm(), CentroidTolerancePx(d)) << d.pixel.transpose();
  // 60 deg over 640 px: 0.265 deg is about 2.8 px.
  EXPECT_NEAR(d.expected_radius_px, kSunRadiusDeg * kDeg * k.fx, 0.1);
  EXPECT_NEAR(d.radius_px, d.expected_radius_px, 1.0);
  EXPECT_GT(d.sigma_deg, 0);
  EXPECT_LT(d.sigma_deg, 0.01);
}

TEST(SunDisc, FisheyeWithNoise) {
  const Intrinsics k = Intrinsics::FisheyeFov(800, 800, 185);
  const Pose pose = Camera(75, 88, 0);
  const Eigen::Vector3d sun = EnuFromAzEl(230, 28);
  const Image img = RenderSky(k, pose, {{sun}}, 0.02, 7);
  const SunDisc d = DetectSunDisc(img, k, {});
  const Eigen::Vector2d truth = *Project(k, pose.rotation.transpose() * sun);
  EXPECT_LT((d.pixel - truth).norm(), CentroidTolerancePx(d)) << d.pixel.transpose();
  EXPECT_LT(d.expected_radius_px, 2.0);  // an unresolved-ish disc: ~1.2 px
}

TEST(SunDisc, NoSunIsAnError) {
  const Intrinsics k = Intrinsics::PinholeFov(320, 240, 60);
  const Image img = RenderSky(k, Camera(10, 20, 0), {});
  try {
    DetectSunDisc(img, k, {}, "sky.exr");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("sky.exr: no sun disc"));
  }
}

TEST(SunDisc, TwoSunsAreAnError) {
  const Intrinsics k = Intrinsics::PinholeFov(320, 240, 60);
  const Pose pose = Camera(180, 30, 0);
  const Image img = RenderSky(k, pose, {{EnuFromAzEl(175, 32)}, {EnuFromAzEl(190, 25)}});
  try {
    DetectSunDisc(img, k);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("two bright blobs"));
  }
}

TEST(SunDisc, HugeBlobIsAnError) {
  // A 3 deg "sun": flare or a saturated sun seen through bloom.
  const Intrinsics k = Intrinsics::PinholeFov(320, 240, 60);
  const Pose pose = Camera(180, 30, 0);
  SunSpec big{EnuFromAzEl(178, 31), 3.0};
  const Image img = RenderSky(k, pose, {big});
  try {
    DetectSunDisc(img, k);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("flare or a clipped sun"));
  }
}

TEST(SunDisc, ClippedLdrIsAnError) {
  const Intrinsics k = Intrinsics::PinholeFov(320, 240, 60);
  const Pose pose = Camera(180, 30, 0);
  Image img = RenderSky(k, pose, {{EnuFromAzEl(178, 31)}});
  img.units = PixelUnits::kDigital;
  for (float& v : img.data) v = std::min(255.f, 2 * v);  // an 8-bit frame, sun saturated
  try {
    DetectSunDisc(img, k);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("clipped"));
  }
  // The same frame through an ND filter: no longer clipped, and found.
  Image nd = RenderSky(k, pose, {{EnuFromAzEl(178, 31)}});
  nd.units = PixelUnits::kDigital;
  for (float& v : nd.data) v = std::round(std::min(255.f, v * 0.004f));
  const SunDisc d = DetectSunDisc(nd, k);
  const Eigen::Vector2d truth = *Project(k, pose.rotation.transpose() * EnuFromAzEl(178, 31));
  EXPECT_LT((d.pixel - truth).norm(), 0.25);  // 8-bit rounding of ~200 DN: well under 1/4 px
}

TEST(SunDisc, SizeMismatchIsAnError) {
  const Intrinsics k = Intrinsics::PinholeFov(320, 240, 60);
  const Image img(100, 100, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(DetectSunDisc(img, k), Error);
}

// Detects the sun in a rendered photo and orients the camera; returns the rotation error, deg.
struct OrientCase {
  Intrinsics k;
  Pose truth;
  Eigen::Vector3d sun;
  double noise = 0;
};

TEST(OrientFromSun, FisheyeWithOneLandmark) {
  OrientCase c{Intrinsics::FisheyeFov(800, 800, 185), Camera(75, 88, 0), EnuFromAzEl(230, 28),
               0.02};
  const Image img = RenderSky(c.k, c.truth, {{c.sun}}, c.noise, 3);
  const SunDisc d = DetectSunDisc(img, c.k);
  // A landmark: a church spire at azimuth 40 deg, elevation 3 deg, clicked exactly.
  const Eigen::Vector3d spire = EnuFromAzEl(40, 3);
  const SkyLandmark lm{*Project(c.k, c.truth.rotation.transpose() * spire), spire, 0.05};
  const SkyOrientation o = OrientFromSun(c.k, d.ray_cam, d.sigma_deg, c.sun, {lm}, {});
  const double sun_err =
      std::acos(std::min(1.0, d.ray_cam.dot(c.truth.rotation.transpose() * c.sun)));
  const double sep = std::acos(spire.dot(c.sun)) / kDeg;
  const double err = RotationAngleDeg(o.pose.rotation, c.truth.rotation);
  EXPECT_LT(err, RotationToleranceDeg(sun_err + CentroidTolerancePx(d) / c.k.fx, sep));
  EXPECT_LT(err, 0.05);
  ASSERT_EQ(o.landmark_residual_deg.size(), 1u);
  EXPECT_LT(o.sun_residual_deg, 0.05);
  EXPECT_GT(o.rotation_sigma_deg, 0);
  RecordProperty("fisheye_landmark_error_deg", std::to_string(err));
  std::printf("fisheye + landmark: rotation error %.5f deg (sigma %.5f)\n", err,
              o.rotation_sigma_deg);
}

TEST(OrientFromSun, PinholeWithHorizonPoints) {
  const Intrinsics k = Intrinsics::PinholeFov(640, 480, 70);
  const Pose truth = Camera(200, 12, 3);  // slightly rolled
  const Eigen::Vector3d sun = EnuFromAzEl(212, 27);
  const Image img = RenderSky(k, truth, {{sun}}, 0.01, 5);
  const SunDisc d = DetectSunDisc(img, k);
  std::vector<HorizonPoint> hz;
  for (double az : {175.0, 190.0, 205.0, 220.0}) {
    const auto p = Project(k, truth.rotation.transpose() * EnuFromAzEl(az, 0));
    ASSERT_TRUE(p.has_value());
    hz.push_back({*p, 0.05});
  }
  const SkyOrientation o = OrientFromSun(k, d.ray_cam, d.sigma_deg, sun, {}, hz);
  const double err = RotationAngleDeg(o.pose.rotation, truth.rotation);
  // The horizon 27 deg below the sun fixes the roll with a lever of sin(27 deg) at least.
  const double sun_err = CentroidTolerancePx(d) / k.fx;
  EXPECT_LT(err, RotationToleranceDeg(sun_err, 27));
  EXPECT_FALSE(o.had_mirror_solution);
  EXPECT_EQ(o.horizon_residual_deg.size(), 4u);
  std::printf("pinhole + 4 horizon points: rotation error %.5f deg\n", err);
}

TEST(OrientFromSun, LevelCameraPicksTheUprightSolution) {
  const Intrinsics k = Intrinsics::PinholeFov(640, 480, 70);
  const Pose truth = Camera(100, 20, 0);  // level: no roll
  const Eigen::Vector3d sun = EnuFromAzEl(90, 30);
  const Image img = RenderSky(k, truth, {{sun}});
  const SunDisc d = DetectSunDisc(img, k);
  OrientOptions opt;
  opt.level = true;
  const SkyOrientation o = OrientFromSun(k, d.ray_cam, d.sigma_deg, sun, {}, {}, opt);
  const double err = RotationAngleDeg(o.pose.rotation, truth.rotation);
  EXPECT_LT(err, RotationToleranceDeg(CentroidTolerancePx(d) / k.fx, 30));
  EXPECT_LT(std::abs(o.level_residual_deg), 0.01);
  std::printf("pinhole + level: rotation error %.5f deg (mirror solution: %d)\n", err,
              o.had_mirror_solution);
}

TEST(OrientFromSun, LevelFisheyeLookingAtTheZenith) {
  const Intrinsics k = Intrinsics::FisheyeFov(600, 600, 180);
  const Pose truth = Camera(0, 90, 0);  // optical axis up, image rows horizontal
  const Eigen::Vector3d sun = EnuFromAzEl(140, 35);
  const Image img = RenderSky(k, truth, {{sun}});
  const SunDisc d = DetectSunDisc(img, k);
  OrientOptions opt;
  opt.level = true;
  const SkyOrientation o = OrientFromSun(k, d.ray_cam, d.sigma_deg, sun, {}, {}, opt);
  const double err = RotationAngleDeg(o.pose.rotation, truth.rotation);
  // The level constraint acts on the x axis, 55 deg from the sun ray at most: lever >= sin 35.
  EXPECT_LT(err, RotationToleranceDeg(CentroidTolerancePx(d) / k.fx, 35));
  std::printf("zenith fisheye + level: rotation error %.5f deg (mirror solution: %d)\n", err,
              o.had_mirror_solution);
}

TEST(OrientFromSun, ExactRaysGiveExactRotation) {
  const Intrinsics k = Intrinsics::FisheyeFov(1000, 1000, 180);
  const Pose truth = Camera(300, 70, -25);
  const Eigen::Vector3d sun = EnuFromAzEl(280, 50);
  const Eigen::Vector3d cs = truth.rotation.transpose() * sun;
  std::vector<SkyLandmark> lms;
  for (auto [az, el] : {std::pair{10.0, 2.0}, {200.0, 5.0}, {250.0, 1.0}}) {
    const Eigen::Vector3d w = EnuFromAzEl(az, el);
    const auto p = Project(k, truth.rotation.transpose() * w);
    ASSERT_TRUE(p.has_value());
    lms.push_back({*p, w, 0.1});
  }
  const SkyOrientation o = OrientFromSun(k, cs, 0.01, sun, lms, {});
  EXPECT_LT(RotationAngleDeg(o.pose.rotation, truth.rotation), 1e-6);
  EXPECT_LT(o.sun_residual_deg, 1e-6);
}

TEST(OrientFromSun, BadInputIsAnError) {
  const Intrinsics k = Intrinsics::PinholeFov(640, 480, 70);
  const Pose truth = Camera(200, 20, 0);
  const Eigen::Vector3d sun = EnuFromAzEl(205, 25);
  const Eigen::Vector3d cs = truth.rotation.transpose() * sun;
  auto message = [&](const std::vector<SkyLandmark>& lms, const std::vector<HorizonPoint>& hz) {
    try {
      OrientFromSun(k, cs, 0.01, sun, lms, hz);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_THAT(message({}, {}), HasSubstr("roll about the sun axis free"));
  // A landmark right beside the sun.
  const Eigen::Vector3d near_sun = EnuFromAzEl(205.5, 25.5);
  EXPECT_THAT(message({{*Project(k, truth.rotation.transpose() * near_sun), near_sun}}, {}),
              HasSubstr("parallel to the sun axis"));
  // A landmark whose direction is 8 deg off what the photo shows.
  const Eigen::Vector3d lm = EnuFromAzEl(185, 5);
  EXPECT_THAT(message({{*Project(k, truth.rotation.transpose() * lm), EnuFromAzEl(193, 5)}}, {}),
              HasSubstr("disagrees with the sun"));
  // A horizon point straight below the sun does not fix the roll (to first order).
  const Eigen::Vector3d below = EnuFromAzEl(205, 0);
  const std::string m = message({}, {{*Project(k, truth.rotation.transpose() * below)}});
  EXPECT_THAT(m, HasSubstr("do not fix the roll"));
  EXPECT_THROW(OrientFromSun(k, Eigen::Vector3d::Zero(), 0.01, sun, {}, {}, {}), Error);
}

}  // namespace
}  // namespace rouen
