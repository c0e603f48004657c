// Texture atlases of values on the surface grid (§4.1's grid points: albedos, flags), one per
// block of the model, with the texture coordinates that map the model onto them, so that other
// tools (Blender, a glTF viewer) can show what rouen recovered without rouen's grid code.
//
// Each triangle with grid points gets a square tile of n x k texels (n: its subdivision, k:
// texels per grid cell) plus a one-texel border; barycentric (u, v) maps to the tile's lower
// triangle, the upper one mirrors it so that bilinear filtering never reads an unset texel.
// Tiles are packed on shelves, tallest first.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/mesh.h"
#include "solve/grid.h"

namespace rouen {

struct AtlasOptions {
  int texels_per_cell = 2;  // k: texels along one grid cell's edge
  int max_side = 8192;      // an atlas wider than this is an error (coarser grid, smaller k)
  void Validate() const;    // throws rouen::Error
};

struct AtlasTile {
  int block = -1;
  int x = 0, y = 0;  // top-left texel of the tile (with its border) in the block's atlas
  int size = 0;      // texels along the tile's edge without the border (0: no tile)
};

struct AtlasLayout {
  std::vector<int> width, height;  // per block; 0 x 0 for a block without grid points
  std::vector<AtlasTile> tiles;    // per triangle
  int texels_per_cell = 2;

  // Texture coordinate (OBJ/glTF convention: origin at the bottom-left, v up) of barycentric
  // (u, v) of `triangle` (p = (1-u-v) a + u b + v c) in its block's atlas.
  Eigen::Vector2d Uv(int triangle, double u, double v) const;
};

// Lays out every triangle of `grid` (built on `mesh`); throws rouen::Error when a block's
// atlas would exceed options.max_side.
AtlasLayout LayoutAtlases(const Mesh& mesh, const SurfaceGrid& grid, const AtlasOptions& options);

// The atlas of `block`: every texel of every tile holds the grid's interpolated value
// (SurfaceGrid::Interpolate) at the texel's centre; texels outside all tiles are 0.
Image BakeAtlas(const AtlasLayout& layout, const SurfaceGrid& grid,
                const std::vector<Eigen::Vector3d>& values, int block);

// An OBJ of `mesh` with per-corner texture coordinates into the atlases and an MTL beside it
// naming, per block, the texture file `textures[block]` (relative to the OBJ's folder; a
// block with an empty name has no texture). Written atomically.
void WriteTexturedObj(const std::filesystem::path& obj, const Mesh& mesh, const AtlasLayout& layout,
                      const std::vector<std::string>& textures);

}  // namespace rouen
