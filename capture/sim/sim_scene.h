// Internal to the simulated world: the scene's planar patches (tower, plaza, surrounding
// blocks, near ground), their materials and albedo fields, and the model mesh a user would
// give the solver. ENU metres, origin at the site.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace rouen::sim {

enum Material : int {
  kStone = 0,  // tower walls
  kRoofMetal,  // the pyramid roof (weathered copper)
  kPaving,     // the plaza
  kBlockA,     // surrounding blocks (not in the model)
  kBlockB,
  kBlockC,
  kBlockD,
  kBlockE,
  kGround,  // ground beyond the plaza (to infinity)
  kMaterialCount
};

// Smooth RGB albedo of a material at a point (Lambertian), within [0.05, 0.8].
Eigen::Vector3d MaterialAlbedo(int material, const Eigen::Vector3d& p);

// A material's specular reflection on top of its diffuse albedo: a grey Phong lobe around the
// mirror direction, f_s(u, v) = rho_s (m(v) . u)^n with m(v) the view mirrored about the
// normal (1/sr). rho_s 0: matte. Only the copper roof is mildly glossy (its lobe reflects
// 2 pi rho_s / (n + 2) of normally incident light, 2%).
struct MaterialGloss {
  double rho_s = 0;
  double n = 1;
};
MaterialGloss MaterialSpecular(int material);

// A planar rectangle (origin o, unit axes u, v; extents su, sv) or triangle (vertices
// (0,0), (su,0), (apex_s, sv) in (u, v) coordinates). Normal n = u x v points outward.
struct Patch {
  Eigen::Vector3d o, u, v, n;
  double su = 0, sv = 0;
  bool triangle = false;
  double apex_s = 0;
  int world_block = -1;  // index into SceneGeometry::block_names
  int model_block = -1;  // block in the model mesh, or -1 when not in the model
  int material = kStone;
  double texel_m = 1;  // lighting texel size
  // Lighting texel grid over [0, su] x [0, sv].
  int nu = 1, nv = 1, texel_offset = 0;
  double du = 1, dv = 1;

  Eigen::Vector2d Local(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d d = p - o;
    return Eigen::Vector2d(d.dot(u), d.dot(v));
  }
  Eigen::Vector3d Point(double s, double t) const { return o + s * u + t * v; }
  // Distance from p to the patch (polygon, not plane).
  double Distance(const Eigen::Vector3d& p) const;
  // Closest point of the patch to p.
  Eigen::Vector3d Closest(const Eigen::Vector3d& p) const;
  // The lighting texel containing local coordinates (s, t) (clamped to the grid).
  int TexelAt(double s, double t) const;
};

struct SceneGeometry {
  std::vector<Patch> patches;
  std::vector<std::string> block_names;  // world blocks: tower parts, plaza, blocks, ground
  Mesh model;                            // base, shaft, belfry, roof, plaza
  double ground_half_extent_m = 200;     // textured ground square; beyond it, analytic ground
  double tower_rotation_deg = 40;
};

struct TexelSizes {
  double tower_m = 0.5, plaza_m = 1.0, block_m = 1.0, ground_m = 4.0;
};

SceneGeometry BuildScene(const TexelSizes& sizes);

}  // namespace rouen::sim
