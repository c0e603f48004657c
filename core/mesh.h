// Triangle meshes from Wavefront OBJ; OBJ groups ("g name") become blocks.
#pragma once

#include <Eigen/Core>
#include <string>
#include <string_view>
#include <vector>

namespace rouen {

struct Mesh {
  std::vector<Eigen::Vector3d> vertices;   // world frame (ENU metres)
  std::vector<Eigen::Vector3i> triangles;  // counter-clockwise seen from outside
  std::vector<int> triangle_block;         // block index per triangle
  std::vector<std::string> block_names;

  Eigen::Vector3d Normal(int t) const;  // unit outward normal
  double Area(int t) const;
  int AddBlock(const std::string& name);
  void AddTriangle(int a, int b, int c, int block);
  // Adds a planar convex polygon (vertices counter-clockwise seen from outside) as a fan.
  void AddPolygon(const std::vector<Eigen::Vector3d>& points, int block);
  // Adds every triangle of `other` in blocks of their own, in `other`'s block order. Throws
  // rouen::Error naming a block `other` shares with this mesh.
  void Append(const Mesh& other);
};

// Throws rouen::Error with file and line for malformed input (bad indices, bad numbers,
// faces with fewer than 3 vertices, degenerate triangles), and naming the file for a model
// with no faces at all (empty, or comments only).
Mesh ReadObj(const std::string& path);
// The same from the text of an OBJ file; `name` (the file) is used in messages.
Mesh ParseObj(std::string_view text, const std::string& name);
// Reads the OBJ at `path` (ReadObj) and appends it to `mesh` (Mesh::Append); returns its block
// names. Throws rouen::Error naming `path` for a malformed file or a block `mesh` has too.
std::vector<std::string> AppendObj(const std::string& path, Mesh* mesh);
void WriteObj(const std::string& path, const Mesh& mesh);

}  // namespace rouen
