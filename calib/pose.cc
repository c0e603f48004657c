#include "calib/pose.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/files.h"
#include "core/mesh.h"

namespace rouen {
namespace {

// Rays more than this far off the optical axis cannot be put on the z = 1 plane for PnP.
const double kMaxPnpAngleCos = std::cos(85.0 * 3.14159265358979323846 / 180.0);

Eigen::Vector3d ReadVec(const nlohmann::json& j, int n, const std::string& what) {
  if (!j.is_array() || static_cast<int>(j.size()) != n) {
    throw Error(what + " must be an array of " + std::to_string(n) + " numbers");
  }
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    if (!j[i].is_number()) throw Error(what + " has a non-number");
    v[i] = j[i].get<double>();
    if (!std::isfinite(v[i])) throw Error(what + " has a non-finite number");
  }
  return v;
}

// Reprojection residual in pixels of one landmark through core Project; the pose is
// camera-from-world angle-axis (3) and translation (3): x_cam = R X + t.
struct ReprojectionCost {
  ReprojectionCost(const Intrinsics* k, const Eigen::Vector2d& pixel, const Eigen::Vector3d& x)
      : k_(k), pixel_(pixel), x_(x) {}
  bool operator()(const double* aa, const double* t, double* res) const {
    double p[3];
    const double x[3] = {x_.x(), x_.y(), x_.z()};
    ceres::AngleAxisRotatePoint(aa, x, p);
    const auto q = Project(*k_, Eigen::Vector3d(p[0] + t[0], p[1] + t[1], p[2] + t[2]));
    if (!q || !q->allFinite()) return false;
    res[0] = q->x() - pixel_.x();
    res[1] = q->y() - pixel_.y();
    return true;
  }
  const Intrinsics* k_;
  Eigen::Vector2d pixel_;
  Eigen::Vector3d x_;
};

struct CameraFromWorld {
  Eigen::Vector3d aa = Eigen::Vector3d::Zero();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Matrix3d R() const {
    const double a = aa.norm();
    if (a < 1e-300) return Eigen::Matrix3d::Identity();
    return Eigen::AngleAxisd(a, aa / a).toRotationMatrix();
  }
};

// Pixel error of each landmark (-1 when it does not project).
std::vector<double> Errors(const Intrinsics& k, const std::vector<Landmark>& pts,
                           const CameraFromWorld& c) {
  const Eigen::Matrix3d r = c.R();
  std::vector<double> e(pts.size(), -1.0);
  for (size_t i = 0; i < pts.size(); ++i) {
    const auto q = Project(k, r * pts[i].world + c.t);
    if (q && q->allFinite()) e[i] = (*q - pts[i].pixel).norm();
  }
  return e;
}

int Refine(const Intrinsics& k, const std::vector<Landmark>& pts, const std::vector<int>& use,
           double huber_px, CameraFromWorld* c) {
  ceres::Problem problem;
  for (int i : use) {
    auto* cost = new ceres::NumericDiffCostFunction<ReprojectionCost, ceres::CENTRAL, 2, 3, 3>(
        new ReprojectionCost(&k, pts[i].pixel, pts[i].world));
    problem.AddResidualBlock(cost, new ceres::HuberLoss(huber_px), c->aa.data(), c->t.data());
  }
  ceres::Solver::Options opt;
  opt.linear_solver_type = ceres::DENSE_QR;
  opt.max_num_iterations = 100;
  opt.function_tolerance = 1e-12;
  opt.parameter_tolerance = 1e-12;
  opt.num_threads = 1;
  ceres::Solver::Summary sum;
  ceres::Solve(opt, &problem, &sum);
  return static_cast<int>(sum.iterations.size());
}

}  // namespace

void PoseOptions::Validate() const {
  if (!(inlier_threshold_px > 0) || !std::isfinite(inlier_threshold_px)) {
    throw Error("pose options: inlier_threshold_px must be positive pixels");
  }
  if (!(ransac_confidence > 0 && ransac_confidence < 1)) {
    throw Error("pose options: ransac_confidence must be in (0, 1)");
  }
  if (ransac_iterations < 1) throw Error("pose options: ransac_iterations must be positive");
  if (!(huber_px > 0) || !std::isfinite(huber_px)) {
    throw Error("pose options: huber_px must be positive pixels");
  }
  if (min_inliers < 4) throw Error("pose options: min_inliers must be at least 4");
}

LandmarkFile ReadLandmarks(const std::string& path) {
  const std::string text = ReadFileToString(path);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not valid JSON (" + e.what() + ")");
  }
  if (!j.is_object()) throw Error(path + ": expected a JSON object with \"points\"");
  LandmarkFile out;
  if (j.contains("image")) {
    if (!j["image"].is_string()) throw Error(path + ": \"image\" must be a string");
    out.image = j["image"].get<std::string>();
  }
  const auto pts = j.find("points");
  if (pts == j.end() || !pts->is_array()) throw Error(path + ": missing \"points\" array");
  std::unique_ptr<Mesh> model;
  const std::filesystem::path base = std::filesystem::path(path).parent_path();
  for (size_t i = 0; i < pts->size(); ++i) {
    const nlohmann::json& p = (*pts)[i];
    std::string what = path + ": point " + std::to_string(i);
    if (!p.is_object()) throw Error(what + " is not an object");
    Landmark l;
    l.name = std::to_string(i);
    if (p.contains("name")) {
      if (!p["name"].is_string()) throw Error(what + ": \"name\" must be a string");
      l.name = p["name"].get<std::string>();
      what += " (\"" + l.name + "\")";
    }
    if (!p.contains("pixel")) throw Error(what + ": missing \"pixel\"");
    l.pixel = ReadVec(p["pixel"], 2, what + ": \"pixel\"").head<2>();
    const bool has_world = p.contains("world"), has_vertex = p.contains("vertex");
    if (has_world == has_vertex)
      throw Error(what + ": needs exactly one of \"world\" or \"vertex\"");
    if (has_world) {
      l.world = ReadVec(p["world"], 3, what + ": \"world\"");
    } else {
      if (!p["vertex"].is_number_integer()) throw Error(what + ": \"vertex\" must be an integer");
      if (!model) {
        if (!j.contains("model") || !j["model"].is_string()) {
          throw Error(what + ": \"vertex\" needs a \"model\" OBJ path at the top level");
        }
        std::filesystem::path m(j["model"].get<std::string>());
        if (m.is_relative()) m = base / m;
        model = std::make_unique<Mesh>(ReadObj(m.string()));
      }
      const long long v = p["vertex"].get<long long>();
      if (v < 0 || v >= static_cast<long long>(model->vertices.size())) {
        throw Error(what + ": vertex " + std::to_string(v) + " is not in the model (" +
                    std::to_string(model->vertices.size()) + " vertices)");
      }
      l.world = model->vertices[v];
    }
    out.points.push_back(l);
  }
  return out;
}

PoseSummary EstimatePose(const Intrinsics& k, const std::vector<Landmark>& pts,
                         const PoseOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  options.Validate();
  k.Validate();
  if (k.projection == Projection::kEquirect) {
    throw Error("camera pose: equirectangular cameras are not supported (pinhole or fisheye)");
  }
  const int n = static_cast<int>(pts.size());
  if (n < 4) {
    throw Error("camera pose: " + std::to_string(n) +
                " landmarks given; at least 4 (better 6 or more) are needed");
  }
  for (const Landmark& l : pts) {
    if (!l.pixel.allFinite() || !l.world.allFinite()) {
      throw Error("camera pose: landmark \"" + l.name + "\" has non-finite coordinates");
    }
    if (l.pixel.x() < -k.width || l.pixel.x() > 2.0 * k.width || l.pixel.y() < -k.height ||
        l.pixel.y() > 2.0 * k.height) {
      throw Error("camera pose: landmark \"" + l.name + "\" pixel (" + std::to_string(l.pixel.x()) +
                  ", " + std::to_string(l.pixel.y()) + ") is far outside the " +
                  std::to_string(k.width) + "x" + std::to_string(k.height) + " image");
    }
  }
  // World geometry: the points must span at least a plane (collinear points leave the
  // rotation about their line free).
  {
    Eigen::MatrixXd w(n, 3);
    for (int i = 0; i < n; ++i) w.row(i) = pts[i].world.transpose();
    w.rowwise() -= w.colwise().mean();
    const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::MatrixXd>(w).singularValues();
    if (!(sv[0] > 1e-9)) throw Error("camera pose: all landmarks are at the same world point");
    if (sv[1] < 1e-4 * sv[0]) {
      throw Error(
          "camera pose: the landmarks' world points are collinear; the pose is not "
          "determined (add points off that line)");
    }
  }
  // Normalised image points for PnP (works for fisheye too).
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  std::vector<int> pnp_index;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d ray = Unproject(k, pts[i].pixel);
    if (ray.z() <= kMaxPnpAngleCos) continue;
    obj.emplace_back(pts[i].world.x(), pts[i].world.y(), pts[i].world.z());
    img.emplace_back(ray.x() / ray.z(), ray.y() / ray.z());
    pnp_index.push_back(i);
  }
  const int m = static_cast<int>(obj.size());
  if (m < 4) {
    throw Error("camera pose: only " + std::to_string(m) +
                " landmarks lie within 85 degrees of the optical axis; at least 4 are needed");
  }
  {
    // Image-side degeneracy: all rays in one plane means the camera centre lies in the plane
    // of (coplanar) landmarks, or the pixels were clicked along one line.
    Eigen::MatrixXd q(m, 2);
    for (int i = 0; i < m; ++i) q.row(i) << img[i].x, img[i].y;
    q.rowwise() -= q.colwise().mean();
    const Eigen::Vector2d sv = Eigen::JacobiSVD<Eigen::MatrixXd>(q).singularValues();
    const double px = 0.5 * (k.fx + k.fy) / std::sqrt(static_cast<double>(m));
    const double along_px = sv[0] * px, across_px = sv[1] * px;  // RMS spreads, ~pixels
    if (across_px < std::max(2.0, 0.02 * along_px)) {
      throw Error(
          "camera pose: the landmark pixels are (nearly) collinear; the camera sees "
          "the points edge-on and the pose is not determined");
    }
  }

  const double f = 0.5 * (k.fx + k.fy);
  cv::Mat rvec, tvec;
  std::vector<int> inl;
  bool ok = false;
  try {
    if (m >= 6) {
      ok = cv::solvePnPRansac(obj, img, cv::Mat::eye(3, 3, CV_64F), cv::noArray(), rvec, tvec,
                              false, options.ransac_iterations,
                              static_cast<float>(options.inlier_threshold_px / f),
                              options.ransac_confidence, inl, cv::SOLVEPNP_EPNP);
    }
    if (!ok || static_cast<int>(inl.size()) < 4) {
      // Too few points for a RANSAC sample plus a check, or RANSAC failed: all points.
      ok = cv::solvePnP(obj, img, cv::Mat::eye(3, 3, CV_64F), cv::noArray(), rvec, tvec, false,
                        m >= 6 ? cv::SOLVEPNP_EPNP : cv::SOLVEPNP_SQPNP);
      inl.resize(m);
      for (int i = 0; i < m; ++i) inl[i] = i;
    }
  } catch (const cv::Exception& e) {
    throw Error("camera pose: OpenCV PnP failed: " + e.msg);
  }
  CameraFromWorld c;
  if (ok) {
    rvec.convertTo(rvec, CV_64F);
    tvec.convertTo(tvec, CV_64F);
    c.aa = Eigen::Vector3d(rvec.ptr<double>()[0], rvec.ptr<double>()[1], rvec.ptr<double>()[2]);
    c.t = Eigen::Vector3d(tvec.ptr<double>()[0], tvec.ptr<double>()[1], tvec.ptr<double>()[2]);
  }
  if (!ok || !c.aa.allFinite() || !c.t.allFinite()) {
    throw Error("camera pose: PnP found no pose consistent with the landmarks");
  }
  // Keep the RANSAC inliers that are in front of the camera for refinement.
  std::vector<int> use;
  std::vector<double> err = Errors(k, pts, c);
  for (int i : inl) {
    if (err[pnp_index[i]] >= 0) use.push_back(pnp_index[i]);
  }
  if (static_cast<int>(use.size()) < 4) {
    throw Error("camera pose: the best PnP pose puts " + std::to_string(inl.size() - use.size()) +
                " of its " + std::to_string(inl.size()) +
                " consistent landmarks behind the camera; check the pixel/world pairing");
  }
  PoseSummary s;
  s.ransac_used = m;
  s.ceres_iterations = Refine(k, pts, use, options.huber_px, &c);
  // Final inliers over all points (including those too far off-axis for PnP), refine again.
  err = Errors(k, pts, c);
  use.clear();
  for (int i = 0; i < n; ++i) {
    if (err[i] >= 0 && err[i] <= options.inlier_threshold_px) use.push_back(i);
  }
  if (static_cast<int>(use.size()) >= 4) {
    s.ceres_iterations += Refine(k, pts, use, options.huber_px, &c);
    err = Errors(k, pts, c);
  }
  if (!c.aa.allFinite() || !c.t.allFinite()) {
    throw Error("camera pose: the refinement diverged (non-finite pose)");
  }
  int behind = 0;
  double ss = 0;
  for (int i = 0; i < n; ++i) {
    PointReport r;
    r.name = pts[i].name;
    r.error_px = err[i];
    r.behind = err[i] < 0;
    r.inlier = err[i] >= 0 && err[i] <= options.inlier_threshold_px;
    if (r.behind) ++behind;
    if (r.inlier) {
      ++s.inliers;
      ss += err[i] * err[i];
      s.max_px = std::max(s.max_px, err[i]);
    }
    s.points.push_back(r);
  }
  if (s.inliers < options.min_inliers) {
    std::string detail;
    for (const PointReport& r : s.points) {
      detail += "\n  " + r.name + ": " +
                (r.behind ? std::string("behind the camera") : std::to_string(r.error_px) + " px");
    }
    throw Error("camera pose: only " + std::to_string(s.inliers) + " of " + std::to_string(n) +
                " landmarks reproject within " + std::to_string(options.inlier_threshold_px) +
                " px (" + std::to_string(behind) + " behind the camera); at least " +
                std::to_string(options.min_inliers) + " are needed:" + detail);
  }
  s.rms_px = std::sqrt(ss / s.inliers);
  const Eigen::Matrix3d r = c.R();
  s.pose.rotation = r.transpose();
  s.pose.position = -r.transpose() * c.t;
  if (!s.pose.rotation.allFinite() || !s.pose.position.allFinite() || !std::isfinite(s.rms_px)) {
    throw Error("camera pose: non-finite result");
  }
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return s;
}

nlohmann::json PoseJson(const PoseSummary& s) {
  nlohmann::json j = s.pose;
  nlohmann::json pts = nlohmann::json::array();
  for (const PointReport& p : s.points) {
    nlohmann::json e = {{"name", p.name}, {"inlier", p.inlier}};
    if (p.behind) {
      e["error_px"] = nullptr;
      e["behind"] = true;
    } else {
      e["error_px"] = p.error_px;
    }
    pts.push_back(e);
  }
  j["reprojection"] = {
      {"rms_px", s.rms_px}, {"max_px", s.max_px}, {"inliers", s.inliers}, {"points", pts}};
  return j;
}

}  // namespace rouen
