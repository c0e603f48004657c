// Small meshes and skies shared by the solve tests (not part of the library API).
#pragma once

#include <Eigen/Core>

#include "core/mesh.h"
#include "solve/sky_model.h"

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

// A sky of uniform radiance l in every channel (eq. 9 with a = c = e = 0).
inline SkyModel UniformSkyModel(double l) {
  SkyModel m;
  for (auto& c : m.channel) c = SkyParams{l, 0, 0, 0, 0, 0, 1};
  return m;
}

// A CIE-like clear sky with a strong circumsolar peak, the sun towards `sun`.
inline SkyModel ClearSky(const Eigen::Vector3d& sun) {
  SkyModel m;
  m.channel[0] = SkyParams{1.0, -1.0, -0.32, 10, -3, 0.45, 1};
  m.channel[1] = SkyParams{1.2, -1.0, -0.4, 12, -3.2, 0.5, 1};
  m.channel[2] = SkyParams{1.5, -1.0, -0.5, 8, -2.5, 0.3, 1};
  m.sun_dir = sun.normalized();
  return m;
}

}  // namespace rouen::testing
