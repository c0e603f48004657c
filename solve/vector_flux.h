// Analytic irradiance from extended sources of piecewise uniform radiance (Yu & Malik 1998,
// App. A): the vector flux (irradiance vector, Arvo 1995) of spherical polygons, clipping of
// spherical polygons by planes through the centre and by the model faces in front of a
// surface point, and the sky / environment irradiance gathered from them.
//
// Conventions: a SphericalPolygon is a list of unit vectors (directions from the surface
// point); consecutive vertices (and the last with the first) are joined by the shorter great
// arc, which must be shorter than pi. Vertices run counter-clockwise seen from outside the
// sphere, i.e. the region lies to the left when walking along the boundary with the outward
// direction as "up". (The paper's eq. 20 writes Pi_AB = -(OA x OB), i.e. it lists vertices the
// other way round; the region and the result are the same.) Polygons may be non-convex; a
// degenerate edge (zero length, or running back along itself) contributes nothing.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "core/mesh.h"
#include "solve/environment.h"
#include "solve/raycast.h"
#include "solve/sky_model.h"

namespace rouen {

using SphericalPolygon = std::vector<Eigen::Vector3d>;

// App. A, eq. 20: vector flux of a spherical polygon of uniform unit radiance,
//   Phi = 1/2 sum_i Theta_i unit(v_i x v_{i+1}),  Theta_i = angle between v_i and v_{i+1}.
// For uniform radiance L over the polygon, the irradiance on a surface with unit normal n is
// L n.Phi when the polygon lies in the half space n.x >= 0 (units: L x sr). It equals the
// integral over the polygon of the direction w dw (a boundary integral: valid for any size).
Eigen::Vector3d VectorFlux(const SphericalPolygon& poly);

// Signed solid angle (sr) of a polygon smaller than a hemisphere, fan of Van Oosterom-Strackee
// triangles from the first vertex; positive for counter-clockwise polygons.
double SolidAngle(const SphericalPolygon& poly);

// The part of `poly` with m.x >= 0 (a plane through the centre: the cut runs along a great
// circle, so new vertices, the chord intersections pushed back onto the sphere, are exact).
// Empty when nothing is left. `m` need not be unit. `poly` must lie in an open hemisphere
// (e.g. be convex and smaller than a hemisphere), so that the cut is shorter than pi.
SphericalPolygon ClipToHalfSpace(const SphericalPolygon& poly, const Eigen::Vector3d& m);

// A cap holding every vertex of a polygon, about their normalised mean (and so, when it is
// smaller than a hemisphere, every short arc between them); `valid` false when it is not.
struct SphericalCap {
  Eigen::Vector3d centre = Eigen::Vector3d::UnitZ();
  double cos = -1, sin = 0;
  bool valid = false;
  SphericalCap() = default;
  explicit SphericalCap(const SphericalPolygon& p);
};

// A convex spherical polygon (smaller than a hemisphere) with its inward edge normals
// (unit; the polygon is the intersection of the half spaces edge_normal[i].x >= 0).
struct ConvexSpherical {
  SphericalPolygon vertices;
  std::vector<Eigen::Vector3d> edge_normal;
  Eigen::Vector3d cap_centre = Eigen::Vector3d::UnitZ();  // bounding cap of the vertices
  double cap_radius = 0;                                  // radians
  double cap_cos = 1, cap_sin = 0;                        // of cap_radius
  // From counter-clockwise vertices; false (and nothing set) when degenerate.
  bool Set(const SphericalPolygon& ccw);
};

// Appends the parts of `p` outside the convex `q` to `outside` (at most one piece per edge
// of q; convex when p is) and, when `inside` is not null, the part inside q to `inside`.
void SubtractConvex(const SphericalPolygon& p, const ConvexSpherical& q,
                    std::vector<SphericalPolygon>* outside,
                    std::vector<SphericalPolygon>* inside = nullptr);

// The planar convex polygon `points` (world frame) as seen from `origin`, clipped to the half
// space normal.(x - origin) >= 0 and projected onto the unit sphere about `origin`, oriented
// counter-clockwise. False when nothing of it lies in front or it is seen edge-on.
bool ProjectPolygon(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& origin,
                    const Eigen::Vector3d& normal, ConvexSpherical* out);

// Faces sharing a corner with each face (corners welded by position, 1e-9 x the mesh extent):
// the neighbours used to grow a ray-cast occluder set.
class FaceAdjacency {
 public:
  explicit FaceAdjacency(const Mesh& mesh);
  // Neighbours of face t: [begin, end).
  const int* begin(int t) const { return list_.data() + offset_[t]; }
  const int* end(int t) const { return list_.data() + offset_[t + 1]; }
  int num_faces() const { return static_cast<int>(offset_.size()) - 1; }

 private:
  std::vector<int> offset_, list_;
};

struct OccluderSelectOptions {
  // App. A's id buffer, rendered by ray casting: about resolution^2 rays from the point, on
  // a grid of equal steps in polar angle (resolution / 2 rows over 90 deg) and azimuth about
  // the normal. A face no ray hits covers no pixel centre: less than about a pixel, of solid
  // angle (pi / resolution)^2 sin(theta) and cosine weight cos(theta) (projected solid angle
  // <= (pi / resolution)^2 / 2 sr).
  int resolution = 32;
  // Rings of corner-sharing neighbours added to the faces hit (faces visible only between
  // the rays, e.g. slivers along a silhouette).
  int grow_rings = 1;
  void Validate() const;  // throws rouen::Error
};

// App. A, first step: the model faces in front of a surface point, found with the building
// model (Embree) as an id buffer -- the faces hit by the buffer's rays from `origin`, plus
// every face in front whose bounding cap reaches a silhouette pixel (one whose id differs from
// a neighbour's), grown by `grow_rings` rings of corner-sharing neighbours; sorted,
// `own_triangle` left out. A face is missed only when it lies between pixel centres of one
// uniform id (within about a pixel); faces hidden behind nearer ones are culled. On the demo
// model it changes the irradiance by 2e-5 mean, 3e-4 max relative (bench/irradiance_bench).
// `rays` (optional) receives the number of rays cast.
std::vector<int> SelectOccluders(const Mesh& mesh, const RayCaster& model,
                                 const FaceAdjacency& adjacency, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& normal, int own_triangle,
                                 const OccluderSelectOptions& options, int* rays = nullptr);

// The model's faces as occluders: edge-adjacent, coplanar triangles of one block merged into
// convex planar polygons (a box's side is one quad, not two triangles), so that a point sees
// fewer, larger faces and more of the far ones are culled behind a single nearer one. Built
// once per model.
class OccluderFaces {
 public:
  explicit OccluderFaces(const Mesh& mesh);
  int size() const { return static_cast<int>(polygons_.size()); }
  // Counter-clockwise seen from outside (as the mesh's triangles).
  const std::vector<Eigen::Vector3d>& polygon(int f) const { return polygons_[f]; }
  int face_of_triangle(int t) const { return face_of_[t]; }  // -1: a malformed triangle
  int num_triangles() const { return static_cast<int>(face_of_.size()); }

 private:
  std::vector<std::vector<Eigen::Vector3d>> polygons_;
  std::vector<int> face_of_;
};

// What a surface point sees: the hemisphere above its tangent plane minus the model faces
// in front of it (either every triangle with a vertex in front of the plane, or a given
// candidate list such as SelectOccluders' -- extra faces hidden behind others cost time, never
// accuracy). Faces whose projection lies inside one single larger face's are dropped (exact:
// what the point sees is the hemisphere less the union of the projections).
class PointVisibility {
 public:
  // `origin`: the surface point lifted off the surface (as for the ray-cast gathering);
  // `normal`: unit surface normal; `own_triangle` is skipped (-1: none).
  PointVisibility(const Mesh& mesh, const Eigen::Vector3d& origin, const Eigen::Vector3d& normal,
                  int own_triangle = -1);
  // Only the faces listed in `candidates` (indices into mesh.triangles) can occlude.
  PointVisibility(const Mesh& mesh, const Eigen::Vector3d& origin, const Eigen::Vector3d& normal,
                  int own_triangle, const std::vector<int>& candidates);
  // The faces of `faces` in front of the point (the face holding `own_triangle` skipped), or
  // with `candidates` (triangle indices, e.g. SelectOccluders') only the faces holding them.
  PointVisibility(const OccluderFaces& faces, const Eigen::Vector3d& origin,
                  const Eigen::Vector3d& normal, int own_triangle,
                  const std::vector<int>* candidates = nullptr);
  // Appends the visible parts of `patch` to `out` (convex pieces when `patch` is convex).
  void Clip(const SphericalPolygon& patch, std::vector<SphericalPolygon>* out) const;
  // The same with only the occluders listed in `subset` (indices into this object's list,
  // e.g. from Classify).
  void ClipWith(const SphericalPolygon& patch, const std::vector<int>& subset,
                std::vector<SphericalPolygon>* out) const;

  enum class Cover { kHidden, kFull, kPartial };
  // For hierarchical clipping: kHidden when `patch` lies behind the tangent plane or inside
  // one occluder; kFull when it lies in front of the plane and no occluder (of `subset`; all
  // when null) overlaps it; else kPartial, with the occluders that may overlap it appended to
  // `overlapping` (conservative: cheap bounding tests only). `patch`'s edges are great arcs
  // shorter than pi; `convex` enables one more rejection test.
  Cover Classify(const SphericalPolygon& patch, const std::vector<int>* subset, bool convex,
                 std::vector<int>* overlapping) const;
  // The same with the patch's bounding cap given (SphericalCap(patch)).
  Cover Classify(const SphericalPolygon& patch, const SphericalCap& cap,
                 const std::vector<int>* subset, bool convex, std::vector<int>* overlapping) const;

  const Eigen::Vector3d& origin() const { return origin_; }
  const Eigen::Vector3d& normal() const { return normal_; }
  int num_occluders() const { return static_cast<int>(occluders_.size()); }
  int num_culled() const { return culled_; }  // faces in front inside one other's projection
  const ConvexSpherical& occluder(int k) const { return occluders_[k]; }

 private:
  struct Candidate {
    double omega;  // solid angle, sr
    ConvexSpherical cs;
  };
  void Add(const Mesh& mesh, int t, std::vector<Candidate>* found) const;
  void AddPolygon(const std::vector<Eigen::Vector3d>& pts, std::vector<Candidate>* found) const;
  // Sorts by solid angle and drops faces whose projection lies inside a single larger one's:
  // exact culling, as only the union of the projections is seen past (nearer or farther).
  void Finish(std::vector<Candidate>* found);
  Eigen::Vector3d origin_, normal_;
  std::vector<ConvexSpherical> occluders_;  // largest solid angle first
  int culled_ = 0;
};

struct VectorFluxOptions {
  // The sky hemisphere starts as the 4 octant triangles above the horizon, each split into
  // 4^sky_initial_split (the "small set of large patches" clipped for visibility).
  int sky_initial_split = 1;
  // A visible sky patch is subdivided while the sky radiance at its vertices, centre and
  // (when inside) the sun differs by more than this fraction of their mean in some channel.
  // The patch then contributes L(centre) n.Phi (centre: the direction of Phi), a midpoint
  // rule: on a clear sky 0.1 gives ~3e-4 relative error with ~3000 patches per point, 0.05
  // ~8e-5 with ~15000 (VectorFluxTest.AdaptiveSkyMatchesFineQuadrature).
  double sky_tolerance = 0.1;
  int sky_max_depth = 14;    // subdivisions below a visible patch
  double sky_min_sr = 1e-7;  // patches smaller than this are not split further
  // Environment regions' edges along parallels (small circles) are followed by this many
  // great arcs per region (at least one per 60 deg of azimuth).
  int env_parallel_segments = 4;
  // Used by ComputeIrradiance (solve/irradiance.h): the sky tree's levels below the octants
  // (SkyPatchTree, solve/vector_flux_cache.h; 6: 1.4-degree deepest triangles), and whether the
  // occluders are found with the building model (SelectOccluders) rather than taking every
  // face in front of each point (with exact culling of faces hidden behind one other face).
  // On small models every face is both exact and faster; the id buffer pays off on larger
  // ones (bench/irradiance_bench measures both).
  int sky_tree_levels = 6;
  bool select_occluders = false;
  OccluderSelectOptions select;
  void Validate() const;  // throws rouen::Error
};

struct FluxStats {
  int occluders = 0;  // model faces projected
  int patches = 0;    // visible patches whose flux was summed
};

// Direct sky irradiance (sky model above the horizon, nothing below) at one point,
// RGB, relative radiance x sr.
Eigen::Vector3d SkyIrradianceVectorFlux(const PointVisibility& vis, const SkyModel& sky,
                                        const VectorFluxOptions& options,
                                        FluxStats* stats = nullptr);

// The environment map's regions (bands of elevation x sectors of azimuth) as spherical
// polygons, counter-clockwise, with their bounding caps: built once per map layout and shared
// by every point and every lighting of that layout.
class EnvironmentRegions {
 public:
  EnvironmentRegions(const EnvironmentMap& env, const VectorFluxOptions& options);
  int size() const { return static_cast<int>(polygons_.size()); }
  const SphericalPolygon& polygon(int r) const { return polygons_[r]; }
  const SphericalCap& cap(int r) const { return caps_[r]; }
  const Eigen::Vector3d& flux(int r) const { return flux_[r]; }  // eq. 20 of the whole region
  bool below_horizon(int r) const { return r < bands_below_ * sectors_; }
  // Whether `env` has this layout (its radiances can be looked up by these regions' indices).
  bool Fits(const EnvironmentMap& env) const;
  // Appends the regions whose polygons may meet `q` (conservative: q's elevation range, from
  // its vertices and its edges' highest and lowest points, against each band's, and the
  // sectors its azimuths span; every sector when q holds a pole).
  void Near(const ConvexSpherical& q, std::vector<int>* out) const;

 private:
  int bands_below_ = 0, bands_above_ = 0, sectors_ = 0;
  double margin_ = 0;  // how far a polygon's great arcs bulge beyond its band, radians
  std::vector<SphericalPolygon> polygons_;
  std::vector<SphericalCap> caps_;
  std::vector<Eigen::Vector3d> flux_;
};

// What one surface point sees of each environment region (geometry only): Phi (sr) of the
// visible part of every region not hidden and whether that is the whole region, and, when asked,
// the visible pieces of the regions below the horizon (where a ground shadow may cut them).
struct EnvironmentView {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  std::vector<int32_t> region;
  std::vector<Eigen::Vector3d> flux;  // Phi of the visible part of each region
  std::vector<uint8_t> whole;         // 1: the whole region is visible
  std::vector<int32_t> piece_region;  // region of each piece
  std::vector<SphericalPolygon> pieces;
  void Clear();
};

// App. A: clips every region against the point's tangent plane and the occluders that may
// overlap it (EnvironmentRegions::Near), replacing `view`.
void SeeEnvironment(const PointVisibility& vis, const EnvironmentRegions& regions,
                    bool keep_ground_pieces, EnvironmentView* view, FluxStats* stats = nullptr);

// One lighting's sky shape (SkyShape) over a layout's regions: each region's moment for when it
// is wholly seen (SkyShape::Moment of the region's polygon flux).
struct ShapedRegions {
  const SkyShape* shape = nullptr;      // not owned
  std::vector<Eigen::Matrix3d> moment;  // per region (the polygon's flux below the horizon)
  ShapedRegions(const SkyShape& shape, const EnvironmentRegions& regions);
};

// Direct environment irradiance from a view: sum of L(region at height z) n . Phi, RGB. With
// `shaped`, regions above the horizon are spread by the sky's shape: a region wholly seen gives
// L_c n . moment_c, a part of one L_c shape_c(towards its Phi) n . Phi.
// Throws rouen::Error when the view holds a region the map does not have.
Eigen::Vector3d EnvironmentIrradiance(const EnvironmentView& view, const EnvironmentMap& env,
                                      double z, const ShapedRegions* shaped = nullptr);

// The change the ground shadow makes to a view's irradiance: the visible pieces below the
// horizon inside the shadow polygons (convex, seen from the point, possibly overlapping:
// their union is taken piece by piece) count `shadow_ratio` of their radiance, per channel.
// Needs the view's ground pieces.
Eigen::Vector3d GroundShadowChange(const EnvironmentView& view, const EnvironmentRegions& regions,
                                   const EnvironmentMap& env, double z,
                                   const std::vector<ConvexSpherical>& ground_shadow,
                                   const Eigen::Vector3d& shadow_ratio);

// Direct environment irradiance at one point: regions (uniform radiance, looked up at height
// `z`) clipped for visibility, no subdivision. When `ground_shadow` is given (convex spherical
// polygons, seen from the point, of the ground in the model's cast shadow), visible parts
// below the horizon inside them are scaled per channel by `shadow_ratio`.
Eigen::Vector3d EnvironmentIrradianceVectorFlux(const PointVisibility& vis,
                                                const EnvironmentMap& env, double z,
                                                const EnvironmentRegions& regions,
                                                const std::vector<ConvexSpherical>* ground_shadow,
                                                const Eigen::Vector3d& shadow_ratio,
                                                FluxStats* stats = nullptr);

// The model's shadow on the ground plane z = ground_z, cast along the sun direction `sun`
// (z > 0): convex planar polygons (world frame, on the plane), possibly overlapping. A convex
// block standing on the ground, closed but for its bottom, casts one polygon, the convex hull
// of its corners' shadows; another closed block the shadows of its faces (`faces`, built from
// `mesh`) that face the sun; any other block the shadows of all its faces above the plane.
// Built once per lighting.
std::vector<std::vector<Eigen::Vector3d>> GroundShadowOnPlane(const Mesh& mesh,
                                                              const OccluderFaces& faces,
                                                              const Eigen::Vector3d& sun,
                                                              double ground_z);

// The parts of the shadow polygons (on the plane z = ground_z) outside every face of `faces`
// that lies on that plane facing up (a plaza): the ground under such a face is never seen, so
// its shadow changes nothing. Convex pieces; none when the whole shadow falls on such faces.
std::vector<std::vector<Eigen::Vector3d>> ShadowBeyondGroundFaces(
    const std::vector<std::vector<Eigen::Vector3d>>& shadow, const OccluderFaces& faces,
    double ground_z);

// The same union of shadow polygons on the plane (as GroundShadowOnPlane's) as fewer, larger
// convex polygons, counter-clockwise seen from above: polygons lying under the union of the
// others are dropped, and a pair whose convex hull lies under the union of all is replaced by
// the hull (a box's faces' shadows become one), until no pair is left. Built once per lighting;
// each point then sees fewer polygons (GroundShadowPolygons).
std::vector<std::vector<Eigen::Vector3d>> MergeGroundShadow(
    const std::vector<std::vector<Eigen::Vector3d>>& shadow);

// Those polygons seen from `origin` (above the plane): convex spherical polygons.
std::vector<ConvexSpherical> GroundShadowPolygons(
    const std::vector<std::vector<Eigen::Vector3d>>& on_plane, const Eigen::Vector3d& origin);

}  // namespace rouen
