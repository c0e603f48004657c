// Camera intrinsics from photographs of a calibration board (chessboard or ChArUco), through
// OpenCV's detectors and calibrators, mapped exactly onto core/camera.h's models:
//   pinhole: OpenCV's standard model, distortion (k1, k2, p1, p2, k3) -> our k1, k2, p1, p2, k3;
//   fisheye: OpenCV's cv::fisheye model (theta_d = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 +
//            k4 t^8), zero skew) -> our kFisheye with the same k1..k4.
// Pixel coordinates: OpenCV puts pixel centres at integers, rouen at integer + 0.5; detected
// corners are shifted by +0.5 before calibration, so cx, cy come out in rouen's convention.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

// A printed calibration target. Sizes count SQUARES (cols along the board's x axis, rows
// along y), so a chessboard "9x6" has 8x5 inner corners. Board frame (metres): origin at the
// outer corner of square (0, 0), x along cols, y along rows (down in DrawBoard's image), z
// into the board, z = 0 on it. Square (0, 0) is black on a chessboard; on a ChArUco board
// the layout is OpenCV 4.6's (markers in the white squares, ids row by row).
struct BoardSpec {
  enum class Type { kChessboard, kCharuco };
  Type type = Type::kChessboard;
  int cols = 0, rows = 0;
  double square_m = 0;     // side of one square
  double marker_m = 0;     // ChArUco: side of one marker (< square_m)
  std::string dictionary;  // ChArUco: OpenCV dictionary, e.g. "DICT_5X5_100"

  // "chessboard:COLSxROWS:SQUARE_M" or "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT".
  static BoardSpec Parse(const std::string& text);
  std::string ToString() const;
  // Throws rouen::Error when sizes are not positive, the marker does not fit in a square,
  // the dictionary is unknown or too small for the board, or ChArUco support is missing.
  void Validate() const;
  // Board-frame positions of the corners a detector can report, indexed by corner id
  // (row-major over the (cols-1) x (rows-1) inner corners).
  std::vector<Eigen::Vector3d> CornerPoints() const;
};

// True when this build has OpenCV's aruco module (ChArUco boards).
bool HaveCharucoSupport();

// A printable image of the board: `pixels_per_square` per square, a white margin of one
// square around it; one channel, digital numbers 0 (black) .. 255 (white). Board-frame point
// (x, y) maps to image pixel ((x / square_m + 1) * pixels_per_square, same for y).
Image DrawBoard(const BoardSpec& board, int pixels_per_square);

// Synthetic photographs of the board through a known camera (tests, and checking a lens
// file): each pixel averages supersample x supersample rays from core Unproject, intersected
// with the board plane and looked up in DrawBoard's image (nearest texel, so square edges are
// exact). Off-board pixels get `background`. Output: one channel, kDigital, black = 0 and
// white = 255 before `dark`/`bright` remapping.
class BoardRenderer {
 public:
  BoardRenderer(const BoardSpec& board, const Intrinsics& camera, int supersample,
                int pixels_per_square = 64);
  // camera_from_board: x_cam = rotation * x_board + translation (metres).
  Image Render(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation,
               float dark = 0.f, float bright = 255.f, float background = 128.f) const;
  // Where a board corner lands (core Project), or nothing when it does not project.
  std::optional<Eigen::Vector2d> CornerPixel(int id, const Eigen::Matrix3d& rotation,
                                             const Eigen::Vector3d& translation) const;

 private:
  BoardSpec board_;
  Intrinsics camera_;
  int supersample_, pps_;
  Image texture_;
  std::vector<Eigen::Vector3f> rays_;  // per pixel, supersample^2 unit rays
};

// Corners found in one image: ids index BoardSpec::CornerPoints(); pixels in rouen's
// convention (pixel centres at integer + 0.5).
struct BoardDetection {
  std::vector<int> ids;
  std::vector<Eigen::Vector2d> pixels;
};
// Detects the board with sub-pixel corners. Accepts 1-, 3- or 4-channel kDigital images.
// Returns false when the board is not found (or, ChArUco, fewer than 6 corners are seen).
// Chessboards: OpenCV's classic detector, then (sector_fallback) the slower sector-based one,
// which copes better with strong distortion. Corners are refined by cv::cornerSubPix (for
// ChArUco too: OpenCV 4.6's own interpolation is ~0.5 px off on sharp images).
bool DetectBoard(const Image& image, const BoardSpec& board, BoardDetection* out,
                 bool sector_fallback = true);

struct IntrinsicsOptions {
  Projection model = Projection::kPinhole;  // kPinhole or kFisheye
  BoardSpec board;
  int min_views = 3;                // images in which the board must be found
  bool estimate_k3 = true;          // pinhole k3 (turn off for narrow lenses and few views)
  bool estimate_tangential = true;  // pinhole p1, p2
  bool sector_fallback = true;      // see DetectBoard
  void Validate() const;            // throws rouen::Error
};

struct IntrinsicsSummary {
  Intrinsics intrinsics;
  double rms_px = 0;  // reprojection RMS over all corners, pixels (through core Project)
  double max_px = 0;  // largest corner reprojection error, pixels
  int views_used = 0;
  int corners_used = 0;
  std::vector<std::string> used;       // names of images in which the board was found
  std::vector<std::string> not_found;  // names of images without a detectable board
  std::vector<double> view_rms_px;     // per used view
  // One-sigma standard deviations from the Gauss-Newton covariance sigma^2 (J^T J)^-1 with
  // sigma^2 = residual sum of squares / degrees of freedom; order fx, fy, cx, cy, then the
  // model's distortion terms (pinhole k1, k2, k3, p1, p2; fisheye k1, k2, k3, k4).
  std::vector<double> stddev;
  double seconds = 0;
  std::string board;  // BoardSpec::ToString()
};

// Calibrates from in-memory images (names are used in messages). Throws rouen::Error for
// mixed image sizes (naming the image), no board found in any image (listing them all) or
// fewer than min_views views, and when the calibration fails or yields non-finite values.
IntrinsicsSummary CalibrateIntrinsics(const std::vector<Image>& images,
                                      const std::vector<std::string>& names,
                                      const IntrinsicsOptions& options);
// Loads each path with ReadImage (8/16-bit photographs), then as above.
IntrinsicsSummary CalibrateIntrinsicsFromFiles(const std::vector<std::string>& paths,
                                               const IntrinsicsOptions& options);

// A rig lens file (rigs/lenses/*.json): the core/camera.h Intrinsics keys, plus a
// "calibration" object {rms_px, max_px, views, corners, board, stddev, images}, which
// readers of lens files ignore
// (core/lens.h ReadLensFile reads them).
nlohmann::json LensJson(const IntrinsicsSummary& summary);
void WriteLensFile(const std::string& path, const IntrinsicsSummary& summary);

}  // namespace rouen
