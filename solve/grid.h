// Surface grid on the building model (Yu & Malik 1998, §4.1): every triangle is subdivided
// regularly in barycentric coordinates and one grid point sits at each sub-triangle's
// centroid. Pseudo-albedos and irradiances live on these points.
#pragma once

#include <Eigen/Core>
#include <array>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace rouen {

enum class GridSubdivision {
  kLongestEdge,     // n = ceil(longest edge / spacing)
  kEquivalentArea,  // n = ceil(edge of the equilateral triangle of the same area / spacing):
                    // the same n for well-shaped triangles, far fewer points on slivers
};

struct GridOptions {
  double spacing_m = 0.6;  // target sub-triangle edge length, metres
  GridSubdivision subdivision = GridSubdivision::kEquivalentArea;
  // Per-block overrides of spacing_m, by block name (e.g. {"plaza", 1.5}).
  std::map<std::string, double> block_spacing_m;
  int max_subdivision = 512;  // cap on n per triangle (n^2 points per triangle)

  // Throws rouen::Error when a spacing is not positive and finite.
  void Validate() const;
  double SpacingFor(const std::string& block) const;
};

void to_json(nlohmann::json& j, const GridOptions& o);
void from_json(const nlohmann::json& j, GridOptions& o);

struct GridPoint {
  Eigen::Vector3d position;  // ENU metres (sub-triangle centroid)
  Eigen::Vector3d normal;    // unit outward normal of the triangle
  int triangle = -1;
  int block = -1;
  double area = 0;  // m^2 of the sub-triangle
};

// Up to 18 grid points and weights (summing to 1) that interpolate a value at a surface point.
struct GridStencil {
  int count = 0;
  std::array<int, 18> index{};
  std::array<double, 18> weight{};
};

struct SurfaceGrid {
  std::vector<GridPoint> points;
  std::vector<int> triangle_first;  // first point of each triangle; size = triangles + 1
  std::vector<int> triangle_n;      // subdivision per triangle (0: degenerate, no points)
  int skipped_triangles = 0;        // degenerate or invalid triangles (no points)

  int size() const { return static_cast<int>(points.size()); }
  // Grid point whose sub-triangle contains barycentric (u, v) of `triangle` (p = (1-u-v) a +
  // u b + v c); -1 for a triangle without points.
  int NearestPoint(int triangle, double u, double v) const;
  // Smooth interpolation stencil inside one triangle: values at the sub-triangle lattice
  // vertices are the means of the adjacent cells; (u, v) is interpolated linearly in its
  // cell. Empty stencil for a triangle without points.
  GridStencil Stencil(int triangle, double u, double v) const;
  Eigen::Vector3d Interpolate(const std::vector<Eigen::Vector3d>& values, int triangle, double u,
                              double v) const;
};

// Deterministic: the same mesh and options give the same points in the same order (by
// triangle, then by sub-triangle). Degenerate triangles get no points and are counted.
SurfaceGrid BuildSurfaceGrid(const Mesh& mesh, const GridOptions& options);
// The number of points BuildSurfaceGrid would make, without making them.
int64_t CountGridPoints(const Mesh& mesh, const GridOptions& options);

}  // namespace rouen
