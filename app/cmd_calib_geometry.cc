// rouen calib intrinsics / rouen calib pose: lens calibration from board photographs and
// camera pose from clicked landmarks.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/commands.h"
#include "app/options.h"
#include "calib/intrinsics.h"
#include "calib/pose.h"
#include "core/error.h"
#include "core/files.h"
#include "core/lens.h"
#include "core/outputs.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

struct IntrinsicsArgs {
  std::string images, board, model = "pinhole", out;
  int min_views = 3;
};
struct PoseArgs {
  std::string points, lens, out;
  double threshold_px = 4.0;
};

bool IsImageName(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), ::tolower);
  for (const char* x : {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm", ".dng",
                        ".cr2", ".nef", ".arw"}) {
    if (e == x) return true;
  }
  return false;
}

// A folder of images (sorted by name) or a list file (first word of each line).
std::vector<std::string> ImagePaths(const std::string& where) {
  std::vector<std::string> out;
  std::error_code ec;
  if (fs::is_directory(where, ec)) {
    for (const auto& e : fs::directory_iterator(where)) {
      if (e.is_regular_file() && IsImageName(e.path())) out.push_back(e.path().string());
    }
    std::sort(out.begin(), out.end());
    if (out.empty()) throw Error(where + ": no image files (png, jpg, tif, ...) in the folder");
    return out;
  }
  if (!fs::exists(where, ec)) throw Error(where + ": no such folder or list file");
  const fs::path base = fs::path(where).parent_path();
  ForEachListLine(where, [&](const std::vector<std::string>& words, const std::string&) {
    fs::path p(words[0]);
    if (p.is_relative()) p = base / p;
    out.push_back(p.string());
  });
  return out;
}

void RunIntrinsics(const IntrinsicsArgs& a) {
  IntrinsicsOptions opt;
  if (a.model == "pinhole") {
    opt.model = Projection::kPinhole;
  } else if (a.model == "fisheye") {
    opt.model = Projection::kFisheye;
  } else {
    throw Error("--model must be pinhole or fisheye, not \"" + a.model + "\"");
  }
  opt.board = BoardSpec::Parse(a.board);
  opt.min_views = a.min_views;
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  const IntrinsicsSummary s = CalibrateIntrinsicsFromFiles(ImagePaths(a.images), opt);
  WriteLensFile(out, s);
  outputs.Commit();
  const Intrinsics& k = s.intrinsics;
  std::printf("%s: %s %dx%d, fx %.2f fy %.2f cx %.2f cy %.2f, k1 %.5f k2 %.5f k3 %.5f",
              a.out.c_str(), a.model.c_str(), k.width, k.height, k.fx, k.fy, k.cx, k.cy, k.k1, k.k2,
              k.k3);
  if (k.projection == Projection::kFisheye) {
    std::printf(" k4 %.5f\n", k.k4);
  } else {
    std::printf(" p1 %.5f p2 %.5f\n", k.p1, k.p2);
  }
  std::printf(
      "reprojection RMS %.3f px (max %.3f px) over %d corners in %d of %zu images, "
      "%.2f s\n",
      s.rms_px, s.max_px, s.corners_used, s.views_used, s.used.size() + s.not_found.size(),
      s.seconds);
  for (const std::string& n : s.not_found) std::printf("  board not found: %s\n", n.c_str());
}

void RunPose(const PoseArgs& a) {
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  const Intrinsics k = ReadLensFile(a.lens).intrinsics;
  const LandmarkFile lm = ReadLandmarks(a.points);
  PoseOptions opt;
  opt.inlier_threshold_px = a.threshold_px;
  PoseSummary s;
  try {
    s = EstimatePose(k, lm.points, opt);
  } catch (const Error& e) {
    throw Error(a.points + ": " + e.what());
  }
  WriteFileAtomic(out, PoseJson(s).dump(2) + "\n");
  outputs.Commit();
  const Eigen::Vector3d& c = s.pose.position;
  std::printf(
      "%s: camera at (%.3f, %.3f, %.3f) m; reprojection RMS %.3f px, max %.3f px, "
      "%d of %zu landmarks inliers, %.1f ms\n",
      a.out.c_str(), c.x(), c.y(), c.z(), s.rms_px, s.max_px, s.inliers, s.points.size(),
      1e3 * s.seconds);
  for (const PointReport& p : s.points) {
    if (p.behind) {
      std::printf("  %-20s behind the camera (outlier)\n", p.name.c_str());
    } else {
      std::printf("  %-20s %8.3f px%s\n", p.name.c_str(), p.error_px,
                  p.inlier ? "" : "  (outlier)");
    }
  }
}

}  // namespace

void RegisterCalibGeometry(CLI::App* calib) {
  auto ia = std::make_shared<IntrinsicsArgs>();
  CLI::App* c = calib->add_subcommand(
      "intrinsics", "Calibrate a lens from photographs of a chessboard or ChArUco board");
  c->footer(
      "Boards count squares: chessboard:COLSxROWS:SQUARE_M (a 9x7 board has 8x6 inner\n"
      "corners) or charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT (DICT e.g. DICT_5X5_100).\n"
      "Models: pinhole (Brown-Conrady k1 k2 k3 p1 p2) or fisheye (equidistant, k1..k4).\n"
      "--images is a folder of images or a list file (one path per line, relative to it).\n"
      "Writes a rig lens file (rigs/lenses/*.json) with the reprojection RMS.\n"
      "Example: rouen calib intrinsics --images shots/ --board chessboard:9x7:0.025 \\\n"
      "           --model pinhole --out rigs/lenses/mycam.json");
  c->add_option("--images", ia->images, "Folder of board photographs, or a list file")->required();
  c->add_option("--board", ia->board,
                "Board: chessboard:COLSxROWS:SQUARE_M or "
                "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT")
      ->required();
  c->add_option("--model", ia->model, "pinhole or fisheye")->capture_default_str();
  c->add_option("--min-views", ia->min_views, "Images in which the board must be found (>= 2)")
      ->check(CLI::Range(2, 10000))
      ->capture_default_str();
  c->add_option("--out", ia->out, "Lens JSON to write")->required();
  c->callback([ia] { RunIntrinsics(*ia); });

  auto pa = std::make_shared<PoseArgs>();
  CLI::App* p = calib->add_subcommand(
      "pose", "Camera pose from clicked 2D-3D landmarks (PnP + RANSAC, Ceres refinement)");
  p->footer(
      "PTS.json: {\"image\": \"photo.jpg\", \"model\": \"building.obj\", \"points\": [\n"
      "  {\"name\": \"NW corner\", \"pixel\": [u, v], \"world\": [x, y, z]},\n"
      "  {\"name\": \"door\", \"pixel\": [u, v], \"vertex\": 17}]}\n"
      "pixels: x right, y down, pixel centres at integer + 0.5; world: site ENU metres;\n"
      "vertex: 0-based OBJ vertex of \"model\" (path relative to PTS.json). At least 4 points,\n"
      "not all on one line. Writes the pose (session format) with per-point errors.\n"
      "Example: rouen calib pose --points west.json --lens rigs/lenses/mycam.json --out pose.json");
  p->add_option("--points", pa->points, "Landmark JSON")->required();
  p->add_option("--lens", pa->lens, "Lens JSON (rouen calib intrinsics or rigs/lenses)")
      ->required();
  p->add_option("--out", pa->out, "Pose JSON to write")->required();
  p->add_option("--threshold", pa->threshold_px, "Inlier threshold, pixels")
      ->check(Positive())
      ->capture_default_str();
  p->callback([pa] { RunPose(*pa); });
}

}  // namespace rouen
