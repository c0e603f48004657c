// Intrinsics calibration on synthetic board photographs rendered through known cameras with
// core/camera.h, and the exact correspondence of our camera models with OpenCV's.
#include "calib/intrinsics.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <random>

#include "core/angles.h"
#include "core/error.h"
#include "core/files.h"
#include "core/lens.h"

namespace rouen {
namespace {

Eigen::Matrix3d Rot(double ax_deg, double ay_deg, double az_deg) {
  const double d = kPi / 180;
  return (Eigen::AngleAxisd(az_deg * d, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(ay_deg * d, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(ax_deg * d, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

struct ViewPose {
  Eigen::Matrix3d r;
  Eigen::Vector3d t;
};

// Board poses spread over the image with tilts up to ~35 degrees: the board centre is put
// on the ray through a chosen pixel at a chosen distance.
std::vector<ViewPose> SpreadViews(const BoardSpec& b, const Intrinsics& k, double distance,
                                  double reach) {
  const Eigen::Vector3d centre(0.5 * b.cols * b.square_m, 0.5 * b.rows * b.square_m, 0);
  std::vector<ViewPose> out;
  const double tilts[][3] = {{0, 0, 0},     {30, 0, 5},   {-30, 0, -5},  {0, 30, 10},
                             {0, -30, -10}, {20, 25, 0},  {-25, 20, 15}, {25, -20, -15},
                             {-20, -25, 0}, {10, 10, 90}, {35, 0, 0},    {0, 35, 0}};
  const double offs[][2] = {{0, 0},      {0.5, 0.5},  {-0.5, -0.5}, {0.5, -0.5},
                            {-0.5, 0.5}, {0.8, 0},    {-0.8, 0},    {0, 0.8},
                            {0, -0.8},   {0.3, -0.3}, {0.6, 0.6},   {-0.6, -0.6}};
  for (int i = 0; i < 12; ++i) {
    const Eigen::Vector2d px(k.cx + reach * offs[i][0] * 0.5 * k.width,
                             k.cy + reach * offs[i][1] * 0.5 * k.height);
    const Eigen::Vector3d at = Unproject(k, px) * distance;
    ViewPose v;
    v.r = Rot(tilts[i][0], tilts[i][1], tilts[i][2]);
    v.t = at - v.r * centre;
    out.push_back(v);
  }
  return out;
}

struct Synthetic {
  std::vector<Image> images;
  std::vector<std::string> names;
  std::vector<ViewPose> poses;
};

Synthetic Render(const BoardSpec& b, const Intrinsics& k, double distance, double reach,
                 double noise_dn, unsigned seed, int supersample = 3, size_t views = 12) {
  BoardRenderer renderer(b, k, supersample);
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.f, static_cast<float>(noise_dn));
  Synthetic s;
  s.poses = SpreadViews(b, k, distance, reach);
  s.poses.resize(std::min(views, s.poses.size()));
  for (size_t i = 0; i < s.poses.size(); ++i) {
    Image im = renderer.Render(s.poses[i].r, s.poses[i].t, 30.f, 220.f, 120.f);
    for (float& v : im.data) v = std::clamp(v + noise(rng), 0.f, 255.f);
    s.images.push_back(std::move(im));
    s.names.push_back("view" + std::to_string(i) + ".png");
  }
  return s;
}

// RMS distance between detected corners and where core Project puts the true corners: the
// corner localisation noise that all tolerances below derive from.
double CornerNoise(const Synthetic& s, const BoardSpec& b, const Intrinsics& k) {
  BoardRenderer renderer(b, k, 1, 16);
  double ss = 0;
  int n = 0;
  for (size_t i = 0; i < s.images.size(); ++i) {
    BoardDetection det;
    if (!DetectBoard(s.images[i], b, &det)) continue;
    // A chessboard's corner order may start from either end; take the closer of the two.
    const int nc = static_cast<int>(b.CornerPoints().size());
    double e_fwd = 0, e_rev = 0;
    for (size_t j = 0; j < det.ids.size(); ++j) {
      const auto p = renderer.CornerPixel(det.ids[j], s.poses[i].r, s.poses[i].t);
      const auto q = renderer.CornerPixel(nc - 1 - det.ids[j], s.poses[i].r, s.poses[i].t);
      e_fwd += (det.pixels[j] - *p).squaredNorm();
      e_rev += (det.pixels[j] - *q).squaredNorm();
    }
    ss += b.type == BoardSpec::Type::kCharuco ? e_fwd : std::min(e_fwd, e_rev);
    n += static_cast<int>(det.ids.size());
  }
  return n ? std::sqrt(ss / n) : -1;
}

// |estimate - truth| within 5 standard deviations of the estimate (plus a floor for the bias
// the renderer's 3x3 supersampling and the detector leave, expressed through the corner
// noise: a parameter whose one-pixel effect is J moves at most ~noise/J).
void ExpectRecovered(const IntrinsicsSummary& s, const Intrinsics& truth) {
  const Intrinsics& k = s.intrinsics;
  const bool fish = truth.projection == Projection::kFisheye;
  const std::vector<double> est =
      fish ? std::vector<double>{k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.k3, k.k4}
           : std::vector<double>{k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.k3, k.p1, k.p2};
  const std::vector<double> tru =
      fish ? std::vector<double>{truth.fx, truth.fy, truth.cx, truth.cy,
                                 truth.k1, truth.k2, truth.k3, truth.k4}
           : std::vector<double>{truth.fx, truth.fy, truth.cx, truth.cy, truth.k1,
                                 truth.k2, truth.k3, truth.p1, truth.p2};
  const char* names[] = {"fx", "fy", "cx", "cy", "k1", "k2", "k3", fish ? "k4" : "p1", "p2"};
  ASSERT_EQ(s.stddev.size(), est.size());
  for (size_t i = 0; i < est.size(); ++i) {
    EXPECT_TRUE(std::isfinite(est[i]));
    EXPECT_GT(s.stddev[i], 0) << names[i];
    EXPECT_LE(std::abs(est[i] - tru[i]), 5 * s.stddev[i])
        << names[i] << " estimate " << est[i] << " truth " << tru[i] << " sd " << s.stddev[i];
  }
  // The covariance is meaningful only if the estimate is tight: focal length to 1%.
  EXPECT_LT(s.stddev[0], 0.01 * truth.fx);
  EXPECT_LT(s.stddev[1], 0.01 * truth.fy);
}

TEST(BoardSpec, ParsesAndRejects) {
  const BoardSpec c = BoardSpec::Parse("chessboard:9x7:0.03");
  EXPECT_EQ(c.type, BoardSpec::Type::kChessboard);
  EXPECT_EQ(c.cols, 9);
  EXPECT_EQ(c.rows, 7);
  EXPECT_DOUBLE_EQ(c.square_m, 0.03);
  EXPECT_EQ(c.CornerPoints().size(), 8u * 6u);
  EXPECT_EQ(BoardSpec::Parse(c.ToString()).ToString(), c.ToString());
  for (const char* bad :
       {"chessboard:9x7", "chessboard:9:0.03", "chessboard:2x7:0.03", "chessboard:9x7:-1",
        "chessboard:9x7:abc", "square:9x7:0.03", "charuco:9x7:0.03:0.04:DICT_5X5_100",
        "charuco:9x7:0.03:0.02:NOPE", "charuco:20x20:0.03:0.02:DICT_4X4_50"}) {
    EXPECT_THROW(BoardSpec::Parse(bad), Error) << bad;
  }
  if (HaveCharucoSupport()) {
    const BoardSpec a = BoardSpec::Parse("charuco:7x5:0.04:0.03:5x5_100");
    EXPECT_EQ(a.dictionary, "DICT_5X5_100");
  }
}

// Our Brown-Conrady and fisheye models are OpenCV's exactly, once pixel centres are shifted
// by 0.5: project random points both ways.
TEST(CameraModels, MatchOpenCv) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  Intrinsics p;
  p.projection = Projection::kPinhole;
  p.width = 800, p.height = 600;
  p.fx = 700, p.fy = 690, p.cx = 401.3, p.cy = 297.8;
  p.k1 = -0.21, p.k2 = 0.07, p.k3 = -0.01, p.p1 = 0.0012, p.p2 = -0.0008;
  Intrinsics f = p;
  f.projection = Projection::kFisheye;
  f.fx = 250, f.fy = 251;
  f.k1 = 0.03, f.k2 = -0.01, f.k3 = 0.002, f.k4 = -0.0004, f.p1 = f.p2 = 0;
  std::vector<cv::Point3d> pts;
  for (int i = 0; i < 200; ++i) pts.emplace_back(0.6 * u(rng), 0.6 * u(rng), 1 + 0.5 * u(rng));
  const cv::Matx33d kp(p.fx, 0, p.cx - 0.5, 0, p.fy, p.cy - 0.5, 0, 0, 1);
  const cv::Matx33d kf(f.fx, 0, f.cx - 0.5, 0, f.fy, f.cy - 0.5, 0, 0, 1);
  std::vector<cv::Point2d> cp, cf;
  cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), kp,
                    std::vector<double>{p.k1, p.k2, p.p1, p.p2, p.k3}, cp);
  cv::fisheye::projectPoints(pts, cf, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), kf,
                             cv::Vec4d(f.k1, f.k2, f.k3, f.k4));
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector3d d(pts[i].x, pts[i].y, pts[i].z);
    const auto a = Project(p, d);
    const auto b = Project(f, d);
    ASSERT_TRUE(a && b);
    EXPECT_NEAR(a->x(), cp[i].x + 0.5, 1e-9);
    EXPECT_NEAR(a->y(), cp[i].y + 0.5, 1e-9);
    EXPECT_NEAR(b->x(), cf[i].x + 0.5, 1e-9);
    EXPECT_NEAR(b->y(), cf[i].y + 0.5, 1e-9);
  }
}

TEST(DrawBoard, CornersWhereDocumented) {
  // Detecting the flat drawing recovers corner (x, y) at ((x/s + 1) pps, (y/s + 1) pps).
  std::vector<BoardSpec> boards{BoardSpec::Parse("chessboard:9x7:0.03")};
  if (HaveCharucoSupport())
    boards.push_back(BoardSpec::Parse("charuco:7x5:0.04:0.03:DICT_5X5_100"));
  for (const BoardSpec& b : boards) {
    const int pps = 40;
    const Image im = DrawBoard(b, pps);
    EXPECT_EQ(im.width, (b.cols + 2) * pps);
    BoardDetection det;
    ASSERT_TRUE(DetectBoard(im, b, &det)) << b.ToString();
    const auto pts = b.CornerPoints();
    const int nc = static_cast<int>(pts.size());
    const bool charuco = b.type == BoardSpec::Type::kCharuco;
    double fwd = 0, rev = 0;
    for (size_t j = 0; j < det.ids.size(); ++j) {
      const Eigen::Vector3d& p = pts[det.ids[j]];
      const Eigen::Vector3d& q = pts[nc - 1 - det.ids[j]];
      const Eigen::Vector2d at_p = (p.head<2>() / b.square_m + Eigen::Vector2d(1, 1)) * pps;
      const Eigen::Vector2d at_q = (q.head<2>() / b.square_m + Eigen::Vector2d(1, 1)) * pps;
      fwd = std::max(fwd, (det.pixels[j] - at_p).norm());
      rev = std::max(rev, (det.pixels[j] - at_q).norm());
    }
    // ChArUco ids are unambiguous; a chessboard may be reported from either end. Sharp
    // (unantialiased) corners are localised to a few hundredths of a pixel.
    const double err = charuco ? fwd : std::min(fwd, rev);
    EXPECT_LT(err, 0.1) << b.ToString();
  }
}

class CalibrateModel : public ::testing::TestWithParam<std::tuple<Projection, std::string>> {};

TEST_P(CalibrateModel, RecoversKnownCamera) {
  const Projection model = std::get<0>(GetParam());
  const std::string board_text = std::get<1>(GetParam());
  if (board_text.rfind("charuco", 0) == 0 && !HaveCharucoSupport()) {
    GTEST_SKIP() << "this build has no OpenCV aruco module";
  }
  const BoardSpec board = BoardSpec::Parse(board_text);
  Intrinsics truth;
  double distance = 0, reach = 0.6;
  if (model == Projection::kPinhole) {
    truth = Intrinsics::PinholeFov(480, 360, 60);
    truth.fy = truth.fx * 1.004;
    truth.cx += 6.3;
    truth.cy -= 4.1;
    truth.k1 = -0.22, truth.k2 = 0.09, truth.k3 = 0, truth.p1 = 0.0012, truth.p2 = -0.0007;
    distance = 0.6;
  } else {
    truth = Intrinsics::FisheyeFov(480, 360, 150);
    truth.fy = truth.fx * 1.003;
    truth.cx -= 5.2;
    truth.cy += 3.7;
    truth.k1 = 0.03, truth.k2 = -0.012, truth.k3 = 0.002, truth.k4 = 0;
    distance = 0.3;
    reach = 0.4;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const Synthetic s = Render(board, truth, distance, reach, 1.5, 7);
  const double render_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double noise = CornerNoise(s, board, truth);
  ASSERT_GT(noise, 0) << "no board detected in the synthetic views";
  IntrinsicsOptions opt;
  opt.model = model;
  opt.board = board;
  opt.sector_fallback = false;  // keeps the test fast; the classic detector finds most views
  const IntrinsicsSummary sum = CalibrateIntrinsics(s.images, s.names, opt);
  // Without the slow sector detector the classic one misses the most curved fisheye views.
  EXPECT_GE(sum.views_used, model == Projection::kFisheye ? 5 : 10);
  // The fit's RMS cannot beat the corner noise by more than the parameters it absorbs, nor
  // exceed it by much when the model is right.
  EXPECT_LT(sum.rms_px, 1.5 * noise);
  EXPECT_GT(sum.rms_px, 0.5 * noise);
  ExpectRecovered(sum, truth);
  std::printf(
      "[ measured ] %s %s: %d views, corner noise %.4f px, fit RMS %.4f px, max %.4f px, "
      "fx err %.3f px (sd %.3f), cx err %.3f px (sd %.3f), k1 err %.5f (sd %.5f); "
      "render %.2f s, calibrate %.2f s\n",
      model == Projection::kPinhole ? "pinhole" : "fisheye", board_text.c_str(), sum.views_used,
      noise, sum.rms_px, sum.max_px, sum.intrinsics.fx - truth.fx, sum.stddev[0],
      sum.intrinsics.cx - truth.cx, sum.stddev[2], sum.intrinsics.k1 - truth.k1, sum.stddev[4],
      render_s, sum.seconds);
}

INSTANTIATE_TEST_SUITE_P(
    Boards, CalibrateModel,
    ::testing::Values(std::make_tuple(Projection::kPinhole, std::string("chessboard:9x7:0.03")),
                      std::make_tuple(Projection::kFisheye, std::string("chessboard:9x7:0.03")),
                      std::make_tuple(Projection::kPinhole,
                                      std::string("charuco:9x7:0.03:0.018:DICT_5X5_100"))));

TEST(Calibrate, LensFileRoundTrip) {
  const BoardSpec board = BoardSpec::Parse("chessboard:9x7:0.03");
  Intrinsics truth = Intrinsics::PinholeFov(480, 360, 60);
  truth.k1 = -0.1;
  const Synthetic s = Render(board, truth, 0.6, 0.6, 1.0, 11, 2, 6);
  IntrinsicsOptions opt;
  opt.board = board;
  const IntrinsicsSummary sum = CalibrateIntrinsics(s.images, s.names, opt);
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("rouen_intrinsics_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "lens.json").string();
  WriteLensFile(path, sum);
  const Intrinsics back = ReadLensFile(path).intrinsics;
  EXPECT_EQ(back.projection, Projection::kPinhole);
  EXPECT_EQ(back.width, 480);
  EXPECT_DOUBLE_EQ(back.fx, sum.intrinsics.fx);
  EXPECT_DOUBLE_EQ(back.k1, sum.intrinsics.k1);
  EXPECT_DOUBLE_EQ(back.p2, sum.intrinsics.p2);
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(path));
  EXPECT_DOUBLE_EQ(j["calibration"]["rms_px"].get<double>(), sum.rms_px);
  EXPECT_EQ(j["calibration"]["views"].get<int>(), sum.views_used);
  EXPECT_EQ(j["calibration"]["images"].size(), static_cast<size_t>(sum.views_used));
  std::filesystem::remove_all(dir);
}

TEST(Calibrate, BadInput) {
  const BoardSpec board = BoardSpec::Parse("chessboard:9x7:0.03");
  IntrinsicsOptions opt;
  opt.board = board;
  // No board anywhere: the message lists every image.
  std::vector<Image> blank(3, Image(320, 240, 1, PixelUnits::kDigital, 128.f));
  try {
    CalibrateIntrinsics(blank, {"a.png", "b.png", "c.png"}, opt);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("not found in any"), std::string::npos) << m;
    for (const char* n : {"a.png", "b.png", "c.png"}) EXPECT_NE(m.find(n), std::string::npos);
  }
  // Mixed sizes: names the odd image.
  std::vector<Image> mixed{Image(320, 240, 1, PixelUnits::kDigital, 128.f),
                           Image(321, 240, 1, PixelUnits::kDigital, 128.f)};
  try {
    CalibrateIntrinsics(mixed, {"a.png", "odd.png"}, opt);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("odd.png: size 321x240"), std::string::npos) << e.what();
  }
  // Too few views: two boards found, three needed.
  const Intrinsics k = Intrinsics::PinholeFov(480, 360, 60);
  Synthetic s = Render(board, k, 0.6, 0.6, 1.0, 5, 1, 2);
  std::vector<Image> two{s.images[0], s.images[1], blank[0]};
  two[2] = Image(480, 360, 1, PixelUnits::kDigital, 128.f);
  try {
    CalibrateIntrinsics(two, {"v0.png", "v1.png", "empty.png"}, opt);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("found in only 2 of 3"), std::string::npos) << m;
    EXPECT_NE(m.find("not found: empty.png"), std::string::npos) << m;
  }
  EXPECT_THROW(CalibrateIntrinsics({}, {}, opt), Error);
  EXPECT_THROW(CalibrateIntrinsicsFromFiles({"/nonexistent/board.png"}, opt), Error);
  opt.model = Projection::kEquirect;
  EXPECT_THROW(opt.Validate(), Error);
}

}  // namespace
}  // namespace rouen
