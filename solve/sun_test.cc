#include "solve/sun.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

Eigen::Vector3d AzEl(double az_deg, double el_deg) {
  const double az = az_deg * kDeg, el = el_deg * kDeg;
  return {std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el)};
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) / kDeg;
}

struct SunDisc {
  Eigen::Vector3d dir;
  double radius;       // angular radius, rad
  Eigen::Vector3d I0;  // centre radiance per channel
  double u = 0.6;      // linear limb darkening I = I0 (1 - u (1 - mu))

  double Profile(double theta) const {
    if (theta >= radius) return 0;
    const double rho = std::sin(theta) / std::sin(radius);
    return 1 - u * (1 - std::sqrt(std::max(0.0, 1 - rho * rho)));
  }
  double SolidAngle() const { return 2 * kPi * (1 - std::cos(radius)); }
  // Mean radiance over the cap, by quadrature of the profile over 2 pi sin(theta) d theta.
  Eigen::Vector3d MeanRadiance() const {
    const int n = 20000;
    double sum = 0;
    for (int i = 0; i < n; ++i) {
      const double t = (i + 0.5) / n * radius;
      sum += Profile(t) * 2 * kPi * std::sin(t) * radius / n;
    }
    return I0 * (sum / SolidAngle());
  }
};

Eigen::Vector3d Sky(const Eigen::Vector3d& d) {
  // Linear in the direction, so the annulus median equals the value under the disc.
  const double s = 1 + 0.3 * d.x() + 0.2 * d.z();
  return Eigen::Vector3d(0.6, 0.8, 1.0) * s;
}

// Renders sky + disc: disc pixels supersampled (16 x 16 within 1.5 px of the limb, where the
// profile is steep, 4 x 4 inside), the disc blurred by a Gaussian of `blur_px` (normalised, so
// it keeps the disc's sum), then the sky added.
Image Render(const Intrinsics& k, const Pose& pose, const SunDisc& sun, double blur_px) {
  const int w = k.width, h = k.height;
  std::vector<double> disc(static_cast<size_t>(w) * h * 3, 0.0);
  auto angle_to_sun = [&](double px, double py) {
    const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(px, py));
    return std::atan2(d.cross(sun.dir).norm(), d.dot(sun.dir));
  };
  const auto centre = Project(k, pose.WorldToCamera(sun.dir));
  if (!centre) return Image(w, h, 3, PixelUnits::kRadiance);
  const double px_angle = angle_to_sun(centre->x() + 0.5, centre->y()) +
                          angle_to_sun(centre->x() - 0.5, centre->y());  // ~1 px, rad
  const int reach = static_cast<int>(std::ceil(sun.radius / px_angle)) + 3;
  for (int y = std::max(0, static_cast<int>(centre->y()) - reach);
       y < std::min(h, static_cast<int>(centre->y()) + reach); ++y) {
    for (int x = std::max(0, static_cast<int>(centre->x()) - reach);
         x < std::min(w, static_cast<int>(centre->x()) + reach); ++x) {
      const double t = angle_to_sun(x + 0.5, y + 0.5);
      if (t > sun.radius + 1.5 * px_angle) continue;
      const int ss = std::abs(t - sun.radius) < 1.5 * px_angle ? 16 : 4;
      double sum = 0;
      for (int j = 0; j < ss; ++j) {
        for (int i = 0; i < ss; ++i) {
          sum += sun.Profile(angle_to_sun(x + (i + 0.5) / ss, y + (j + 0.5) / ss));
        }
      }
      for (int c = 0; c < 3; ++c) {
        disc[(static_cast<size_t>(y) * w + x) * 3 + c] = sun.I0[c] * sum / (ss * ss);
      }
    }
  }
  if (blur_px > 0) {
    const int r = static_cast<int>(std::ceil(4 * blur_px));
    std::vector<double> kern(2 * r + 1);
    double ks = 0;
    for (int i = -r; i <= r; ++i) ks += kern[i + r] = std::exp(-0.5 * i * i / (blur_px * blur_px));
    for (double& v : kern) v /= ks;
    for (int pass = 0; pass < 2; ++pass) {
      std::vector<double> out(disc.size(), 0.0);
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          for (int i = -r; i <= r; ++i) {
            const int xx = pass == 0 ? x + i : x, yy = pass == 0 ? y : y + i;
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            for (int c = 0; c < 3; ++c) {
              out[(static_cast<size_t>(yy) * w + xx) * 3 + c] +=
                  kern[i + r] * disc[(static_cast<size_t>(y) * w + x) * 3 + c];
            }
          }
        }
      }
      disc.swap(out);
    }
  }
  Image img(w, h, 3, PixelUnits::kRadiance);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3d sky =
          Sky(pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5)));
      for (int c = 0; c < 3; ++c) {
        img.at(x, y, c) =
            static_cast<float>(sky[c] + disc[(static_cast<size_t>(y) * w + x) * 3 + c]);
      }
    }
  }
  return img;
}

SunDisc TypicalSun(const Eigen::Vector3d& dir) {
  // 0.2666 deg: the mean solar semi-diameter; about 1e4 times the sky, as behind ND filters.
  return {dir, 0.2666 * kDeg, Eigen::Vector3d(9000, 10000, 9500)};
}

void ExpectMeasured(const SunMeasurement& m, const SunDisc& sun) {
  const Eigen::Vector3d truth = sun.MeanRadiance();
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.radiance[c] / truth[c], 1.0, 0.01) << "channel " << c;
  EXPECT_LT(AngleDeg(m.direction_enu, sun.dir), 0.01);
  ::testing::Test::RecordProperty("radiance_rel_error_g",
                                  std::to_string(m.radiance[1] / truth[1] - 1));
  ::testing::Test::RecordProperty("centroid_error_deg",
                                  std::to_string(AngleDeg(m.direction_enu, sun.dir)));
  EXPECT_FALSE(m.any_invalid);
  EXPECT_GT(m.disc_pixels, 0);
  // The background is the sky under the disc.
  const Eigen::Vector3d sky = Sky(sun.dir);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.background[c] / sky[c], 1.0, 0.01);
}

TEST(MeasureSun, PinholeBlurredLimbDarkenedDisc) {
  const Intrinsics k = Intrinsics::PinholeFov(320, 240, 10);  // 0.031 deg per pixel
  const Pose pose = Pose::Level(Eigen::Vector3d::Zero(), 150, 35);
  const SunDisc sun = TypicalSun(AzEl(151.2, 35.7));
  const Image img = Render(k, pose, sun, 1.2);
  // The prediction is off by ~1.3 deg: within the default 3 deg search radius.
  const Eigen::Vector3d predicted = AzEl(150.3, 34.6);
  const SunMeasurement m = MeasureSun(img, k, pose, predicted, sun.SolidAngle(), SunOptions{});
  ExpectMeasured(m, sun);
  EXPECT_NEAR(m.offset_deg, AngleDeg(sun.dir, predicted), 0.01);
}

TEST(MeasureSun, FisheyeSolidAngleFromTheCameraModel) {
  // 15 deg off-axis in an equidistant fisheye: pixel solid angles differ from a pinhole's.
  const Intrinsics k = Intrinsics::FisheyeFov(720, 720, 40);  // 0.056 deg per pixel
  const Pose pose = Pose::Level(Eigen::Vector3d::Zero(), 200, 30);
  const SunDisc sun = TypicalSun(AzEl(214, 40));
  const Image img = Render(k, pose, sun, 0.7);
  const SunMeasurement m = MeasureSun(img, k, pose, AzEl(213, 39), sun.SolidAngle(), SunOptions{});
  ExpectMeasured(m, sun);
}

TEST(MeasureSun, FlagsInvalidDiscPixels) {
  const Intrinsics k = Intrinsics::PinholeFov(200, 160, 8);
  const Pose pose = Pose::Level(Eigen::Vector3d::Zero(), 90, 20);
  const SunDisc sun = TypicalSun(AzEl(90.5, 20.3));
  const Image img = Render(k, pose, sun, 1.0);
  std::vector<uint8_t> mask(static_cast<size_t>(k.width) * k.height, 1);
  // Invalid far from the disc: not flagged.
  mask[5 * k.width + 5] = 0;
  SunMeasurement m = MeasureSun(img, k, pose, sun.dir, sun.SolidAngle(), SunOptions{}, &mask);
  EXPECT_FALSE(m.any_invalid);
  // Invalid (e.g. saturated in every frame) at the disc centre: flagged.
  const auto c = Project(k, pose.WorldToCamera(sun.dir));
  ASSERT_TRUE(c.has_value());
  mask[static_cast<size_t>(c->y()) * k.width + static_cast<size_t>(c->x())] = 0;
  m = MeasureSun(img, k, pose, sun.dir, sun.SolidAngle(), SunOptions{}, &mask);
  EXPECT_TRUE(m.any_invalid);
}

TEST(MeasureSun, RejectsBadInput) {
  const Intrinsics k = Intrinsics::PinholeFov(200, 160, 8);
  const Pose pose = Pose::Level(Eigen::Vector3d::Zero(), 90, 20);
  const SunDisc sun = TypicalSun(AzEl(90.5, 20.3));
  const Image img = Render(k, pose, sun, 1.0);
  const double omega = sun.SolidAngle();
  EXPECT_NO_THROW(MeasureSun(img, k, pose, sun.dir, omega, SunOptions{}));
  // Behind the camera.
  EXPECT_THROW(MeasureSun(img, k, pose, AzEl(270, 20), omega, SunOptions{}), Error);
  // Far outside the frame.
  EXPECT_THROW(MeasureSun(img, k, pose, AzEl(130, 20), omega, SunOptions{}), Error);
  EXPECT_THROW(MeasureSun(img, k, pose, sun.dir, 0.0, SunOptions{}), Error);
  EXPECT_THROW(MeasureSun(img, k, pose, sun.dir, std::nan(""), SunOptions{}), Error);
  EXPECT_THROW(MeasureSun(img, k, pose, Eigen::Vector3d::Zero(), omega, SunOptions{}), Error);
  Image digital = img;
  digital.units = PixelUnits::kDigital;
  EXPECT_THROW(MeasureSun(digital, k, pose, sun.dir, omega, SunOptions{}), Error);
  Intrinsics other = k;
  other.width = 100;
  EXPECT_THROW(MeasureSun(img, other, pose, sun.dir, omega, SunOptions{}), Error);
  std::vector<uint8_t> short_mask(7, 1);
  EXPECT_THROW(MeasureSun(img, k, pose, sun.dir, omega, SunOptions{}, &short_mask), Error);
  // A sky without a sun.
  Image flat(k.width, k.height, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(MeasureSun(flat, k, pose, sun.dir, omega, SunOptions{}), Error);
  // A disc cut by the image border.
  const SunDisc edge = TypicalSun(AzEl(94.0, 20.0));  // 4 deg right of centre, hfov 8 deg
  const Image cut = Render(k, pose, edge, 1.0);
  EXPECT_THROW(MeasureSun(cut, k, pose, edge.dir, omega, SunOptions{}), Error);
  SunOptions bad;
  bad.annulus_inner_factor = 1.0;
  EXPECT_THROW(bad.Validate(), Error);
}

}  // namespace
}  // namespace rouen
