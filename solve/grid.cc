#include "solve/grid.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"
#include "core/json_text.h"

namespace rouen {

namespace {

// Sub-triangle index inside a triangle subdivided n times: row i holds upward cells
// j = 0..n-1-i (even slots) and downward cells j = 0..n-2-i (odd slots).
inline int CellIndex(int n, int i, int j, bool down) { return 2 * n * i - i * i + 2 * j + down; }

inline bool CellValid(int n, int i, int j, bool down) {
  return i >= 0 && j >= 0 && i + j <= n - 1 - (down ? 1 : 0);
}

// Locates (u, v) in the lattice of an n-subdivided triangle.
void Locate(int n, double u, double v, int* i, int* j, bool* down, double* fx, double* fy) {
  u = std::clamp(u, 0.0, 1.0);
  v = std::clamp(v, 0.0, 1.0);
  if (u + v > 1) {
    const double s = u + v;
    u /= s;
    v /= s;
  }
  const double x = u * n, y = v * n;
  int a = std::clamp(static_cast<int>(std::floor(x)), 0, n - 1);
  int b = std::clamp(static_cast<int>(std::floor(y)), 0, n - 1);
  if (a + b > n - 1) {  // on the far edge after rounding: step back into the triangle
    if (a >= b)
      a = n - 1 - b;
    else
      b = n - 1 - a;
  }
  double ffx = x - a, ffy = y - b;
  bool d = ffx + ffy > 1.0 && CellValid(n, a, b, true);
  *i = a;
  *j = b;
  *down = d;
  *fx = ffx;
  *fy = ffy;
}

}  // namespace

void GridOptions::Validate() const {
  if (!(std::isfinite(spacing_m) && spacing_m > 0)) {
    throw Error("GridOptions: spacing_m must be positive and finite, got " +
                std::to_string(spacing_m));
  }
  for (const auto& [name, s] : block_spacing_m) {
    if (!(std::isfinite(s) && s > 0)) {
      throw Error("GridOptions: spacing for block '" + name +
                  "' must be positive and finite, got " + std::to_string(s));
    }
  }
  if (max_subdivision < 1) throw Error("GridOptions: max_subdivision must be >= 1");
}

double GridOptions::SpacingFor(const std::string& block) const {
  auto it = block_spacing_m.find(block);
  return it == block_spacing_m.end() ? spacing_m : it->second;
}

void to_json(nlohmann::json& j, const GridOptions& o) {
  j = nlohmann::json{
      {"spacing_m", o.spacing_m},
      {"subdivision",
       o.subdivision == GridSubdivision::kLongestEdge ? "longest_edge" : "equivalent_area"},
      {"block_spacing_m", o.block_spacing_m},
      {"max_subdivision", o.max_subdivision}};
}

void from_json(const nlohmann::json& j, GridOptions& o) {
  try {
    o = GridOptions();
    o.spacing_m = j.at("spacing_m").get<double>();
    if (j.contains("block_spacing_m")) {
      o.block_spacing_m = j.at("block_spacing_m").get<std::map<std::string, double>>();
    }
    if (j.contains("max_subdivision"))
      o.max_subdivision = JsonGet<int>(j.at("max_subdivision"), "max_subdivision");
    if (j.contains("subdivision")) {
      const std::string s = j.at("subdivision").get<std::string>();
      if (s == "longest_edge") {
        o.subdivision = GridSubdivision::kLongestEdge;
      } else if (s == "equivalent_area") {
        o.subdivision = GridSubdivision::kEquivalentArea;
      } else {
        throw Error("grid options: unknown subdivision '" + s + "'");
      }
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("grid options: ") + e.what());
  }
  o.Validate();
}

namespace {

// Triangle t's subdivisions per edge (n: n^2 grid points), 0 for a degenerate or malformed one.
int Subdivisions(const Mesh& mesh, int t, const GridOptions& options) {
  const Eigen::Vector3i& f = mesh.triangles[t];
  if (f.minCoeff() < 0 || f.maxCoeff() >= static_cast<int>(mesh.vertices.size())) return 0;
  const Eigen::Vector3d& a = mesh.vertices[f[0]];
  const Eigen::Vector3d& b = mesh.vertices[f[1]];
  const Eigen::Vector3d& c = mesh.vertices[f[2]];
  const double area = 0.5 * (b - a).cross(c - a).norm();
  const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
  if (!std::isfinite(area) || !(area > 1e-12 * longest * longest) || !(longest > 0)) return 0;
  const int block = t < static_cast<int>(mesh.triangle_block.size()) ? mesh.triangle_block[t] : -1;
  const std::string name = block >= 0 && block < static_cast<int>(mesh.block_names.size())
                               ? mesh.block_names[block]
                               : "";
  const double spacing = options.SpacingFor(name);
  const double size = options.subdivision == GridSubdivision::kLongestEdge
                          ? longest
                          : std::sqrt(4.0 * area / std::sqrt(3.0));
  return std::clamp(static_cast<int>(std::ceil(size / spacing - 1e-9)), 1, options.max_subdivision);
}

}  // namespace

int64_t CountGridPoints(const Mesh& mesh, const GridOptions& options) {
  options.Validate();
  int64_t points = 0;
  for (int t = 0; t < static_cast<int>(mesh.triangles.size()); ++t) {
    const int64_t n = Subdivisions(mesh, t, options);
    points += n * n;
  }
  return points;
}

SurfaceGrid BuildSurfaceGrid(const Mesh& mesh, const GridOptions& options) {
  options.Validate();
  SurfaceGrid grid;
  const int num_tris = static_cast<int>(mesh.triangles.size());
  grid.triangle_first.assign(num_tris + 1, 0);
  grid.triangle_n.assign(num_tris, 0);
  for (int t = 0; t < num_tris; ++t) {
    grid.triangle_first[t] = grid.size();
    const int n = Subdivisions(mesh, t, options);
    if (n == 0) {
      ++grid.skipped_triangles;
      continue;
    }
    const Eigen::Vector3i& f = mesh.triangles[t];
    const Eigen::Vector3d& a = mesh.vertices[f[0]];
    const Eigen::Vector3d& b = mesh.vertices[f[1]];
    const Eigen::Vector3d& c = mesh.vertices[f[2]];
    const Eigen::Vector3d cross = (b - a).cross(c - a);
    const double area = 0.5 * cross.norm();
    const int block =
        t < static_cast<int>(mesh.triangle_block.size()) ? mesh.triangle_block[t] : -1;
    grid.triangle_n[t] = n;
    const Eigen::Vector3d normal = cross.normalized();
    const double cell_area = area / (static_cast<double>(n) * n);
    const Eigen::Vector3d eb = (b - a) / n, ec = (c - a) / n;
    for (int i = 0; i < n; ++i) {
      for (int s = 0; s < 2 * (n - i) - 1; ++s) {
        const int j = s / 2;
        const bool down = s % 2 == 1;
        const double off = down ? 2.0 / 3.0 : 1.0 / 3.0;
        GridPoint p;
        p.position = a + (i + off) * eb + (j + off) * ec;
        p.normal = normal;
        p.triangle = t;
        p.block = block;
        p.area = cell_area;
        grid.points.push_back(p);
      }
    }
  }
  grid.triangle_first[num_tris] = grid.size();
  return grid;
}

int SurfaceGrid::NearestPoint(int triangle, double u, double v) const {
  if (triangle < 0 || triangle >= static_cast<int>(triangle_n.size())) return -1;
  const int n = triangle_n[triangle];
  if (n == 0) return -1;
  int i, j;
  bool down;
  double fx, fy;
  Locate(n, u, v, &i, &j, &down, &fx, &fy);
  return triangle_first[triangle] + CellIndex(n, i, j, down);
}

GridStencil SurfaceGrid::Stencil(int triangle, double u, double v) const {
  GridStencil st;
  if (triangle < 0 || triangle >= static_cast<int>(triangle_n.size())) return st;
  const int n = triangle_n[triangle];
  if (n == 0) return st;
  const int first = triangle_first[triangle];
  if (n == 1) {
    st.count = 1;
    st.index[0] = first;
    st.weight[0] = 1;
    return st;
  }
  int i, j;
  bool down;
  double fx, fy;
  Locate(n, u, v, &i, &j, &down, &fx, &fy);
  // Lattice vertices of the cell and the linear weights of (u, v) inside it.
  std::array<std::array<int, 2>, 3> verts;
  std::array<double, 3> w;
  if (!down) {
    verts = {{{i, j}, {i + 1, j}, {i, j + 1}}};
    w = {1 - fx - fy, fx, fy};
  } else {
    verts = {{{i + 1, j + 1}, {i, j + 1}, {i + 1, j}}};
    w = {fx + fy - 1, 1 - fx, 1 - fy};
  }
  for (double& x : w) x = std::clamp(x, 0.0, 1.0);
  const double wsum = w[0] + w[1] + w[2];
  for (int k = 0; k < 3; ++k) {
    if (w[k] <= 0) continue;
    const int a = verts[k][0], b = verts[k][1];
    // Cells around lattice vertex (a, b).
    const std::array<std::array<int, 3>, 6> cells = {
        {{a, b, 0}, {a - 1, b, 0}, {a, b - 1, 0}, {a - 1, b, 1}, {a, b - 1, 1}, {a - 1, b - 1, 1}}};
    int valid[6];
    int nvalid = 0;
    for (int c = 0; c < 6; ++c) {
      if (CellValid(n, cells[c][0], cells[c][1], cells[c][2] != 0)) {
        valid[nvalid++] = first + CellIndex(n, cells[c][0], cells[c][1], cells[c][2] != 0);
      }
    }
    for (int c = 0; c < nvalid; ++c) {
      const double wc = w[k] / wsum / nvalid;
      int slot = -1;
      for (int s = 0; s < st.count; ++s) {
        if (st.index[s] == valid[c]) slot = s;
      }
      if (slot < 0) {
        slot = st.count++;
        st.index[slot] = valid[c];
        st.weight[slot] = 0;
      }
      st.weight[slot] += wc;
    }
  }
  return st;
}

Eigen::Vector3d SurfaceGrid::Interpolate(const std::vector<Eigen::Vector3d>& values, int triangle,
                                         double u, double v) const {
  const GridStencil st = Stencil(triangle, u, v);
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  for (int s = 0; s < st.count; ++s) out += st.weight[s] * values[st.index[s]];
  return out;
}

}  // namespace rouen
