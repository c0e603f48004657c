#include "core/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/angles.h"
#include "core/error.h"
#include "core/solar.h"

namespace rouen {
namespace {

Intrinsics DistortedPinhole() {
  Intrinsics k = Intrinsics::PinholeFov(640, 480, 70.0);
  k.fy = k.fx * 1.01;
  k.cx = 322.5;
  k.cy = 237.25;
  k.k1 = -0.21;
  k.k2 = 0.047;
  k.k3 = -0.004;
  k.p1 = 0.0012;
  k.p2 = -0.0007;
  return k;
}

Intrinsics DistortedFisheye() {
  Intrinsics k = Intrinsics::FisheyeFov(800, 600, 190.0);
  k.k1 = -0.02;
  k.k2 = 0.003;
  k.k3 = -0.0004;
  k.k4 = 0.00002;
  return k;
}

void ExpectPixelRoundTrip(const Intrinsics& k, double x0, double x1, double y0, double y1) {
  int checked = 0;
  for (double y = y0; y <= y1; y += (y1 - y0) / 23) {
    for (double x = x0; x <= x1; x += (x1 - x0) / 31) {
      const Eigen::Vector2d px(x, y);
      const Eigen::Vector3d ray = Unproject(k, px);
      EXPECT_NEAR(ray.norm(), 1.0, 1e-12);
      const auto back = Project(k, ray);
      ASSERT_TRUE(back.has_value()) << x << " " << y;
      EXPECT_LT((*back - px).norm(), 1e-6) << x << " " << y;
      ++checked;
    }
  }
  EXPECT_GT(checked, 500);
}

TEST(CameraTest, PinholeRoundTrip) {
  const Intrinsics k = DistortedPinhole();
  ExpectPixelRoundTrip(k, 0, 640, 0, 480);
  // Directions -> pixels -> directions.
  for (double a = -0.5; a <= 0.5; a += 0.1) {
    for (double b = -0.4; b <= 0.4; b += 0.1) {
      const Eigen::Vector3d d = Eigen::Vector3d(a, b, 1).normalized();
      const auto px = Project(k, d);
      ASSERT_TRUE(px.has_value());
      EXPECT_LT((Unproject(k, *px) - d).norm(), 1e-9);
    }
  }
}

TEST(CameraTest, DistortionMovesPixels) {
  const Intrinsics k = DistortedPinhole();
  Intrinsics ideal = k;
  ideal.k1 = ideal.k2 = ideal.k3 = ideal.p1 = ideal.p2 = 0;
  const Eigen::Vector3d corner(0.6, 0.45, 1.0);
  const double shift = (*Project(k, corner) - *Project(ideal, corner)).norm();
  EXPECT_GT(shift, 10.0);  // k1 = -0.21 at r^2 = 0.56 pulls the corner in by ~12% of ~340 px
  // The principal ray is unaffected.
  EXPECT_LT((*Project(k, Eigen::Vector3d(0, 0, 1)) - Eigen::Vector2d(k.cx, k.cy)).norm(), 1e-12);
  // Without distortion a pinhole is a plain perspective division.
  const Eigen::Vector2d p = *Project(ideal, Eigen::Vector3d(0.2, -0.1, 2.0));
  EXPECT_NEAR(p.x(), ideal.fx * 0.1 + ideal.cx, 1e-9);
  EXPECT_NEAR(p.y(), ideal.fy * -0.05 + ideal.cy, 1e-9);
}

TEST(CameraTest, FisheyeRoundTrip) {
  const Intrinsics k = DistortedFisheye();
  ExpectPixelRoundTrip(k, 100, 700, 0, 600);
  // Radius grows with the angle from the axis; 90 deg off axis is still in front of a 190 deg lens.
  const Intrinsics ideal = Intrinsics::FisheyeFov(800, 600, 180.0);
  const auto side = Project(ideal, Eigen::Vector3d(1, 0, 0));
  ASSERT_TRUE(side.has_value());
  EXPECT_NEAR(side->x(), 400 + 300, 1e-9);  // fov edge at radius min(w,h)/2
  const Eigen::Vector3d behind_side(1, 0, -0.2);
  ASSERT_TRUE(Project(ideal, behind_side).has_value());
  EXPECT_FALSE(Project(ideal, Eigen::Vector3d(0, 0, -1)).has_value());
}

TEST(CameraTest, EquirectRoundTripAndOrientation) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);
  ExpectPixelRoundTrip(k, 0.5, 719.5, 0.5, 359.5);
  // A level camera looking north: columns are compass azimuth, row 0 is the zenith.
  const Pose pose = Pose::Level(Eigen::Vector3d(5, -3, 2), 0.0, 0.0);
  for (double az = 5; az < 360; az += 40) {
    for (double el = -80; el <= 80; el += 20) {
      const Eigen::Vector3d world = pose.position + 10 * EnuFromAzEl(az, el);
      const auto px = Project(k, pose.WorldToCamera(world));
      ASSERT_TRUE(px.has_value());
      EXPECT_NEAR(px->x() / 720 * 360, az, 1e-9);
      EXPECT_NEAR(px->y() / 360 * 180, 90 - el, 1e-9);
    }
  }
}

// Pixel solid angles: an equirect pixel spans d(azimuth) x d(sin elevation) exactly; the
// corner quadrilateral is exact to second order in the pixel's angular size t, so each pixel
// is within t^2 of it (relative) and the sphere sums to 4 pi within the same; a 180-degree
// fisheye's pixels inside its circle sum to the hemisphere, 2 pi, within t^2 plus the circle's
// edge pixels (a ring one pixel wide: 2 / radius of it, relative).
TEST(CameraTest, PixelSolidAngleIsExactToSecondOrder) {
  const int w = 64, h = 32;
  const Intrinsics k = Intrinsics::Equirect(w, h);
  const double t = kPi / h;
  double sum = 0;
  for (int y = 0; y < h; ++y) {
    const double exact = 2 * kPi / w * (std::cos(y * t) - std::cos((y + 1) * t));
    for (int x = 0; x < w; ++x) {
      const double omega = PixelSolidAngle(k, x, y);
      EXPECT_NEAR(omega / exact, 1, t * t) << x << " " << y;
      sum += omega;
    }
  }
  EXPECT_NEAR(sum / (4 * kPi), 1, t * t);
  const Intrinsics f = Intrinsics::FisheyeFov(200, 200, 180);
  double hemi = 0;
  for (int y = 0; y < f.height; ++y) {
    for (int x = 0; x < f.width; ++x) {
      if (std::hypot(x + 0.5 - f.cx, y + 0.5 - f.cy) < 100) hemi += PixelSolidAngle(f, x, y);
    }
  }
  EXPECT_NEAR(hemi / (2 * kPi), 1, 2.0 / 100 + std::pow(kPi / 200, 2));
}

TEST(CameraTest, BehindOrDegenerateDirections) {
  const Intrinsics k = DistortedPinhole();
  EXPECT_FALSE(Project(k, Eigen::Vector3d(0, 0, -1)).has_value());
  EXPECT_FALSE(Project(k, Eigen::Vector3d(1, 0, 0)).has_value());
  EXPECT_FALSE(Project(k, Eigen::Vector3d(0.1, 0.2, -3)).has_value());
  EXPECT_FALSE(Project(k, Eigen::Vector3d::Zero()).has_value());
  EXPECT_FALSE(Project(Intrinsics::Equirect(10, 5), Eigen::Vector3d::Zero()).has_value());
}

TEST(CameraTest, LookAtIsAProperRotation) {
  const Eigen::Vector3d eye(1, 2, 3);
  const Pose north = Pose::LookAt(eye, eye + Eigen::Vector3d(0, 10, 0));
  EXPECT_TRUE(north.rotation.col(0).isApprox(Eigen::Vector3d(1, 0, 0)));   // right = east
  EXPECT_TRUE(north.rotation.col(1).isApprox(Eigen::Vector3d(0, 0, -1)));  // down
  EXPECT_TRUE(north.rotation.col(2).isApprox(Eigen::Vector3d(0, 1, 0)));   // forward
  const Eigen::Vector3d targets[] = {
      {3, -4, 1}, {-1, 0.5, -2}, {0, 0, 10}, {0, 0, -10}, {1e-12, 0, 5}};
  for (const Eigen::Vector3d& t : targets) {
    const Pose p = Pose::LookAt(eye, eye + t);
    EXPECT_NEAR(p.rotation.determinant(), 1.0, 1e-12);
    EXPECT_LT((p.rotation.transpose() * p.rotation - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_TRUE(p.WorldToCamera(eye + t).normalized().isApprox(Eigen::Vector3d(0, 0, 1), 1e-9));
    // Image-up (-y) never points below the horizon.
    EXPECT_GE((-p.rotation.col(1)).z(), -1e-12);
  }
  // Straight up: image-up is north.
  const Pose up = Pose::LookAt(eye, eye + Eigen::Vector3d(0, 0, 1));
  EXPECT_TRUE((-up.rotation.col(1)).isApprox(Eigen::Vector3d(0, 1, 0)));
  const Pose down = Pose::LookAt(eye, eye - Eigen::Vector3d(0, 0, 1));
  EXPECT_TRUE((-down.rotation.col(1)).isApprox(Eigen::Vector3d(0, 1, 0)));
  // Level(az, el) looks along EnuFromAzEl.
  const Pose level = Pose::Level(eye, 135, 20);
  EXPECT_TRUE(level.rotation.col(2).isApprox(EnuFromAzEl(135, 20)));
  EXPECT_NEAR(level.rotation.col(0).z(), 0.0, 1e-12);  // no roll
}

TEST(CameraTest, ValidateExplainsItself) {
  EXPECT_NO_THROW(DistortedPinhole().Validate());
  EXPECT_NO_THROW(Intrinsics::Equirect(100, 50).Validate());
  Intrinsics k = DistortedPinhole();
  k.width = 0;
  EXPECT_THROW(k.Validate(), Error);
  k = DistortedPinhole();
  k.fx = -1;
  try {
    k.Validate();
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fx"), std::string::npos);
  }
  k = DistortedPinhole();
  k.k2 = NAN;
  EXPECT_THROW(k.Validate(), Error);
  EXPECT_THROW(Intrinsics().Validate(), Error);
}

TEST(CameraTest, JsonRoundTrip) {
  for (const Intrinsics& k :
       {DistortedPinhole(), DistortedFisheye(), Intrinsics::Equirect(2048, 1024)}) {
    const nlohmann::json j = k;
    const Intrinsics back = nlohmann::json::parse(j.dump()).get<Intrinsics>();
    EXPECT_EQ(back.projection, k.projection);
    EXPECT_EQ(back.width, k.width);
    EXPECT_EQ(back.height, k.height);
    for (auto [a, b] : {std::pair{back.fx, k.fx},
                        {back.fy, k.fy},
                        {back.cx, k.cx},
                        {back.cy, k.cy},
                        {back.k1, k.k1},
                        {back.k2, k.k2},
                        {back.k3, k.k3},
                        {back.k4, k.k4},
                        {back.p1, k.p1},
                        {back.p2, k.p2}}) {
      EXPECT_EQ(a, b);
    }
  }
  EXPECT_EQ(nlohmann::json(DistortedFisheye())["projection"], "fisheye");
  const Pose p = Pose::Level(Eigen::Vector3d(1, -2, 3.5), 37, 12);
  const Pose q = nlohmann::json::parse(nlohmann::json(p).dump()).get<Pose>();
  EXPECT_EQ(q.rotation, p.rotation);
  EXPECT_EQ(q.position, p.position);
  EXPECT_EQ(nlohmann::json(p)["rotation"][0].size(), 3u);  // row-major rows
  EXPECT_EQ(nlohmann::json(p)["rotation"][0][1], p.rotation(0, 1));
}

TEST(CameraTest, BadJsonNamesTheKey) {
  nlohmann::json j = DistortedPinhole();
  j.erase("fx");
  try {
    j.get<Intrinsics>();
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("\"fx\""), std::string::npos) << e.what();
  }
  j = DistortedPinhole();
  j["projection"] = "orthographic";
  EXPECT_THROW(j.get<Intrinsics>(), Error);
  j = DistortedPinhole();
  j["width"] = "640";
  EXPECT_THROW(j.get<Intrinsics>(), Error);
  j = DistortedPinhole();
  j["fy"] = 0;
  EXPECT_THROW(j.get<Intrinsics>(), Error);
  for (nlohmann::json width : {nlohmann::json(4294967936LL), nlohmann::json(-4294967296LL),
                               nlohmann::json(18446744073709551615ULL)}) {
    j = DistortedPinhole();
    j["width"] = width;  // not truncated to 640, 0 or -1
    EXPECT_THROW(j.get<Intrinsics>(), Error) << width;
  }
  nlohmann::json pj = Pose();
  pj.erase("position");
  try {
    pj.get<Pose>();
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("\"position\""), std::string::npos) << e.what();
  }
  pj = Pose();
  pj["rotation"][0][0] = 2.0;  // not orthonormal
  EXPECT_THROW(pj.get<Pose>(), Error);
  // A camera 1e300 m out: before, Embree's ray check aborted rouen render.
  pj = Pose();
  pj["position"][1] = 1e300;
  try {
    pj.get<Pose>();
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()),
              "pose: \"position\": coordinate 1e+300 m is outside -100000..100000 m of the "
              "site's east-north-up frame");
  }
  EXPECT_THROW(nlohmann::json::array().get<Pose>(), Error);
}

TEST(CameraTest, ParsePoseNamesTheFile) {
  const Pose p = ParsePose(R"({"rotation": [1, 0, 0, 0, 1, 0, 0, 0, 1], "position": [1, 2, 3],
                               "reprojection": {"rms_px": 0.5}})",
                           "pose.json");
  EXPECT_EQ(p.position, Eigen::Vector3d(1, 2, 3));
  for (const char* text : {"{", R"({"rotation": [1, 0, 0], "position": [0, 0, 0]})", "[]"}) {
    try {
      ParsePose(text, "pose.json");
      ADD_FAILURE() << text;
    } catch (const Error& e) {
      EXPECT_EQ(std::string(e.what()).rfind("pose.json: ", 0), 0u) << e.what();
    }
  }
}

}  // namespace
}  // namespace rouen
