#include "solve/ground_apron.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/error.h"
#include "core/limits.h"
#include "solve/environment.h"

namespace rouen {

void GroundApronOptions::Validate() const {
  if (!(radius_m >= 0 && radius_m <= 10000))
    throw Error("ground.radius_m must be within 0..10000 metres, not " + FormatNumber(radius_m));
  if (!(cell_m >= 0.01 && cell_m <= 100))
    throw Error("ground.cell_m must be within 0.01..100 metres, not " + FormatNumber(cell_m));
  if (!(max_face_m >= cell_m && max_face_m <= 10000))
    throw Error("ground.max_face_m must be at least ground.cell_m (" + FormatNumber(cell_m) +
                ") and at most 10000 metres, not " + FormatNumber(max_face_m));
  if (block.empty()) throw Error("ground.block must name a block");
  if (!(spacing_m >= 0.01 && spacing_m <= 100))
    throw Error("ground.spacing_m must be within 0.01..100 metres, not " + FormatNumber(spacing_m));
}

GroundApronSummary AddGroundApron(const RayCaster& model, const GroundApronOptions& options,
                                  Mesh* mesh) {
  options.Validate();
  GroundApronSummary summary;
  summary.level_z = GroundLevel(model);
  if (options.radius_m == 0) return summary;
  if (model.bounds().isEmpty()) throw Error("ground: the model has no vertices to stand on");
  if (std::find(mesh->block_names.begin(), mesh->block_names.end(), options.block) !=
      mesh->block_names.end())
    throw Error("ground: the model already has a block named '" + options.block +
                "' (name the modelled ground otherwise: ground.block)");

  // Cells of cell_m from the grown rectangle's south-west corner (the last row and column cut
  // at its edge), in tiles of at most max_face_m.
  const Eigen::AlignedBox3d& box = model.bounds();
  const double c = options.cell_m;
  const double x0 = box.min().x() - options.radius_m, y0 = box.min().y() - options.radius_m;
  const double wx = box.sizes().x() + 2 * options.radius_m;
  const double wy = box.sizes().y() + 2 * options.radius_m;
  if (wx / c * (wy / c) > 5e7)
    throw Error("ground: " + FormatNumber(wx) + " x " + FormatNumber(wy) + " m in cells of " +
                FormatNumber(c) + " m is too many cells (raise ground.cell_m)");
  const int nx = std::max(1, static_cast<int>(std::ceil(wx / c - 1e-9)));
  const int ny = std::max(1, static_cast<int>(std::ceil(wy / c - 1e-9)));
  const int per_tile = std::max(1, static_cast<int>(std::floor(options.max_face_m / c + 1e-9)));
  const int tiles_x = (nx + per_tile - 1) / per_tile, tiles_y = (ny + per_tile - 1) / per_tile;
  auto edge_x = [&](int i) { return std::min(x0 + i * c, x0 + wx); };
  auto edge_y = [&](int j) { return std::min(y0 + j * c, y0 + wy); };

  // A cell is under the model when a ray up from just below the ground meets the back of a face
  // first (inside a building without a bottom, or under the model's own level ground).
  const double z = summary.level_z;
  const double below = z - model.surface_offset();
  std::vector<char> keep(static_cast<size_t>(nx) * ny, 1);
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const Eigen::Vector3d o(0.5 * (edge_x(i) + edge_x(i + 1)), 0.5 * (edge_y(j) + edge_y(j + 1)),
                              below);
      const RayHit h = model.Intersect(o, up);
      if (h.hit && mesh->Normal(h.triangle).z() > 0) {
        keep[static_cast<size_t>(j) * nx + i] = 0;
        ++summary.cells_under_model;
      } else {
        ++summary.cells_kept;
      }
    }
  }

  // Within each tile, the kept cells merged greedily into rectangles (rows first, then grown
  // upwards while the whole span is kept), each a face facing up.
  const int block = mesh->AddBlock(options.block);
  std::vector<char> used(keep.size(), 0);
  auto free_cell = [&](int i, int j) {
    const size_t k = static_cast<size_t>(j) * nx + i;
    return keep[k] && !used[k];
  };
  for (int ty = 0; ty < tiles_y; ++ty) {
    for (int tx = 0; tx < tiles_x; ++tx) {
      const int i0 = tx * per_tile, i1 = std::min(nx, i0 + per_tile);
      const int j0 = ty * per_tile, j1 = std::min(ny, j0 + per_tile);
      for (int j = j0; j < j1; ++j) {
        for (int i = i0; i < i1; ++i) {
          if (!free_cell(i, j)) continue;
          int ie = i + 1;
          while (ie < i1 && free_cell(ie, j)) ++ie;
          int je = j + 1;
          for (; je < j1; ++je) {
            bool row = true;
            for (int k = i; k < ie && row; ++k) row = free_cell(k, je);
            if (!row) break;
          }
          for (int jj = j; jj < je; ++jj)
            for (int ii = i; ii < ie; ++ii) used[static_cast<size_t>(jj) * nx + ii] = 1;
          const double ax = edge_x(i), bx = edge_x(ie), ay = edge_y(j), by = edge_y(je);
          // Counter-clockwise seen from above: the face's outward normal is up.
          mesh->AddPolygon({{ax, ay, z}, {bx, ay, z}, {bx, by, z}, {ax, by, z}}, block);
          ++summary.faces;
          summary.area_m2 += (bx - ax) * (by - ay);
        }
      }
    }
  }
  return summary;
}

Mesh WithGroundApron(Mesh model, const GroundApronOptions& options, GroundApronSummary* summary) {
  GroundApronSummary s;
  if (options.radius_m > 0) s = AddGroundApron(RayCaster(model), options, &model);
  if (summary) *summary = s;
  return model;
}

void to_json(nlohmann::json& j, const GroundApronOptions& o) {
  j = {{"radius_m", o.radius_m},
       {"cell_m", o.cell_m},
       {"max_face_m", o.max_face_m},
       {"block", o.block},
       {"spacing_m", o.spacing_m}};
}

void from_json(const nlohmann::json& j, GroundApronOptions& o) {
  o = GroundApronOptions{};
  o.radius_m = j.value("radius_m", o.radius_m);
  o.cell_m = j.value("cell_m", o.cell_m);
  o.max_face_m = j.value("max_face_m", o.max_face_m);
  o.block = j.value("block", o.block);
  o.spacing_m = j.value("spacing_m", o.spacing_m);
  o.Validate();
}

}  // namespace rouen
