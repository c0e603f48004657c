#include "core/camera.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/json_text.h"
#include "core/limits.h"
#include "core/solar.h"

namespace rouen {
namespace {

// Brown-Conrady distortion of normalised coordinates (x, y) -> (xd, yd), with Jacobian.
Eigen::Vector2d Distort(const Intrinsics& k, const Eigen::Vector2d& p, Eigen::Matrix2d* jac) {
  const double x = p.x(), y = p.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
  const double xd = x * radial + 2 * k.p1 * x * y + k.p2 * (r2 + 2 * x * x);
  const double yd = y * radial + k.p1 * (r2 + 2 * y * y) + 2 * k.p2 * x * y;
  if (jac) {
    const double dradial_dr2 = k.k1 + r2 * (2 * k.k2 + 3 * k.k3 * r2);
    const double drdx = dradial_dr2 * 2 * x, drdy = dradial_dr2 * 2 * y;
    (*jac)(0, 0) = radial + x * drdx + 2 * k.p1 * y + 6 * k.p2 * x;
    (*jac)(0, 1) = x * drdy + 2 * k.p1 * x + 2 * k.p2 * y;
    (*jac)(1, 0) = y * drdx + 2 * k.p1 * x + 2 * k.p2 * y;
    (*jac)(1, 1) = radial + y * drdy + 6 * k.p1 * y + 2 * k.p2 * x;
  }
  return Eigen::Vector2d(xd, yd);
}

// Fisheye radial function r(theta) = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8) and r'.
double FisheyeR(const Intrinsics& k, double t, double* dr) {
  const double t2 = t * t;
  const double poly = 1 + t2 * (k.k1 + t2 * (k.k2 + t2 * (k.k3 + t2 * k.k4)));
  if (dr) *dr = 1 + t2 * (3 * k.k1 + t2 * (5 * k.k2 + t2 * (7 * k.k3 + t2 * 9 * k.k4)));
  return t * poly;
}

const char* ProjectionName(Projection p) {
  switch (p) {
    case Projection::kPinhole:
      return "pinhole";
    case Projection::kFisheye:
      return "fisheye";
    case Projection::kEquirect:
      return "equirect";
  }
  return "pinhole";
}

template <typename T>
T GetKey(const nlohmann::json& j, const char* key, const char* what) {
  if (!j.is_object()) throw Error(std::string(what) + ": expected a JSON object");
  auto it = j.find(key);
  if (it == j.end()) throw Error(std::string(what) + ": missing key \"" + key + "\"");
  if constexpr (std::is_same_v<T, double>) {
    if (!it->is_number()) throw Error(std::string(what) + ": key \"" + key + "\" is not a number");
  } else if constexpr (std::is_same_v<T, int>) {
    // Not truncated to 32 bits: 4294967936 is no width of 640.
    return JsonGet<int>(*it, std::string(what) + ": key \"" + key + "\"");
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!it->is_string()) throw Error(std::string(what) + ": key \"" + key + "\" is not a string");
  }
  return it->get<T>();
}

double GetOptional(const nlohmann::json& j, const char* key, const char* what) {
  auto it = j.find(key);
  if (it == j.end() || it->is_null()) return 0.0;
  if (!it->is_number()) throw Error(std::string(what) + ": key \"" + key + "\" is not a number");
  return it->get<double>();
}

}  // namespace

Intrinsics Intrinsics::PinholeFov(int width, int height, double hfov_deg) {
  Intrinsics k;
  k.projection = Projection::kPinhole;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 0.5 * width / std::tan(0.5 * hfov_deg * kDeg);
  k.cx = 0.5 * width;
  k.cy = 0.5 * height;
  return k;
}

Intrinsics Intrinsics::FisheyeFov(int width, int height, double fov_deg) {
  Intrinsics k;
  k.projection = Projection::kFisheye;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 0.5 * std::min(width, height) / (0.5 * fov_deg * kDeg);
  k.cx = 0.5 * width;
  k.cy = 0.5 * height;
  return k;
}

Intrinsics Intrinsics::Equirect(int width, int height) {
  Intrinsics k;
  k.projection = Projection::kEquirect;
  k.width = width;
  k.height = height;
  // Informational: pixels per radian and the image centre; projection uses width/height.
  k.fx = width / (2 * kPi);
  k.fy = height / kPi;
  k.cx = 0.5 * width;
  k.cy = 0.5 * height;
  return k;
}

void Intrinsics::Validate() const {
  const std::string what = std::string("camera intrinsics (") + ProjectionName(projection) + ")";
  if (width <= 0 || height <= 0) {
    throw Error(what + ": image size " + std::to_string(width) + "x" + std::to_string(height) +
                " must be positive");
  }
  for (double v : {fx, fy, cx, cy, k1, k2, k3, k4, p1, p2}) {
    if (!std::isfinite(v)) throw Error(what + ": non-finite parameter");
  }
  if (projection != Projection::kEquirect && (fx <= 0 || fy <= 0)) {
    throw Error(what + ": focal lengths fx=" + std::to_string(fx) + " fy=" + std::to_string(fy) +
                " must be positive");
  }
}

std::optional<Eigen::Vector2d> Project(const Intrinsics& k, const Eigen::Vector3d& d) {
  const double n = d.norm();
  if (!(n > 0) || !std::isfinite(n)) return std::nullopt;
  switch (k.projection) {
    case Projection::kPinhole: {
      if (d.z() <= 1e-12 * n) return std::nullopt;
      const Eigen::Vector2d pd = Distort(k, Eigen::Vector2d(d.x() / d.z(), d.y() / d.z()), nullptr);
      return Eigen::Vector2d(k.fx * pd.x() + k.cx, k.fy * pd.y() + k.cy);
    }
    case Projection::kFisheye: {
      const double rxy = std::hypot(d.x(), d.y());
      const double theta = std::atan2(rxy, d.z());
      if (theta > kPi - 1e-9) return std::nullopt;  // straight behind: no unique pixel
      double dr = 0;
      const double r = FisheyeR(k, theta, &dr);
      if (dr <= 0) return std::nullopt;  // beyond where the distortion polynomial folds back
      if (rxy == 0) return Eigen::Vector2d(k.cx, k.cy);
      return Eigen::Vector2d(k.fx * r * d.x() / rxy + k.cx, k.fy * r * d.y() / rxy + k.cy);
    }
    case Projection::kEquirect: {
      double az = std::atan2(d.x(), d.z());
      if (az < 0) az += 2 * kPi;
      const double el = std::asin(std::clamp(-d.y() / n, -1.0, 1.0));
      double u = az / (2 * kPi) * k.width;
      if (u >= k.width) u -= k.width;
      return Eigen::Vector2d(u, (0.5 * kPi - el) / kPi * k.height);
    }
  }
  return std::nullopt;
}

Eigen::Vector3d Unproject(const Intrinsics& k, const Eigen::Vector2d& pixel) {
  switch (k.projection) {
    case Projection::kPinhole: {
      const Eigen::Vector2d target((pixel.x() - k.cx) / k.fx, (pixel.y() - k.cy) / k.fy);
      // Without distortion the guess below is the answer: no Newton step to take.
      if (k.k1 == 0 && k.k2 == 0 && k.k3 == 0 && k.p1 == 0 && k.p2 == 0)
        return Eigen::Vector3d(target.x(), target.y(), 1.0).normalized();
      Eigen::Vector2d p = target;
      // Newton on Distort(p) = target; the undistorted guess is exact without distortion.
      for (int it = 0; it < 50; ++it) {
        Eigen::Matrix2d jac;
        const Eigen::Vector2d r = Distort(k, p, &jac) - target;
        if (r.norm() < 1e-14) break;
        const Eigen::Vector2d step = jac.partialPivLu().solve(r);
        if (!step.allFinite()) break;
        p -= step;
        if (step.norm() < 1e-15) break;
      }
      return Eigen::Vector3d(p.x(), p.y(), 1.0).normalized();
    }
    case Projection::kFisheye: {
      const double xn = (pixel.x() - k.cx) / k.fx, yn = (pixel.y() - k.cy) / k.fy;
      const double r = std::hypot(xn, yn);
      if (r == 0) return Eigen::Vector3d(0, 0, 1);
      double theta = std::min(r, kPi);
      const bool equidistant = k.k1 == 0 && k.k2 == 0 && k.k3 == 0 && k.k4 == 0;
      for (int it = 0; it < 50 && !equidistant; ++it) {
        double dr = 0;
        const double f = FisheyeR(k, theta, &dr) - r;
        if (std::abs(f) < 1e-14) break;
        if (dr <= 0) break;
        const double step = f / dr;
        theta = std::clamp(theta - step, 0.0, kPi);
        if (std::abs(step) < 1e-15) break;
      }
      const double s = std::sin(theta);
      return Eigen::Vector3d(s * xn / r, s * yn / r, std::cos(theta));
    }
    case Projection::kEquirect: {
      const double az = pixel.x() / k.width * 2 * kPi;
      const double el = 0.5 * kPi - pixel.y() / k.height * kPi;
      return Eigen::Vector3d(std::cos(el) * std::sin(az), -std::sin(el),
                             std::cos(el) * std::cos(az));
    }
  }
  return Eigen::Vector3d(0, 0, 1);
}

double PixelSolidAngle(const Intrinsics& k, int x, int y) {
  const Eigen::Vector3d a = Unproject(k, Eigen::Vector2d(x, y));
  const Eigen::Vector3d b = Unproject(k, Eigen::Vector2d(x + 1, y));
  const Eigen::Vector3d c = Unproject(k, Eigen::Vector2d(x, y + 1));
  const Eigen::Vector3d d = Unproject(k, Eigen::Vector2d(x + 1, y + 1));
  return 0.5 * (d - a).cross(c - b).norm();
}

Pose Pose::LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  Pose p;
  p.position = eye;
  const Eigen::Vector3d diff = target - eye;
  if (!(diff.norm() > 0)) return p;  // degenerate: keep identity rotation
  const Eigen::Vector3d forward = diff.normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ());
  // Looking straight up or down: image-up points north.
  if (right.norm() < 1e-9) right = forward.cross(Eigen::Vector3d::UnitY());
  right.normalize();
  const Eigen::Vector3d down = forward.cross(right);
  p.rotation.col(0) = right;
  p.rotation.col(1) = down;
  p.rotation.col(2) = forward;
  return p;
}

Pose Pose::Level(const Eigen::Vector3d& eye, double azimuth_deg, double elevation_deg) {
  return LookAt(eye, eye + EnuFromAzEl(azimuth_deg, elevation_deg));
}

void to_json(nlohmann::json& j, const Intrinsics& k) {
  j = nlohmann::json{{"projection", ProjectionName(k.projection)},
                     {"width", k.width},
                     {"height", k.height},
                     {"fx", k.fx},
                     {"fy", k.fy},
                     {"cx", k.cx},
                     {"cy", k.cy},
                     {"k1", k.k1},
                     {"k2", k.k2},
                     {"k3", k.k3},
                     {"k4", k.k4},
                     {"p1", k.p1},
                     {"p2", k.p2}};
}

void from_json(const nlohmann::json& j, Intrinsics& k) {
  const char* what = "intrinsics";
  Intrinsics r;
  const std::string proj = GetKey<std::string>(j, "projection", what);
  if (proj == "pinhole") {
    r.projection = Projection::kPinhole;
  } else if (proj == "fisheye") {
    r.projection = Projection::kFisheye;
  } else if (proj == "equirect") {
    r.projection = Projection::kEquirect;
  } else {
    throw Error(std::string(what) + ": unknown projection \"" + proj +
                "\" (pinhole, fisheye or equirect)");
  }
  r.width = GetKey<int>(j, "width", what);
  r.height = GetKey<int>(j, "height", what);
  if (r.projection == Projection::kEquirect) {
    const Intrinsics e = Intrinsics::Equirect(r.width, r.height);
    r.fx = j.contains("fx") ? GetKey<double>(j, "fx", what) : e.fx;
    r.fy = j.contains("fy") ? GetKey<double>(j, "fy", what) : e.fy;
    r.cx = j.contains("cx") ? GetKey<double>(j, "cx", what) : e.cx;
    r.cy = j.contains("cy") ? GetKey<double>(j, "cy", what) : e.cy;
  } else {
    r.fx = GetKey<double>(j, "fx", what);
    r.fy = GetKey<double>(j, "fy", what);
    r.cx = GetKey<double>(j, "cx", what);
    r.cy = GetKey<double>(j, "cy", what);
  }
  r.k1 = GetOptional(j, "k1", what);
  r.k2 = GetOptional(j, "k2", what);
  r.k3 = GetOptional(j, "k3", what);
  r.k4 = GetOptional(j, "k4", what);
  r.p1 = GetOptional(j, "p1", what);
  r.p2 = GetOptional(j, "p2", what);
  r.Validate();
  k = r;
}

void to_json(nlohmann::json& j, const Pose& p) {
  nlohmann::json rot = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) {
    rot.push_back({p.rotation(r, 0), p.rotation(r, 1), p.rotation(r, 2)});
  }
  j = nlohmann::json{{"rotation", rot},
                     {"position", {p.position.x(), p.position.y(), p.position.z()}}};
}

void from_json(const nlohmann::json& j, Pose& p) {
  if (!j.is_object()) throw Error("pose: expected a JSON object");
  auto rot = j.find("rotation");
  if (rot == j.end()) throw Error("pose: missing key \"rotation\"");
  auto pos = j.find("position");
  if (pos == j.end()) throw Error("pose: missing key \"position\"");
  Pose r;
  // Rotation: 3 rows of 3 numbers (row-major); a flat array of 9 is accepted too.
  std::vector<double> v;
  if (rot->is_array() && rot->size() == 3) {
    for (const auto& row : *rot) {
      if (!row.is_array() || row.size() != 3) throw Error("pose: \"rotation\" must be 3x3");
      for (const auto& x : row) {
        if (!x.is_number()) throw Error("pose: \"rotation\" has a non-number");
        v.push_back(x.get<double>());
      }
    }
  } else if (rot->is_array() && rot->size() == 9) {
    for (const auto& x : *rot) {
      if (!x.is_number()) throw Error("pose: \"rotation\" has a non-number");
      v.push_back(x.get<double>());
    }
  } else {
    throw Error("pose: \"rotation\" must be 3x3 (row-major)");
  }
  for (int i = 0; i < 9; ++i) r.rotation(i / 3, i % 3) = v[i];
  if (!pos->is_array() || pos->size() != 3) throw Error("pose: \"position\" must be 3 numbers");
  for (int i = 0; i < 3; ++i) {
    if (!(*pos)[i].is_number()) throw Error("pose: \"position\" has a non-number");
    r.position[i] = (*pos)[i].get<double>();
  }
  if (!r.rotation.allFinite() || !r.position.allFinite()) throw Error("pose: non-finite values");
  for (int i = 0; i < 3; ++i) Require(CoordinateProblem(r.position[i]), "pose: \"position\"");
  const double ortho = (r.rotation.transpose() * r.rotation - Eigen::Matrix3d::Identity()).norm();
  if (ortho > 1e-6 || r.rotation.determinant() < 0) {
    throw Error("pose: \"rotation\" is not a proper rotation (orthonormality error " +
                std::to_string(ortho) + ")");
  }
  p = r;
}

Pose ParsePose(std::string_view text, const std::string& name) {
  const nlohmann::json j = ParseJsonText(text, name);
  try {
    return j.get<Pose>();
  } catch (const Error& e) {
    throw Error(name + ": " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw Error(name + ": " + e.what());
  }
}

}  // namespace rouen
