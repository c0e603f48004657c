// Small meshes shared by the solve tests (not part of the library API).
#pragma once

#include <Eigen/Core>

#include "core/mesh.h"

namespace rouen::testing {

// An axis-aligned rectangle in the plane z = `z`, [x0, x1] x [y0, y1], normal +z (or -z).
inline void AddHorizontalRect(Mesh* m, double x0, double x1, double y0, double y1, double z,
                              bool up, int block) {
  const int base = static_cast<int>(m->vertices.size());
  m->vertices.push_back({x0, y0, z});
  m->vertices.push_back({x1, y0, z});
  m->vertices.push_back({x1, y1, z});
  m->vertices.push_back({x0, y1, z});
  if (up) {
    m->AddTriangle(base, base + 1, base + 2, block);
    m->AddTriangle(base, base + 2, base + 3, block);
  } else {
    m->AddTriangle(base, base + 2, base + 1, block);
    m->AddTriangle(base, base + 3, base + 2, block);
  }
}

// A closed axis-aligned box [lo, hi] with outward normals (bottom face included when asked).
inline void AddBox(Mesh* m, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int block,
                   bool bottom = false) {
  const double x0 = lo.x(), y0 = lo.y(), z0 = lo.z(), x1 = hi.x(), y1 = hi.y(), z1 = hi.z();
  m->AddPolygon({{x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}}, block);  // top
  m->AddPolygon({{x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}}, block);  // south
  m->AddPolygon({{x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}}, block);  // east
  m->AddPolygon({{x1, y1, z0}, {x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}}, block);  // north
  m->AddPolygon({{x0, y1, z0}, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}}, block);  // west
  if (bottom) m->AddPolygon({{x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, {x1, y0, z0}}, block);
}

}  // namespace rouen::testing
