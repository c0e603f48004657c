#include "capture/sim/sim_scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>

#include "core/angles.h"

namespace rouen::sim {
namespace {

struct Wave {
  Eigen::Vector3d k;  // 2 pi direction / wavelength (1/m)
  double phase;
};

struct AlbedoField {
  Eigen::Vector3d base;
  std::array<Wave, 3> waves;  // shared by the channels (brightness pattern)
  Wave tint;                  // small per-channel pattern
  Eigen::Vector3d tint_phase;
};

// Deterministic pseudo-random numbers for the fixed albedo patterns.
double Lcg(uint64_t* s) {
  *s = *s * 6364136223846793005ULL + 1442695040888963407ULL;
  return static_cast<double>(*s >> 11) * (1.0 / 9007199254740992.0);
}

Eigen::Vector3d RandomUnit(uint64_t* s) {
  const double z = 2 * Lcg(s) - 1, phi = 2 * kPi * Lcg(s);
  const double r = std::sqrt(std::max(0.0, 1 - z * z));
  return Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z);
}

AlbedoField MakeField(int material, const Eigen::Vector3d& base, double min_wl, double max_wl) {
  AlbedoField f;
  f.base = base;
  uint64_t s = 0x9E3779B97F4A7C15ULL * (material + 1);
  for (Wave& w : f.waves) {
    const double wl = min_wl + (max_wl - min_wl) * Lcg(&s);
    w.k = RandomUnit(&s) * (2 * kPi / wl);
    w.phase = 2 * kPi * Lcg(&s);
  }
  f.tint.k = RandomUnit(&s) * (2 * kPi / (min_wl + (max_wl - min_wl) * Lcg(&s)));
  f.tint.phase = 0;
  f.tint_phase = Eigen::Vector3d(0, 2.1, 4.2) + Eigen::Vector3d::Constant(2 * kPi * Lcg(&s));
  return f;
}

const std::array<AlbedoField, kMaterialCount>& Fields() {
  static const std::array<AlbedoField, kMaterialCount> fields = {
      MakeField(kStone, {0.55, 0.50, 0.42}, 3, 10),
      MakeField(kRoofMetal, {0.28, 0.40, 0.34}, 3, 8),
      MakeField(kPaving, {0.28, 0.27, 0.26}, 4, 10),
      MakeField(kBlockA, {0.45, 0.26, 0.19}, 3, 10),   // brick
      MakeField(kBlockB, {0.62, 0.57, 0.47}, 3, 10),   // beige render
      MakeField(kBlockC, {0.30, 0.33, 0.38}, 3, 10),   // grey-blue concrete
      MakeField(kBlockD, {0.66, 0.62, 0.42}, 3, 10),   // pale yellow
      MakeField(kBlockE, {0.24, 0.34, 0.20}, 3, 10),   // hedge green
      MakeField(kGround, {0.20, 0.19, 0.14}, 20, 60),  // dry grass and soil
  };
  return fields;
}

Patch MakeRect(const Eigen::Vector3d& o, const Eigen::Vector3d& eu, const Eigen::Vector3d& ev) {
  Patch p;
  p.o = o;
  p.su = eu.norm();
  p.sv = ev.norm();
  p.u = eu / p.su;
  p.v = ev / p.sv;
  p.n = p.u.cross(p.v).normalized();
  assert(std::abs(p.u.dot(p.v)) < 1e-9);
  return p;
}

// Triangle a, b, c counter-clockwise seen from outside.
Patch MakeTri(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  Patch p;
  p.triangle = true;
  p.o = a;
  p.su = (b - a).norm();
  p.u = (b - a) / p.su;
  p.n = (b - a).cross(c - a).normalized();
  p.v = p.n.cross(p.u);
  p.sv = (c - a).dot(p.v);
  p.apex_s = (c - a).dot(p.u);
  return p;
}

class Builder {
 public:
  explicit Builder(SceneGeometry* g) : g_(g) {}

  int Block(const std::string& name) {
    g_->block_names.push_back(name);
    return static_cast<int>(g_->block_names.size()) - 1;
  }
  void Add(Patch p, int world_block, int model_block, int material, double texel) {
    p.world_block = world_block;
    p.model_block = model_block;
    p.material = material;
    p.texel_m = texel;
    g_->patches.push_back(p);
  }

  // Tower parts are built in the tower's own frame and rotated about z.
  Eigen::Vector3d T(const Eigen::Vector3d& p) const { return rot_ * p; }
  void SetRotation(double deg) {
    rot_ = Eigen::AngleAxisd(deg * kPi / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }

  // Vertical rectangle with outward horizontal normal m (tower frame), on the plane
  // m.p = d, spanning s in [s0, s1] along e = z x m and z in [z0, z1].
  void Vertical(const Eigen::Vector3d& m, double d, double s0, double s1, double z0, double z1,
                int wb, int mb, int mat, double texel) {
    const Eigen::Vector3d e = Eigen::Vector3d::UnitZ().cross(m);
    const Eigen::Vector3d o = d * m + s0 * e + z0 * Eigen::Vector3d::UnitZ();
    Add(MakeRect(T(o), rot_ * ((s1 - s0) * e), rot_ * ((z1 - z0) * Eigen::Vector3d::UnitZ())), wb,
        mb, mat, texel);
  }
  // Horizontal rectangle [x0,x1] x [y0,y1] at height z, facing up or down (tower frame).
  void Horizontal(double x0, double x1, double y0, double y1, double z, bool up, int wb, int mb,
                  int mat, double texel) {
    const Eigen::Vector3d o(x0, y0, z);
    const Eigen::Vector3d ex(x1 - x0, 0, 0), ey(0, y1 - y0, 0);
    if (up) {
      Add(MakeRect(T(o), rot_ * ex, rot_ * ey), wb, mb, mat, texel);
    } else {
      Add(MakeRect(T(o), rot_ * ey, rot_ * ex), wb, mb, mat, texel);
    }
  }
  // The ring between squares of half-sizes a < b at height z, as four pinwheel rectangles.
  void Ring(double a, double b, double z, bool up, int wb, int mb, int mat, double texel) {
    Horizontal(a, b, -a, b, z, up, wb, mb, mat, texel);
    Horizontal(-b, a, a, b, z, up, wb, mb, mat, texel);
    Horizontal(-b, -a, -b, a, z, up, wb, mb, mat, texel);
    Horizontal(-a, b, -b, -a, z, up, wb, mb, mat, texel);
  }
  // A wall of half-width hw between z0 and z1 with a centred hole (half-width hh, hz0..hz1).
  void WallWithHole(const Eigen::Vector3d& m, double d, double hw, double z0, double z1, double hh,
                    double hz0, double hz1, int wb, int mb, int mat, double texel) {
    Vertical(m, d, -hw, hw, z0, hz0, wb, mb, mat, texel);
    Vertical(m, d, -hw, hw, hz1, z1, wb, mb, mat, texel);
    Vertical(m, d, -hw, -hh, hz0, hz1, wb, mb, mat, texel);
    Vertical(m, d, hh, hw, hz0, hz1, wb, mb, mat, texel);
  }
  void Tri(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, int wb,
           int mb, int mat, double texel) {
    Add(MakeTri(T(a), T(b), T(c)), wb, mb, mat, texel);
  }

 private:
  SceneGeometry* g_;
  Eigen::Matrix3d rot_ = Eigen::Matrix3d::Identity();
};

void AddPatchToMesh(const Patch& p, Mesh* mesh) {
  const int base = static_cast<int>(mesh->vertices.size());
  if (p.triangle) {
    mesh->vertices.push_back(p.o);
    mesh->vertices.push_back(p.Point(p.su, 0));
    mesh->vertices.push_back(p.Point(p.apex_s, p.sv));
    mesh->AddTriangle(base, base + 1, base + 2, p.model_block);
    return;
  }
  mesh->vertices.push_back(p.o);
  mesh->vertices.push_back(p.Point(p.su, 0));
  mesh->vertices.push_back(p.Point(p.su, p.sv));
  mesh->vertices.push_back(p.Point(0, p.sv));
  mesh->AddTriangle(base, base + 1, base + 2, p.model_block);
  mesh->AddTriangle(base, base + 2, base + 3, p.model_block);
}

// The plaza for the model: the square [-h, h]^2 minus the tower's rotated base footprint,
// triangulated by zipping the two outlines (both star-shaped around the origin) by angle.
void AddPlazaToMesh(double h, double base_half, double rot_deg, int block, Mesh* mesh) {
  struct Pt {
    Eigen::Vector3d p;
    double angle;
  };
  std::vector<Pt> outer, inner;
  const double c = std::cos(rot_deg * kPi / 180), s = std::sin(rot_deg * kPi / 180);
  const double corners[4][2] = {{1, 1}, {-1, 1}, {-1, -1}, {1, -1}};
  for (const auto& k : corners) {
    const Eigen::Vector3d po(h * k[0], h * k[1], 0);
    const Eigen::Vector3d pi(base_half * (c * k[0] - s * k[1]), base_half * (s * k[0] + c * k[1]),
                             0);
    outer.push_back({po, std::atan2(po.y(), po.x())});
    inner.push_back({pi, std::atan2(pi.y(), pi.x())});
  }
  auto by_angle = [](const Pt& a, const Pt& b) { return a.angle < b.angle; };
  std::sort(inner.begin(), inner.end(), by_angle);
  const double a0 = inner[0].angle;
  for (Pt& q : outer) {
    while (q.angle < a0) q.angle += 2 * kPi;
    while (q.angle >= a0 + 2 * kPi) q.angle -= 2 * kPi;
  }
  std::sort(outer.begin(), outer.end(), by_angle);
  // P: inner outline closed back to its start; Q: outer outline from the vertex before a0.
  std::vector<Pt> pp(inner), qq;
  pp.push_back({inner[0].p, inner[0].angle + 2 * kPi});
  qq.push_back({outer[3].p, outer[3].angle - 2 * kPi});
  for (const Pt& q : outer) qq.push_back(q);
  auto add_tri = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                     const Eigen::Vector3d& cc) {
    const int base = static_cast<int>(mesh->vertices.size());
    const bool ccw = (b - a).cross(cc - a).z() > 0;
    mesh->vertices.push_back(a);
    mesh->vertices.push_back(ccw ? b : cc);
    mesh->vertices.push_back(ccw ? cc : b);
    mesh->AddTriangle(base, base + 1, base + 2, block);
  };
  size_t i = 0, o = 0;
  while (i + 1 < pp.size() || o + 1 < qq.size()) {
    const double next_inner = i + 1 < pp.size() ? pp[i + 1].angle : 1e30;
    const double next_outer = o + 1 < qq.size() ? qq[o + 1].angle : 1e30;
    if (next_inner <= next_outer) {
      add_tri(pp[i].p, qq[o].p, pp[i + 1].p);
      ++i;
    } else {
      add_tri(pp[i].p, qq[o].p, qq[o + 1].p);
      ++o;
    }
  }
}

}  // namespace

Eigen::Vector3d MaterialAlbedo(int material, const Eigen::Vector3d& p) {
  const AlbedoField& f = Fields()[std::clamp(material, 0, kMaterialCount - 1)];
  double sum = 0;
  for (const Wave& w : f.waves) sum += std::sin(w.k.dot(p) + w.phase);
  const double tint_arg = f.tint.k.dot(p);
  Eigen::Vector3d out;
  for (int c = 0; c < 3; ++c) {
    const double tint = 0.04 * std::sin(tint_arg + f.tint_phase[c]);
    out[c] = std::clamp(f.base[c] * (1.0 + 0.12 * sum + tint), 0.05, 0.8);
  }
  return out;
}

MaterialGloss MaterialSpecular(int material) {
  if (material == kRoofMetal) return {0.07, 20.0};
  return {};
}

Eigen::Vector3d Patch::Closest(const Eigen::Vector3d& p) const {
  const Eigen::Vector2d st = Local(p);
  if (!triangle) {
    return Point(std::clamp(st.x(), 0.0, su), std::clamp(st.y(), 0.0, sv));
  }
  // Closest point on a 2-D triangle (a, b, c) to q.
  const Eigen::Vector2d a(0, 0), b(su, 0), c(apex_s, sv), q = st;
  auto cross = [](const Eigen::Vector2d& x, const Eigen::Vector2d& y) {
    return x.x() * y.y() - x.y() * y.x();
  };
  const bool inside =
      cross(b - a, q - a) >= 0 && cross(c - b, q - b) >= 0 && cross(a - c, q - c) >= 0;
  if (inside) return Point(q.x(), q.y());
  auto seg = [](const Eigen::Vector2d& x, const Eigen::Vector2d& y, const Eigen::Vector2d& z) {
    const Eigen::Vector2d d = y - x;
    const double t = std::clamp((z - x).dot(d) / d.squaredNorm(), 0.0, 1.0);
    return Eigen::Vector2d(x + t * d);
  };
  Eigen::Vector2d best = seg(a, b, q);
  for (const Eigen::Vector2d& cand : {seg(b, c, q), seg(c, a, q)}) {
    if ((cand - q).squaredNorm() < (best - q).squaredNorm()) best = cand;
  }
  return Point(best.x(), best.y());
}

double Patch::Distance(const Eigen::Vector3d& p) const { return (Closest(p) - p).norm(); }

int Patch::TexelAt(double s, double t) const {
  const int i = std::clamp(static_cast<int>(std::floor(s / du)), 0, nu - 1);
  const int j = std::clamp(static_cast<int>(std::floor(t / dv)), 0, nv - 1);
  return texel_offset + j * nu + i;
}

SceneGeometry BuildScene(const TexelSizes& sizes) {
  SceneGeometry g;
  Builder b(&g);
  const Eigen::Vector3d ex = Eigen::Vector3d::UnitX(), ey = Eigen::Vector3d::UnitY();
  const std::array<Eigen::Vector3d, 4> sides = {ex, ey, -ex, -ey};

  // Model blocks (the building model the solver gets).
  const int m_base = g.model.AddBlock("base");
  const int m_shaft = g.model.AddBlock("shaft");
  const int m_belfry = g.model.AddBlock("belfry");
  const int m_roof = g.model.AddBlock("roof");
  const int m_plaza = g.model.AddBlock("plaza");
  const int w_base = b.Block("base"), w_shaft = b.Block("shaft"), w_belfry = b.Block("belfry"),
            w_roof = b.Block("roof"), w_plaza = b.Block("plaza");

  // The tower, in its own frame rotated by 40 degrees about z.
  b.SetRotation(g.tower_rotation_deg);
  const double tt = sizes.tower_m;
  for (const Eigen::Vector3d& m : sides) {
    b.Vertical(m, 7.0, -7.0, 7.0, 0.0, 8.0, w_base, m_base, kStone, tt);     // base 14x14x8
    b.Vertical(m, 4.5, -4.5, 4.5, 8.0, 48.0, w_shaft, m_shaft, kStone, tt);  // shaft 9x9
    // Belfry 10x10, 48..58 m, walls 0.8 m thick with a 4 x 6 m opening on each side.
    b.WallWithHole(m, 5.0, 5.0, 48.0, 58.0, 2.0, 50.0, 56.0, w_belfry, m_belfry, kStone, tt);
    b.WallWithHole(-m, -4.2, 4.2, 48.0, 58.0, 2.0, 50.0, 56.0, w_belfry, m_belfry, kStone, tt);
    const Eigen::Vector3d e = Eigen::Vector3d::UnitZ().cross(m);
    // Reveals of the opening: the two sides (facing into the hole), sill and lintel.
    b.Vertical(-e, -2.0, 4.2, 5.0, 50.0, 56.0, w_belfry, m_belfry, kStone, tt);
    b.Vertical(e, -2.0, -5.0, -4.2, 50.0, 56.0, w_belfry, m_belfry, kStone, tt);
    b.Add(MakeRect(b.T(4.2 * m - 2.0 * e + 50.0 * Eigen::Vector3d::UnitZ()), b.T(0.8 * m),
                   b.T(4.0 * e)),
          w_belfry, m_belfry, kStone, tt);
    b.Add(MakeRect(b.T(4.2 * m - 2.0 * e + 56.0 * Eigen::Vector3d::UnitZ()), b.T(4.0 * e),
                   b.T(0.8 * m)),
          w_belfry, m_belfry, kStone, tt);
    // Roof face: base edge of the 10 x 10 square at 58 m, apex at 66 m.
    const Eigen::Vector3d a = 5.0 * m - 5.0 * e + 58.0 * Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d c = 5.0 * m + 5.0 * e + 58.0 * Eigen::Vector3d::UnitZ();
    b.Tri(a, c, Eigen::Vector3d(0, 0, 66.0), w_roof, m_roof, kRoofMetal, tt);
  }
  b.Ring(4.5, 7.0, 8.0, true, w_base, m_base, kStone, tt);        // top of the base
  b.Ring(4.5, 5.0, 48.0, false, w_belfry, m_belfry, kStone, tt);  // belfry overhang, below
  b.Horizontal(-4.2, 4.2, -4.2, 4.2, 48.0, true, w_belfry, m_belfry, kStone, tt);   // floor
  b.Horizontal(-4.2, 4.2, -4.2, 4.2, 58.0, false, w_belfry, m_belfry, kStone, tt);  // ceiling
  // The plaza (in the model) and the ground around it (not in the model).
  b.SetRotation(0);
  b.Horizontal(-50, 50, -50, 50, 0.0, true, w_plaza, m_plaza, kPaving, sizes.plaza_m);
  const int w_ground = b.Block("ground");
  b.Ring(50, g.ground_half_extent_m, 0.0, true, w_ground, -1, kGround, sizes.ground_m);

  // Surrounding blocks: centre (x, y), size (w along x, d along y), height.
  struct Box {
    const char* name;
    double x, y, w, d, h;
    int material;
  };
  const Box boxes[] = {{"block_n", 0, 85, 35, 20, 22, kBlockA},
                       {"block_e", 80, 20, 20, 30, 15, kBlockB},
                       {"block_sw", -70, -55, 25, 25, 12, kBlockC},
                       {"block_sse", 45, -85, 30, 18, 25, kBlockD},
                       {"block_w", -90, 35, 18, 28, 10, kBlockE}};
  for (const Box& box : boxes) {
    const int wb = b.Block(box.name);
    const double hx = box.w / 2, hy = box.d / 2;
    for (const Eigen::Vector3d& m : sides) {
      const double half_normal = std::abs(m.x()) > 0.5 ? hx : hy;
      const double half_along = std::abs(m.x()) > 0.5 ? hy : hx;
      const Eigen::Vector3d e = Eigen::Vector3d::UnitZ().cross(m);
      const Eigen::Vector3d centre(box.x, box.y, 0);
      const Eigen::Vector3d o = centre + half_normal * m - half_along * e;
      b.Add(MakeRect(o, 2 * half_along * e, box.h * Eigen::Vector3d::UnitZ()), wb, -1, box.material,
            sizes.block_m);
    }
    b.Horizontal(box.x - hx, box.x + hx, box.y - hy, box.y + hy, box.h, true, wb, -1, box.material,
                 sizes.block_m);
  }

  // The model mesh: the tower's patches, and the plaza without the base's footprint.
  for (const Patch& p : g.patches) {
    if (p.model_block >= 0 && p.model_block != m_plaza) AddPatchToMesh(p, &g.model);
  }
  AddPlazaToMesh(50.0, 7.0, g.tower_rotation_deg, m_plaza, &g.model);

  // Lighting texel grids.
  int offset = 0;
  for (Patch& p : g.patches) {
    p.nu = std::max(1, static_cast<int>(std::ceil(p.su / p.texel_m - 1e-9)));
    p.nv = std::max(1, static_cast<int>(std::ceil(p.sv / p.texel_m - 1e-9)));
    p.du = p.su / p.nu;
    p.dv = p.sv / p.nv;
    p.texel_offset = offset;
    offset += p.nu * p.nv;
  }
  return g;
}

}  // namespace rouen::sim
