#include "solve/vector_flux_cache.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {

namespace {

using Tri = std::array<Eigen::Vector3d, 3>;

Tri Child(const Tri& t, int j) {
  const Eigen::Vector3d ab = (t[0] + t[1]).normalized(), bc = (t[1] + t[2]).normalized(),
                        ca = (t[2] + t[0]).normalized();
  switch (j) {
    case 0:
      return {t[0], ab, ca};
    case 1:
      return {ab, t[1], bc};
    case 2:
      return {ca, bc, t[2]};
    default:
      return {ab, bc, ca};
  }
}

SphericalPolygon AsPolygon(const Tri& t) { return {t[0], t[1], t[2]}; }

}  // namespace

SkyPatchTree::SkyPatchTree(int levels) : levels_(levels) {
  if (levels < 0 || levels > kMaxLevels) {
    throw Error("SkyPatchTree: levels must be in 0.." + std::to_string(kMaxLevels) + ", got " +
                std::to_string(levels));
  }
  offset_.assign(levels + 2, 0);
  int count = 4;
  for (int l = 0; l <= levels; ++l) {
    offset_[l + 1] = offset_[l] + count;
    count *= 4;
  }
  corners_.resize(offset_[levels + 1]);
  flux_.resize(corners_.size());
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const std::array<Eigen::Vector3d, 4> h = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                            -Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY()};
  // Counter-clockwise seen from outside: horizon point, the next one anticlockwise seen from
  // above, zenith.
  for (int q = 0; q < 4; ++q) corners_[q] = {h[q], h[(q + 1) % 4], z};
  for (int l = 0; l < levels; ++l) {
    for (int node = offset_[l]; node < offset_[l + 1]; ++node) {
      const int c0 = FirstChild(node, l);
      for (int j = 0; j < 4; ++j) corners_[c0 + j] = Child(corners_[node], j);
    }
  }
  for (size_t k = 0; k < corners_.size(); ++k) flux_[k] = VectorFlux(AsPolygon(corners_[k]));
}

namespace {

struct SkyIntegrator {
  const SkyModel& sky;
  const VectorFluxOptions& o;
  int64_t* evals;

  Eigen::Vector3d L(const Eigen::Vector3d& d) const {
    ++*evals;
    return sky.Radiance(d);
  }

  bool SunInside(const Tri& t) const {
    for (int i = 0; i < 3; ++i) {
      if (t[i].cross(t[(i + 1) % 3]).dot(sky.sun_dir) < 0) return false;
    }
    return true;
  }

  // Integral of L w^T dw over t (rows: channels), given the radiance at its corners.
  Eigen::Matrix3d Leaf(const Tri& t, const Tri& lt, int depth) const {
    const Eigen::Vector3d phi = VectorFlux(AsPolygon(t));
    const double len = phi.norm();
    if (!(len > 0)) return Eigen::Matrix3d::Zero();
    const Eigen::Vector3d lc = L(phi / len);
    bool split = false;
    if (depth < o.sky_max_depth && std::abs(SolidAngle(AsPolygon(t))) > o.sky_min_sr) {
      Eigen::Vector3d lo = lc.cwiseMin(lt[0]).cwiseMin(lt[1]).cwiseMin(lt[2]);
      Eigen::Vector3d hi = lc.cwiseMax(lt[0]).cwiseMax(lt[1]).cwiseMax(lt[2]);
      Eigen::Vector3d sum = lc + lt[0] + lt[1] + lt[2];
      int count = 4;
      if (SunInside(t)) {
        const Eigen::Vector3d ls = L(sky.sun_dir);
        lo = lo.cwiseMin(ls);
        hi = hi.cwiseMax(ls);
        sum += ls;
        ++count;
      }
      const Eigen::Vector3d mean = sum / count;
      for (int ch = 0; ch < 3; ++ch) {
        if (hi[ch] - lo[ch] > o.sky_tolerance * std::max(mean[ch], 1e-300)) split = true;
      }
    }
    if (!split) return lc * phi.transpose();
    return Split(t, lt, depth);
  }

  // Sum over the 4 children, each integrated adaptively.
  Eigen::Matrix3d Split(const Tri& t, const Tri& lt, int depth) const {
    const Tri m = {(t[0] + t[1]).normalized(), (t[1] + t[2]).normalized(),
                   (t[2] + t[0]).normalized()};
    const Tri lm = {L(m[0]), L(m[1]), L(m[2])};
    const std::array<Tri, 4> kids = {Tri{t[0], m[0], m[2]}, Tri{m[0], t[1], m[1]},
                                     Tri{m[2], m[1], t[2]}, Tri{m[0], m[1], m[2]}};
    const std::array<Tri, 4> lk = {Tri{lt[0], lm[0], lm[2]}, Tri{lm[0], lt[1], lm[1]},
                                   Tri{lm[2], lm[1], lt[2]}, Tri{lm[0], lm[1], lm[2]}};
    Eigen::Matrix3d g = Eigen::Matrix3d::Zero();
    for (int j = 0; j < 4; ++j) g += Leaf(kids[j], lk[j], depth + 1);
    return g;
  }
};

}  // namespace

SkyTreeRadiance::SkyTreeRadiance(const SkyPatchTree& tree, const SkyModel& sky,
                                 const VectorFluxOptions& options) {
  options.Validate();
  g_.assign(tree.num_nodes(), Eigen::Matrix3d::Zero());
  const SkyIntegrator integ{sky, options, &evaluations_};
  // Corner radiances per node, level by level (children share the parents' corners).
  std::vector<Tri> lcorner(tree.num_nodes());
  for (int q = 0; q < 4; ++q) {
    const Tri& t = tree.corners(q);
    lcorner[q] = {integ.L(t[0]), integ.L(t[1]), integ.L(t[2])};
  }
  const int deepest = tree.levels();
  for (int l = 0; l < deepest; ++l) {
    for (int node = tree.level_offset(l); node < tree.level_offset(l + 1); ++node) {
      const Tri& t = tree.corners(node);
      const Tri& lt = lcorner[node];
      const Tri lm = {integ.L((t[0] + t[1]).normalized()), integ.L((t[1] + t[2]).normalized()),
                      integ.L((t[2] + t[0]).normalized())};
      const int c0 = tree.FirstChild(node, l);
      lcorner[c0 + 0] = {lt[0], lm[0], lm[2]};
      lcorner[c0 + 1] = {lm[0], lt[1], lm[1]};
      lcorner[c0 + 2] = {lm[2], lm[1], lt[2]};
      lcorner[c0 + 3] = {lm[0], lm[1], lm[2]};
    }
  }
  for (int node = tree.level_offset(deepest); node < tree.level_offset(deepest + 1); ++node) {
    g_[node] = integ.Leaf(tree.corners(node), lcorner[node], 0);
  }
  for (int l = deepest - 1; l >= 0; --l) {
    for (int node = tree.level_offset(l); node < tree.level_offset(l + 1); ++node) {
      const int c0 = tree.FirstChild(node, l);
      g_[node] = g_[c0] + g_[c0 + 1] + g_[c0 + 2] + g_[c0 + 3];
    }
  }
}

namespace {

struct SkyCacher {
  const PointVisibility& vis;
  const SkyPatchTree& tree;
  PointFluxCache* cache;
  std::vector<SphericalPolygon> pieces;

  void Visit(int node, int level, const std::vector<int>* subset) {
    const SphericalPolygon poly = AsPolygon(tree.corners(node));
    std::vector<int> overlap;
    const PointVisibility::Cover cover = vis.Classify(poly, subset, true, &overlap);
    if (cover == PointVisibility::Cover::kHidden) return;
    const Eigen::Vector3d& n = vis.normal();
    if (cover == PointVisibility::Cover::kFull) {
      cache->sky_node.push_back(node);
      cache->sky_weight.push_back(n.cast<float>());
      return;
    }
    const int c0 = tree.FirstChild(node, level);
    if (c0 >= 0) {
      for (int j = 0; j < 4; ++j) Visit(c0 + j, level + 1, &overlap);
      return;
    }
    pieces.clear();
    vis.ClipWith(poly, overlap, &pieces);
    if (pieces.empty()) return;
    Eigen::Vector3d phi = Eigen::Vector3d::Zero();
    for (const auto& p : pieces) phi += VectorFlux(p);
    const double w = n.dot(phi);
    const Eigen::Vector3d& full = tree.flux(node);
    const double len = full.norm();
    if (!(w > 0) || !(len > 0)) return;
    // (n . Phi_visible) Lbar = (n . Phi_visible) c . G / |Phi| with c = Phi / |Phi|.
    cache->sky_node.push_back(node);
    cache->sky_weight.push_back((full * (w / (len * len))).cast<float>());
    ++cache->partial_nodes;
  }
};

}  // namespace

void CacheSky(const PointVisibility& vis, const SkyPatchTree& tree, PointFluxCache* cache) {
  cache->sky_node.clear();
  cache->sky_weight.clear();
  cache->partial_nodes = 0;
  SkyCacher c{vis, tree, cache, {}};
  for (int q = 0; q < 4; ++q) c.Visit(q, 0, nullptr);
}

Eigen::Vector3d EvaluateSky(const PointFluxCache& cache, const SkyTreeRadiance& sky) {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  const size_t n = cache.sky_node.size();
  for (size_t k = 0; k < n; ++k) {
    e += sky.G(cache.sky_node[k]) * cache.sky_weight[k].cast<double>();
  }
  return e;
}

}  // namespace rouen
