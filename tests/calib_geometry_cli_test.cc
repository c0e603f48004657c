// End-to-end tests of `rouen calib intrinsics` and `rouen calib pose`: synthetic board
// photographs and landmarks written to disk, the binary run on them, its outputs read back.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/intrinsics.h"
#include "core/camera.h"
#include "core/files.h"
#include "core/image.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using rouen::cli_test::Q;
using rouen::cli_test::Result;
using rouen::cli_test::RunRouen;
using rouen::cli_test::TempDir;

TEST(CalibGeometryCli, HelpExplains) {
  const Result i = RunRouen("calib intrinsics --help");
  EXPECT_EQ(i.code, 0) << i.out;
  EXPECT_NE(i.out.find("chessboard:COLSxROWS:SQUARE_M"), std::string::npos) << i.out;
  EXPECT_NE(i.out.find("fisheye"), std::string::npos);
  const Result p = RunRouen("calib pose --help");
  EXPECT_EQ(p.code, 0) << p.out;
  EXPECT_NE(p.out.find("\"vertex\""), std::string::npos) << p.out;
}

TEST(CalibGeometryCli, IntrinsicsThenPose) {
  const fs::path dir = TempDir("ok");
  const BoardSpec board = BoardSpec::Parse("chessboard:9x7:0.03");
  Intrinsics truth = Intrinsics::PinholeFov(480, 360, 60);
  truth.k1 = -0.15;
  truth.k2 = 0.05;
  BoardRenderer renderer(board, truth, 2);
  const Eigen::Vector3d centre(0.135, 0.105, 0);
  const double tilts[][3] = {{0, 0, 0},     {30, 0, 5},  {-30, 0, -5},  {0, 30, 10},
                             {0, -30, -10}, {20, 25, 0}, {-25, 20, 15}, {25, -20, -15}};
  const double offs[][2] = {{0, 0},      {0.3, 0.3}, {-0.3, -0.3}, {0.3, -0.3},
                            {-0.3, 0.3}, {0.45, 0},  {-0.45, 0},   {0, 0.45}};
  fs::create_directories(dir / "shots");
  for (int i = 0; i < 8; ++i) {
    const double d = 3.14159265358979323846 / 180;
    const Eigen::Matrix3d r = (Eigen::AngleAxisd(tilts[i][2] * d, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(tilts[i][1] * d, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(tilts[i][0] * d, Eigen::Vector3d::UnitX()))
                                  .toRotationMatrix();
    const Eigen::Vector3d at =
        Unproject(truth, {truth.cx + offs[i][0] * 240, truth.cy + offs[i][1] * 180}) * 0.6;
    const Image im = renderer.Render(r, at - r * centre, 30.f, 220.f, 120.f);
    WriteImage((dir / "shots" / ("board" + std::to_string(i) + ".png")).string(), im,
               StoredType::kUint8);
  }
  const fs::path lens = dir / "lens.json";
  const Result a = RunRouen("calib intrinsics --images " + Q(dir / "shots") +
                            " --board chessboard:9x7:0.03 --model pinhole --out " + Q(lens));
  ASSERT_EQ(a.code, 0) << a.out;
  EXPECT_NE(a.out.find("reprojection RMS"), std::string::npos) << a.out;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(lens));
  const Intrinsics k = j.get<Intrinsics>();
  // 8 views of 48 corners pin fx to well under 1% (the unit tests check the statistics).
  EXPECT_NEAR(k.fx, truth.fx, 0.01 * truth.fx);
  EXPECT_NEAR(k.cx, truth.cx, 3.0);
  EXPECT_NEAR(k.k1, truth.k1, 0.03);
  EXPECT_LT(j["calibration"]["rms_px"].get<double>(), 0.5);
  EXPECT_EQ(j["calibration"]["views"].get<int>(), 8);

  // Landmarks through a known pose with the calibrated lens's truth.
  const Pose pose = Pose::LookAt({-12, -30, 1.6}, {5, 5, 8});
  nlohmann::json pts = {{"image", "west.jpg"}, {"points", nlohmann::json::array()}};
  int made = 0;
  for (int i = 0; made < 10 && i < 1000; ++i) {
    const Eigen::Vector3d w(20.0 * ((i * 7) % 11) / 10, 14.0 * ((i * 3) % 7) / 6,
                            24.0 * ((i * 5) % 13) / 12);
    const auto px = Project(truth, pose.WorldToCamera(w));
    if (!px || px->x() < 0 || px->y() < 0 || px->x() >= 480 || px->y() >= 360) continue;
    pts["points"].push_back({{"name", "p" + std::to_string(made++)},
                             {"pixel", {px->x(), px->y()}},
                             {"world", {w.x(), w.y(), w.z()}}});
  }
  ASSERT_EQ(made, 10);
  WriteFileAtomic(dir / "pts.json", pts.dump());
  const fs::path out = dir / "pose.json";
  const Result b = RunRouen("calib pose --points " + Q(dir / "pts.json") + " --lens " + Q(lens) +
                            " --out " + Q(out));
  ASSERT_EQ(b.code, 0) << b.out;
  const nlohmann::json pj = nlohmann::json::parse(ReadFileToString(out));
  const Pose got = pj.get<Pose>();
  // The lens is estimated, so the pose is only as good as the lens: within a metre at 35 m.
  EXPECT_LT((got.position - pose.position).norm(), 1.0) << b.out;
  EXPECT_EQ(pj["reprojection"]["inliers"].get<int>(), 10) << b.out;
  EXPECT_LT(pj["reprojection"]["rms_px"].get<double>(), 2.0);

  // Bad input: three landmarks only.
  nlohmann::json three = pts;
  three["points"] =
      nlohmann::json(std::vector<nlohmann::json>(pts["points"].begin(), pts["points"].begin() + 3));
  WriteFileAtomic(dir / "three.json", three.dump());
  const Result c = RunRouen("calib pose --points " + Q(dir / "three.json") + " --lens " + Q(lens) +
                            " --out " + Q(dir / "bad.json"));
  EXPECT_NE(c.code, 0);
  EXPECT_NE(c.out.find("rouen: error:"), std::string::npos) << c.out;
  EXPECT_NE(c.out.find("three.json"), std::string::npos) << c.out;
  EXPECT_NE(c.out.find("at least 4"), std::string::npos) << c.out;
  EXPECT_FALSE(fs::exists(dir / "bad.json"));
  fs::remove_all(dir);
}

TEST(CalibGeometryCli, IntrinsicsBadInput) {
  const fs::path dir = TempDir("bad");
  // No board in any image: the error names them.
  fs::create_directories(dir / "blank");
  for (const char* n : {"a.png", "b.png"}) {
    WriteImage((dir / "blank" / n).string(), Image(160, 120, 1, PixelUnits::kDigital, 100.f),
               StoredType::kUint8);
  }
  Result r = RunRouen("calib intrinsics --images " + Q(dir / "blank") +
                      " --board chessboard:9x7:0.03 --out " + Q(dir / "lens.json"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("not found in any"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("a.png"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("b.png"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "lens.json"));
  // Mixed sizes.
  WriteImage((dir / "blank" / "c.png").string(), Image(200, 120, 1, PixelUnits::kDigital, 100.f),
             StoredType::kUint8);
  r = RunRouen("calib intrinsics --images " + Q(dir / "blank") +
               " --board chessboard:9x7:0.03 --out " + Q(dir / "lens.json"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("c.png: size 200x120"), std::string::npos) << r.out;
  // Unreadable image through a list file, bad board text, bad model, missing folder.
  std::ofstream(dir / "list.txt") << "# shots\nmissing.png\n";
  r = RunRouen("calib intrinsics --images " + Q(dir / "list.txt") +
               " --board chessboard:9x7:0.03 --out " + Q(dir / "lens.json"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("missing.png"), std::string::npos) << r.out;
  r = RunRouen("calib intrinsics --images " + Q(dir / "blank") + " --board chess:9x7 --out " +
               Q(dir / "lens.json"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("chess:9x7"), std::string::npos) << r.out;
  r = RunRouen("calib intrinsics --images " + Q(dir / "blank") +
               " --board chessboard:9x7:0.03 --model fish --out " + Q(dir / "lens.json"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("pinhole or fisheye"), std::string::npos) << r.out;
  r = RunRouen("calib intrinsics --images " + Q(dir / "nowhere") +
               " --board chessboard:9x7:0.03 --out " + Q(dir / "lens.json"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("nowhere"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
