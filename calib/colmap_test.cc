#include "calib/colmap.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "calib/colmap_test_support.h"
#include "core/error.h"
#include "core/error_of.h"
#include "core/files.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

class ColmapTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rouen_colmap_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "txt");
    poses_ = {Pose::LookAt({30, -40, 1.6}, {0, 0, 10}), Pose::LookAt({-25, 35, 1.7}, {0, 0, 20}),
              Pose::LookAt({5, -60, 1.5}, {2, 0, 5}), Pose::LookAt({40, 10, 1.6}, {0, 0, 30})};
    std::string cameras =
        "# Camera list with one line of data per camera:\n"
        "1 PINHOLE 640 480 500.5 501.25 320.5 240.25\n"
        "2 OPENCV 800 600 700 690 401 299 -0.12 0.031 0.0011 -0.0007\n"
        "3 OPENCV_FISHEYE 1000 1000 320 321 500 500 0.02 -0.01 0.003 -0.0004\n"
        "7 SIMPLE_RADIAL 640 480 510 320 240 -0.05\n";
    std::string images = "# Image list with two lines of data per image:\n";
    const int camera_of[] = {1, 2, 3, 7};
    for (int i = 0; i < 4; ++i) {
      images += std::to_string(10 + i) + " " + ColmapPoseText(poses_[i]) + " " +
                std::to_string(camera_of[i]) + " day1/IMG_" + std::to_string(i) + ".JPG\n";
      images += i == 1 ? "\n" : "100.5 200.5 -1\n";  // an image with no 2D point at all
    }
    WriteFileAtomic(dir_ / "txt" / "cameras.txt", cameras);
    WriteFileAtomic(dir_ / "txt" / "images.txt", images);
    WriteFileAtomic(dir_ / "txt" / "points3D.txt",
                    "# 3D point list\n1 1.5 -2.25 3 120 130 140 0.5\n2 -4 5 6.5 10 20 30 0.25\n");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // COLMAP's own conversion of the text model to binary; false when colmap is not installed.
  bool ConvertWithColmap() {
    if (std::system("command -v colmap >/dev/null 2>&1") != 0) return false;
    fs::create_directories(dir_ / "bin");
    const std::string cmd = "colmap model_converter --input_path '" + (dir_ / "txt").string() +
                            "' --output_path '" + (dir_ / "bin").string() +
                            "' --output_type BIN >/dev/null 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    return true;
  }

  fs::path dir_;
  std::vector<Pose> poses_;
};

TEST_F(ColmapTest, TheTextModelGivesEachImagesPoseAndCamera) {
  const ColmapModel m = ReadColmapModel(dir_ / "txt");
  EXPECT_FALSE(m.binary);
  ASSERT_EQ(m.images.size(), 4u);
  for (int i = 0; i < 4; ++i) {
    const ColmapImage& im = m.images[i];
    EXPECT_EQ(im.id, 10 + i);
    EXPECT_EQ(im.name, "day1/IMG_" + std::to_string(i) + ".JPG");
    EXPECT_LT((im.pose.position - poses_[i].position).norm(), 1e-9) << i;
    EXPECT_LT((im.pose.rotation - poses_[i].rotation).norm(), 1e-12) << i;
  }
  const Intrinsics& pin = m.images[0].intrinsics;
  EXPECT_EQ(pin.projection, Projection::kPinhole);
  EXPECT_EQ(pin.width, 640);
  EXPECT_EQ(pin.fx, 500.5);
  EXPECT_EQ(pin.fy, 501.25);
  EXPECT_EQ(pin.cx, 320.5);
  EXPECT_EQ(pin.cy, 240.25);
  const Intrinsics& cv = m.images[1].intrinsics;
  EXPECT_EQ(cv.k1, -0.12);
  EXPECT_EQ(cv.k2, 0.031);
  EXPECT_EQ(cv.p1, 0.0011);
  EXPECT_EQ(cv.p2, -0.0007);
  const Intrinsics& fish = m.images[2].intrinsics;
  EXPECT_EQ(fish.projection, Projection::kFisheye);
  EXPECT_EQ(fish.k4, -0.0004);
  const Intrinsics& radial = m.images[3].intrinsics;
  EXPECT_EQ(radial.fx, 510);
  EXPECT_EQ(radial.fy, 510);
  EXPECT_EQ(radial.k1, -0.05);
  ASSERT_EQ(m.points.size(), 2u);
  EXPECT_EQ(m.points[1], Eigen::Vector3d(-4, 5, 6.5));
  // By its path, else by its file name when only one image has it.
  ASSERT_NE(m.Find("day1/IMG_2.JPG"), nullptr);
  EXPECT_EQ(m.Find("IMG_2.JPG")->id, 12);
  EXPECT_EQ(m.Find("IMG_9.JPG"), nullptr);
}

// A world point lands on the same pixel through COLMAP's camera (its formula for OPENCV,
// written out here: x_cam = R X + t, u = x/z, radial and tangential terms, f and c) and
// through rouen's camera made from the model.
TEST_F(ColmapTest, APointProjectsWhereColmapProjectsIt) {
  const ColmapModel m = ReadColmapModel(dir_ / "txt");
  const ColmapImage& im = m.images[1];
  const Eigen::Matrix3d r = im.pose.rotation.transpose();
  const Eigen::Vector3d t = -(r * im.pose.position);
  for (const Eigen::Vector3d& x : {Eigen::Vector3d(0, 0, 20), Eigen::Vector3d(3, -2, 25)}) {
    const Eigen::Vector3d c = r * x + t;
    const double u = c.x() / c.z(), v = c.y() / c.z(), r2 = u * u + v * v;
    const double k1 = -0.12, k2 = 0.031, p1 = 0.0011, p2 = -0.0007;
    const double radial = k1 * r2 + k2 * r2 * r2;
    const double du = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u);
    const double dv = v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v);
    const Eigen::Vector2d colmap(700 * (u + du) + 401, 690 * (v + dv) + 299);
    const auto ours = Project(im.intrinsics, im.pose.WorldToCamera(x));
    ASSERT_TRUE(ours.has_value());
    EXPECT_LT((*ours - colmap).norm(), 1e-9) << x.transpose();
  }
}

TEST_F(ColmapTest, ColmapsBinaryModelReadsAsItsText) {
  if (!ConvertWithColmap()) GTEST_SKIP() << "colmap is not installed (apt-get install colmap)";
  const ColmapModel text = ReadColmapModel(dir_ / "txt");
  const ColmapModel bin = ReadColmapModel(dir_ / "bin");
  EXPECT_TRUE(bin.binary);
  ASSERT_EQ(bin.images.size(), text.images.size());
  for (const ColmapImage& a : text.images) {
    const ColmapImage* b = bin.Find(a.name);
    ASSERT_NE(b, nullptr) << a.name;
    EXPECT_EQ(b->id, a.id);
    EXPECT_LT((b->pose.position - a.pose.position).norm(), 1e-9) << a.name;
    EXPECT_LT((b->pose.rotation - a.pose.rotation).norm(), 1e-12) << a.name;
    EXPECT_EQ(b->intrinsics.projection, a.intrinsics.projection);
    EXPECT_EQ(b->intrinsics.fx, a.intrinsics.fx);
    EXPECT_EQ(b->intrinsics.k1, a.intrinsics.k1);
    EXPECT_EQ(b->intrinsics.p2, a.intrinsics.p2);
  }
  ASSERT_EQ(bin.points.size(), text.points.size());

  // Cut short, a binary file is named with the byte where it ends.
  const std::string cameras = ReadFileToString(dir_ / "bin" / "cameras.bin");
  WriteFileAtomic(dir_ / "bin" / "cameras.bin", cameras.substr(0, cameras.size() - 5));
  EXPECT_NE(ErrorOf([&] {
              ReadColmapModel(dir_ / "bin");
            }).find((dir_ / "bin" / "cameras.bin").string() + ": at byte "),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadColmapModel(dir_ / "bin"); }).find("ends early"), std::string::npos);
}

TEST_F(ColmapTest, BadModelsAreNamedWithTheirFileAndLine) {
  EXPECT_EQ(ErrorOf([&] { ReadColmapModel(dir_ / "none"); }),
            (dir_ / "none").string() + ": no such folder (a COLMAP sparse model, e.g. sparse/0)");
  fs::create_directories(dir_ / "empty");
  EXPECT_EQ(ErrorOf([&] { ReadColmapModel(dir_ / "empty"); }),
            (dir_ / "empty").string() +
                ": no COLMAP sparse model (cameras and images, .bin or .txt) in this folder");
  const fs::path cams = dir_ / "txt" / "cameras.txt";
  WriteFileAtomic(cams, "# c\n1 PINHOLE 640 480 500 500 320 abc\n");
  EXPECT_EQ(ErrorOf([&] { ReadColmapModel(dir_ / "txt"); }),
            cams.string() + ":2: 'abc' is not a finite number");
  WriteFileAtomic(cams, "1 FOV 640 480 500 500 320 240 0.9\n");
  EXPECT_NE(ErrorOf([&] {
              ReadColmapModel(dir_ / "txt");
            }).find(cams.string() + ":1: camera model FOV cannot be carried over"),
            std::string::npos);
  WriteFileAtomic(cams, "1 FULL_OPENCV 640 480 500 500 320 240 0 0 0 0 0 0.1 0 0\n");
  EXPECT_NE(ErrorOf([&] { ReadColmapModel(dir_ / "txt"); }).find("rational distortion"),
            std::string::npos);
  WriteFileAtomic(cams, "1 PINHOLE 640 480 500 500 320\n");
  EXPECT_EQ(ErrorOf([&] { ReadColmapModel(dir_ / "txt"); }),
            cams.string() + ":1: PINHOLE has 4 parameters, the line 3");
  WriteFileAtomic(cams, "1 PINHOLE 640 480 500 500 320 240\n");
  EXPECT_EQ(ErrorOf([&] { ReadColmapModel(dir_ / "txt"); }),
            (dir_ / "txt" / "images.txt").string() + ":4: camera 2 is not in cameras.txt");
}

TEST(FitSimilarity, RecoversAKnownTransformExactly) {
  Similarity truth;
  truth.scale = 2.5;
  truth.rotation = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).matrix();
  truth.translation = Eigen::Vector3d(100, -20, 3);
  const std::vector<Eigen::Vector3d> from = {
      {0, 0, 0}, {1, 0, 0}, {0, 2, 0}, {1, 1, 3}, {-2, 1, 1}};
  std::vector<Eigen::Vector3d> to;
  for (const auto& x : from) to.push_back(truth.Apply(x));
  const SimilarityFit fit = FitSimilarity(from, to);
  EXPECT_NEAR(fit.transform.scale, 2.5, 1e-12);
  EXPECT_LT((fit.transform.rotation - truth.rotation).norm(), 1e-12);
  EXPECT_LT((fit.transform.translation - truth.translation).norm(), 1e-9);
  EXPECT_LT(fit.rms_m, 1e-9);
  EXPECT_EQ(fit.points, 5);
  EXPECT_EQ(fit.BriefReport(),
            "residual RMS 0.000 m, largest 0.000 m over 5 control points (scale 2.5)");
  // A pose carried along keeps its orientation relative to the points.
  const Pose p = Pose::LookAt({3, 4, 1}, {0, 0, 0});
  const Pose q = fit.transform.Apply(p);
  EXPECT_LT((q.WorldToCamera(truth.Apply({0, 0, 0})).normalized() -
             p.WorldToCamera({0, 0, 0}).normalized())
                .norm(),
            1e-12);
}

TEST(FitSimilarity, ReportsTheResidualAndRefusesWhatFixesNoRotation) {
  // A mirror image cannot be reached by a rotation: the best fit leaves a residual.
  const std::vector<Eigen::Vector3d> from = {{0, 0, 0}, {4, 0, 0}, {0, 3, 0}, {0, 0, 2}};
  std::vector<Eigen::Vector3d> mirrored;
  for (const auto& x : from) mirrored.push_back({-x.x(), x.y(), x.z()});
  const SimilarityFit fit = FitSimilarity(from, mirrored);
  EXPECT_GT(fit.transform.rotation.determinant(), 0.999);
  EXPECT_GT(fit.rms_m, 0.5);
  EXPECT_GE(fit.max_m, fit.rms_m);
  EXPECT_EQ(ErrorOf([&] {
              FitSimilarity({{0, 0, 0}, {1, 1, 1}}, {{0, 0, 0}, {1, 1, 1}});
            }),
            "similarity: 2 point pairs; at least 3 not on a line");
  EXPECT_NE(ErrorOf([&] {
              FitSimilarity({{0, 0, 0}, {1, 1, 1}, {2, 2, 2}}, {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}});
            }).find("lie on a line"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              FitSimilarity({{0, 0, 0}}, {});
            }).find("1 points to map onto 0"),
            std::string::npos);
}

}  // namespace
}  // namespace rouen
