// Internal to the simulated world: its patches as an Embree scene, traced one ray at a time or
// in packets of rays from one origin (the lighting texels' hemisphere samples).
#pragma once

#include <Eigen/Core>
#include <limits>
#include <vector>

#include "capture/sim/sim_scene.h"

struct RTCDeviceTy;
struct RTCSceneTy;

namespace rouen::sim {

struct RayHit {
  int patch = -1;  // index into the patches, -1: missed
  double t = std::numeric_limits<double>::infinity();
};

class RayScene {
 public:
  static constexpr int kPacket = 8;

  // Every patch as one or two triangles; throws rouen::Error when Embree is unavailable.
  explicit RayScene(const std::vector<Patch>& patches);
  ~RayScene();
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;

  // The first patch along o + t d, t > 0 (d need not be unit; t in units of |d|).
  RayHit Trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const;
  // Whether anything lies along o + t d, t > 0.
  bool Occluded(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const;
  // Trace for the n <= kPacket directions d[0..n) from o, through one Embree packet: the same
  // hits as n calls of Trace.
  void TracePacket(const Eigen::Vector3d& o, const Eigen::Vector3d* d, int n, RayHit* out) const;

 private:
  RTCDeviceTy* device_ = nullptr;
  RTCSceneTy* scene_ = nullptr;
  std::vector<int> tri_patch_;  // Embree primitive -> patch
};

}  // namespace rouen::sim
