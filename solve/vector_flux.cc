#include "solve/vector_flux.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <unordered_map>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {

namespace {

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

namespace {

// Cheap tests that `p` (edges great arcs shorter than pi) and the convex `q` are disjoint:
// bounding caps apart, or every vertex of p outside one edge of q (or, when p is convex, every
// vertex of q outside one edge of p).
// A bounding cap of a polygon's vertices (about their normalised mean); `valid` false when
// it is not smaller than a hemisphere.
struct Cap {
  Eigen::Vector3d centre;
  double cos = -1, sin = 0;
  bool valid = false;
  explicit Cap(const SphericalPolygon& p) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& v : p) c += v;
    const double len = c.norm();
    if (!(len > 1e-9)) return;
    centre = c / len;
    double m = 1;
    for (const auto& v : p) m = std::min(m, centre.dot(v));
    m -= 1e-12;
    if (!(m > 0)) return;
    cos = m;
    sin = std::sqrt(std::max(0.0, 1 - m * m));
    valid = true;
  }
};

bool Disjoint(const SphericalPolygon& p, const Cap& pcap, const ConvexSpherical& q, bool p_convex) {
  // Bounding caps apart (valid for caps smaller than a hemisphere): the angle between the
  // centres exceeds the sum of the radii.
  if (pcap.valid && q.cap_radius < kPi / 2 &&
      pcap.centre.dot(q.cap_centre) < pcap.cos * q.cap_cos - pcap.sin * q.cap_sin) {
    return true;
  }
  for (const auto& m : q.edge_normal) {
    bool all_out = true;
    for (const auto& v : p) {
      if (m.dot(v) > kSideEps) {
        all_out = false;
        break;
      }
    }
    if (all_out) return true;
  }
  if (p_convex) {
    const size_t n = p.size();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d m = p[i].cross(p[(i + 1) % n]);
      const double s = m.norm();
      if (!(s > 1e-14)) continue;
      bool all_out = true;
      for (const auto& v : q.vertices) {
        if (m.dot(v) > kSideEps * s) {
          all_out = false;
          break;
        }
      }
      if (all_out) return true;
    }
  }
  return false;
}

// Every vertex of `p` inside the convex `q`: p lies inside q.
bool Inside(const SphericalPolygon& p, const ConvexSpherical& q) {
  for (const auto& m : q.edge_normal) {
    for (const auto& v : p) {
      if (m.dot(v) < -kSideEps) return false;
    }
  }
  return true;
}

}  // namespace

void SubtractConvex(const SphericalPolygon& p, const ConvexSpherical& q,
                    std::vector<SphericalPolygon>* outside, std::vector<SphericalPolygon>* inside) {
  if (p.size() < 3) return;
  if (Disjoint(p, Cap(p), q, false)) {
    outside->push_back(p);
    return;
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

FaceAdjacency::FaceAdjacency(const Mesh& mesh) {
  const int nt = static_cast<int>(mesh.triangles.size());
  const int nv = static_cast<int>(mesh.vertices.size());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& v : mesh.vertices) {
    if (!v.allFinite()) continue;
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const double extent = (hi - lo).allFinite() ? std::max((hi - lo).norm(), 1e-9) : 1.0;
  const double q = 1e-9 * extent;
  // Weld: vertex -> representative id by quantised position.
  struct KeyHash {
    size_t operator()(const std::array<int64_t, 3>& k) const {
      return std::hash<int64_t>()(k[0] * 73856093 ^ k[1] * 19349663 ^ k[2] * 83492791);
    }
  };
  std::unordered_map<std::array<int64_t, 3>, int, KeyHash> ids;
  std::vector<int> weld(nv, -1);
  for (int i = 0; i < nv; ++i) {
    const Eigen::Vector3d& v = mesh.vertices[i];
    if (!v.allFinite()) continue;
    const std::array<int64_t, 3> key = {std::llround((v.x() - lo.x()) / q),
                                        std::llround((v.y() - lo.y()) / q),
                                        std::llround((v.z() - lo.z()) / q)};
    weld[i] = ids.emplace(key, static_cast<int>(ids.size())).first->second;
  }
  std::vector<std::vector<int>> faces_of(ids.size());
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      const int v = mesh.triangles[t][k];
      if (v >= 0 && v < nv && weld[v] >= 0) faces_of[weld[v]].push_back(t);
    }
  }
  offset_.assign(nt + 1, 0);
  std::vector<int> nb;
  for (int t = 0; t < nt; ++t) {
    nb.clear();
    for (int k = 0; k < 3; ++k) {
      const int v = mesh.triangles[t][k];
      if (v < 0 || v >= nv || weld[v] < 0) continue;
      for (int f : faces_of[weld[v]]) {
        if (f != t) nb.push_back(f);
      }
    }
    std::sort(nb.begin(), nb.end());
    nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
    list_.insert(list_.end(), nb.begin(), nb.end());
    offset_[t + 1] = static_cast<int>(list_.size());
  }
}

void OccluderSelectOptions::Validate() const {
  if (resolution < 1 || resolution > 4096) {
    throw Error("OccluderSelectOptions: resolution must be in 1..4096, got " +
                std::to_string(resolution));
  }
  if (grow_rings < 0 || grow_rings > 8) {
    throw Error("OccluderSelectOptions: grow_rings must be in 0..8, got " +
                std::to_string(grow_rings));
  }
}

std::vector<int> SelectOccluders(const Mesh& mesh, const RayCaster& model,
                                 const FaceAdjacency& adjacency, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& normal, int own_triangle,
                                 const OccluderSelectOptions& options, int* rays) {
  const int nt = static_cast<int>(mesh.triangles.size());
  if (adjacency.num_faces() != nt) {
    throw Error("occluder selection: the adjacency has " + std::to_string(adjacency.num_faces()) +
                " faces but the mesh " + std::to_string(nt));
  }
  // Tangent frame about the normal.
  Eigen::Vector3d t =
      std::abs(normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  t = (t - t.dot(normal) * normal).normalized();
  const Eigen::Vector3d b = normal.cross(t);
  // Polar angle and azimuth about the normal in equal steps: n_theta x n_phi = resolution^2
  // pixels; near the tangent plane (faces low on the horizon) the pixels are thin in polar
  // angle, where a projected-solid-angle layout would leave wide gaps.
  const int res = options.resolution;
  const int n_theta = std::max(1, res / 2), n_phi = (res * res + n_theta - 1) / n_theta;
  std::vector<int> ids(static_cast<size_t>(n_theta) * n_phi, -1);
  std::vector<Eigen::Vector3d> dirs(ids.size());
  std::vector<int> hit;
  for (int i = 0; i < n_theta; ++i) {
    const double theta = (i + 0.5) / n_theta * (kPi / 2);
    const double st = std::sin(theta), ct = std::cos(theta);
    for (int j = 0; j < n_phi; ++j) {
      const double phi = (j + 0.5) / n_phi * (2 * kPi);
      const Eigen::Vector3d d =
          (st * std::cos(phi) * t + st * std::sin(phi) * b + ct * normal).normalized();
      const RayHit h = model.Intersect(origin, d, 0.0);
      dirs[static_cast<size_t>(i) * n_phi + j] = d;
      if (h.hit && h.triangle >= 0 && h.triangle < nt) {
        hit.push_back(h.triangle);
        ids[static_cast<size_t>(i) * n_phi + j] = h.triangle;
      }
    }
  }
  if (rays) *rays = n_theta * n_phi;
  std::sort(hit.begin(), hit.end());
  hit.erase(std::unique(hit.begin(), hit.end()), hit.end());
  // Silhouette pixels (an id differing from a neighbour's): faces no ray hit can only show
  // between pixel centres there -- or inside one pixel anywhere. Every face in front whose
  // bounding cap reaches a silhouette pixel is added.
  struct EdgePixel {
    Eigen::Vector3d dir;
    double radius;
  };
  std::vector<EdgePixel> edges;
  const double dtheta = (kPi / 2) / n_theta, dphi = 2 * kPi / n_phi;
  for (int i = 0; i < n_theta; ++i) {
    const double smax = std::sin(std::min(kPi / 2, (i + 1) * dtheta));
    const double radius = 1.05 * std::hypot(dtheta / 2, smax * dphi / 2);
    for (int j = 0; j < n_phi; ++j) {
      const int id = ids[static_cast<size_t>(i) * n_phi + j];
      bool edge = ids[static_cast<size_t>(i) * n_phi + (j + 1) % n_phi] != id ||
                  ids[static_cast<size_t>(i) * n_phi + (j + n_phi - 1) % n_phi] != id;
      if (i > 0) edge |= ids[static_cast<size_t>(i - 1) * n_phi + j] != id;
      if (i + 1 < n_theta) edge |= ids[static_cast<size_t>(i + 1) * n_phi + j] != id;
      if (edge) edges.push_back({dirs[static_cast<size_t>(i) * n_phi + j], radius});
    }
  }
  if (!edges.empty()) {
    std::vector<int> extra;
    for (int f = 0; f < nt; ++f) {
      if (f == own_triangle || std::binary_search(hit.begin(), hit.end(), f)) continue;
      const Eigen::Vector3i& tri = mesh.triangles[f];
      if (tri.minCoeff() < 0 || tri.maxCoeff() >= static_cast<int>(mesh.vertices.size())) continue;
      const std::vector<Eigen::Vector3d> pts = {mesh.vertices[tri[0]], mesh.vertices[tri[1]],
                                                mesh.vertices[tri[2]]};
      bool front = false;
      for (const auto& v : pts) front |= normal.dot(v - origin) > 0;
      if (!front) continue;
      ConvexSpherical cs;
      if (!ProjectPolygon(pts, origin, normal, &cs)) continue;
      for (const auto& e : edges) {
        if (e.dir.dot(cs.cap_centre) >= std::cos(std::min(kPi, cs.cap_radius + e.radius))) {
          extra.push_back(f);
          break;
        }
      }
    }
    std::vector<int> merged;
    std::merge(hit.begin(), hit.end(), extra.begin(), extra.end(), std::back_inserter(merged));
    hit.swap(merged);
  }
  std::vector<int> ring = hit, next;
  for (int g = 0; g < options.grow_rings && !ring.empty(); ++g) {
    next.clear();
    for (int f : ring) next.insert(next.end(), adjacency.begin(f), adjacency.end(f));
    std::sort(next.begin(), next.end());
    next.erase(std::unique(next.begin(), next.end()), next.end());
    ring.clear();
    std::set_difference(next.begin(), next.end(), hit.begin(), hit.end(), std::back_inserter(ring));
    std::vector<int> merged;
    std::merge(hit.begin(), hit.end(), ring.begin(), ring.end(), std::back_inserter(merged));
    hit.swap(merged);
  }
  if (own_triangle >= 0) {
    auto it = std::lower_bound(hit.begin(), hit.end(), own_triangle);
    if (it != hit.end() && *it == own_triangle) hit.erase(it);
  }
  return hit;
}

void PointVisibility::Add(const Mesh& mesh, int t, std::vector<Candidate>* found) const {
  const Eigen::Vector3i& tri = mesh.triangles[t];
  const int nv = static_cast<int>(mesh.vertices.size());
  if (tri.minCoeff() < 0 || tri.maxCoeff() >= nv) return;
  const std::vector<Eigen::Vector3d> pts = {mesh.vertices[tri[0]], mesh.vertices[tri[1]],
                                            mesh.vertices[tri[2]]};
  bool front = false;
  for (const auto& v : pts) front |= normal_.dot(v - origin_) > 0;
  if (!front) return;
  Candidate c;
  if (!ProjectPolygon(pts, origin_, normal_, &c.cs)) return;
  c.omega = std::abs(SolidAngle(c.cs.vertices));
  if (!(c.omega > 0)) return;
  c.plane_n = (pts[1] - pts[0]).cross(pts[2] - pts[0]).normalized();
  c.plane_d = c.plane_n.dot(pts[0]);
  c.corners = {pts[0], pts[1], pts[2]};
  found->push_back(std::move(c));
}

void PointVisibility::Finish(std::vector<Candidate>* found) {
  std::sort(found->begin(), found->end(),
            [](const Candidate& a, const Candidate& b) { return a.omega > b.omega; });
  std::vector<int> kept;
  for (int k = 0; k < static_cast<int>(found->size()); ++k) {
    const Candidate& f = (*found)[k];
    bool hidden = false;
    for (int j : kept) {
      const Candidate& q = (*found)[j];
      const double so = q.plane_n.dot(origin_) - q.plane_d;  // the origin's side of q
      if (!(std::abs(so) > 0)) continue;
      bool behind = true;
      const double tol = 1e-9 * (1 + std::abs(q.plane_d));
      for (const auto& v : f.corners) {
        const double sv = q.plane_n.dot(v) - q.plane_d;
        if (so > 0 ? sv > tol : sv < -tol) {
          behind = false;
          break;
        }
      }
      if (behind && Inside(f.cs.vertices, q.cs)) {
        hidden = true;
        break;
      }
    }
    if (hidden) {
      ++culled_;
    } else {
      kept.push_back(k);
    }
  }
  occluders_.reserve(kept.size());
  for (int k : kept) occluders_.push_back(std::move((*found)[k].cs));
}

PointVisibility::PointVisibility(const Mesh& mesh, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& normal, int own_triangle)
    : origin_(origin), normal_(normal) {
  std::vector<Candidate> found;
  const int nt = static_cast<int>(mesh.triangles.size());
  for (int t = 0; t < nt; ++t) {
    if (t != own_triangle) Add(mesh, t, &found);
  }
  Finish(&found);
}

PointVisibility::PointVisibility(const Mesh& mesh, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& normal, int own_triangle,
                                 const std::vector<int>& candidates)
    : origin_(origin), normal_(normal) {
  std::vector<Candidate> found;
  const int nt = static_cast<int>(mesh.triangles.size());
  for (int t : candidates) {
    if (t >= 0 && t < nt && t != own_triangle) Add(mesh, t, &found);
  }
  Finish(&found);
}

void PointVisibility::Clip(const SphericalPolygon& patch,
                           std::vector<SphericalPolygon>* out) const {
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

void PointVisibility::ClipWith(const SphericalPolygon& patch, const std::vector<int>& subset,
                               std::vector<SphericalPolygon>* out) const {
  SphericalPolygon front = ClipToHalfSpace(patch, normal_);
  if (front.empty()) return;
  std::vector<SphericalPolygon> pieces = {std::move(front)}, next;
  for (int k : subset) {
    next.clear();
    for (const auto& p : pieces) SubtractConvex(p, occluders_[k], &next);
    pieces.swap(next);
    if (pieces.empty()) return;
  }
  for (auto& p : pieces) out->push_back(std::move(p));
}

PointVisibility::Cover PointVisibility::Classify(const SphericalPolygon& patch,
                                                 const std::vector<int>* subset, bool convex,
                                                 std::vector<int>* overlapping) const {
  bool all_front = true, all_back = true;
  for (const auto& v : patch) {
    const double d = normal_.dot(v);
    all_front &= d >= 0;
    all_back &= d <= kSideEps;
  }
  if (all_back) return Cover::kHidden;
  const size_t start = overlapping->size();
  const Cap cap(patch);
  auto test = [&](int k) {
    const ConvexSpherical& q = occluders_[k];
    if (Disjoint(patch, cap, q, convex)) return false;
    if (Inside(patch, q)) return true;
    overlapping->push_back(k);
    return false;
  };
  if (subset != nullptr) {
    for (int k : *subset) {
      if (test(k)) {
        overlapping->resize(start);
        return Cover::kHidden;
      }
    }
  } else {
    for (int k = 0; k < num_occluders(); ++k) {
      if (test(k)) {
        overlapping->resize(start);
        return Cover::kHidden;
      }
    }
  }
  if (all_front && overlapping->size() == start) return Cover::kFull;
  return Cover::kPartial;
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
  if (sky_tree_levels < 0 || sky_tree_levels > 9) {
    throw Error("VectorFluxOptions: sky_tree_levels must be in 0..9, got " +
                std::to_string(sky_tree_levels));
  }
  select.Validate();
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
  for (int q = 0; q < 4; ++q)
    SplitTriangle({h[q], h[(q + 1) % 4], z}, options.sky_initial_split, &patches);
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

Eigen::Vector3d EnvironmentIrradianceVectorFlux(const PointVisibility& vis,
                                                const EnvironmentMap& env, double z,
                                                const std::vector<SphericalPolygon>& regions,
                                                const std::vector<ConvexSpherical>* ground_shadow,
                                                const Eigen::Vector3d& shadow_ratio,
                                                FluxStats* stats) {
  if (static_cast<int>(regions.size()) != env.num_regions()) {
    throw Error("vector flux: " + std::to_string(regions.size()) +
                " region polygons for an environment map of " + std::to_string(env.num_regions()) +
                " regions");
  }
  if (stats) stats->occluders = vis.num_occluders();
  const Eigen::Vector3d& n = vis.normal();
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  std::vector<SphericalPolygon> visible, rest, next, inside;
  std::vector<int> overlap;
  double el0, el1, az0, az1;
  for (int r = 0; r < env.num_regions(); ++r) {
    visible.clear();
    overlap.clear();
    // Cheap whole-region tests first (behind the plane, inside one occluder, or untouched).
    const PointVisibility::Cover cover = vis.Classify(regions[r], nullptr, false, &overlap);
    if (cover == PointVisibility::Cover::kHidden) continue;
    if (cover == PointVisibility::Cover::kFull) {
      visible.push_back(regions[r]);
    } else {
      vis.ClipWith(regions[r], overlap, &visible);
    }
    if (visible.empty()) continue;
    env.RegionBounds(r, &el0, &el1, &az0, &az1);
    const Eigen::Vector3d l = env.Radiance(Direction((el0 + el1) / 2, (az0 + az1) / 2), z);
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    for (const auto& p : visible) phi += VectorFlux(p);
    e += l * n.dot(phi);
    if (stats) stats->patches += static_cast<int>(visible.size());
    if (ground_shadow == nullptr || ground_shadow->empty() || el0 >= 0) continue;
    // Shadowed ground: the union of the (overlapping) shadow polygons, taken apart piece by
    // piece so no direction counts twice; shadows clear of the whole region are skipped.
    Eigen::Vector3d phi_shadow = Eigen::Vector3d::Zero();
    const Cap region_cap(regions[r]);
    rest = visible;
    for (const auto& s : *ground_shadow) {
      if (Disjoint(regions[r], region_cap, s, false)) continue;
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
