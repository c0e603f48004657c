// Vector-flux irradiance split into a time-independent geometric part, cached per surface
// point, and a per-lighting part shared by every point (Yu & Malik 1998, App. A, reorganised).
//
// The sky hemisphere is a fixed hierarchy of spherical triangles (SkyPatchTree: the 4 octant
// triangles above the horizon, each split into 4 by its edge midpoints per level). Per point
// the tree is clipped top-down against the tangent plane and the occluders (PointVisibility):
// a node wholly visible is kept as it is (its cosine-weighted integral is exact given the
// node's radiance moment), a node partly visible is split, down to the deepest level, where
// its visible part's flux (eq. 20) is kept. Per lighting, SkyTreeRadiance integrates the sky
// once over every node -- G_c(node) = integral over the node of L_c(w) w dw, adaptively
// subdivided below the deepest level until the radiance is nearly uniform -- so that each
// point's sky irradiance is a short sum of dot products:
//   E_c = sum over whole nodes of n . G_c(node)
//       + sum over partly visible deepest nodes of (n . Phi_visible) Lbar_c(node),
// with Lbar_c(node) = c . G_c / |Phi(node)| (c: the direction of Phi(node)), the node's mean
// radiance. The environment regions (uniform radiance) keep n . Phi of their visible parts
// (EnvironmentView, solve/vector_flux.h).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "solve/environment.h"
#include "solve/sky_model.h"
#include "solve/vector_flux.h"

namespace rouen {

class SkyPatchTree {
 public:
  static constexpr int kMaxLevels = 9;
  // Levels below the 4 octants: 0..kMaxLevels (6: 16384 deepest triangles of ~1.4 deg).
  explicit SkyPatchTree(int levels);
  int levels() const { return levels_; }
  int num_nodes() const { return static_cast<int>(corners_.size()); }
  int level_offset(int level) const { return offset_[level]; }  // first node of a level
  // Nodes of level l are level_offset(l) + k, k in [0, 4^(l+1)); their children are
  // level_offset(l + 1) + 4k + j, j in 0..3 (none at the deepest level).
  int FirstChild(int node, int level) const {
    return level >= levels_ ? -1 : offset_[level + 1] + 4 * (node - offset_[level]);
  }
  // Counter-clockwise seen from outside.
  const std::array<Eigen::Vector3d, 3>& corners(int node) const { return corners_[node]; }
  const Eigen::Vector3d& flux(int node) const { return flux_[node]; }  // eq. 20, sr

 private:
  int levels_ = 0;
  std::vector<int> offset_;
  std::vector<std::array<Eigen::Vector3d, 3>> corners_;
  std::vector<Eigen::Vector3d> flux_;
};

// One sky's radiance moments over every node of a tree.
class SkyTreeRadiance {
 public:
  // Deepest nodes are subdivided (midpoint rule L(c) Phi on each piece) while the radiance at
  // their corners, centre and (when inside) the sun differs by more than
  // options.sky_tolerance of their mean in some channel, at most options.sky_max_depth times.
  SkyTreeRadiance(const SkyPatchTree& tree, const SkyModel& sky, const VectorFluxOptions& options);
  // Row c: integral over the node of L_c(w) w^T dw (relative radiance x sr).
  const Eigen::Matrix3d& G(int node) const { return g_[node]; }
  int64_t evaluations() const { return evaluations_; }  // sky radiance evaluations

 private:
  std::vector<Eigen::Matrix3d> g_;
  int64_t evaluations_ = 0;
};

// What one surface point keeps between lightings.
struct PointFluxCache {
  // Sky: E_c += sky_weight[k] . G_c(sky_node[k]).
  std::vector<int32_t> sky_node;
  std::vector<Eigen::Vector3f> sky_weight;
  int partial_nodes = 0;  // deepest sky nodes clipped
  size_t Bytes() const { return sky_node.size() * (sizeof(int32_t) + sizeof(Eigen::Vector3f)); }
};

// Clips the tree for one point (replaces the sky part of `cache`).
void CacheSky(const PointVisibility& vis, const SkyPatchTree& tree, PointFluxCache* cache);
// Direct sky irradiance (sky model above the horizon, nothing below), RGB.
Eigen::Vector3d EvaluateSky(const PointFluxCache& cache, const SkyTreeRadiance& sky);
}  // namespace rouen
