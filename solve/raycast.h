// Ray casting against the building model (Embree 3). Shared by visibility (App. B), the
// irradiance gathering (App. A) and the renderer. World frame: local ENU metres.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>

#include "core/mesh.h"

namespace rouen {

struct RayHit {
  bool hit = false;
  double t = 0;       // distance along the (unit) ray direction, metres
  int triangle = -1;  // index into Mesh::triangles
  // Barycentric coordinates of the hit: p = (1 - u - v) a + u b + v c for triangle (a, b, c).
  double u = 0, v = 0;
};

// An immutable, thread-safe ray-casting scene of a mesh. Degenerate triangles never hit.
class RayCaster {
 public:
  explicit RayCaster(const Mesh& mesh);
  ~RayCaster();
  RayCaster(RayCaster&&) noexcept;
  RayCaster& operator=(RayCaster&&) noexcept;
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // Nearest hit along origin + t dir for t in [tmin, tmax]; `dir` must be unit length.
  RayHit Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double tmin = 0,
                   double tmax = 1e30) const;
  // True when anything lies on origin + t dir for t in [tmin, tmax].
  bool Occluded(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double tmin = 0,
                double tmax = 1e30) const;

  // Diagonal of the mesh bounding box, metres (>= 1e-6).
  double scene_scale() const { return scale_; }
  // Bounding box of the mesh vertices (empty box for an empty mesh).
  const Eigen::AlignedBox3d& bounds() const { return bounds_; }
  // Offset applied along the normal to ray origins leaving a surface: 1e-4 x scene scale
  // (about 1.4 cm on a 100 m plaza; far above float precision there).
  double surface_offset() const { return 1e-4 * scale_; }
  int num_triangles() const { return num_triangles_; }
  // Triangles left out because their area is zero or not finite.
  int num_degenerate() const { return num_degenerate_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  double scale_ = 1;
  Eigen::AlignedBox3d bounds_;
  int num_triangles_ = 0;
  int num_degenerate_ = 0;
};

}  // namespace rouen
