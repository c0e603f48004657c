// Camera pose from landmarks: synthetic correspondences through known poses and lenses, with
// pixel noise and gross outliers; tolerances from the pose covariance the noise implies.
#include "calib/pose.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

double RotationAngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() * 180 / kPi;
}

// One-sigma position (m) and rotation (deg) uncertainty of a pose from `n` landmarks with
// isotropic pixel noise sigma: sigma^2 (J^T J)^-1, J by central differences through core
// Project over a small world-frame rotation (3) and the camera position (3).
void PoseSigma(const Intrinsics& k, const Pose& pose, const std::vector<Eigen::Vector3d>& world,
               double sigma, double* pos_m, double* rot_deg) {
  auto residuals = [&](const Eigen::Matrix<double, 6, 1>& d) {
    Pose p = pose;
    const double a = d.head<3>().norm();
    if (a > 0) p.rotation = Eigen::AngleAxisd(a, d.head<3>() / a).toRotationMatrix() * p.rotation;
    p.position += d.tail<3>();
    Eigen::VectorXd r(2 * world.size());
    for (size_t i = 0; i < world.size(); ++i)
      r.segment<2>(2 * i) = *Project(k, p.WorldToCamera(world[i]));
    return r;
  };
  Eigen::MatrixXd jac(2 * world.size(), 6);
  for (int c = 0; c < 6; ++c) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d[c] = 1e-6;
    jac.col(c) = (residuals(d) - residuals(-d)) / 2e-6;
  }
  const Eigen::MatrixXd cov = (jac.transpose() * jac).inverse() * sigma * sigma;
  *rot_deg = std::sqrt(cov.block<3, 3>(0, 0).trace()) * 180 / kPi;
  *pos_m = std::sqrt(cov.block<3, 3>(3, 3).trace());
}

struct Scene {
  Intrinsics k;
  Pose truth;
  std::vector<Landmark> points;
  std::vector<Eigen::Vector3d> clean_world;  // the non-outlier points
  std::vector<bool> outlier;
};

// Landmarks on the faces of a 20 x 14 x 24 m block seen by `k` from `truth`; `noise_px`
// Gaussian pixel noise; `outliers` of them paired with a wrong pixel.
Scene MakeScene(const Intrinsics& k, const Pose& truth, int count, double noise_px, int outliers,
                unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, noise_px);
  Scene s{k, truth, {}, {}, {}};
  while (static_cast<int>(s.points.size()) < count) {
    // A point on one of the block's faces facing the camera (west x = 0, south y = 0, roof).
    const int face = static_cast<int>(u(rng) * 3);
    Eigen::Vector3d p(20 * u(rng), 14 * u(rng), 24 * u(rng));
    if (face == 0) p.x() = 0;
    if (face == 1) p.y() = 0;
    if (face == 2) p.z() = 24;
    const auto px = Project(k, truth.WorldToCamera(p));
    if (!px || px->x() < 0 || px->y() < 0 || px->x() >= k.width || px->y() >= k.height) continue;
    Landmark l;
    l.name = "p" + std::to_string(s.points.size());
    l.world = p;
    l.pixel = *px + Eigen::Vector2d(g(rng), g(rng));
    const bool bad = static_cast<int>(s.points.size()) < outliers;
    if (bad) {
      // A wrong pairing: a pixel at least 50 px from the true one.
      Eigen::Vector2d q;
      do {
        q = Eigen::Vector2d(u(rng) * k.width, u(rng) * k.height);
      } while ((q - *px).norm() < 50);
      l.pixel = q;
    } else {
      s.clean_world.push_back(p);
    }
    s.outlier.push_back(bad);
    s.points.push_back(l);
  }
  return s;
}

Intrinsics Pinhole() {
  Intrinsics k = Intrinsics::PinholeFov(1920, 1080, 65);
  k.cx += 7;
  k.cy -= 5;
  k.k1 = -0.12, k.k2 = 0.03, k.p1 = 0.0005, k.p2 = -0.0003;
  return k;
}

Intrinsics Fisheye() {
  Intrinsics k = Intrinsics::FisheyeFov(1936, 1216, 190);
  k.k1 = 0.02, k.k2 = -0.004;
  return k;
}

void CheckRecovery(const Scene& s, double noise_px, const char* label) {
  const PoseSummary r = EstimatePose(s.k, s.points);
  double pos_sd = 0, rot_sd = 0;
  PoseSigma(s.k, s.truth, s.clean_world, noise_px, &pos_sd, &rot_sd);
  const double pos_err = (r.pose.position - s.truth.position).norm();
  const double rot_err = RotationAngleDeg(r.pose.rotation, s.truth.rotation);
  // The error of a 3-vector estimate is within ~4.5 sigma (chi-square, 3 dof, p < 1e-3).
  EXPECT_LT(pos_err, 4.5 * pos_sd) << label;
  EXPECT_LT(rot_err, 4.5 * rot_sd) << label;
  // Every planted outlier rejected, every good point kept (noise << threshold).
  for (size_t i = 0; i < s.points.size(); ++i) {
    EXPECT_EQ(r.points[i].inlier, !s.outlier[i]) << label << " " << s.points[i].name;
    EXPECT_TRUE(std::isfinite(r.points[i].error_px));
  }
  // Inlier RMS of a 6-parameter fit to 2n noisy coordinates: sigma sqrt(2 (1 - 6/2n)).
  const double expect_rms = noise_px * std::sqrt(2.0 * (1 - 3.0 / r.inliers));
  EXPECT_NEAR(r.rms_px, expect_rms, 0.35 * expect_rms) << label;
  std::printf(
      "[ measured ] %s: %zu points (%d inliers), noise %.2f px -> position error %.4f m "
      "(sd %.4f), rotation error %.4f deg (sd %.4f), RMS %.3f px, max %.3f px, "
      "%d Ceres iterations, %.1f ms\n",
      label, s.points.size(), r.inliers, noise_px, pos_err, pos_sd, rot_err, rot_sd, r.rms_px,
      r.max_px, r.ceres_iterations, 1e3 * r.seconds);
}

TEST(EstimatePose, PinholeWithNoiseAndOutliers) {
  const Pose truth = Pose::LookAt({-18, -35, 1.6}, {10, 7, 12});
  const Scene s = MakeScene(Pinhole(), truth, 40, 0.7, 8, 1);
  CheckRecovery(s, 0.7, "pinhole 40 points, 8 outliers");
}

TEST(EstimatePose, FisheyeWideField) {
  // A fisheye close to the building: landmarks up to ~95 degrees off the axis.
  const Pose truth = Pose::LookAt({-6, -8, 1.5}, {10, 7, 30});
  const Scene s = MakeScene(Fisheye(), truth, 30, 0.5, 5, 2);
  double widest = 0;
  for (const Landmark& l : s.points) {
    widest = std::max(widest, std::acos(Unproject(s.k, l.pixel).z()) * 180 / kPi);
  }
  EXPECT_GT(widest, 80);
  CheckRecovery(s, 0.5, "fisheye 30 points, 5 outliers");
}

TEST(EstimatePose, ExactDataExactPose) {
  const Pose truth = Pose::LookAt({-18, -35, 1.6}, {10, 7, 12});
  const Scene s = MakeScene(Pinhole(), truth, 6, 0.0, 0, 3);
  const PoseSummary r = EstimatePose(s.k, s.points);
  EXPECT_LT((r.pose.position - truth.position).norm(), 1e-6);
  EXPECT_LT(RotationAngleDeg(r.pose.rotation, truth.rotation), 1e-6);
  EXPECT_LT(r.rms_px, 1e-6);
  // Four points (no RANSAC) still work.
  std::vector<Landmark> four(s.points.begin(), s.points.begin() + 4);
  const PoseSummary r4 = EstimatePose(s.k, four);
  EXPECT_LT((r4.pose.position - truth.position).norm(), 1e-4);
}

void ExpectError(const Intrinsics& k, const std::vector<Landmark>& pts, const std::string& what) {
  try {
    const PoseSummary r = EstimatePose(k, pts);
    FAIL() << "expected an error containing \"" << what << "\", got a pose at "
           << r.pose.position.transpose();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(EstimatePose, DegenerateInputFailsClearly) {
  const Intrinsics k = Pinhole();
  const Pose truth = Pose::LookAt({-18, -35, 1.6}, {10, 7, 12});
  const Scene s = MakeScene(k, truth, 10, 0.3, 0, 4);
  ExpectError(k, {s.points.begin(), s.points.begin() + 3}, "at least 4");
  ExpectError(k, {}, "at least 4");
  // Collinear world points (a vertical edge).
  std::vector<Landmark> line;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d p(0, 0, 3.0 * i);
    line.push_back({"edge" + std::to_string(i), *Project(k, truth.WorldToCamera(p)), p});
  }
  ExpectError(k, line, "collinear");
  // Coplanar points seen edge-on: camera in the plane z = 1.6 of the points.
  std::vector<Landmark> edge_on;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d p(2.0 * i, 3.0 * (i % 3), 1.6);
    const auto px = Project(k, truth.WorldToCamera(p));
    if (px) edge_on.push_back({"f" + std::to_string(i), *px, p});
  }
  ASSERT_GE(edge_on.size(), 4u);
  ExpectError(k, edge_on, "collinear");
  // Points behind the camera: the mirrored scene has no valid pose in front.
  std::vector<Landmark> behind;
  for (const Landmark& l : s.points) {
    Landmark m = l;
    m.world = 2 * truth.position - l.world;  // point reflection through the camera centre
    behind.push_back(m);
  }
  try {
    EstimatePose(k, behind);
    FAIL() << "expected an error for landmarks behind the camera";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_TRUE(msg.find("behind") != std::string::npos) << msg;
  }
  // Non-finite and wildly out-of-image input.
  std::vector<Landmark> bad = s.points;
  bad[2].pixel.x() = std::nan("");
  ExpectError(k, bad, "non-finite");
  bad = s.points;
  bad[1].pixel.x() = 1e7;
  ExpectError(k, bad, "far outside");
  Intrinsics eq = Intrinsics::Equirect(1000, 500);
  ExpectError(eq, s.points, "equirect");
  PoseOptions o;
  o.inlier_threshold_px = 0;
  EXPECT_THROW(o.Validate(), Error);
}

TEST(ReadLandmarks, WorldAndVertexReferences) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("rouen_pose_" + std::to_string(getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "model.obj") << "v 0 0 0\nv 10 0 0\nv 10 0 5\nv 0 0 5\nf 1 2 3\nf 1 3 4\n";
  auto write = [&](const std::string& text) {
    std::ofstream(dir / "pts.json") << text;
    return (dir / "pts.json").string();
  };
  const LandmarkFile f = ReadLandmarks(write(
      R"({"image": "a.jpg", "model": "model.obj", "points": [
           {"name": "roof", "pixel": [10.5, 20.5], "vertex": 2},
           {"pixel": [30, 40], "world": [1, 2, 3]}]})"));
  EXPECT_EQ(f.image, "a.jpg");
  ASSERT_EQ(f.points.size(), 2u);
  EXPECT_EQ(f.points[0].name, "roof");
  EXPECT_EQ(f.points[0].world, Eigen::Vector3d(10, 0, 5));
  EXPECT_EQ(f.points[0].pixel, Eigen::Vector2d(10.5, 20.5));
  EXPECT_EQ(f.points[1].name, "1");
  EXPECT_EQ(f.points[1].world, Eigen::Vector3d(1, 2, 3));
  const std::pair<const char*, const char*> bad[] = {
      {R"({"points": [{"pixel": [1, 2]}]})", "exactly one of"},
      {R"({"points": [{"pixel": [1, 2], "world": [1, 2, 3], "vertex": 1}]})", "exactly one of"},
      {R"({"points": [{"world": [1, 2, 3]}]})", "missing \"pixel\""},
      {R"({"points": [{"pixel": [1], "world": [1, 2, 3]}]})", "array of 2"},
      {R"({"points": [{"pixel": [1, 2], "vertex": 1}]})", "\"model\""},
      {R"({"model": "model.obj", "points": [{"name": "x", "pixel": [1, 2], "vertex": 9}]})",
       "vertex 9 is not in the model"},
      {R"({"pts": []})", "\"points\""},
      {R"({"points": [)", "not valid JSON"}};
  for (const auto& [text, what] : bad) {
    try {
      ReadLandmarks(write(text));
      ADD_FAILURE() << "accepted " << text;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("pts.json"), std::string::npos) << e.what();
    }
  }
  fs::remove_all(dir);
}

TEST(PoseJson, ReadsBackAsPose) {
  const Pose truth = Pose::LookAt({-18, -35, 1.6}, {10, 7, 12});
  const Scene s = MakeScene(Pinhole(), truth, 12, 0.3, 2, 5);
  const PoseSummary r = EstimatePose(s.k, s.points);
  const nlohmann::json j = PoseJson(r);
  const Pose back = j.get<Pose>();
  EXPECT_LT((back.position - r.pose.position).norm(), 1e-12);
  EXPECT_EQ(j["reprojection"]["inliers"].get<int>(), r.inliers);
  EXPECT_EQ(j["reprojection"]["points"].size(), s.points.size());
}

}  // namespace
}  // namespace rouen
