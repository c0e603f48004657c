#include "calib/intrinsics.h"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#ifdef ROUEN_HAVE_ARUCO
#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#endif

#include "core/error.h"
#include "core/files.h"
#include "core/text.h"

namespace rouen {
namespace {

constexpr int kMinCharucoCorners = 6;

const std::map<std::string, int>& DictionaryIds() {
  // Values of cv::aruco::PREDEFINED_DICTIONARY_NAME (stable since OpenCV 3.x).
  static const std::map<std::string, int> ids = {
      {"DICT_4X4_50", 0},         {"DICT_4X4_100", 1},         {"DICT_4X4_250", 2},
      {"DICT_4X4_1000", 3},       {"DICT_5X5_50", 4},          {"DICT_5X5_100", 5},
      {"DICT_5X5_250", 6},        {"DICT_5X5_1000", 7},        {"DICT_6X6_50", 8},
      {"DICT_6X6_100", 9},        {"DICT_6X6_250", 10},        {"DICT_6X6_1000", 11},
      {"DICT_7X7_50", 12},        {"DICT_7X7_100", 13},        {"DICT_7X7_250", 14},
      {"DICT_7X7_1000", 15},      {"DICT_ARUCO_ORIGINAL", 16}, {"DICT_APRILTAG_16h5", 17},
      {"DICT_APRILTAG_25h9", 18}, {"DICT_APRILTAG_36h10", 19}, {"DICT_APRILTAG_36h11", 20}};
  return ids;
}

int DictionarySize(const std::string& name) {
  if (name == "DICT_ARUCO_ORIGINAL") return 1024;
  if (name == "DICT_APRILTAG_16h5") return 30;
  if (name == "DICT_APRILTAG_25h9") return 35;
  if (name == "DICT_APRILTAG_36h10") return 2320;
  if (name == "DICT_APRILTAG_36h11") return 587;
  return std::stoi(name.substr(name.rfind('_') + 1));
}

std::string CanonicalDictionary(std::string name) {
  if (name.rfind("DICT_", 0) != 0) name = "DICT_" + name;
  for (const auto& [key, id] : DictionaryIds()) {
    std::string a = key, b = name;
    std::transform(a.begin(), a.end(), a.begin(), ::toupper);
    std::transform(b.begin(), b.end(), b.begin(), ::toupper);
    if (a == b) return key;
  }
  return name;
}

double ParsePositive(const std::string& s, const std::string& what, const std::string& spec) {
  double v = 0;
  if (!ParseDecimal(s, &v))
    throw Error("board \"" + spec + "\": " + what + " '" + s + "' is not a number");
  return v;
}

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream in(s);
  while (std::getline(in, cur, sep)) out.push_back(cur);
  return out;
}

// 8-bit grey copy of a kDigital image for OpenCV.
cv::Mat ToGray8(const Image& im) {
  cv::Mat g(im.height, im.width, CV_8UC1);
  const int c = im.channels;
  for (int y = 0; y < im.height; ++y) {
    uint8_t* row = g.ptr<uint8_t>(y);
    for (int x = 0; x < im.width; ++x) {
      double v = 0;
      if (c >= 3) {
        v = 0.299 * im.at(x, y, 0) + 0.587 * im.at(x, y, 1) + 0.114 * im.at(x, y, 2);
      } else {
        v = im.at(x, y, 0);
      }
      if (!std::isfinite(v)) v = 0;
      row[x] = static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L));
    }
  }
  return g;
}

// Sub-pixel corner refinement with a search window of a third of the smallest spacing
// between detected neighbouring corners (ids row-major over the inner corners).
void RefineCorners(const cv::Mat& gray, const BoardSpec& board, const std::vector<int>& ids,
                   std::vector<cv::Point2f>* corners) {
  const int nx = board.cols - 1;
  double spacing = 1e9;
  for (size_t a = 0; a < ids.size(); ++a) {
    for (size_t b = 0; b < ids.size(); ++b) {
      const bool right = ids[b] == ids[a] + 1 && ids[a] % nx != nx - 1;
      const bool below = ids[b] == ids[a] + nx;
      if (!right && !below) continue;
      const cv::Point2f d = (*corners)[b] - (*corners)[a];
      spacing = std::min(spacing, static_cast<double>(std::hypot(d.x, d.y)));
    }
  }
  if (spacing > 1e8) return;
  double half = spacing / 3;
  if (board.type == BoardSpec::Type::kCharuco) {
    // Stay inside the white margin between a corner and the markers next to it.
    half = std::min(half, 0.9 * spacing * (board.square_m - board.marker_m) / (2 * board.square_m));
  }
  const int win = std::clamp(static_cast<int>(half), 2, 11);
  cv::cornerSubPix(gray, *corners, cv::Size(win, win), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
}

#ifdef ROUEN_HAVE_ARUCO
cv::Ptr<cv::aruco::CharucoBoard> MakeCharuco(const BoardSpec& b) {
  auto dict = cv::aruco::getPredefinedDictionary(DictionaryIds().at(b.dictionary));
  return cv::aruco::CharucoBoard::create(b.cols, b.rows, static_cast<float>(b.square_m),
                                         static_cast<float>(b.marker_m), dict);
}
#endif

// Number of distortion parameters of a model, in IntrinsicsSummary::stddev order.
int NumDistortion(Projection p) { return p == Projection::kFisheye ? 4 : 5; }

// Parameter vector <-> Intrinsics: fx, fy, cx, cy, then k1, k2, k3, p1, p2 (pinhole) or
// k1..k4 (fisheye).
Eigen::VectorXd PackIntrinsics(const Intrinsics& k) {
  Eigen::VectorXd v(4 + NumDistortion(k.projection));
  v.head<4>() << k.fx, k.fy, k.cx, k.cy;
  if (k.projection == Projection::kFisheye) {
    v.tail<4>() << k.k1, k.k2, k.k3, k.k4;
  } else {
    v.tail<5>() << k.k1, k.k2, k.k3, k.p1, k.p2;
  }
  return v;
}

Intrinsics UnpackIntrinsics(const Intrinsics& base, const Eigen::VectorXd& v) {
  Intrinsics k = base;
  k.fx = v[0], k.fy = v[1], k.cx = v[2], k.cy = v[3];
  if (k.projection == Projection::kFisheye) {
    k.k1 = v[4], k.k2 = v[5], k.k3 = v[6], k.k4 = v[7];
  } else {
    k.k1 = v[4], k.k2 = v[5], k.k3 = v[6], k.p1 = v[7], k.p2 = v[8];
  }
  return k;
}

struct View {
  std::vector<Eigen::Vector3d> board;              // board-frame points
  std::vector<Eigen::Vector2d> pixels;             // rouen pixel convention
  Eigen::Vector3d rvec = Eigen::Vector3d::Zero();  // camera-from-board: x_cam = R(rvec) x + tvec
  Eigen::Vector3d tvec = Eigen::Vector3d::Zero();
};

Eigen::Matrix3d RotationFromVector(const Eigen::Vector3d& r) {
  const double a = r.norm();
  if (a < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, r / a).toRotationMatrix();
}

// Reprojection residuals of every corner through core Project; a point that does not project
// gets a large residual (never NaN).
void Residuals(const Intrinsics& k, const std::vector<View>& views, Eigen::VectorXd* res) {
  int n = 0;
  for (const View& v : views) n += static_cast<int>(v.board.size());
  res->resize(2 * n);
  int i = 0;
  for (const View& v : views) {
    const Eigen::Matrix3d r = RotationFromVector(v.rvec);
    for (size_t j = 0; j < v.board.size(); ++j, ++i) {
      const auto p = Project(k, r * v.board[j] + v.tvec);
      if (p && p->allFinite()) {
        (*res)[2 * i] = p->x() - v.pixels[j].x();
        (*res)[2 * i + 1] = p->y() - v.pixels[j].y();
      } else {
        (*res)[2 * i] = (*res)[2 * i + 1] = 1e6;
      }
    }
  }
}

// Standard deviations of the intrinsic parameters from sigma^2 (J^T J)^-1 over intrinsics and
// all view poses, J by central differences through core Project.
std::vector<double> IntrinsicStddev(const Intrinsics& k, std::vector<View> views,
                                    const Eigen::VectorXd& res0) {
  const Eigen::VectorXd kp = PackIntrinsics(k);
  const int ni = static_cast<int>(kp.size());
  const int np = ni + 6 * static_cast<int>(views.size());
  const int m = static_cast<int>(res0.size());
  if (m <= np) return std::vector<double>(ni, 0.0);
  Eigen::MatrixXd jac = Eigen::MatrixXd::Zero(m, np);
  Eigen::VectorXd rp, rm;
  for (int p = 0; p < ni; ++p) {
    const double h = 1e-6 * std::max(1.0, std::abs(kp[p]));
    Eigen::VectorXd a = kp, b = kp;
    a[p] += h;
    b[p] -= h;
    Residuals(UnpackIntrinsics(k, a), views, &rp);
    Residuals(UnpackIntrinsics(k, b), views, &rm);
    jac.col(p) = (rp - rm) / (2 * h);
  }
  int row = 0;
  for (size_t vi = 0; vi < views.size(); ++vi) {
    std::vector<View> one{views[vi]};
    const int rows = 2 * static_cast<int>(views[vi].board.size());
    for (int p = 0; p < 6; ++p) {
      View a = views[vi], b = views[vi];
      Eigen::Vector3d& pa = p < 3 ? a.rvec : a.tvec;
      Eigen::Vector3d& pb = p < 3 ? b.rvec : b.tvec;
      const double h = 1e-7 * std::max(1.0, std::abs(pa[p % 3]));
      pa[p % 3] += h;
      pb[p % 3] -= h;
      one[0] = a;
      Residuals(k, one, &rp);
      one[0] = b;
      Residuals(k, one, &rm);
      jac.block(row, ni + 6 * static_cast<int>(vi) + p, rows, 1) = (rp - rm) / (2 * h);
    }
    row += rows;
  }
  const double sigma2 = res0.squaredNorm() / (m - np);
  const Eigen::MatrixXd jtj = jac.transpose() * jac;
  const Eigen::MatrixXd cov = jtj.ldlt().solve(Eigen::MatrixXd::Identity(np, np)) * sigma2;
  std::vector<double> sd(ni);
  for (int p = 0; p < ni; ++p) {
    const double v = cov(p, p);
    sd[p] = std::isfinite(v) && v > 0 ? std::sqrt(v) : 0.0;
  }
  return sd;
}

}  // namespace

bool HaveCharucoSupport() {
#ifdef ROUEN_HAVE_ARUCO
  return true;
#else
  return false;
#endif
}

BoardSpec BoardSpec::Parse(const std::string& text) {
  const std::vector<std::string> f = Split(text, ':');
  BoardSpec b;
  const std::string usage =
      "expected chessboard:COLSxROWS:SQUARE_M or charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT";
  if (f.empty()) throw Error("board \"" + text + "\": " + usage);
  if (f[0] == "chessboard" && f.size() == 3) {
    b.type = Type::kChessboard;
  } else if (f[0] == "charuco" && f.size() == 5) {
    b.type = Type::kCharuco;
  } else {
    throw Error("board \"" + text + "\": " + usage);
  }
  const size_t x = f[1].find_first_of("xX");
  if (x == std::string::npos) throw Error("board \"" + text + "\": size must be COLSxROWS");
  const double cols = ParsePositive(f[1].substr(0, x), "column count", text);
  const double rows = ParsePositive(f[1].substr(x + 1), "row count", text);
  if (cols != std::floor(cols) || rows != std::floor(rows) || cols > 1000 || rows > 1000) {
    throw Error("board \"" + text + "\": COLSxROWS must be whole numbers of squares");
  }
  b.cols = static_cast<int>(cols);
  b.rows = static_cast<int>(rows);
  b.square_m = ParsePositive(f[2], "square size", text);
  if (b.type == Type::kCharuco) {
    b.marker_m = ParsePositive(f[3], "marker size", text);
    b.dictionary = CanonicalDictionary(f[4]);
  }
  b.Validate();
  return b;
}

std::string BoardSpec::ToString() const {
  std::ostringstream s;
  s.precision(10);
  s << (type == Type::kCharuco ? "charuco:" : "chessboard:") << cols << "x" << rows << ":"
    << square_m;
  if (type == Type::kCharuco) s << ":" << marker_m << ":" << dictionary;
  return s.str();
}

void BoardSpec::Validate() const {
  const std::string what = "board \"" + ToString() + "\": ";
  if (cols < 3 || rows < 3) {
    throw Error(what + "needs at least 3x3 squares (2x2 inner corners), got " +
                std::to_string(cols) + "x" + std::to_string(rows));
  }
  if (!(square_m > 0) || !std::isfinite(square_m)) {
    throw Error(what + "square size must be positive metres");
  }
  if (type == Type::kChessboard) return;
  if (!(marker_m > 0) || !(marker_m < square_m)) {
    throw Error(what + "marker size must be positive and smaller than the square");
  }
  if (!DictionaryIds().count(dictionary)) {
    std::string names;
    for (const auto& [name, id] : DictionaryIds()) names += (names.empty() ? "" : ", ") + name;
    throw Error(what + "unknown dictionary \"" + dictionary + "\" (one of " + names + ")");
  }
  const int markers = cols * rows / 2;
  if (markers > DictionarySize(dictionary)) {
    throw Error(what + "needs " + std::to_string(markers) + " markers but " + dictionary + " has " +
                std::to_string(DictionarySize(dictionary)));
  }
  if (!HaveCharucoSupport()) {
    throw Error(what + "ChArUco boards need OpenCV's aruco module, absent from this build");
  }
}

std::vector<Eigen::Vector3d> BoardSpec::CornerPoints() const {
  std::vector<Eigen::Vector3d> p;
  for (int j = 1; j < rows; ++j) {
    for (int i = 1; i < cols; ++i) p.emplace_back(i * square_m, j * square_m, 0.0);
  }
  return p;
}

Image DrawBoard(const BoardSpec& board, int pixels_per_square) {
  board.Validate();
  if (pixels_per_square < 8 || pixels_per_square > 1000) {
    throw Error("DrawBoard: pixels_per_square must be in 8..1000");
  }
  const int s = pixels_per_square;
  const int w = (board.cols + 2) * s, h = (board.rows + 2) * s;
  Image im(w, h, 1, PixelUnits::kDigital, 255.f);
  if (board.type == BoardSpec::Type::kChessboard) {
    for (int y = s; y < h - s; ++y) {
      for (int x = s; x < w - s; ++x) {
        const int i = x / s - 1, j = y / s - 1;
        if ((i + j) % 2 == 0) im.at(x, y) = 0.f;
      }
    }
    return im;
  }
#ifdef ROUEN_HAVE_ARUCO
  cv::Mat drawn;
  MakeCharuco(board)->draw(cv::Size(w, h), drawn, s, 1);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) im.at(x, y) = drawn.at<uint8_t>(y, x);
  }
#endif
  return im;
}

bool DetectBoard(const Image& image, const BoardSpec& board, BoardDetection* out,
                 bool sector_fallback) {
  board.Validate();
  if (image.empty()) return false;
  out->ids.clear();
  out->pixels.clear();
  const cv::Mat gray = ToGray8(image);
  if (board.type == BoardSpec::Type::kChessboard) {
    const cv::Size pattern(board.cols - 1, board.rows - 1);
    std::vector<cv::Point2f> corners;
    bool found = cv::findChessboardCorners(
        gray, pattern, corners,
        cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK);
    if (!found && sector_fallback) {
      // The sector-based detector copes better with strong (fisheye) distortion (but is slow).
      found = cv::findChessboardCornersSB(gray, pattern, corners, cv::CALIB_CB_ACCURACY);
    }
    if (!found) return false;
    std::vector<int> ids(corners.size());
    for (size_t i = 0; i < ids.size(); ++i) ids[i] = static_cast<int>(i);
    RefineCorners(gray, board, ids, &corners);
    for (size_t i = 0; i < corners.size(); ++i) {
      out->ids.push_back(static_cast<int>(i));
      out->pixels.emplace_back(corners[i].x + 0.5, corners[i].y + 0.5);
    }
    return true;
  }
#ifdef ROUEN_HAVE_ARUCO
  const auto cb = MakeCharuco(board);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  auto params = cv::aruco::DetectorParameters::create();
  cv::aruco::detectMarkers(gray, cb->dictionary, marker_corners, marker_ids, params);
  if (marker_ids.empty()) return false;
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, cb, corners, ids);
  if (static_cast<int>(ids.size()) < kMinCharucoCorners) return false;
  RefineCorners(gray, board, ids, &corners);
  // OpenCV's ChArUco corner ids are row-major with y down the drawn board, as ours.
  for (size_t n = 0; n < ids.size(); ++n) {
    out->ids.push_back(ids[n]);
    out->pixels.emplace_back(corners[n].x + 0.5, corners[n].y + 0.5);
  }
  return true;
#else
  return false;
#endif
}

void IntrinsicsOptions::Validate() const {
  if (model != Projection::kPinhole && model != Projection::kFisheye) {
    throw Error("intrinsics calibration: model must be pinhole or fisheye");
  }
  board.Validate();
  if (min_views < 2) throw Error("intrinsics calibration: min_views must be at least 2");
}

IntrinsicsSummary CalibrateIntrinsics(const std::vector<Image>& images,
                                      const std::vector<std::string>& names,
                                      const IntrinsicsOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  options.Validate();
  if (images.size() != names.size()) throw Error("intrinsics calibration: one name per image");
  if (images.empty()) throw Error("intrinsics calibration: no images given");
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].empty()) throw Error(names[i] + ": empty image");
    if (images[i].width != images[0].width || images[i].height != images[0].height) {
      throw Error(names[i] + ": size " + std::to_string(images[i].width) + "x" +
                  std::to_string(images[i].height) + " differs from " + names[0] + " (" +
                  std::to_string(images[0].width) + "x" + std::to_string(images[0].height) +
                  "); all calibration images must come from one camera mode");
    }
  }
  IntrinsicsSummary sum;
  sum.board = options.board.ToString();
  const std::vector<Eigen::Vector3d> corner_points = options.board.CornerPoints();
  std::vector<View> views;
  for (size_t i = 0; i < images.size(); ++i) {
    BoardDetection det;
    if (!DetectBoard(images[i], options.board, &det, options.sector_fallback)) {
      sum.not_found.push_back(names[i]);
      continue;
    }
    View v;
    for (size_t n = 0; n < det.ids.size(); ++n) {
      v.board.push_back(corner_points[det.ids[n]]);
      v.pixels.push_back(det.pixels[n]);
    }
    views.push_back(std::move(v));
    sum.used.push_back(names[i]);
  }
  if (views.empty()) {
    std::string list;
    for (const std::string& n : sum.not_found) list += "\n  " + n;
    throw Error("board " + sum.board + " not found in any of the " + std::to_string(images.size()) +
                " images:" + list);
  }
  if (static_cast<int>(views.size()) < options.min_views) {
    std::string list;
    for (const std::string& n : sum.not_found) list += "\n  not found: " + n;
    throw Error("board " + sum.board + " found in only " + std::to_string(views.size()) + " of " +
                std::to_string(images.size()) + " images; at least " +
                std::to_string(options.min_views) + " views are needed" + list);
  }

  const int w = images[0].width, h = images[0].height;
  Intrinsics k;
  k.projection = options.model;
  k.width = w;
  k.height = h;
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    if (options.model == Projection::kPinhole) {
      std::vector<std::vector<cv::Point3f>> obj(views.size());
      std::vector<std::vector<cv::Point2f>> img(views.size());
      for (size_t v = 0; v < views.size(); ++v) {
        for (size_t n = 0; n < views[v].board.size(); ++n) {
          const Eigen::Vector3d& p = views[v].board[n];
          obj[v].emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), 0.f);
          img[v].emplace_back(static_cast<float>(views[v].pixels[n].x()),
                              static_cast<float>(views[v].pixels[n].y()));
        }
      }
      int flags = 0;
      if (!options.estimate_k3) flags |= cv::CALIB_FIX_K3;
      if (!options.estimate_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
      cv::Mat cam, dist;
      cv::calibrateCamera(
          obj, img, cv::Size(w, h), cam, dist, rvecs, tvecs, flags,
          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
      cam.convertTo(cam, CV_64F);
      dist.convertTo(dist, CV_64F);
      const double* d = dist.ptr<double>();
      k.fx = cam.at<double>(0, 0);
      k.fy = cam.at<double>(1, 1);
      k.cx = cam.at<double>(0, 2);
      k.cy = cam.at<double>(1, 2);
      // OpenCV order: k1, k2, p1, p2, k3.
      k.k1 = d[0], k.k2 = d[1], k.p1 = d[2], k.p2 = d[3];
      k.k3 = dist.total() > 4 ? d[4] : 0.0;
    } else {
      std::vector<std::vector<cv::Point3d>> obj(views.size());
      std::vector<std::vector<cv::Point2d>> img(views.size());
      for (size_t v = 0; v < views.size(); ++v) {
        for (size_t n = 0; n < views[v].board.size(); ++n) {
          const Eigen::Vector3d& p = views[v].board[n];
          obj[v].emplace_back(p.x(), p.y(), 0.0);
          img[v].emplace_back(views[v].pixels[n].x(), views[v].pixels[n].y());
        }
      }
      cv::Matx33d cam;
      cv::Vec4d dist;
      cv::fisheye::calibrate(
          obj, img, cv::Size(w, h), cam, dist, rvecs, tvecs,
          cv::fisheye::CALIB_RECOMPUTE_EXTRINSIC | cv::fisheye::CALIB_FIX_SKEW,
          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-12));
      k.fx = cam(0, 0);
      k.fy = cam(1, 1);
      k.cx = cam(0, 2);
      k.cy = cam(1, 2);
      k.k1 = dist[0], k.k2 = dist[1], k.k3 = dist[2], k.k4 = dist[3];
    }
  } catch (const cv::Exception& e) {
    throw Error("intrinsics calibration (" + sum.board + ", " + std::to_string(views.size()) +
                " views) failed in OpenCV: " + e.msg);
  }
  try {
    k.Validate();
  } catch (const Error& e) {
    throw Error(std::string("intrinsics calibration gave an invalid camera: ") + e.what());
  }
  for (size_t v = 0; v < views.size(); ++v) {
    cv::Mat r, t;
    rvecs[v].convertTo(r, CV_64F);
    tvecs[v].convertTo(t, CV_64F);
    views[v].rvec = Eigen::Vector3d(r.ptr<double>()[0], r.ptr<double>()[1], r.ptr<double>()[2]);
    views[v].tvec = Eigen::Vector3d(t.ptr<double>()[0], t.ptr<double>()[1], t.ptr<double>()[2]);
  }

  Eigen::VectorXd res;
  Residuals(k, views, &res);
  if (!res.allFinite()) throw Error("intrinsics calibration: non-finite reprojection errors");
  sum.intrinsics = k;
  sum.views_used = static_cast<int>(views.size());
  sum.corners_used = static_cast<int>(res.size() / 2);
  sum.rms_px = std::sqrt(res.squaredNorm() / sum.corners_used);
  int at = 0;
  for (const View& v : views) {
    const int n = static_cast<int>(v.board.size());
    double ss = 0;
    for (int j = 0; j < n; ++j) {
      const double e = std::hypot(res[2 * (at + j)], res[2 * (at + j) + 1]);
      ss += e * e;
      sum.max_px = std::max(sum.max_px, e);
    }
    sum.view_rms_px.push_back(std::sqrt(ss / n));
    at += n;
  }
  sum.stddev = IntrinsicStddev(k, views, res);
  sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

IntrinsicsSummary CalibrateIntrinsicsFromFiles(const std::vector<std::string>& paths,
                                               const IntrinsicsOptions& options) {
  options.Validate();
  std::vector<Image> images;
  for (const std::string& p : paths) {
    Image im = ReadImage(p);
    if (im.units != PixelUnits::kDigital) {
      throw Error(p + ": expected an 8- or 16-bit photograph of the board, got a float image");
    }
    images.push_back(std::move(im));
  }
  return CalibrateIntrinsics(images, paths, options);
}

nlohmann::json LensJson(const IntrinsicsSummary& s) {
  nlohmann::json j = s.intrinsics;
  if (s.intrinsics.projection == Projection::kFisheye) {
    j.erase("p1");
    j.erase("p2");
  } else {
    j.erase("k4");
  }
  nlohmann::json images = nlohmann::json::array();
  for (const std::string& n : s.used) images.push_back(n);
  std::vector<std::string> names =
      s.intrinsics.projection == Projection::kFisheye
          ? std::vector<std::string>{"fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"}
          : std::vector<std::string>{"fx", "fy", "cx", "cy", "k1", "k2", "k3", "p1", "p2"};
  nlohmann::json sd = nlohmann::json::object();
  for (size_t i = 0; i < names.size() && i < s.stddev.size(); ++i) sd[names[i]] = s.stddev[i];
  j["calibration"] = {{"board", s.board},      {"rms_px", s.rms_px},        {"max_px", s.max_px},
                      {"views", s.views_used}, {"corners", s.corners_used}, {"stddev", sd},
                      {"images", images}};
  return j;
}

void WriteLensFile(const std::string& path, const IntrinsicsSummary& summary) {
  WriteFileAtomic(path, LensJson(summary).dump(2) + "\n");
}

}  // namespace rouen

namespace rouen {

BoardRenderer::BoardRenderer(const BoardSpec& board, const Intrinsics& camera, int supersample,
                             int pixels_per_square)
    : board_(board),
      camera_(camera),
      supersample_(supersample),
      pps_(pixels_per_square),
      texture_(DrawBoard(board, pixels_per_square)) {
  camera.Validate();
  if (supersample < 1 || supersample > 16) throw Error("BoardRenderer: supersample in 1..16");
  const int n = supersample;
  rays_.resize(static_cast<size_t>(camera.width) * camera.height * n * n);
  size_t i = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      for (int sy = 0; sy < n; ++sy) {
        for (int sx = 0; sx < n; ++sx) {
          const Eigen::Vector2d px(x + (sx + 0.5) / n, y + (sy + 0.5) / n);
          rays_[i++] = Unproject(camera, px).cast<float>();
        }
      }
    }
  }
}

Image BoardRenderer::Render(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation,
                            float dark, float bright, float background) const {
  Image im(camera_.width, camera_.height, 1, PixelUnits::kDigital);
  const int n2 = supersample_ * supersample_;
  const Eigen::Vector3d normal = rotation.col(2);
  const double nt = normal.dot(translation);
  const Eigen::Matrix3d rt = rotation.transpose();
  const double scale = pps_ / board_.square_m;
  size_t i = 0;
  for (int y = 0; y < camera_.height; ++y) {
    for (int x = 0; x < camera_.width; ++x) {
      double acc = 0;
      for (int s = 0; s < n2; ++s, ++i) {
        const Eigen::Vector3d d = rays_[i].cast<double>();
        const double dn = normal.dot(d);
        double v = background;
        const double dist = nt / dn;
        if (dn != 0 && dist > 0 && std::isfinite(dist)) {
          const Eigen::Vector3d b = rt * (dist * d - translation);
          const double u = b.x() * scale + pps_, w = b.y() * scale + pps_;
          if (u >= 0 && w >= 0 && u < texture_.width && w < texture_.height) {
            const float t = texture_.at(static_cast<int>(u), static_cast<int>(w)) / 255.f;
            v = dark + (bright - dark) * t;
          }
        }
        acc += v;
      }
      im.at(x, y) = static_cast<float>(acc / n2);
    }
  }
  return im;
}

std::optional<Eigen::Vector2d> BoardRenderer::CornerPixel(
    int id, const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation) const {
  const std::vector<Eigen::Vector3d> pts = board_.CornerPoints();
  if (id < 0 || id >= static_cast<int>(pts.size())) return std::nullopt;
  return Project(camera_, rotation * pts[id] + translation);
}

}  // namespace rouen
