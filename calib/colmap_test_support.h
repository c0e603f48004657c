// For tests: COLMAP's text format written as `colmap model_converter` writes it.
#pragma once

#include <Eigen/Geometry>
#include <cstdio>
#include <string>

#include "core/camera.h"

namespace rouen {

// A camera's pose as images.txt holds it: the world-to-camera quaternion (w, x, y, z) and
// translation of `p` (a camera-to-world pose in the model's frame).
inline std::string ColmapPoseText(const Pose& p) {
  const Eigen::Matrix3d r = p.rotation.transpose();
  const Eigen::Quaterniond q(r);
  const Eigen::Vector3d t = -(r * p.position);
  char buf[256];
  std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g %.17g %.17g %.17g %.17g", q.w(), q.x(), q.y(),
                q.z(), t.x(), t.y(), t.z());
  return buf;
}

}  // namespace rouen
