#include "solve/vector_flux.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Plane-side tolerance for unit vectors (about 2e-7 degrees).
constexpr double kSideEps = 1e-12;

// Removes consecutive (and first/last) vertices closer than ~1e-13 rad.
void DropDuplicates(SphericalPolygon* p) {
  if (p->size() < 2) return;
  SphericalPolygon q;
  q.reserve(p->size());
  for (const auto& v : *p) {
    if (q.empty() || (v - q.back()).squaredNorm() > 1e-26) q.push_back(v);
  }
  while (q.size() > 1 && (q.front() - q.back()).squaredNorm() <= 1e-26) q.pop_back();
  p->swap(q);
}

Eigen::Vector3d Direction(double el, double az) {
  return {std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el)};
}

// A cap about the normalised vertex mean holding every vertex (and so, when it is smaller
// than a hemisphere, every short arc between them).
void BoundingCap(const SphericalPolygon& p, Eigen::Vector3d* centre, double* radius) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& v : p) c += v;
  const double len = c.norm();
  if (!(len > 1e-9)) {
    *centre = Eigen::Vector3d::UnitZ();
    *radius = kPi;
    return;
  }
  c /= len;
  double min_dot = 1;
  for (const auto& v : p) min_dot = std::min(min_dot, c.dot(v));
  *centre = c;
  *radius = std::acos(std::clamp(min_dot, -1.0, 1.0)) + 1e-12;
}

}  // namespace

// App. A, eq. 20 (generalised to any spherical polygon).
Eigen::Vector3d VectorFlux(const SphericalPolygon& poly) {
  Eigen::Vector3d phi = Eigen::Vector3d::Zero();
  const size_t n = poly.size();
  if (n < 2) return phi;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& a = poly[i];
    const Eigen::Vector3d& b = poly[(i + 1) % n];
    const Eigen::Vector3d c = a.cross(b);
    const double s = c.norm();
    if (s < 1e-300) continue;
    const double theta = std::atan2(s, a.dot(b));
    phi += (theta / s) * c;
  }
  return 0.5 * phi;
}

double SolidAngle(const SphericalPolygon& poly) {
  double omega = 0;
  for (size_t i = 1; i + 1 < poly.size(); ++i) {
    const Eigen::Vector3d& a = poly[0];
    const Eigen::Vector3d& b = poly[i];
    const Eigen::Vector3d& c = poly[i + 1];
    const double num = a.dot(b.cross(c));
    const double den = 1 + a.dot(b) + b.dot(c) + c.dot(a);
    omega += 2 * std::atan2(num, den);
  }
  return omega;
}

SphericalPolygon ClipToHalfSpace(const SphericalPolygon& poly, const Eigen::Vector3d& m) {
  SphericalPolygon out;
  const size_t n = poly.size();
  if (n < 3) return out;
  out.reserve(n + 2);
  const double scale = m.norm();
  if (!(scale > 0)) return out;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& a = poly[i];
    const Eigen::Vector3d& b = poly[(i + 1) % n];
    const double da = m.dot(a) / scale, db = m.dot(b) / scale;
    const bool ina = da >= -kSideEps, inb = db >= -kSideEps;
    if (ina) out.push_back(a);
    if (ina != inb && std::abs(da - db) > 0) {
      // The chord meets the plane where the great arc does (both lie in the plane of O, a, b).
      const double t = da / (da - db);
      const Eigen::Vector3d x = a + t * (b - a);
      const double len = x.norm();
      if (len > 0) out.push_back(x / len);
    }
  }
  DropDuplicates(&out);
  if (out.size() < 3) out.clear();
  return out;
}

bool ConvexSpherical::Set(const SphericalPolygon& ccw) {
  SphericalPolygon v = ccw;
  DropDuplicates(&v);
  if (v.size() < 3) return false;
  std::vector<Eigen::Vector3d> normals;
  for (size_t i = 0; i < v.size(); ++i) {
    const Eigen::Vector3d c = v[i].cross(v[(i + 1) % v.size()]);
    const double s = c.norm();
    if (!(s > 1e-14)) return false;
    normals.push_back(c / s);
  }
  vertices = std::move(v);
  edge_normal = std::move(normals);
  BoundingCap(vertices, &cap_centre, &cap_radius);
  cap_cos = std::cos(cap_radius);
  cap_sin = std::sin(cap_radius);
  return true;
}

void SubtractConvex(const SphericalPolygon& p, const ConvexSpherical& q,
                    std::vector<SphericalPolygon>* outside, std::vector<SphericalPolygon>* inside) {
  if (p.size() < 3) return;
  // Bounding caps apart (valid for caps smaller than a hemisphere): the angle between the
  // centres exceeds the sum of the radii.
  if (q.cap_radius < kPi / 2) {
    Eigen::Vector3d pc = Eigen::Vector3d::Zero();
    for (const auto& v : p) pc += v;
    const double len = pc.norm();
    if (len > 1e-9) {
      pc /= len;
      double pcos = 1;
      for (const auto& v : p) pcos = std::min(pcos, pc.dot(v));
      pcos -= 1e-12;
      if (pcos > 0) {
        const double psin = std::sqrt(std::max(0.0, 1 - pcos * pcos));
        if (pc.dot(q.cap_centre) < pcos * q.cap_cos - psin * q.cap_sin) {
          outside->push_back(p);
          return;
        }
      }
    }
  }
  // Entirely on the outer side of one edge's great circle: disjoint from q.
  for (const auto& m : q.edge_normal) {
    bool all_out = true;
    for (const auto& v : p) {
      if (m.dot(v) > kSideEps) {
        all_out = false;
        break;
      }
    }
    if (all_out) {
      outside->push_back(p);
      return;
    }
  }
  SphericalPolygon rest = p;
  for (const auto& m : q.edge_normal) {
    SphericalPolygon out = ClipToHalfSpace(rest, -m);
    if (!out.empty()) outside->push_back(std::move(out));
    rest = ClipToHalfSpace(rest, m);
    if (rest.empty()) return;
  }
  if (inside != nullptr) inside->push_back(std::move(rest));
}

bool ProjectPolygon(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& origin,
                    const Eigen::Vector3d& normal, ConvexSpherical* out) {
  // Clip the planar polygon (relative to the origin) to normal.x >= 0 in 3-D.
  std::vector<Eigen::Vector3d> rel;
  const size_t n = points.size();
  rel.reserve(n + 2);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d a = points[i] - origin, b = points[(i + 1) % n] - origin;
    const double da = normal.dot(a), db = normal.dot(b);
    if (da >= 0) rel.push_back(a);
    if ((da >= 0) != (db >= 0)) rel.push_back(a + (da / (da - db)) * (b - a));
  }
  if (rel.size() < 3) return false;
  // Orientation as seen from the origin: Newell normal against the plane's offset.
  Eigen::Vector3d newell = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < rel.size(); ++i) newell += rel[i].cross(rel[(i + 1) % rel.size()]);
  const double area2 = newell.norm();
  if (!(area2 > 0)) return false;
  const double dist = newell.dot(rel[0]) / area2;  // signed distance of the plane from origin
  double extent = 0;
  for (const auto& r : rel) extent = std::max(extent, r.norm());
  if (std::abs(dist) <= 1e-9 * extent) return false;  // seen edge-on
  SphericalPolygon s;
  s.reserve(rel.size());
  for (const auto& r : rel) {
    const double len = r.norm();
    if (!(len > 0)) return false;  // the origin lies on the polygon
    s.push_back(r / len);
  }
  if (dist < 0) std::reverse(s.begin(), s.end());
  return out->Set(s);
}

PointVisibility::PointVisibility(const Mesh& mesh, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& normal, int own_triangle)
    : origin_(origin), normal_(normal) {
  std::vector<std::pair<double, ConvexSpherical>> found;
  const int nt = static_cast<int>(mesh.triangles.size());
  for (int t = 0; t < nt; ++t) {
    if (t == own_triangle) continue;
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const std::vector<Eigen::Vector3d> pts = {mesh.vertices[tri[0]], mesh.vertices[tri[1]],
                                              mesh.vertices[tri[2]]};
    bool front = false;
    for (const auto& v : pts) front |= normal.dot(v - origin) > 0;
    if (!front) continue;
    ConvexSpherical cs;
    if (!ProjectPolygon(pts, origin, normal, &cs)) continue;
    const double omega = std::abs(SolidAngle(cs.vertices));
    if (!(omega > 0)) continue;
    found.emplace_back(omega, std::move(cs));
  }
  std::sort(found.begin(), found.end(),
            [](const auto& a, const auto& b) { return a.first > b.first; });
  occluders_.reserve(found.size());
  for (auto& f : found) occluders_.push_back(std::move(f.second));
}

void PointVisibility::Clip(const SphericalPolygon& patch, std::vector<SphericalPolygon>* out) const {
  SphericalPolygon front = ClipToHalfSpace(patch, normal_);
  if (front.empty()) return;
  std::vector<SphericalPolygon> pieces = {std::move(front)}, next;
  for (const auto& occ : occluders_) {
    next.clear();
    for (const auto& p : pieces) SubtractConvex(p, occ, &next);
    pieces.swap(next);
    if (pieces.empty()) return;
  }
  for (auto& p : pieces) out->push_back(std::move(p));
}

void VectorFluxOptions::Validate() const {
  if (sky_initial_split < 0 || sky_initial_split > 4) {
    throw Error("VectorFluxOptions: sky_initial_split must be in 0..4, got " +
                std::to_string(sky_initial_split));
  }
  if (!(sky_tolerance > 0 && sky_tolerance < 10)) {
    throw Error("VectorFluxOptions: sky_tolerance must be in (0, 10)");
  }
  if (sky_max_depth < 0 || sky_max_depth > 30) {
    throw Error("VectorFluxOptions: sky_max_depth must be in 0..30");
  }
  if (!(sky_min_sr >= 0 && sky_min_sr < 1)) {
    throw Error("VectorFluxOptions: sky_min_sr must be in [0, 1)");
  }
  if (env_parallel_segments < 1 || env_parallel_segments > 64) {
    throw Error("VectorFluxOptions: env_parallel_segments must be in 1..64");
  }
}

namespace {

void SplitTriangle(const SphericalPolygon& t, int levels, std::vector<SphericalPolygon>* out) {
  if (levels == 0) {
    out->push_back(t);
    return;
  }
  const Eigen::Vector3d ab = (t[0] + t[1]).normalized(), bc = (t[1] + t[2]).normalized(),
                        ca = (t[2] + t[0]).normalized();
  SplitTriangle({t[0], ab, ca}, levels - 1, out);
  SplitTriangle({ab, t[1], bc}, levels - 1, out);
  SplitTriangle({ca, bc, t[2]}, levels - 1, out);
  SplitTriangle({ab, bc, ca}, levels - 1, out);
}

struct SkyAdaptive {
  const SkyModel& sky;
  const Eigen::Vector3d& normal;
  const VectorFluxOptions& o;
  FluxStats* stats;

  Eigen::Vector3d L(const Eigen::Vector3d& d) const { return sky.Radiance(d); }

  // Sum of L(centre) n.Phi over the patch, split until the radiance is nearly uniform.
  Eigen::Vector3d Patch(const SphericalPolygon& p, int depth) const {
    const Eigen::Vector3d phi = VectorFlux(p);
    const double len = phi.norm();
    if (!(len > 0)) return Eigen::Vector3d::Zero();
    const Eigen::Vector3d c = phi / len;
    const Eigen::Vector3d lc = L(c);
    bool split = false;
    if (depth < o.sky_max_depth && SolidAngle(p) > o.sky_min_sr) {
      Eigen::Vector3d lo = lc, hi = lc, sum = lc;
      int count = 1;
      auto add = [&](const Eigen::Vector3d& d) {
        const Eigen::Vector3d l = L(d);
        lo = lo.cwiseMin(l);
        hi = hi.cwiseMax(l);
        sum += l;
        ++count;
      };
      for (size_t i = 0; i < p.size(); ++i) {
        add(p[i]);
        add((p[i] + p[(i + 1) % p.size()]).normalized());
      }
      // The circumsolar peak: sample the sun when it lies inside the (convex) patch.
      bool sun_inside = true;
      for (size_t i = 0; i < p.size() && sun_inside; ++i) {
        sun_inside = p[i].cross(p[(i + 1) % p.size()]).dot(sky.sun_dir) >= 0;
      }
      if (sun_inside) add(sky.sun_dir);
      const Eigen::Vector3d mean = sum / count;
      for (int ch = 0; ch < 3; ++ch) {
        if (hi[ch] - lo[ch] > o.sky_tolerance * std::max(mean[ch], 1e-300)) split = true;
      }
    }
    if (!split) {
      if (stats) ++stats->patches;
      return lc * normal.dot(phi);
    }
    // Cut through the centre across the patch's widest vertex pair.
    double best = 2;
    size_t bi = 0, bj = 0;
    for (size_t i = 0; i < p.size(); ++i) {
      for (size_t j = i + 1; j < p.size(); ++j) {
        const double d = p[i].dot(p[j]);
        if (d < best) best = d, bi = i, bj = j;
      }
    }
    Eigen::Vector3d m = p[bi] - p[bj];
    m -= m.dot(c) * c;
    if (!(m.norm() > 1e-15)) {
      if (stats) ++stats->patches;
      return lc * normal.dot(phi);
    }
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& side : {m, Eigen::Vector3d(-m)}) {
      const SphericalPolygon half = ClipToHalfSpace(p, side);
      if (!half.empty()) e += Patch(half, depth + 1);
    }
    return e;
  }
};

}  // namespace

Eigen::Vector3d SkyIrradianceVectorFlux(const PointVisibility& vis, const SkyModel& sky,
                                        const VectorFluxOptions& options, FluxStats* stats) {
  if (stats) stats->occluders = vis.num_occluders();
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const std::array<Eigen::Vector3d, 4> h = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                            -Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY()};
  std::vector<SphericalPolygon> patches, visible;
  // Counter-clockwise seen from outside: horizon point, the next one anticlockwise (seen from
  // above), zenith.
  for (int q = 0; q < 4; ++q) SplitTriangle({h[q], h[(q + 1) % 4], z}, options.sky_initial_split,
                                            &patches);
  for (const auto& p : patches) vis.Clip(p, &visible);
  const SkyAdaptive adapt{sky, vis.normal(), options, stats};
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  for (const auto& p : visible) e += adapt.Patch(p, 0);
  return e;
}

std::vector<SphericalPolygon> EnvironmentRegionPolygons(const EnvironmentMap& env,
                                                        const VectorFluxOptions& options) {
  std::vector<SphericalPolygon> regions(env.num_regions());
  for (int r = 0; r < env.num_regions(); ++r) {
    double el0, el1, az0, az1;
    env.RegionBounds(r, &el0, &el1, &az0, &az1);
    const int seg = std::max(options.env_parallel_segments,
                             static_cast<int>(std::ceil((az1 - az0) / (kPi / 3) - 1e-9)));
    SphericalPolygon p;
    for (int k = 0; k <= seg; ++k) p.push_back(Direction(el0, az0 + (az1 - az0) * k / seg));
    for (int k = seg; k >= 0; --k) p.push_back(Direction(el1, az0 + (az1 - az0) * k / seg));
    DropDuplicates(&p);
    // Azimuth runs clockwise seen from above: make the loop counter-clockwise from outside.
    const Eigen::Vector3d mid = Direction((el0 + el1) / 2, (az0 + az1) / 2);
    if (VectorFlux(p).dot(mid) < 0) std::reverse(p.begin(), p.end());
    regions[r] = std::move(p);
  }
  return regions;
}

Eigen::Vector3d EnvironmentIrradianceVectorFlux(
    const PointVisibility& vis, const EnvironmentMap& env, double z,
    const std::vector<SphericalPolygon>& regions, const std::vector<ConvexSpherical>* ground_shadow,
    const Eigen::Vector3d& shadow_ratio, FluxStats* stats) {
  if (static_cast<int>(regions.size()) != env.num_regions()) {
    throw Error("vector flux: " + std::to_string(regions.size()) +
                " region polygons for an environment map of " +
                std::to_string(env.num_regions()) + " regions");
  }
  if (stats) stats->occluders = vis.num_occluders();
  const Eigen::Vector3d& n = vis.normal();
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  std::vector<SphericalPolygon> visible, rest, next, inside;
  double el0, el1, az0, az1;
  for (int r = 0; r < env.num_regions(); ++r) {
    visible.clear();
    vis.Clip(regions[r], &visible);
    if (visible.empty()) continue;
    env.RegionBounds(r, &el0, &el1, &az0, &az1);
    const Eigen::Vector3d l = env.Radiance(Direction((el0 + el1) / 2, (az0 + az1) / 2), z);
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    for (const auto& p : visible) phi += VectorFlux(p);
    e += l * n.dot(phi);
    if (stats) stats->patches += static_cast<int>(visible.size());
    if (ground_shadow == nullptr || ground_shadow->empty() || el0 >= 0) continue;
    // Shadowed ground: the union of the (overlapping) shadow polygons, taken apart piece by
    // piece so no direction counts twice.
    Eigen::Vector3d phi_shadow = Eigen::Vector3d::Zero();
    rest = visible;
    for (const auto& s : *ground_shadow) {
      next.clear();
      inside.clear();
      for (const auto& p : rest) SubtractConvex(p, s, &next, &inside);
      for (const auto& p : inside) phi_shadow += VectorFlux(p);
      rest.swap(next);
      if (rest.empty()) break;
    }
    e += l.cwiseProduct(shadow_ratio - Eigen::Vector3d::Ones()) * n.dot(phi_shadow);
  }
  return e;
}

std::vector<ConvexSpherical> GroundShadowPolygons(const Mesh& mesh, const Eigen::Vector3d& sun,
                                                  double ground_z, const Eigen::Vector3d& origin) {
  std::vector<ConvexSpherical> out;
  if (!(sun.z() > 1e-9) || !(origin.z() > ground_z)) return out;
  const Eigen::Vector3d down = -Eigen::Vector3d::UnitZ();
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    std::vector<Eigen::Vector3d> g;
    bool above = false;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& v = mesh.vertices[mesh.triangles[t][k]];
      const double h = v.z() - ground_z;
      above |= h > 1e-9;
      g.push_back(v - (h / sun.z()) * sun);
      g.back().z() = ground_z;
    }
    if (!above) continue;  // a face on the ground shades nothing beyond itself
    ConvexSpherical cs;
    if (ProjectPolygon(g, origin, down, &cs)) out.push_back(std::move(cs));
  }
  return out;
}

}  // namespace rouen
