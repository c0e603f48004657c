// Camera models. Camera frame: x right, y down, z forward. World frame: the site's local
// east-north-up frame (x east, y north, z up), metres.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <string_view>

namespace rouen {

enum class Projection {
  kPinhole,   // perspective with Brown-Conrady distortion (k1, k2, k3, p1, p2)
  kFisheye,   // equidistant r = f * theta, with odd polynomial distortion in theta (k1..k4)
  kEquirect,  // full sphere: column = azimuth about -y from +z towards +x; row 0 = -y (up)
};

struct Intrinsics {
  Projection projection = Projection::kPinhole;
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;  // pixels; pixel centres at integer + 0.5
  double k1 = 0, k2 = 0, k3 = 0, k4 = 0, p1 = 0, p2 = 0;

  static Intrinsics PinholeFov(int width, int height, double hfov_deg);
  static Intrinsics FisheyeFov(int width, int height, double fov_deg);  // circle fills min(w,h)
  static Intrinsics Equirect(int width, int height);
  // Checks that sizes and focal lengths are positive and finite; throws rouen::Error.
  void Validate() const;
};

// Projects a camera-frame direction (need not be unit) to pixel coordinates. Returns nothing
// when the direction is behind a pinhole camera or outside the fisheye's field of view.
// The pixel may lie outside the image; callers check bounds.
std::optional<Eigen::Vector2d> Project(const Intrinsics& k, const Eigen::Vector3d& dir_cam);
// Unit camera-frame ray through pixel coordinates (inverse of Project).
Eigen::Vector3d Unproject(const Intrinsics& k, const Eigen::Vector2d& pixel);
// Solid angle (sr) the pixel with top-left corner (x, y) sees: the quadrilateral of its four
// corners' rays, half the cross product of its diagonals (exact to second order in the pixel).
double PixelSolidAngle(const Intrinsics& k, int x, int y);

// Camera pose in the world: x_world = rotation * x_cam + position.
struct Pose {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d position = Eigen::Vector3d::Zero();

  // A camera at `eye` looking at `target` with image-up as close to world +z as possible.
  static Pose LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target);
  // A level camera at `eye` whose forward axis points to azimuth (deg, from north eastward)
  // and elevation (deg). For an equirect camera with azimuth 0 and elevation 0 the column
  // azimuth equals the compass azimuth and row 0 is the zenith.
  static Pose Level(const Eigen::Vector3d& eye, double azimuth_deg, double elevation_deg);
  Eigen::Vector3d WorldToCamera(const Eigen::Vector3d& p) const {
    return rotation.transpose() * (p - position);
  }
};

void to_json(nlohmann::json& j, const Intrinsics& k);
void from_json(const nlohmann::json& j, Intrinsics& k);
void to_json(nlohmann::json& j, const Pose& p);
void from_json(const nlohmann::json& j, Pose& p);

// The text of a pose file: {"rotation": 3x3, "position": [x, y, z], ...} (as `rouen calib
// pose` and `rouen calib orient` write them). Throws rouen::Error naming `name` (the file).
Pose ParsePose(std::string_view text, const std::string& name);

}  // namespace rouen
