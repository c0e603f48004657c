#include "solve/atlas.h"

#include <algorithm>
#include <cstdio>
#include <numeric>

#include "core/error.h"
#include "core/files.h"

namespace rouen {

void AtlasOptions::Validate() const {
  if (texels_per_cell < 1 || texels_per_cell > 64)
    throw Error("atlas: texels_per_cell must be within 1..64");
  if (max_side < 16 || max_side > kMaxImageSide)
    throw Error("atlas: max_side must be within 16.." + std::to_string(kMaxImageSide));
}

Eigen::Vector2d AtlasLayout::Uv(int triangle, double u, double v) const {
  const AtlasTile& t = tiles.at(triangle);
  if (t.size == 0) return Eigen::Vector2d::Zero();
  const double column = t.x + 1 + u * t.size;  // texel units, from the atlas's left edge
  const double row = t.y + 1 + v * t.size;     // from its top edge
  return Eigen::Vector2d(column / width[t.block], 1 - row / height[t.block]);
}

AtlasLayout LayoutAtlases(const Mesh& mesh, const SurfaceGrid& grid, const AtlasOptions& options) {
  options.Validate();
  const int nblocks = static_cast<int>(mesh.block_names.size());
  const int ntri = static_cast<int>(mesh.triangles.size());
  if (static_cast<int>(grid.triangle_n.size()) != ntri)
    throw Error("atlas: the grid was not built on this mesh");
  AtlasLayout layout;
  layout.texels_per_cell = options.texels_per_cell;
  layout.width.assign(nblocks, 0);
  layout.height.assign(nblocks, 0);
  layout.tiles.assign(ntri, AtlasTile{});
  for (int b = 0; b < nblocks; ++b) {
    std::vector<int> order;
    int64_t area = 0;
    int largest = 0;
    for (int t = 0; t < ntri; ++t) {
      if (mesh.triangle_block[t] != b || grid.triangle_n[t] == 0) continue;
      AtlasTile& tile = layout.tiles[t];
      tile.block = b;
      tile.size = grid.triangle_n[t] * options.texels_per_cell;
      order.push_back(t);
      area += static_cast<int64_t>(tile.size + 2) * (tile.size + 2);
      largest = std::max(largest, tile.size + 2);
    }
    if (order.empty()) continue;
    // Shelves of tiles, tallest first, in a square-ish atlas at least as wide as the largest.
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int c) { return layout.tiles[a].size > layout.tiles[c].size; });
    const int side = std::max(largest, static_cast<int>(std::ceil(std::sqrt(area * 1.1))));
    if (side > options.max_side)
      throw Error("atlas: block '" + mesh.block_names[b] + "' needs " + std::to_string(side) +
                  " texels across, more than " + std::to_string(options.max_side) +
                  " (a coarser grid or fewer texels per cell)");
    int x = 0, y = 0, shelf = 0;
    for (int t : order) {
      AtlasTile& tile = layout.tiles[t];
      const int s = tile.size + 2;
      if (x + s > side) {
        x = 0;
        y += shelf;
        shelf = 0;
      }
      tile.x = x;
      tile.y = y;
      x += s;
      shelf = std::max(shelf, s);
    }
    layout.width[b] = side;
    layout.height[b] = y + shelf;
    if (layout.height[b] > options.max_side)
      throw Error("atlas: block '" + mesh.block_names[b] + "' needs " +
                  std::to_string(layout.height[b]) + " texel rows, more than " +
                  std::to_string(options.max_side));
  }
  return layout;
}

Image BakeAtlas(const AtlasLayout& layout, const SurfaceGrid& grid,
                const std::vector<Eigen::Vector3d>& values, int block) {
  if (static_cast<int>(values.size()) != grid.size())
    throw Error("atlas: " + std::to_string(values.size()) + " values for " +
                std::to_string(grid.size()) + " grid points");
  Image img(layout.width.at(block), layout.height.at(block), 3, PixelUnits::kOther, 0.f);
  for (int t = 0; t < static_cast<int>(layout.tiles.size()); ++t) {
    const AtlasTile& tile = layout.tiles[t];
    if (tile.block != block || tile.size == 0) continue;
    const int s = tile.size;
    // Texel (i, j) of the tile, border included (i, j in -1..s): its centre's barycentric
    // coordinates, clamped into the tile and mirrored into the triangle (u + v <= 1).
    for (int j = -1; j <= s; ++j)
      for (int i = -1; i <= s; ++i) {
        double u = (std::clamp(i, 0, s - 1) + 0.5) / s, v = (std::clamp(j, 0, s - 1) + 0.5) / s;
        if (u + v > 1) {
          const double mu = 1 - v, mv = 1 - u;
          u = mu;
          v = mv;
        }
        const Eigen::Vector3d value = grid.Interpolate(values, t, u, v);
        for (int c = 0; c < 3; ++c)
          img.at(tile.x + 1 + i, tile.y + 1 + j, c) = static_cast<float>(value[c]);
      }
  }
  return img;
}

void WriteTexturedObj(const std::filesystem::path& obj, const Mesh& mesh, const AtlasLayout& layout,
                      const std::vector<std::string>& textures) {
  const int nblocks = static_cast<int>(mesh.block_names.size());
  if (static_cast<int>(textures.size()) != nblocks)
    throw Error(obj.string() + ": one texture per block expected");
  const std::string mtl_name = obj.stem().string() + ".mtl";
  std::string out = "# rouen: the model with texture coordinates into its albedo atlases\n";
  out += "mtllib " + mtl_name + "\n";
  std::string mtl = "# rouen: one material per block, its albedo atlas as the diffuse map\n";
  char buf[160];
  for (const Eigen::Vector3d& v : mesh.vertices) {
    if (!v.allFinite()) throw Error(obj.string() + ": refusing to write a non-finite vertex");
    std::snprintf(buf, sizeof buf, "v %.17g %.17g %.17g\n", v.x(), v.y(), v.z());
    out += buf;
  }
  // Three texture coordinates per triangle, in triangle order.
  const int ntri = static_cast<int>(mesh.triangles.size());
  for (int t = 0; t < ntri; ++t)
    for (const auto& [u, v] : {std::pair{0.0, 0.0}, std::pair{1.0, 0.0}, std::pair{0.0, 1.0}}) {
      const Eigen::Vector2d uv = layout.Uv(t, u, v);
      std::snprintf(buf, sizeof buf, "vt %.9g %.9g\n", uv.x(), uv.y());
      out += buf;
    }
  for (int b = 0; b < nblocks; ++b) {
    std::string name = mesh.block_names[b];
    for (char& ch : name)
      if (ch == '\n' || ch == '\r' || ch == '#' || ch == ' ') ch = '_';
    if (name.empty()) name = "default";
    mtl += "newmtl " + name + "\nKd 1 1 1\n";
    if (!textures[b].empty()) mtl += "map_Kd " + textures[b] + "\n";
    out += "g " + name + "\nusemtl " + name + "\n";
    for (int t = 0; t < ntri; ++t) {
      if (mesh.triangle_block[t] != b) continue;
      const Eigen::Vector3i& tri = mesh.triangles[t];
      std::snprintf(buf, sizeof buf, "f %d/%d %d/%d %d/%d\n", tri[0] + 1, 3 * t + 1, tri[1] + 1,
                    3 * t + 2, tri[2] + 1, 3 * t + 3);
      out += buf;
    }
  }
  WriteFileAtomic(obj, out);
  WriteFileAtomic(obj.parent_path() / mtl_name, mtl);
}

}  // namespace rouen
