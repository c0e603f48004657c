#include "solve/vector_flux.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {

namespace {

// Plane-side tolerance for unit vectors (about 2e-7 degrees).
constexpr double kSideEps = 1e-12;

// Removes consecutive (and first/last) vertices closer than ~1e-13 rad (in place: no
// allocation).
void DropDuplicates(SphericalPolygon* p) {
  if (p->size() < 2) return;
  SphericalPolygon& q = *p;
  size_t w = 0;
  for (size_t r = 0; r < q.size(); ++r) {
    if (w == 0 || (q[r] - q[w - 1]).squaredNorm() > 1e-26) q[w++] = q[r];
  }
  while (w > 1 && (q[0] - q[w - 1]).squaredNorm() <= 1e-26) --w;
  q.resize(w);
}

// The cut of ClipToHalfSpace given the vertices' signed distances d[i] = m.v_i / |m|: with
// sign = 1 the part with m.x >= 0, with sign = -1 the part with m.x <= 0 (the same arithmetic
// as cutting by -m: negation is exact, so the vertices are bitwise those of
// ClipToHalfSpace(poly, -m)). Replaces `out` (its storage is reused).
void CutInto(const SphericalPolygon& poly, const std::vector<double>& d, double sign,
             SphericalPolygon* out) {
  out->clear();
  const size_t n = poly.size();
  // Consecutive duplicates dropped as they come (as DropDuplicates would after the cut).
  auto keep = [out](const Eigen::Vector3d& v) {
    if (out->empty() || (v - out->back()).squaredNorm() > 1e-26) out->push_back(v);
  };
  for (size_t i = 0; i < n; ++i) {
    const size_t j = i + 1 == n ? 0 : i + 1;
    const Eigen::Vector3d& a = poly[i];
    const Eigen::Vector3d& b = poly[j];
    const double da = sign * d[i], db = sign * d[j];
    const bool ina = da >= -kSideEps, inb = db >= -kSideEps;
    if (ina) keep(a);
    if (ina != inb && std::abs(da - db) > 0) {
      // The chord meets the plane where the great arc does (both lie in the plane of O, a, b).
      const double t = da / (da - db);
      const Eigen::Vector3d x = a + t * (b - a);
      const double len = x.norm();
      if (len > 0) keep(x / len);
    }
  }
  size_t w = out->size();
  while (w > 1 && ((*out)[0] - (*out)[w - 1]).squaredNorm() <= 1e-26) --w;
  out->resize(w);
  if (out->size() < 3) out->clear();
}

// d[i] = m.v_i / |m| for the vertices of `poly`.
void SignedDistances(const SphericalPolygon& poly, const Eigen::Vector3d& m, double scale,
                     std::vector<double>* d) {
  d->resize(poly.size());
  for (size_t i = 0; i < poly.size(); ++i) (*d)[i] = m.dot(poly[i]) / scale;
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
  if (poly.size() < 3) return out;
  const double scale = m.norm();
  if (!(scale > 0)) return out;
  std::vector<double> d;
  SignedDistances(poly, m, scale, &d);
  out.reserve(poly.size() + 2);
  CutInto(poly, d, 1.0, &out);
  return out;
}

SphericalCap::SphericalCap(const SphericalPolygon& p) {
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
bool Disjoint(const SphericalPolygon& p, const SphericalCap& pcap, const ConvexSpherical& q,
              bool p_convex) {
  // Bounding caps apart (valid for caps smaller than a hemisphere): the angle between the
  // centres exceeds the sum of the radii.
  if (pcap.valid && q.cap_radius < kPi / 2 &&
      pcap.centre.dot(q.cap_centre) < pcap.cos * q.cap_cos - pcap.sin * q.cap_sin) {
    return true;
  }
  for (const auto& m : q.edge_normal) {
    // The whole cap (and so every vertex) beyond this edge's plane: m.x < 0 over the cap when
    // the angle from m to its centre exceeds 90 deg plus its radius.
    if (pcap.valid && m.dot(pcap.centre) < -pcap.sin) return true;
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

namespace {

// A list of polygons whose storage is kept between uses (clear() keeps every polygon's
// capacity), so that clipping in a loop allocates nothing once warm.
class PolygonList {
 public:
  void clear() { count_ = 0; }
  bool empty() const { return count_ == 0; }
  size_t size() const { return count_; }
  SphericalPolygon& operator[](size_t k) { return items_[k]; }
  const SphericalPolygon& operator[](size_t k) const { return items_[k]; }
  // A new, empty polygon at the end.
  SphericalPolygon& Add() {
    if (count_ == items_.size()) items_.emplace_back();
    SphericalPolygon& p = items_[count_++];
    p.clear();
    return p;
  }
  void Add(const SphericalPolygon& p) {
    SphericalPolygon& q = Add();
    q.assign(p.begin(), p.end());
  }
  // Moves `p`'s vertices in (p receives some spare storage).
  void AddSwap(SphericalPolygon* p) { Add().swap(*p); }
  void PopBack() { --count_; }
  void swap(PolygonList& o) {
    items_.swap(o.items_);
    std::swap(count_, o.count_);
  }

 private:
  std::vector<SphericalPolygon> items_;
  size_t count_ = 0;
};

// Buffers of SubtractInto.
struct SubtractScratch {
  std::vector<double> d;
  SphericalPolygon rest, cut;
};

// SubtractConvex into reused storage: the parts of `p` outside `q` appended to `outside`,
// the part inside to `inside` (when not null); the same pieces, bitwise, as cutting by -m and
// m with ClipToHalfSpace for each edge normal m of q, with each vertex's distance to the
// edge's plane computed once for both cuts, and a cut that leaves every vertex on one side
// done without clipping.
void SubtractCut(const SphericalPolygon& p, const ConvexSpherical& q, PolygonList* outside,
                 PolygonList* inside, SubtractScratch* s);

void SubtractInto(const SphericalPolygon& p, const ConvexSpherical& q, PolygonList* outside,
                  PolygonList* inside, SubtractScratch* s) {
  if (p.size() < 3) return;
  if (Disjoint(p, SphericalCap(p), q, false)) {
    outside->Add(p);
    return;
  }
  SubtractCut(p, q, outside, inside, s);
}

// SubtractInto's cuts, for a `p` (3 vertices or more) not known to be disjoint from `q`.
void SubtractCut(const SphericalPolygon& p, const ConvexSpherical& q, PolygonList* outside,
                 PolygonList* inside, SubtractScratch* s) {
  SphericalPolygon& rest = s->rest;
  rest.assign(p.begin(), p.end());
  // Duplicates dropped once: every cut below leaves none.
  DropDuplicates(&rest);
  for (const auto& m : q.edge_normal) {
    const double scale = m.norm();
    if (rest.size() < 3 || !(scale > 0)) return;  // (ClipToHalfSpace: nothing on either side)
    SignedDistances(rest, m, scale, &s->d);
    bool all_in = true, none_out = true;  // m.x >= 0 everywhere; no vertex with -m.x >= 0
    for (const double di : s->d) {
      all_in &= di >= -kSideEps;
      none_out &= -di < -kSideEps;
    }
    if (!none_out) {
      SphericalPolygon& out = outside->Add();
      CutInto(rest, s->d, -1.0, &out);
      if (out.empty()) outside->PopBack();
    }
    if (all_in) {
      // Every vertex kept and no crossing: the cut would change nothing.
    } else {
      CutInto(rest, s->d, 1.0, &s->cut);
      rest.swap(s->cut);
    }
    if (rest.empty()) return;
  }
  if (inside != nullptr) inside->Add(rest);
}

}  // namespace

void SubtractConvex(const SphericalPolygon& p, const ConvexSpherical& q,
                    std::vector<SphericalPolygon>* outside, std::vector<SphericalPolygon>* inside) {
  thread_local PolygonList out, in;
  thread_local SubtractScratch scratch;
  out.clear();
  in.clear();
  SubtractInto(p, q, &out, inside ? &in : nullptr, &scratch);
  for (size_t k = 0; k < out.size(); ++k) outside->push_back(out[k]);
  for (size_t k = 0; k < in.size(); ++k) inside->push_back(in[k]);
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

namespace {

// Convex polygon `a` and `b` (counter-clockwise about `n`) joined along an edge they share in
// opposite directions, when the union is convex: its corners (collinear ones dropped) in
// `out`.
bool JoinConvex(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                const Eigen::Vector3d& n, double tol, std::vector<Eigen::Vector3d>* out) {
  const size_t na = a.size(), nb = b.size();
  for (size_t i = 0; i < na; ++i) {
    for (size_t j = 0; j < nb; ++j) {
      if ((a[i] - b[(j + 1) % nb]).norm() > tol || (a[(i + 1) % na] - b[j]).norm() > tol) {
        continue;
      }
      // a from a[i+1] round to a[i], then b after b[j+1] round to before b[j].
      std::vector<Eigen::Vector3d> p;
      for (size_t k = 0; k < na; ++k) p.push_back(a[(i + 1 + k) % na]);
      for (size_t k = 2; k < nb; ++k) p.push_back(b[(j + k) % nb]);
      // Drop collinear corners, then require every turn to the left.
      std::vector<Eigen::Vector3d> q;
      const size_t m = p.size();
      for (size_t k = 0; k < m; ++k) {
        const Eigen::Vector3d& prev = p[(k + m - 1) % m];
        const Eigen::Vector3d& next = p[(k + 1) % m];
        const double turn = n.dot((p[k] - prev).cross(next - p[k]));
        const double scale = (p[k] - prev).norm() * (next - p[k]).norm();
        if (turn < -1e-9 * scale) return false;
        if (turn > 1e-9 * scale) q.push_back(p[k]);
      }
      if (q.size() < 3) return false;
      *out = std::move(q);
      return true;
    }
  }
  return false;
}

}  // namespace

OccluderFaces::OccluderFaces(const Mesh& mesh) {
  const int nt = static_cast<int>(mesh.triangles.size());
  const int nv = static_cast<int>(mesh.vertices.size());
  face_of_.assign(nt, -1);
  double extent = 0;
  for (const auto& v : mesh.vertices) {
    if (v.allFinite()) extent = std::max(extent, v.cwiseAbs().maxCoeff());
  }
  const double tol = 1e-9 * std::max(extent, 1.0);
  // Triangles grouped by block and plane (normal and offset rounded), then merged greedily.
  struct Item {
    int block;
    std::array<int64_t, 4> plane;
    int t;
  };
  std::vector<Item> items;
  for (int t = 0; t < nt; ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    if (tri.minCoeff() < 0 || tri.maxCoeff() >= nv) continue;
    const Eigen::Vector3d nrm = mesh.Normal(t);
    if (!nrm.allFinite()) continue;
    const double d = nrm.dot(mesh.vertices[tri[0]]);
    const int block =
        t < static_cast<int>(mesh.triangle_block.size()) ? mesh.triangle_block[t] : -1;
    items.push_back(
        {block,
         {std::llround(nrm.x() * 1e7), std::llround(nrm.y() * 1e7), std::llround(nrm.z() * 1e7),
          std::llround(d / (1e-7 * std::max(extent, 1.0)))},
         t});
  }
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
    return std::tie(a.block, a.plane, a.t) < std::tie(b.block, b.plane, b.t);
  });
  for (size_t i = 0; i < items.size();) {
    size_t j = i;
    while (j < items.size() && items[j].block == items[i].block &&
           items[j].plane == items[i].plane) {
      ++j;
    }
    // One plane of one block: its triangles as polygons, joined while a join stays convex.
    const Eigen::Vector3d n = mesh.Normal(items[i].t);
    std::vector<std::vector<Eigen::Vector3d>> polys;
    std::vector<std::vector<int>> tris;
    for (size_t k = i; k < j; ++k) {
      const Eigen::Vector3i& tri = mesh.triangles[items[k].t];
      polys.push_back({mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]});
      tris.push_back({items[k].t});
    }
    // (Large planes, e.g. a finely tessellated plaza, stay triangles: joining is quadratic.)
    constexpr size_t kMaxJoin = 256;
    for (size_t a = 0; a < polys.size() && polys.size() <= kMaxJoin; ++a) {
      for (size_t b = a + 1; b < polys.size();) {
        std::vector<Eigen::Vector3d> u;
        if (!JoinConvex(polys[a], polys[b], n, tol, &u)) {
          ++b;
          continue;
        }
        polys[a] = std::move(u);
        tris[a].insert(tris[a].end(), tris[b].begin(), tris[b].end());
        polys.erase(polys.begin() + b);
        tris.erase(tris.begin() + b);
        b = a + 1;  // the grown polygon may now join one passed over
      }
    }
    for (size_t k = 0; k < polys.size(); ++k) {
      for (int t : tris[k]) face_of_[t] = static_cast<int>(polygons_.size());
      polygons_.push_back(std::move(polys[k]));
    }
    i = j;
  }
}

void PointVisibility::Add(const Mesh& mesh, int t, std::vector<Candidate>* found) const {
  const Eigen::Vector3i& tri = mesh.triangles[t];
  const int nv = static_cast<int>(mesh.vertices.size());
  if (tri.minCoeff() < 0 || tri.maxCoeff() >= nv) return;
  AddPolygon({mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]}, found);
}

void PointVisibility::AddPolygon(const std::vector<Eigen::Vector3d>& pts,
                                 std::vector<Candidate>* found) const {
  bool front = false;
  for (const auto& v : pts) front |= normal_.dot(v - origin_) > 0;
  if (!front) return;
  Candidate c;
  if (!ProjectPolygon(pts, origin_, normal_, &c.cs)) return;
  c.omega = std::abs(SolidAngle(c.cs.vertices));
  if (!(c.omega > 0)) return;
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
      // Inside q's projection needs every corner inside its bounding cap: one checked first.
      if (q.cs.cap_centre.dot(f.cs.vertices[0]) < q.cs.cap_cos - 1e-12) continue;
      if (Inside(f.cs.vertices, q.cs)) {
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

PointVisibility::PointVisibility(const OccluderFaces& faces, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& normal, int own_triangle,
                                 const std::vector<int>* candidates)
    : origin_(origin), normal_(normal) {
  const int own = own_triangle >= 0 && own_triangle < faces.num_triangles()
                      ? faces.face_of_triangle(own_triangle)
                      : -1;
  std::vector<Candidate> found;
  if (candidates == nullptr) {
    for (int f = 0; f < faces.size(); ++f) {
      if (f != own) AddPolygon(faces.polygon(f), &found);
    }
  } else {
    std::vector<int> list;
    for (int t : *candidates) {
      if (t >= 0 && t < faces.num_triangles() && faces.face_of_triangle(t) >= 0) {
        list.push_back(faces.face_of_triangle(t));
      }
    }
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    for (int f : list) {
      if (f != own) AddPolygon(faces.polygon(f), &found);
    }
  }
  Finish(&found);
}

namespace {

// Buffers of VisibleParts.
struct ClipScratch {
  PolygonList pieces, next;
  std::vector<SphericalCap> caps, next_caps;  // of pieces, next
  std::vector<double> d;
  SubtractScratch subtract;
};

// App. A's visibility clipping into reused storage: `s->pieces` receives the part of `patch`
// in front of the tangent plane less the occluders vis.occluder(ids[k]), k < count (the same
// pieces as PointVisibility::Clip / ClipWith).
void VisibleParts(const PointVisibility& vis, const SphericalPolygon& patch, const int* ids,
                  size_t count, ClipScratch* s) {
  s->pieces.clear();
  const double scale = vis.normal().norm();
  if (patch.size() < 3 || !(scale > 0)) return;
  SignedDistances(patch, vis.normal(), scale, &s->d);
  SphericalPolygon& front = s->pieces.Add();
  CutInto(patch, s->d, 1.0, &front);
  if (front.empty()) {
    s->pieces.PopBack();
    return;
  }
  // Each piece's bounding cap is computed once, when the piece is made: a piece clear of an
  // occluder moves on unchanged, with its cap (the same pieces as SubtractInto's).
  s->caps.assign(1, SphericalCap(front));
  for (size_t k = 0; k < count; ++k) {
    const ConvexSpherical& occ = vis.occluder(ids == nullptr ? static_cast<int>(k) : ids[k]);
    s->next.clear();
    s->next_caps.clear();
    for (size_t j = 0; j < s->pieces.size(); ++j) {
      SphericalPolygon& p = s->pieces[j];
      if (p.size() < 3) continue;
      if (Disjoint(p, s->caps[j], occ, false)) {
        s->next.AddSwap(&p);
        s->next_caps.push_back(s->caps[j]);
        continue;
      }
      const size_t before = s->next.size();
      SubtractCut(p, occ, &s->next, nullptr, &s->subtract);
      for (size_t m = before; m < s->next.size(); ++m) s->next_caps.emplace_back(s->next[m]);
    }
    s->pieces.swap(s->next);
    s->caps.swap(s->next_caps);
    if (s->pieces.empty()) return;
  }
}

}  // namespace

void PointVisibility::Clip(const SphericalPolygon& patch,
                           std::vector<SphericalPolygon>* out) const {
  thread_local ClipScratch s;
  VisibleParts(*this, patch, nullptr, occluders_.size(), &s);
  for (size_t k = 0; k < s.pieces.size(); ++k) out->push_back(s.pieces[k]);
}

void PointVisibility::ClipWith(const SphericalPolygon& patch, const std::vector<int>& subset,
                               std::vector<SphericalPolygon>* out) const {
  thread_local ClipScratch s;
  VisibleParts(*this, patch, subset.data(), subset.size(), &s);
  for (size_t k = 0; k < s.pieces.size(); ++k) out->push_back(s.pieces[k]);
}

PointVisibility::Cover PointVisibility::Classify(const SphericalPolygon& patch,
                                                 const std::vector<int>* subset, bool convex,
                                                 std::vector<int>* overlapping) const {
  return Classify(patch, SphericalCap(patch), subset, convex, overlapping);
}

PointVisibility::Cover PointVisibility::Classify(const SphericalPolygon& patch,
                                                 const SphericalCap& cap,
                                                 const std::vector<int>* subset, bool convex,
                                                 std::vector<int>* overlapping) const {
  bool all_front = true, all_back = true;
  // The bounding cap wholly behind or (by more than the side tolerance) in front of the
  // tangent plane decides both without visiting the vertices.
  const double nc = cap.valid ? normal_.dot(cap.centre) : 0;
  if (cap.valid && nc < -cap.sin) return Cover::kHidden;
  if (cap.valid && nc > cap.sin + 1e-9) {
    all_back = false;
  } else {
    for (const auto& v : patch) {
      const double d = normal_.dot(v);
      all_front &= d >= 0;
      all_back &= d <= kSideEps;
    }
  }
  if (all_back) return Cover::kHidden;
  const size_t start = overlapping->size();
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

EnvironmentRegions::EnvironmentRegions(const EnvironmentMap& env, const VectorFluxOptions& options)
    : bands_below_(env.bands_below), bands_above_(env.bands_above), sectors_(env.sectors) {
  options.Validate();
  const int n = env.num_regions();
  polygons_.resize(n);
  caps_.resize(n);
  flux_.resize(n);
  double widest_arc = 0;
  for (int r = 0; r < n; ++r) {
    double el0, el1, az0, az1;
    env.RegionBounds(r, &el0, &el1, &az0, &az1);
    const int seg = std::max(options.env_parallel_segments,
                             static_cast<int>(std::ceil((az1 - az0) / (kPi / 3) - 1e-9)));
    widest_arc = std::max(widest_arc, (az1 - az0) / seg);
    SphericalPolygon p;
    for (int k = 0; k <= seg; ++k) p.push_back(Direction(el0, az0 + (az1 - az0) * k / seg));
    for (int k = seg; k >= 0; --k) p.push_back(Direction(el1, az0 + (az1 - az0) * k / seg));
    DropDuplicates(&p);
    // Azimuth runs clockwise seen from above: make the loop counter-clockwise from outside.
    const Eigen::Vector3d mid = Direction((el0 + el1) / 2, (az0 + az1) / 2);
    if (VectorFlux(p).dot(mid) < 0) std::reverse(p.begin(), p.end());
    caps_[r] = SphericalCap(p);
    flux_[r] = VectorFlux(p);
    polygons_[r] = std::move(p);
  }
  // A great arc between two points of a parallel strays from it by less than 1 - cos of half
  // its azimuth span (in elevation, radians); twice that, and more, as margin.
  margin_ = 2 * (1 - std::cos(widest_arc / 2)) + 1e-9;
}

bool EnvironmentRegions::Fits(const EnvironmentMap& env) const {
  return env.bands_below == bands_below_ && env.bands_above == bands_above_ &&
         env.sectors == sectors_;
}

void EnvironmentRegions::Near(const ConvexSpherical& q, std::vector<int>* out) const {
  const size_t n = q.vertices.size();
  auto all = [&]() {
    for (int r = 0; r < size(); ++r) out->push_back(r);
  };
  if (n < 3 || q.edge_normal.size() != n) return all();
  // Elevations: the boundary's lowest and highest points, at vertices or where an edge passes
  // the top or bottom of its great circle; a pole inside every edge's half space is inside q.
  double zlo = 1, zhi = -1;
  bool zenith = true, nadir = true;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& a = q.vertices[i];
    const Eigen::Vector3d& b = q.vertices[i + 1 == n ? 0 : i + 1];
    const Eigen::Vector3d& m = q.edge_normal[i];
    zlo = std::min(zlo, a.z());
    zhi = std::max(zhi, a.z());
    zenith &= m.z() >= -1e-12;
    nadir &= m.z() <= 1e-12;
    Eigen::Vector3d top(-m.z() * m.x(), -m.z() * m.y(), 1 - m.z() * m.z());
    const double len = top.norm();
    if (!(len > 1e-12)) continue;  // a horizontal great circle: its vertices bound it
    top /= len;
    // A point t of the great circle lies on the arc a -> b when a x t and t x b point along m.
    if (a.cross(top).dot(m) >= 0 && top.cross(b).dot(m) >= 0) zhi = std::max(zhi, top.z());
    if (a.cross(-top).dot(m) >= 0 && (-top).cross(b).dot(m) >= 0) zlo = std::min(zlo, -top.z());
  }
  const double el_lo = nadir ? -kPi / 2 : std::asin(std::clamp(zlo, -1.0, 1.0)) - 1e-9;
  const double el_hi = zenith ? kPi / 2 : std::asin(std::clamp(zhi, -1.0, 1.0)) + 1e-9;
  double lo = 0, hi = 0;  // azimuth span about the first vertex's azimuth, radians
  bool every_sector = zenith || nadir || el_hi >= kPi / 2 || el_lo <= -kPi / 2;
  // An edge's azimuth runs monotonically from one end's to the other's, less than pi apart,
  // unless the edge passes a pole: the edges' signed steps, summed, give the span.
  double sum = 0;
  for (size_t i = 0; i < n && !every_sector; ++i) {
    const Eigen::Vector3d& a = q.vertices[i];
    const Eigen::Vector3d& b = q.vertices[i + 1 == n ? 0 : i + 1];
    if (a.x() * a.x() + a.y() * a.y() < 1e-18) {
      every_sector = true;
      break;
    }
    // Azimuth atan2(x, y) grows from north towards east: the step from a's to b's.
    const double d = std::atan2(a.y() * b.x() - a.x() * b.y(), a.x() * b.x() + a.y() * b.y());
    if (std::abs(d) > kPi - 1e-6) every_sector = true;
    sum += d;
    lo = std::min(lo, sum);
    hi = std::max(hi, sum);
  }
  const double a0 = std::atan2(q.vertices[0].x(), q.vertices[0].y());
  // Round the pole (a winding the pole tests missed), or nearly all the way round.
  if (std::abs(sum) > 1e-6 || hi - lo >= 2 * kPi - 2 * kPi / sectors_) every_sector = true;
  int s_first = 0, s_count = sectors_;
  if (!every_sector) {
    const double width = 2 * kPi / sectors_;
    const int first = static_cast<int>(std::floor((a0 + lo - 1e-9) / width));
    const int last = static_cast<int>(std::floor((a0 + hi + 1e-9) / width));
    if (last - first + 1 < sectors_) {
      s_first = first;
      s_count = last - first + 1;
    }
  }
  // A region's arcs along its parallels stray from them by less than margin_ in elevation; its
  // sides are meridians.
  const int bands = bands_below_ + bands_above_;
  for (int band = 0; band < bands; ++band) {
    const double b_lo = band < bands_below_ ? -kPi / 2 + band * (kPi / 2) / bands_below_
                                            : (band - bands_below_) * (kPi / 2) / bands_above_;
    const double b_hi = band < bands_below_ ? -kPi / 2 + (band + 1) * (kPi / 2) / bands_below_
                                            : (band - bands_below_ + 1) * (kPi / 2) / bands_above_;
    if (b_hi + margin_ < el_lo || b_lo - margin_ > el_hi) continue;
    for (int k = 0; k < s_count; ++k) {
      const int sector = ((s_first + k) % sectors_ + sectors_) % sectors_;
      out->push_back(band * sectors_ + sector);
    }
  }
}

void EnvironmentView::Clear() {
  region.clear();
  flux.clear();
  whole.clear();
  piece_region.clear();
  pieces.clear();
}

void SeeEnvironment(const PointVisibility& vis, const EnvironmentRegions& regions,
                    bool keep_ground_pieces, EnvironmentView* view, FluxStats* stats) {
  view->Clear();
  view->normal = vis.normal();
  if (stats) stats->occluders = vis.num_occluders();
  const int nreg = regions.size();
  // Per-thread buffers, kept between points.
  thread_local std::vector<int> start, near, first_near, fill, list, subset, overlap;
  thread_local ClipScratch clip;
  // The occluders that may overlap each region (compressed rows, occluders in order).
  start.assign(nreg + 1, 0);
  near.clear();
  first_near.assign(vis.num_occluders() + 1, 0);
  for (int k = 0; k < vis.num_occluders(); ++k) {
    regions.Near(vis.occluder(k), &near);
    first_near[k + 1] = static_cast<int>(near.size());
  }
  for (int r : near) ++start[r + 1];
  for (int r = 0; r < nreg; ++r) start[r + 1] += start[r];
  fill.assign(start.begin(), start.end() - 1);
  list.resize(near.size());
  for (int k = 0; k < vis.num_occluders(); ++k) {
    for (int m = first_near[k]; m < first_near[k + 1]; ++m) list[fill[near[m]]++] = k;
  }
  for (int r = 0; r < nreg; ++r) {
    subset.assign(list.begin() + start[r], list.begin() + start[r + 1]);
    const SphericalPolygon& poly = regions.polygon(r);
    overlap.clear();
    const PointVisibility::Cover cover =
        vis.Classify(poly, regions.cap(r), &subset, false, &overlap);
    if (cover == PointVisibility::Cover::kHidden) continue;
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    const bool keep = keep_ground_pieces && regions.below_horizon(r);
    if (cover == PointVisibility::Cover::kFull) {
      phi = regions.flux(r);
      if (stats) ++stats->patches;
      if (keep) {
        view->piece_region.push_back(r);
        view->pieces.push_back(poly);
      }
    } else {
      VisibleParts(vis, poly, overlap.data(), overlap.size(), &clip);
      if (clip.pieces.empty()) continue;
      for (size_t k = 0; k < clip.pieces.size(); ++k) phi += VectorFlux(clip.pieces[k]);
      if (stats) stats->patches += static_cast<int>(clip.pieces.size());
      if (keep) {
        for (size_t k = 0; k < clip.pieces.size(); ++k) {
          view->piece_region.push_back(r);
          view->pieces.push_back(clip.pieces[k]);
        }
      }
    }
    view->region.push_back(r);
    view->flux.push_back(phi);
    view->whole.push_back(cover == PointVisibility::Cover::kFull);
  }
}

ShapedRegions::ShapedRegions(const SkyShape& s, const EnvironmentRegions& regions) : shape(&s) {
  moment.resize(regions.size());
  for (int r = 0; r < regions.size(); ++r) moment[r] = s.Moment(r, regions.flux(r));
}

namespace {

// The layer pair and weight for height z (as EnvironmentMap::Radiance).
struct LayerBlend {
  size_t k0 = 0, k1 = 0;
  double a = 0;
  LayerBlend(const EnvironmentMap& env, double z) {
    const int layers = env.num_layers();
    if (layers <= 1 || z <= env.layer_z.front()) return;
    if (z >= env.layer_z.back()) {
      k0 = k1 = static_cast<size_t>(layers - 1);
      return;
    }
    int k = 0;
    while (k + 2 < layers && z > env.layer_z[k + 1]) ++k;
    a = (z - env.layer_z[k]) / (env.layer_z[k + 1] - env.layer_z[k]);
    k0 = k;
    k1 = k + 1;
  }
  Eigen::Vector3d L(const EnvironmentMap& env, int r) const {
    const size_t nreg = env.num_regions();
    const Eigen::Vector3d& l0 = env.radiance[k0 * nreg + r];
    return a == 0 ? l0 : Eigen::Vector3d((1 - a) * l0 + a * env.radiance[k1 * nreg + r]);
  }
};

void CheckRegion(const EnvironmentMap& env, int r) {
  if (r < 0 || r >= env.num_regions()) {
    throw Error("vector flux: region " + std::to_string(r) + " is not in the environment map (" +
                std::to_string(env.num_regions()) + " regions)");
  }
}

}  // namespace

Eigen::Vector3d EnvironmentIrradiance(const EnvironmentView& view, const EnvironmentMap& env,
                                      double z, const ShapedRegions* shaped) {
  if (env.radiance.size() < static_cast<size_t>(env.num_layers()) * env.num_regions()) {
    throw Error("vector flux: the environment map holds fewer radiances than its regions");
  }
  const LayerBlend blend(env, z);
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  const bool shape = shaped && !shaped->shape->uniform();
  if (view.flux.size() != view.region.size() ||
      (shape && (view.whole.size() != view.region.size() ||
                 shaped->moment.size() != static_cast<size_t>(env.num_regions())))) {
    throw Error("vector flux: the view or the shaped regions do not match the environment map");
  }
  const int first_above = env.bands_below * env.sectors;
  for (size_t k = 0; k < view.region.size(); ++k) {
    const int r = view.region[k];
    CheckRegion(env, r);
    const double weight = view.normal.dot(view.flux[k]);  // n . Phi
    if (!shape || r < first_above) {
      e += weight * blend.L(env, r);
    } else if (view.whole[k]) {
      e += blend.L(env, r).cwiseProduct(shaped->moment[r] * view.normal);
    } else {
      e += weight * blend.L(env, r).cwiseProduct(shaped->shape->InRegion(view.flux[k], r));
    }
  }
  return e;
}

Eigen::Vector3d GroundShadowChange(const EnvironmentView& view, const EnvironmentRegions& regions,
                                   const EnvironmentMap& env, double z,
                                   const std::vector<ConvexSpherical>& ground_shadow,
                                   const Eigen::Vector3d& shadow_ratio) {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  if (ground_shadow.empty() || view.pieces.empty()) return e;
  const LayerBlend blend(env, z);
  // Per-thread buffers, kept between points.
  thread_local std::vector<int> near, owner;
  thread_local std::vector<std::pair<int, int>> by_region;  // (region, shadow)
  thread_local PolygonList rest, next, inside;
  thread_local SubtractScratch scratch;
  // The shadows that may meet each region, in order.
  near.clear();
  owner.clear();
  for (int k = 0; k < static_cast<int>(ground_shadow.size()); ++k) {
    regions.Near(ground_shadow[k], &near);
    owner.resize(near.size(), k);
  }
  by_region.resize(near.size());
  for (size_t m = 0; m < near.size(); ++m) by_region[m] = {near[m], owner[m]};
  std::sort(by_region.begin(), by_region.end());
  size_t k = 0;
  while (k < view.pieces.size()) {
    // The pieces of one region.
    const int r = view.piece_region[k];
    CheckRegion(env, r);
    const size_t first = k;
    while (k < view.pieces.size() && view.piece_region[k] == r) ++k;
    // The shadows that may meet it (none: nothing to take apart).
    auto it = std::lower_bound(by_region.begin(), by_region.end(), std::make_pair(r, -1));
    const auto end = std::find_if(it, by_region.end(), [r](const auto& p) { return p.first != r; });
    while (it != end &&
           Disjoint(regions.polygon(r), regions.cap(r), ground_shadow[it->second], false)) {
      ++it;
    }
    if (it == end) continue;
    rest.clear();
    for (size_t j = first; j < k; ++j) rest.Add(view.pieces[j]);
    // Shadowed ground: the union of the (overlapping) shadow polygons, taken apart piece by
    // piece so no direction counts twice; shadows clear of the whole region are skipped.
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    for (; it != end; ++it) {
      const ConvexSpherical& s = ground_shadow[it->second];
      if (Disjoint(regions.polygon(r), regions.cap(r), s, false)) continue;
      next.clear();
      inside.clear();
      for (size_t j = 0; j < rest.size(); ++j) SubtractInto(rest[j], s, &next, &inside, &scratch);
      for (size_t j = 0; j < inside.size(); ++j) phi += VectorFlux(inside[j]);
      rest.swap(next);
      if (rest.empty()) break;
    }
    e +=
        blend.L(env, r).cwiseProduct(shadow_ratio - Eigen::Vector3d::Ones()) * view.normal.dot(phi);
  }
  return e;
}

Eigen::Vector3d EnvironmentIrradianceVectorFlux(const PointVisibility& vis,
                                                const EnvironmentMap& env, double z,
                                                const EnvironmentRegions& regions,
                                                const std::vector<ConvexSpherical>* ground_shadow,
                                                const Eigen::Vector3d& shadow_ratio,
                                                FluxStats* stats) {
  if (!regions.Fits(env)) {
    throw Error("vector flux: " + std::to_string(regions.size()) +
                " region polygons for an environment map of " + std::to_string(env.num_regions()) +
                " regions");
  }
  const bool shadow = ground_shadow != nullptr && !ground_shadow->empty();
  EnvironmentView view;
  SeeEnvironment(vis, regions, shadow, &view, stats);
  Eigen::Vector3d e = EnvironmentIrradiance(view, env, z);
  if (shadow) e += GroundShadowChange(view, regions, env, z, *ground_shadow, shadow_ratio);
  return e;
}

namespace {

// The shape of one block's triangles: `closed` when every edge is shared by exactly two of
// them (corners welded by position) except edges on the ground z = ground_z (an open bottom),
// `convex` when every corner lies on or behind every face's plane.
struct BlockShape {
  bool closed = false, convex = false;
};

BlockShape ShapeOf(const Mesh& mesh, const std::vector<int>& faces, double ground_z) {
  BlockShape shape;
  std::vector<Eigen::Vector3d> corners;
  for (int t : faces) {
    for (int k = 0; k < 3; ++k) corners.push_back(mesh.vertices[mesh.triangles[t][k]]);
  }
  double extent = 0;
  for (const auto& v : corners) extent = std::max(extent, (v - corners[0]).norm());
  const double tol = 1e-9 * std::max(extent, 1e-9);
  // Corner ids by position, then each undirected edge counted.
  std::vector<int> order(corners.size()), id(corners.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  auto key = [&](int i) {
    return std::array<int64_t, 3>{std::llround(corners[i].x() / tol),
                                  std::llround(corners[i].y() / tol),
                                  std::llround(corners[i].z() / tol)};
  };
  std::sort(order.begin(), order.end(), [&](int a, int b) { return key(a) < key(b); });
  for (size_t k = 0; k < order.size(); ++k) {
    id[order[k]] = k > 0 && key(order[k]) == key(order[k - 1]) ? id[order[k - 1]] : order[k];
  }
  std::vector<std::pair<int, int>> edges;
  for (size_t f = 0; f < faces.size(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = id[3 * f + k], b = id[3 * f + (k + 1) % 3];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  shape.closed = true;
  for (size_t i = 0; i < edges.size() && shape.closed;) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    const bool on_ground = std::abs(corners[edges[i].first].z() - ground_z) <= tol &&
                           std::abs(corners[edges[i].second].z() - ground_z) <= tol;
    if (j - i > 2 || (j - i == 1 && !on_ground)) shape.closed = false;
    i = j;
  }
  std::vector<Eigen::Vector3d> unique;
  for (size_t i = 0; i < id.size(); ++i) {
    if (id[i] == static_cast<int>(i)) unique.push_back(corners[i]);
  }
  shape.convex = true;
  for (size_t f = 0; f < faces.size() && shape.convex; ++f) {
    const Eigen::Vector3d nrm = mesh.Normal(faces[f]);
    const Eigen::Vector3d& v0 = mesh.vertices[mesh.triangles[faces[f]][0]];
    for (const auto& v : unique) {
      if (nrm.dot(v - v0) > tol) {
        shape.convex = false;
        break;
      }
    }
  }
  return shape;
}

// Convex hull of points in the plane z = const (counter-clockwise seen from above; Andrew's
// monotone chain).
std::vector<Eigen::Vector3d> HullXY(std::vector<Eigen::Vector3d> p) {
  std::sort(p.begin(), p.end(), [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  if (p.size() < 3) return p;
  auto cross = [](const Eigen::Vector3d& o, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
  };
  std::vector<Eigen::Vector3d> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i - 1]) <= 0) --k;
    h[k++] = p[i - 1];
  }
  h.resize(k - 1);
  return h;
}

}  // namespace

std::vector<std::vector<Eigen::Vector3d>> GroundShadowOnPlane(const Mesh& mesh,
                                                              const OccluderFaces& faces,
                                                              const Eigen::Vector3d& sun,
                                                              double ground_z) {
  std::vector<std::vector<Eigen::Vector3d>> out;
  if (!(sun.z() > 1e-9)) return out;
  if (faces.num_triangles() != static_cast<int>(mesh.triangles.size())) {
    throw Error("ground shadow: the occluder faces were built from another mesh");
  }
  auto onto_ground = [&](const Eigen::Vector3d& v) {
    Eigen::Vector3d g = v - ((v.z() - ground_z) / sun.z()) * sun;
    g.z() = ground_z;
    return g;
  };
  // Triangles per block (the last list: triangles of no block).
  std::vector<std::vector<int>> of_block(mesh.block_names.size() + 1);
  for (int t = 0; t < faces.num_triangles(); ++t) {
    if (faces.face_of_triangle(t) < 0) continue;  // malformed
    const int b = t < static_cast<int>(mesh.triangle_block.size()) ? mesh.triangle_block[t] : -1;
    const size_t slot = b >= 0 && b < static_cast<int>(mesh.block_names.size())
                            ? static_cast<size_t>(b)
                            : mesh.block_names.size();
    of_block[slot].push_back(t);
  }
  std::vector<int> block_faces;
  for (size_t b = 0; b < of_block.size(); ++b) {
    const std::vector<int>& tris = of_block[b];
    if (tris.empty()) continue;
    bool above = false, below = false;
    for (int t : tris) {
      for (int k = 0; k < 3; ++k) {
        const double h = mesh.vertices[mesh.triangles[t][k]].z() - ground_z;
        above |= h > 1e-9;
        below |= h < -1e-9;
      }
    }
    if (!above) continue;  // on the ground: shades nothing beyond itself
    const BlockShape shape = b < mesh.block_names.size() && !below && tris.size() >= 4
                                 ? ShapeOf(mesh, tris, ground_z)
                                 : BlockShape{};
    if (shape.closed && shape.convex) {
      // A convex solid's shadow is the hull of its corners' shadows.
      std::vector<Eigen::Vector3d> g;
      for (int t : tris) {
        for (int k = 0; k < 3; ++k) g.push_back(onto_ground(mesh.vertices[mesh.triangles[t][k]]));
      }
      std::vector<Eigen::Vector3d> hull = HullXY(std::move(g));
      if (hull.size() >= 3) out.push_back(std::move(hull));
      continue;
    }
    // Its faces (coplanar triangles merged); of a closed solid only those facing the sun: a
    // shadowed ground point's ray to the sun leaves the solid through one of them.
    block_faces.clear();
    for (int t : tris) block_faces.push_back(faces.face_of_triangle(t));
    std::sort(block_faces.begin(), block_faces.end());
    block_faces.erase(std::unique(block_faces.begin(), block_faces.end()), block_faces.end());
    for (int f : block_faces) {
      const std::vector<Eigen::Vector3d>& poly = faces.polygon(f);
      if (shape.closed) {
        Eigen::Vector3d newell = Eigen::Vector3d::Zero();
        for (size_t i = 0; i < poly.size(); ++i)
          newell += poly[i].cross(poly[(i + 1) % poly.size()]);
        if (!(newell.dot(sun) > 0)) continue;
      }
      std::vector<Eigen::Vector3d> g;
      bool face_above = false;
      for (const auto& v : poly) {
        face_above |= v.z() - ground_z > 1e-9;
        g.push_back(onto_ground(v));
      }
      if (face_above) out.push_back(std::move(g));
    }
  }
  return out;
}

namespace {

// Twice the signed area of a polygon in the plane (counter-clockwise seen from above: > 0).
double Area2XY(const std::vector<Eigen::Vector3d>& p) {
  double a = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector3d& u = p[i];
    const Eigen::Vector3d& v = p[(i + 1) % p.size()];
    a += u.x() * v.y() - v.x() * u.y();
  }
  return a;
}

// The planar cuts below take a convex polygon apart piece by piece; many small faces (a
// modelled ground of tiles) or many overlapping slivers fragment it into more pieces at each
// cut. Past this many pieces a cut gives up and keeps the polygon as it was: both cuts only
// save work per point later, and an uncut shadow changes no point's irradiance.
constexpr size_t kMaxCutPieces = 256;

struct BoxXY {
  Eigen::Vector2d lo, hi;
  explicit BoxXY(const std::vector<Eigen::Vector3d>& p) : lo(p[0].head<2>()), hi(lo) {
    for (const auto& v : p) {
      lo = lo.cwiseMin(v.head<2>());
      hi = hi.cwiseMax(v.head<2>());
    }
  }
  bool Apart(const BoxXY& o) const {
    return (lo.array() > o.hi.array()).any() || (o.lo.array() > hi.array()).any();
  }
};

// The part of a convex polygon (in a plane z = const) left of the directed line a -> b, seen
// from above (Sutherland-Hodgman, one edge).
std::vector<Eigen::Vector3d> LeftOf(const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3d& a,
                                    const Eigen::Vector3d& b) {
  std::vector<Eigen::Vector3d> out;
  const Eigen::Vector2d d = (b - a).head<2>();
  auto side = [&](const Eigen::Vector3d& x) {
    const Eigen::Vector2d r = (x - a).head<2>();
    return d.x() * r.y() - d.y() * r.x();
  };
  for (size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector3d& u = p[i];
    const Eigen::Vector3d& v = p[(i + 1) % p.size()];
    const double su = side(u), sv = side(v);
    if (su >= 0) out.push_back(u);
    if ((su >= 0) != (sv >= 0)) out.push_back(u + (su / (su - sv)) * (v - u));
  }
  return out;
}

}  // namespace

std::vector<std::vector<Eigen::Vector3d>> ShadowBeyondGroundFaces(
    const std::vector<std::vector<Eigen::Vector3d>>& shadow, const OccluderFaces& faces,
    double ground_z) {
  // The faces on the plane, facing up: counter-clockwise seen from above.
  std::vector<const std::vector<Eigen::Vector3d>*> ground;
  double extent = 1;
  for (const auto& g : shadow) {
    for (const auto& v : g) extent = std::max(extent, v.cwiseAbs().maxCoeff());
  }
  for (int f = 0; f < faces.size(); ++f) {
    const std::vector<Eigen::Vector3d>& poly = faces.polygon(f);
    bool flat = true;
    for (const auto& v : poly) {
      flat &= std::abs(v.z() - ground_z) <= 1e-9 * std::max(extent, std::abs(v.z()));
    }
    if (flat && Area2XY(poly) > 0) ground.push_back(&poly);
  }
  std::vector<BoxXY> ground_box;
  for (const auto* q : ground) ground_box.emplace_back(*q);
  std::vector<std::vector<Eigen::Vector3d>> out, rest, next;
  for (const auto& g : shadow) {
    std::vector<Eigen::Vector3d> whole = g;
    if (Area2XY(whole) < 0) std::reverse(whole.begin(), whole.end());
    rest.assign(1, whole);
    for (size_t k = 0; k < ground.size() && !rest.empty(); ++k) {
      const auto* q = ground[k];
      next.clear();
      for (auto& p : rest) {
        if (BoxXY(p).Apart(ground_box[k])) {
          next.push_back(std::move(p));
          continue;
        }
        // p less q: the pieces right of each of q's edges, what is left going on to the next;
        // p whole when q leaves nothing of it inside (a line through p is no reason to cut it).
        const size_t first = next.size();
        std::vector<Eigen::Vector3d> inner = p;
        for (size_t e = 0; e < q->size() && inner.size() >= 3; ++e) {
          const Eigen::Vector3d& a = (*q)[e];
          const Eigen::Vector3d& b = (*q)[(e + 1) % q->size()];
          std::vector<Eigen::Vector3d> outside = LeftOf(inner, b, a);
          if (outside.size() >= 3 && Area2XY(outside) > 1e-12 * extent * extent) {
            next.push_back(std::move(outside));
          }
          inner = LeftOf(inner, a, b);
        }
        if (inner.size() < 3 || !(Area2XY(inner) > 1e-12 * extent * extent)) {
          next.resize(first);
          next.push_back(std::move(p));
        }
      }
      rest.swap(next);
      if (rest.size() > kMaxCutPieces) {  // many faces fragment it: keep it whole
        rest.assign(1, whole);
        break;
      }
    }
    for (auto& p : rest) out.push_back(std::move(p));
  }
  return out;
}

namespace {

// Twice the area of the convex `h` (counter-clockwise) outside every polygon of `polys` but
// polys[skip] (convex, counter-clockwise): h less each of them piece by piece; infinity when
// that takes h into more than kMaxCutPieces pieces (taken as uncovered: nothing is merged).
double UncoveredArea2(const std::vector<Eigen::Vector3d>& h,
                      const std::vector<std::vector<Eigen::Vector3d>>& polys,
                      const std::vector<BoxXY>& boxes, size_t skip) {
  const BoxXY hbox(h);
  std::vector<std::vector<Eigen::Vector3d>> rest = {h}, next;
  for (size_t k = 0; k < polys.size() && !rest.empty(); ++k) {
    if (k == skip || hbox.Apart(boxes[k])) continue;
    const std::vector<Eigen::Vector3d>& q = polys[k];
    next.clear();
    for (auto& p : rest) {
      const size_t first = next.size();
      std::vector<Eigen::Vector3d> inner = p;
      for (size_t e = 0; e < q.size() && inner.size() >= 3; ++e) {
        const Eigen::Vector3d& a = q[e];
        const Eigen::Vector3d& b = q[(e + 1) % q.size()];
        std::vector<Eigen::Vector3d> outside = LeftOf(inner, b, a);
        if (outside.size() >= 3) next.push_back(std::move(outside));
        inner = LeftOf(inner, a, b);
      }
      if (inner.size() < 3) {  // q misses p: p whole, not cut along q's lines
        next.resize(first);
        next.push_back(std::move(p));
      }
    }
    rest.swap(next);
    if (rest.size() > kMaxCutPieces) return std::numeric_limits<double>::infinity();
  }
  double area2 = 0;
  for (const auto& p : rest) area2 += Area2XY(p);
  return area2;
}

}  // namespace

std::vector<std::vector<Eigen::Vector3d>> MergeGroundShadow(
    const std::vector<std::vector<Eigen::Vector3d>>& shadow) {
  std::vector<std::vector<Eigen::Vector3d>> polys;
  double extent = 1;
  size_t corners = 0;
  for (const auto& g : shadow) {
    if (g.size() < 3) continue;
    polys.push_back(g);
    if (Area2XY(polys.back()) < 0) std::reverse(polys.back().begin(), polys.back().end());
    for (const auto& v : g) extent = std::max(extent, v.head<2>().cwiseAbs().maxCoeff());
    corners += g.size();
  }
  // Largest first: the small ones are the likeliest to lie under the others.
  std::stable_sort(polys.begin(), polys.end(),
                   [](const auto& a, const auto& b) { return Area2XY(a) > Area2XY(b); });
  std::vector<BoxXY> boxes;
  for (const auto& p : polys) boxes.emplace_back(p);
  // An uncovered area is a sum of twice-areas, each a sum of cross products of coordinates
  // below `extent`, rounded, over the corners of the pieces (the cut's new corners rounded
  // too): within about 4 eps extent^2 per corner. The pieces' corners are taken as at most 4x
  // the polygons' (plus the hull's), and 16x that as the tolerance.
  const double tol =
      64.0 * (4 * corners + 64) * std::numeric_limits<double>::epsilon() * extent * extent;
  auto erase = [&](size_t k) {
    polys.erase(polys.begin() + k);
    boxes.erase(boxes.begin() + k);
  };
  // Polygons under the union of the others add nothing.
  for (size_t k = polys.size(); k-- > 0;) {
    if (UncoveredArea2(polys[k], polys, boxes, k) <= tol) erase(k);
  }
  // A pair whose hull lies under the union of all is replaced by the hull; polygons then
  // under the hull are dropped.
  std::vector<Eigen::Vector3d> both;
  for (size_t i = 0; i < polys.size(); ++i) {
    for (size_t j = i + 1; j < polys.size();) {
      if (boxes[i].Apart(boxes[j])) {
        ++j;
        continue;
      }
      both = polys[i];
      both.insert(both.end(), polys[j].begin(), polys[j].end());
      std::vector<Eigen::Vector3d> hull = HullXY(both);
      if (hull.size() < 3 || UncoveredArea2(hull, polys, boxes, polys.size()) > tol) {
        ++j;
        continue;
      }
      polys[i] = std::move(hull);
      boxes[i] = BoxXY(polys[i]);
      erase(j);
      const std::vector<std::vector<Eigen::Vector3d>> grown = {polys[i]};
      const std::vector<BoxXY> grown_box = {boxes[i]};
      for (size_t k = polys.size(); k-- > 0;) {
        if (k != i && UncoveredArea2(polys[k], grown, grown_box, 1) <= tol) {
          erase(k);
          if (k < i) --i;
        }
      }
      j = i + 1;  // the grown polygon may now merge with one passed over
    }
  }
  return polys;
}

std::vector<ConvexSpherical> GroundShadowPolygons(
    const std::vector<std::vector<Eigen::Vector3d>>& on_plane, const Eigen::Vector3d& origin) {
  std::vector<ConvexSpherical> out;
  if (on_plane.empty() || !(origin.z() > on_plane[0][0].z())) return out;
  const Eigen::Vector3d down = -Eigen::Vector3d::UnitZ();
  for (const auto& g : on_plane) {
    ConvexSpherical cs;
    if (ProjectPolygon(g, origin, down, &cs)) out.push_back(std::move(cs));
  }
  return out;
}

}  // namespace rouen
