#include "capture/sim/sim_world.h"

#include <malloc.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <string>

#include "capture/sim/ray_scene.h"
#include "capture/sim/sim_scene.h"
#include "core/angles.h"
#include "core/error.h"
#include "core/hash_random.h"

namespace rouen {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kEps = 1e-3;    // ray origin offset along the normal, metres
constexpr double kLimb = 0.6;    // limb darkening I(mu) = I0 (1 - kLimb (1 - mu))
constexpr int kSampleBits = 11;  // gather record: target << 11 | sample index
constexpr uint32_t kSampleMask = (1u << kSampleBits) - 1;
constexpr uint32_t kTargetFar = (1u << (32 - kSampleBits)) - 1;  // missed, below horizon
constexpr uint32_t kTargetSky = kTargetFar - 1;                  // missed, above horizon
constexpr int kDiscSuper = 16;  // per-axis subsamples of pixels near the sun's disc

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Eigen::Vector3d Clamp0(const Eigen::Vector3d& v) { return v.cwiseMax(0.0); }

struct State {
  UtcTime t;
  AlmanacSun sun;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d disc_e1, disc_e2;                    // orthonormal frame across the disc
  double sun_radius = 0;                               // rad
  double sun_solid_angle = 0;                          // sr
  Eigen::Vector3d sun_irr = Eigen::Vector3d::Zero();   // normal incidence at the site
  Eigen::Vector3d sun_mean = Eigen::Vector3d::Zero();  // mean disc radiance
  SkyTable sky;
  Eigen::Vector3d sky_h = Eigen::Vector3d::Zero();
  double shadow_reach_m = kInf;
  std::vector<Eigen::Vector3f> e_direct;    // area-averaged direct sun per texel
  std::vector<Eigen::Vector3f> e_indirect;  // sky + interreflections per texel
};

}  // namespace

void SimWorldOptions::Validate() const {
  auto fail = [](const std::string& m) { throw Error("SimWorld options: " + m); };
  if (!(site.lat_deg >= -89 && site.lat_deg <= 89)) fail("site latitude must be in [-89, 89]");
  if (!(site.lon_deg >= -180 && site.lon_deg <= 360)) fail("site longitude out of range");
  if (!(site.height_m > -500 && site.height_m < 9000))
    fail("site height must be in (-500, 9000) m");
  for (double t : {tower_texel_m, plaza_texel_m, block_texel_m, ground_texel_m}) {
    if (!(t == 0 || (t >= 0.05 && t <= 50))) fail("texel sizes must be 0 (default) or 0.05..50 m");
  }
  if (hemisphere_samples != 0) {
    const int m = static_cast<int>(std::lround(std::sqrt(hemisphere_samples)));
    if (m * m != hemisphere_samples || hemisphere_samples < 4 ||
        hemisphere_samples > static_cast<int>(kSampleMask) + 1) {
      fail("hemisphere_samples must be a square number in [4, 2048]");
    }
  }
  if (sun_samples != 0) {
    const int m = static_cast<int>(std::lround(std::sqrt(sun_samples)));
    if (m * m != sun_samples || sun_samples > 1024) fail("sun_samples must be a square <= 1024");
  }
  if (bounces < 0 || bounces > 8) fail("bounces must be in [0, 8]");
  if (!(pressure_mbar > 0 && pressure_mbar < 1200)) fail("pressure_mbar must be in (0, 1200)");
  if (!(temperature_c > -80 && temperature_c < 60)) fail("temperature_c must be in (-80, 60)");
  atmosphere.Validate();
}

struct SimWorld::Impl {
  SimWorldOptions opt;
  sim::SceneGeometry scene;
  std::unique_ptr<Atmosphere> atmosphere;
  std::unique_ptr<sim::RayScene> rays;

  int n_texels = 0, strata = 0, n_samples = 0, sun_strata = 0, bounces = 0;
  std::vector<int> texel_patch;
  std::vector<Eigen::Vector3d> texel_pos;
  std::vector<Eigen::Vector3f> texel_albedo;
  std::vector<int> proxy;          // self when valid; else the nearest valid texel
  std::vector<uint8_t> cv_mode;    // 1: sky = unoccluded - occluded part
  std::vector<int64_t> rec_begin;  // n_texels + 1
  std::vector<uint32_t> records;
  // Bit r: record r is a hit whose sample direction rises (d.z() > 0) in a texel whose sky is
  // estimated as unoccluded minus occluded (cv_mode 1), the only hits whose direction the sky
  // estimate needs (time independent, so found once by Setup).
  std::vector<uint64_t> rec_rising;
  // What each new time needs of a record, found once: the sky angles of the records whose sky
  // the estimate sums (sky records, rising hits of bit set), and the ground point (x, y) of
  // far records (x NaN: the sample sees the horizon's sky instead), each in record order from
  // its texel's begin. Per texel, the sum of the ground's albedo over its far ground points.
  std::vector<int64_t> sky_begin, far_begin;  // n_texels + 1
  std::vector<SkyAngles> sky_angles;
  std::vector<Eigen::Vector2f> far_points;
  std::vector<Eigen::Vector3d> far_albedo;

  std::map<int64_t, std::shared_ptr<const State>> cache;
  std::shared_ptr<const State> cur;
  SimWorldStats stats;

  const State& S() const {
    if (!cur) throw Error("SimWorld: SetTime() has not been called");
    return *cur;
  }

  using Hit = sim::RayHit;
  Hit Trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const { return rays->Trace(o, d); }
  bool Occluded(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
    return rays->Occluded(o, d);
  }

  // Cosine-weighted, stratified direction k of texel i (reproducible from (i, k)).
  Eigen::Vector3d SampleDir(int i, int k) const {
    const sim::Patch& p = scene.patches[texel_patch[i]];
    const int a = k % strata, b = k / strata;
    const uint64_t h =
        MixHash(opt.seed * 0x2545F4914F6CDD1DULL ^ MixHash((static_cast<uint64_t>(i) << 12) | k));
    const double u1 = (a + HashUniformHigh(h)) / strata, u2 = (b + HashUniformLow(h)) / strata;
    const double r = std::sqrt(u1), phi = 2 * kPi * u2;
    return (p.u * (r * std::cos(phi)) + p.v * (r * std::sin(phi)) +
            p.n * std::sqrt(std::max(0.0, 1.0 - u1)))
        .normalized();
  }

  // A direction uniformly distributed over the sun's disc.
  Eigen::Vector3d DiscDir(const State& s, double x1, double x2) const {
    const double r = s.sun_radius * std::sqrt(x1), phi = 2 * kPi * x2;
    return (s.sun_dir + s.disc_e1 * (r * std::cos(phi)) + s.disc_e2 * (r * std::sin(phi)))
        .normalized();
  }

  // Radiance of the analytic ground beyond the textured square (unoccluded sky, sun with a
  // shadow ray where a building's shadow can reach).
  Eigen::Vector3d FarGround(const State& s, const Eigen::Vector3d& p) const {
    Eigen::Vector3d e = s.sky_h;
    if (GroundSunlit(s, p.x(), p.y())) e += s.sun_irr * s.sun_dir.z();
    return sim::MaterialAlbedo(sim::kGround, p).cwiseProduct(e) / kPi;
  }
  // Whether the sun is up and lights the ground at (x, y) (a shadow ray only where a
  // building's shadow can reach).
  bool GroundSunlit(const State& s, double x, double y) const {
    if (s.sun_dir.z() <= 0) return false;
    return std::hypot(x, y) >= s.shadow_reach_m ||
           !Occluded(Eigen::Vector3d(x, y, kEps), s.sun_dir);
  }

  Eigen::Vector3d IndirectAt(const State& s, const sim::Patch& p, double u, double v) const {
    const double fi = std::clamp(u / p.du - 0.5, 0.0, p.nu - 1.0);
    const double fj = std::clamp(v / p.dv - 0.5, 0.0, p.nv - 1.0);
    const int i0 = std::min(static_cast<int>(fi), std::max(p.nu - 2, 0));
    const int j0 = std::min(static_cast<int>(fj), std::max(p.nv - 2, 0));
    const int i1 = std::min(i0 + 1, p.nu - 1), j1 = std::min(j0 + 1, p.nv - 1);
    const double a = fi - i0, b = fj - j0;
    auto at = [&](int i, int j) {
      return s.e_indirect[p.texel_offset + j * p.nu + i].cast<double>();
    };
    return (1 - b) * ((1 - a) * at(i0, j0) + a * at(i1, j0)) +
           b * ((1 - a) * at(i0, j1) + a * at(i1, j1));
  }

  // Direct sun irradiance at a surface point with normal n, from `m` disc samples.
  Eigen::Vector3d DirectAt(const State& s, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                           int m, uint64_t seed) const {
    const double c = n.dot(s.sun_dir);
    if (c <= 0 || s.sun_irr.maxCoeff() <= 0) return Eigen::Vector3d::Zero();
    const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(m))));
    int visible = 0;
    for (int q = 0; q < side * side; ++q) {
      const uint64_t h = MixHash(seed + q);
      const double x1 = ((q % side) + HashUniformHigh(h)) / side,
                   x2 = ((q / side) + HashUniformLow(h)) / side;
      if (!Occluded(p + n * kEps, DiscDir(s, x1, x2))) ++visible;
    }
    return s.sun_irr * (c * visible / (side * side));
  }

  // Radiance along a ray (no sun disc). `block` gets the model block, -1 or -2 (sky).
  Eigen::Vector3d Shade(const State& s, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                        double x1, double x2, int* block) const {
    const Hit h = Trace(o, d);
    if (h.patch >= 0) {
      const sim::Patch& p = scene.patches[h.patch];
      if (block) *block = p.model_block;
      if (d.dot(p.n) >= 0) return Eigen::Vector3d::Zero();  // inside a solid
      const Eigen::Vector3d x = o + h.t * d;
      bool sunlit = false;
      Eigen::Vector3d out = Diffuse(s, p, x, x1, x2, &sunlit);
      const sim::MaterialGloss gloss = sim::MaterialSpecular(p.material);
      if (gloss.rho_s > 0) out += Specular(s, p, x, -d, gloss, sunlit, x1, x2);
      return out;
    }
    if (d.z() > 0 || o.z() <= 0) {
      if (block) *block = d.z() > 0 ? -2 : -1;
      return s.sky.Radiance(d);
    }
    if (block) *block = -1;
    const double t = -o.z() / d.z();
    if (!std::isfinite(t)) return s.sky.Radiance(d);
    return FarGround(s, o + t * d);
  }

  // The diffuse radiance leaving point x of patch p: albedo / pi x (sun through the disc point
  // (x1, x2), shadows in, plus the texel's sky, ground and interreflection).
  Eigen::Vector3d Diffuse(const State& s, const sim::Patch& p, const Eigen::Vector3d& x, double x1,
                          double x2, bool* sunlit) const {
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    const double c = p.n.dot(s.sun_dir);
    *sunlit = c > 0 && s.sun_irr.maxCoeff() > 0 && !Occluded(x + p.n * kEps, DiscDir(s, x1, x2));
    if (*sunlit) e += s.sun_irr * c;
    const Eigen::Vector2d st = p.Local(x);
    e += IndirectAt(s, p, st.x(), st.y());
    return sim::MaterialAlbedo(p.material, x).cwiseProduct(e) / kPi;
  }

  // The specular radiance towards v (unit, from x) of a glossy patch: the sun's through the
  // lobe, and the sky's, the ground's and the surfaces' (their diffuse radiance) by sampling
  // the lobe around the mirror direction (kGlossSamples directions with pdf
  // (n + 1) / 2 pi cos^n, so each weighs rho_s 2 pi / (n + 1) L cos(theta)). The light the
  // lobe reflects onto other surfaces is left out (2% of the roof's light).
  Eigen::Vector3d Specular(const State& s, const sim::Patch& p, const Eigen::Vector3d& x,
                           const Eigen::Vector3d& v, const sim::MaterialGloss& g, bool sunlit,
                           double x1, double x2) const {
    constexpr int kGlossSamples = 4;
    const Eigen::Vector3d m = 2 * v.dot(p.n) * p.n - v;
    Eigen::Vector3d out = Eigen::Vector3d::Zero();
    const double c = p.n.dot(s.sun_dir);
    if (sunlit) out += g.rho_s * std::pow(std::max(0.0, m.dot(s.sun_dir)), g.n) * c * s.sun_irr;
    // An orthonormal frame around m.
    const Eigen::Vector3d a =
        std::abs(m.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
    const Eigen::Vector3d t1 = a.cross(m).normalized(), t2 = m.cross(t1);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int q = 0; q < kGlossSamples; ++q) {
      const uint64_t h = MixHash(MixHash(static_cast<uint64_t>(x1 * 4294967296.0)) ^
                                 (static_cast<uint64_t>(x2 * 4294967296.0) << 3 | q));
      const double cos_a = std::pow(HashUniformHigh(h), 1.0 / (g.n + 1));
      const double sin_a = std::sqrt(std::max(0.0, 1 - cos_a * cos_a));
      const double phi = 2 * kPi * HashUniformLow(h);
      const Eigen::Vector3d u = cos_a * m + sin_a * (std::cos(phi) * t1 + std::sin(phi) * t2);
      const double cu = u.dot(p.n);
      if (cu <= 0) continue;
      const Eigen::Vector3d o = x + p.n * kEps;
      const Hit hit = Trace(o, u);
      Eigen::Vector3d l;
      if (hit.patch >= 0) {
        const sim::Patch& q2 = scene.patches[hit.patch];
        bool lit = false;
        l = u.dot(q2.n) < 0 ? Diffuse(s, q2, o + hit.t * u, x2, x1, &lit) : Eigen::Vector3d::Zero();
      } else if (u.z() > 0 || o.z() <= 0) {
        l = s.sky.Radiance(u);
      } else {
        l = FarGround(s, o + (-o.z() / u.z()) * u);
      }
      sum += l * cu;
    }
    return out + g.rho_s * (2 * kPi / (g.n + 1)) * sum / kGlossSamples;
  }

  int NearestPatch(const Eigen::Vector3d& q, double* dist) const {
    int best = -1;
    double bd = kInf;
    for (size_t i = 0; i < scene.patches.size(); ++i) {
      const double d = scene.patches[i].Distance(q);
      if (d < bd) {
        bd = d;
        best = static_cast<int>(i);
      }
    }
    // The analytic ground beyond the textured square.
    const double g = scene.ground_half_extent_m;
    if ((std::abs(q.x()) > g || std::abs(q.y()) > g) && std::abs(q.z()) < bd) {
      bd = std::abs(q.z());
      best = -1;
    }
    *dist = bd;
    return best;
  }

  void Setup();
  std::shared_ptr<const State> Compute(UtcTime t) const;
};

void SimWorld::Impl::Setup() {
  const auto t0 = std::chrono::steady_clock::now();
  const bool q = opt.quick;
  sim::TexelSizes sizes;
  sizes.tower_m = opt.tower_texel_m > 0 ? opt.tower_texel_m : (q ? 0.6 : 0.4);
  sizes.plaza_m = opt.plaza_texel_m > 0 ? opt.plaza_texel_m : (q ? 2.0 : 1.0);
  sizes.block_m = opt.block_texel_m > 0 ? opt.block_texel_m : (q ? 2.0 : 1.0);
  sizes.ground_m = opt.ground_texel_m > 0 ? opt.ground_texel_m : (q ? 8.0 : 4.0);
  n_samples = opt.hemisphere_samples > 0 ? opt.hemisphere_samples : (q ? 400 : 1024);
  strata = static_cast<int>(std::lround(std::sqrt(n_samples)));
  const int sun_samples = opt.sun_samples > 0 ? opt.sun_samples : (q ? 4 : 16);
  sun_strata = static_cast<int>(std::lround(std::sqrt(sun_samples)));
  bounces = opt.bounces > 0 ? opt.bounces : (q ? 4 : 5);
  scene = sim::BuildScene(sizes);
  atmosphere = std::make_unique<Atmosphere>(opt.atmosphere);

  rays = std::make_unique<sim::RayScene>(scene.patches);

  // Lighting texels.
  for (const sim::Patch& p : scene.patches) n_texels += p.nu * p.nv;
  if (n_texels >= static_cast<int>(kTargetSky)) throw Error("SimWorld: too many lighting texels");
  texel_patch.resize(n_texels);
  texel_pos.resize(n_texels);
  texel_albedo.resize(n_texels);
  for (size_t pi = 0; pi < scene.patches.size(); ++pi) {
    const sim::Patch& p = scene.patches[pi];
    for (int j = 0; j < p.nv; ++j) {
      for (int i = 0; i < p.nu; ++i) {
        const int t = p.texel_offset + j * p.nu + i;
        texel_patch[t] = static_cast<int>(pi);
        texel_pos[t] = p.Point((i + 0.5) * p.du, (j + 0.5) * p.dv);
        texel_albedo[t] = sim::MaterialAlbedo(p.material, texel_pos[t]).cast<float>();
      }
    }
  }

  // The time-independent gather structure: for each texel, which hemisphere samples hit
  // which texel, and which escaped below the horizon (far ground) or above it (sky).
  std::vector<std::vector<uint32_t>> per(n_texels);
  std::vector<std::vector<uint8_t>> per_rising(n_texels);  // per record of per[i]
  std::vector<uint8_t> valid(n_texels, 1);
  cv_mode.assign(n_texels, 1);
  tbb::parallel_for(
      tbb::blocked_range<int>(0, n_texels, 64), [&](const tbb::blocked_range<int>& r) {
        std::vector<uint32_t> sky;
        for (int i = r.begin(); i != r.end(); ++i) {
          const sim::Patch& p = scene.patches[texel_patch[i]];
          const Eigen::Vector3d o = texel_pos[i] + p.n * kEps;
          std::vector<uint32_t>& out = per[i];
          std::vector<uint8_t>& rising = per_rising[i];
          sky.clear();
          int back = 0, occluded_sky = 0;
          Eigen::Vector3d dirs[sim::RayScene::kPacket];
          Hit hits[sim::RayScene::kPacket];
          for (int k = 0; k < n_samples; ++k) {
            const int lane = k % sim::RayScene::kPacket;
            if (lane == 0) {
              const int m = std::min(sim::RayScene::kPacket, n_samples - k);
              for (int j = 0; j < m; ++j) dirs[j] = SampleDir(i, k + j);
              rays->TracePacket(o, dirs, m, hits);
            }
            const Eigen::Vector3d& d = dirs[lane];
            const Hit& h = hits[lane];
            if (h.patch >= 0) {
              const sim::Patch& hp = scene.patches[h.patch];
              if (d.dot(hp.n) > 0) ++back;
              const Eigen::Vector2d st = hp.Local(o + h.t * d);
              out.push_back(static_cast<uint32_t>(hp.TexelAt(st.x(), st.y())) << kSampleBits |
                            static_cast<uint32_t>(k));
              rising.push_back(d.z() > 0);
              if (d.z() > 0) ++occluded_sky;
            } else if (d.z() > 0) {
              sky.push_back(kTargetSky << kSampleBits | static_cast<uint32_t>(k));
            } else {
              out.push_back(kTargetFar << kSampleBits | static_cast<uint32_t>(k));
              rising.push_back(0);
            }
          }
          valid[i] = back * 4 < n_samples;
          // Estimate the sky from the smaller of the occluded and the open parts (the open
          // part alone: no hit's direction is needed).
          if (occluded_sky > static_cast<int>(sky.size())) {
            cv_mode[i] = 0;
            out.insert(out.end(), sky.begin(), sky.end());
            rising.assign(out.size(), 0);
          }
          out.shrink_to_fit();
          rising.shrink_to_fit();
        }
      });
  rec_begin.assign(n_texels + 1, 0);
  for (int i = 0; i < n_texels; ++i) rec_begin[i + 1] = rec_begin[i] + per[i].size();
  records.resize(rec_begin[n_texels]);
  rec_rising.assign((records.size() + 63) / 64, 0);
  for (int i = 0; i < n_texels; ++i) {
    std::copy(per[i].begin(), per[i].end(), records.begin() + rec_begin[i]);
    for (size_t j = 0; j < per_rising[i].size(); ++j) {
      const uint64_t r = static_cast<uint64_t>(rec_begin[i]) + j;
      if (per_rising[i][j]) rec_rising[r / 64] |= uint64_t{1} << (r % 64);
    }
    std::vector<uint32_t>().swap(per[i]);
    std::vector<uint8_t>().swap(per_rising[i]);
  }

  // Whether the sky estimate sums record r's sky (far records have no rising bit).
  auto sums_sky = [&](int64_t r) {
    return (records[r] >> kSampleBits) == kTargetSky || (rec_rising[r / 64] >> (r % 64) & 1);
  };
  sky_begin.assign(n_texels + 1, 0);
  far_begin.assign(n_texels + 1, 0);
  for (int i = 0; i < n_texels; ++i) {
    int64_t sky = 0, far = 0;
    for (int64_t r = rec_begin[i]; r < rec_begin[i + 1]; ++r) {
      if ((records[r] >> kSampleBits) == kTargetFar) ++far;
      if (sums_sky(r)) ++sky;
    }
    sky_begin[i + 1] = sky_begin[i] + sky;
    far_begin[i + 1] = far_begin[i] + far;
  }
  sky_angles.resize(sky_begin[n_texels]);
  far_points.resize(far_begin[n_texels]);
  far_albedo.assign(n_texels, Eigen::Vector3d::Zero());
  tbb::parallel_for(
      tbb::blocked_range<int>(0, n_texels, 256), [&](const tbb::blocked_range<int>& r) {
        for (int i = r.begin(); i != r.end(); ++i) {
          const Eigen::Vector3d o = texel_pos[i] + scene.patches[texel_patch[i]].n * kEps;
          int64_t sk = sky_begin[i], fk = far_begin[i];
          for (int64_t r2 = rec_begin[i]; r2 < rec_begin[i + 1]; ++r2) {
            const uint32_t target = records[r2] >> kSampleBits;
            if (target != kTargetFar && !sums_sky(r2)) continue;
            const Eigen::Vector3d d = SampleDir(i, static_cast<int>(records[r2] & kSampleMask));
            if (target == kTargetFar) {
              Eigen::Vector2f& g = far_points[fk++];
              g = Eigen::Vector2f::Constant(std::numeric_limits<float>::quiet_NaN());
              if (d.z() < -1e-9 && o.z() > 0) {
                const Eigen::Vector3d p = o + (-o.z() / d.z()) * d;
                g = Eigen::Vector2f(static_cast<float>(p.x()), static_cast<float>(p.y()));
                far_albedo[i] += sim::MaterialAlbedo(sim::kGround, p);
              }
            } else {
              sky_angles[sk++] = SkyAngles::Of(d);
            }
          }
        }
      });

  // Texels inside solids (plaza under the tower, ground under blocks) take the values of
  // the nearest valid texel of their patch.
  proxy.resize(n_texels);
  int invalid = 0;
  for (const sim::Patch& p : scene.patches) {
    for (int j = 0; j < p.nv; ++j) {
      for (int i = 0; i < p.nu; ++i) {
        const int t = p.texel_offset + j * p.nu + i;
        proxy[t] = t;
        if (valid[t]) continue;
        ++invalid;
        double best = kInf;
        for (int jj = 0; jj < p.nv; ++jj) {
          for (int ii = 0; ii < p.nu; ++ii) {
            const int u = p.texel_offset + jj * p.nu + ii;
            const double d2 = std::pow((ii - i) * p.du, 2) + std::pow((jj - j) * p.dv, 2);
            if (valid[u] && d2 < best) {
              best = d2;
              proxy[t] = u;
            }
          }
        }
      }
    }
  }
  // The per-texel buffers above, freed, stay in the allocator's arenas (80 MB for the demo's
  // world); give the memory back.
  malloc_trim(0);
  stats.texels = n_texels;
  stats.invalid_texels = invalid;
  stats.gather_records = static_cast<int64_t>(records.size());
  stats.setup_seconds = Seconds(t0);
}

std::shared_ptr<const State> SimWorld::Impl::Compute(UtcTime t) const {
  auto st = std::make_shared<State>();
  State& s = *st;
  s.t = t;
  s.sun = AlmanacSunPosition(t, opt.site, opt.pressure_mbar, opt.temperature_c);
  s.sun_dir = s.sun.DirectionEnu();
  s.disc_e1 = s.sun_dir.cross(Eigen::Vector3d::UnitZ());
  if (s.disc_e1.norm() < 1e-9) s.disc_e1 = Eigen::Vector3d::UnitX();
  s.disc_e1.normalize();
  s.disc_e2 = s.sun_dir.cross(s.disc_e1).normalized();
  s.sun_radius = s.sun.angular_radius_deg * kPi / 180;
  s.sun_solid_angle = 2 * kPi * (1 - std::cos(s.sun_radius));
  const Eigen::Vector3d toa = opt.atmosphere.solar_toa / (s.sun.distance_au * s.sun.distance_au);
  const Eigen::Vector3d tau = atmosphere->OpticalDepthExact(opt.site.height_m, s.sun_dir.z());
  s.sun_irr = std::isfinite(tau[0]) ? Eigen::Vector3d(toa.array() * (-tau).array().exp())
                                    : Eigen::Vector3d::Zero();
  s.sun_mean = s.sun_irr / s.sun_solid_angle;
  s.sky = SkyTable(*atmosphere, opt.site.height_m, s.sun_dir, toa);
  s.sky_h = s.sky.HorizontalIrradiance();
  const double el = std::asin(std::clamp(s.sun_dir.z(), -1.0, 1.0));
  s.shadow_reach_m = el > 1e-3 ? scene.ground_half_extent_m * 1.5 + 70.0 / std::tan(el) : kInf;

  // Unoccluded sky irradiance for each patch's plane (shared by equal normals).
  std::vector<Eigen::Vector3d> unoccluded(scene.patches.size());
  {
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> seen;
    for (size_t i = 0; i < scene.patches.size(); ++i) {
      const Eigen::Vector3d& n = scene.patches[i].n;
      bool found = false;
      for (const auto& [m, e] : seen) {
        if ((m - n).norm() < 1e-9) {
          unoccluded[i] = e;
          found = true;
          break;
        }
      }
      if (!found) {
        unoccluded[i] = s.sky.PlaneIrradiance(n);
        seen.emplace_back(n, unoccluded[i]);
      }
    }
  }

  const int n = n_texels;
  const double w = kPi / n_samples;  // cosine-weighted estimator weight
  const bool sun_up = s.sun_dir.z() > 0;
  const Eigen::Vector3d sun_h = sun_up ? Eigen::Vector3d(s.sun_irr * s.sun_dir.z())
                                       : Eigen::Vector3d::Zero();  // on the ground
  s.e_direct.assign(n, Eigen::Vector3f::Zero());
  std::vector<Eigen::Vector3d> e_sky(n), e_far(n), e_bounce(n, Eigen::Vector3d::Zero());
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i != r.end(); ++i) {
      const sim::Patch& p = scene.patches[texel_patch[i]];
      // Direct sun, averaged over the texel's area and the disc.
      const double c = p.n.dot(s.sun_dir);
      if (c > 0 && s.sun_irr.maxCoeff() > 0) {
        const int j = (i - p.texel_offset) / p.nu, k = (i - p.texel_offset) % p.nu;
        // Points of the texel that lie inside a solid (a texel straddling a wall's foot)
        // see a back face first; they are not part of the surface and do not count.
        int visible = 0, outside = 0;
        const int m = sun_strata;
        for (int q = 0; q < m * m; ++q) {
          const uint64_t h = MixHash(MixHash(opt.seed + 77) ^ (static_cast<uint64_t>(i) << 10 | q));
          const double su = (k + ((q % m) + HashUniformHigh(h)) / m) * p.du;
          const double sv = (j + ((q / m) + HashUniformLow(h)) / m) * p.dv;
          const uint64_t h2 = MixHash(h);
          const Eigen::Vector3d x = p.Point(su, sv) + p.n * kEps;
          const Eigen::Vector3d d = DiscDir(s, HashUniformHigh(h2), HashUniformLow(h2));
          const Hit hit = Trace(x, d);
          if (hit.patch >= 0 && d.dot(scene.patches[hit.patch].n) > 0) continue;
          ++outside;
          if (hit.patch < 0) ++visible;
        }
        if (outside > 0) s.e_direct[i] = (s.sun_irr * (c * visible / outside)).cast<float>();
      }
      // Sky (with occlusion) and the analytic far ground: its albedo over the sky's and the
      // sun's irradiance, less the sun on the points in a building's shadow.
      Eigen::Vector3d occluded = Eigen::Vector3d::Zero(), open = Eigen::Vector3d::Zero(),
                      far = Eigen::Vector3d::Zero(), shadowed = Eigen::Vector3d::Zero();
      int64_t sk = sky_begin[i], fk = far_begin[i];
      for (int64_t r2 = rec_begin[i]; r2 < rec_begin[i + 1]; ++r2) {
        const uint32_t rec = records[r2];
        const uint32_t target = rec >> kSampleBits;
        if (target == kTargetFar) {
          const Eigen::Vector2f& g = far_points[fk++];
          if (std::isnan(g.x())) {
            far += s.sky.Radiance(SampleDir(i, static_cast<int>(rec & kSampleMask)));
          } else if (sun_up && !GroundSunlit(s, g.x(), g.y())) {
            shadowed += sim::MaterialAlbedo(sim::kGround, Eigen::Vector3d(g.x(), g.y(), 0));
          }
        } else if (target == kTargetSky) {
          open += s.sky.Radiance(sky_angles[sk++]);
        } else if (rec_rising[r2 / 64] >> (r2 % 64) & 1) {
          // A hit: the sky behind it counts only above the horizon.
          occluded += s.sky.Radiance(sky_angles[sk++]);
        }
      }
      far += (far_albedo[i].cwiseProduct(s.sky_h + sun_h) - shadowed.cwiseProduct(sun_h)) / kPi;
      e_sky[i] = cv_mode[i] ? Clamp0(unoccluded[texel_patch[i]] - w * occluded) : w * open;
      e_far[i] = w * far;
    }
  });
  for (int i = 0; i < n; ++i) {
    if (proxy[i] != i) {
      s.e_direct[i] = s.e_direct[proxy[i]];
      e_sky[i] = e_sky[proxy[i]];
      e_far[i] = e_far[proxy[i]];
    }
  }

  // Interreflections: gather the radiance of the previous iterate through the stored hits.
  std::vector<Eigen::Vector3f> radiance(n);
  for (int b = 0; b < bounces; ++b) {
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d e = s.e_direct[i].cast<double>() + e_sky[i] + e_bounce[i];
      radiance[i] = (texel_albedo[i].cast<double>().cwiseProduct(e) / kPi).cast<float>();
    }
    std::vector<Eigen::Vector3d> next(n);
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 256), [&](const tbb::blocked_range<int>& r) {
      for (int i = r.begin(); i != r.end(); ++i) {
        Eigen::Vector3f sum = Eigen::Vector3f::Zero();
        for (int64_t r2 = rec_begin[i]; r2 < rec_begin[i + 1]; ++r2) {
          const uint32_t target = records[r2] >> kSampleBits;
          if (target < kTargetSky) sum += radiance[target];
        }
        next[i] = e_far[i] + w * sum.cast<double>();
      }
    });
    for (int i = 0; i < n; ++i) e_bounce[i] = next[proxy[i]];
  }
  s.e_indirect.resize(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d e = e_sky[i] + (bounces > 0 ? e_bounce[i] : e_far[i]);
    if (!e.allFinite() || !s.e_direct[i].allFinite()) {
      throw Error("SimWorld: non-finite irradiance at lighting texel " + std::to_string(i));
    }
    s.e_indirect[i] = e.cast<float>();
  }
  return st;
}

SimWorld::SimWorld(const SimWorldOptions& options) : impl_(std::make_unique<Impl>()) {
  options.Validate();
  impl_->opt = options;
  impl_->Setup();
}

SimWorld::~SimWorld() = default;

const SimWorldOptions& SimWorld::options() const { return impl_->opt; }
const Site& SimWorld::site() const { return impl_->opt.site; }
const SimWorldStats& SimWorld::stats() const { return impl_->stats; }

void SimWorld::SetTime(UtcTime t) {
  // Already current: nothing written (renders of this time may be running on other threads).
  if (impl_->cur && impl_->cur->t == t) return;
  auto it = impl_->cache.find(t.ns);
  if (it != impl_->cache.end()) {
    impl_->cur = it->second;
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  auto st = impl_->Compute(t);
  impl_->cache.emplace(t.ns, st);
  impl_->cur = st;
  impl_->stats.last_time_seconds = Seconds(t0);
  ++impl_->stats.times_computed;
}

bool SimWorld::HasTime() const { return impl_->cur != nullptr; }
UtcTime SimWorld::Time() const { return impl_->S().t; }

const Mesh& SimWorld::Model() const { return impl_->scene.model; }
void SimWorld::WriteModelObj(const std::string& path) const { WriteObj(path, Model()); }

Eigen::Vector3d SimWorld::TrueAlbedo(const Eigen::Vector3d& point) const {
  double d = 0;
  const int p = impl_->NearestPatch(point, &d);
  return sim::MaterialAlbedo(p >= 0 ? impl_->scene.patches[p].material : sim::kGround, point);
}

const AlmanacSun& SimWorld::TrueSun() const { return impl_->S().sun; }
Eigen::Vector3d SimWorld::TrueSunDirection() const { return impl_->S().sun_dir; }
Eigen::Vector3d SimWorld::TrueSunIrradiance() const { return impl_->S().sun_irr; }
Eigen::Vector3d SimWorld::TrueSunRadiance() const { return impl_->S().sun_mean; }
double SimWorld::TrueSunSolidAngle() const { return impl_->S().sun_solid_angle; }
Eigen::Vector3d SimWorld::TrueSkyRadiance(const Eigen::Vector3d& dir) const {
  return impl_->S().sky.Radiance(dir);
}
Eigen::Vector3d SimWorld::TrueSkyIrradiance() const { return impl_->S().sky_h; }

Eigen::Vector3d SimWorld::TrueIrradiance(const Eigen::Vector3d& point) const {
  const State& s = impl_->S();
  double d = 0;
  const int pi = impl_->NearestPatch(point, &d);
  if (pi < 0) {
    const Eigen::Vector3d g(point.x(), point.y(), 0);
    return impl_->FarGround(s, g).cwiseQuotient(sim::MaterialAlbedo(sim::kGround, g)) * kPi;
  }
  const sim::Patch& p = impl_->scene.patches[pi];
  const Eigen::Vector3d x = p.Closest(point);
  const Eigen::Vector2d st = p.Local(x);
  return impl_->DirectAt(s, x, p.n, 256, 12345) + impl_->IndirectAt(s, p, st.x(), st.y());
}

Eigen::Vector3d SimWorld::TrueRadiance(const Eigen::Vector3d& point) const {
  return TrueAlbedo(point).cwiseProduct(TrueIrradiance(point)) / kPi;
}

namespace {

// Pixels outside a fisheye's image circle (which fills min(width, height)) are not imaged.
bool InsideImage(const Intrinsics& k, double x, double y) {
  if (k.projection != Projection::kFisheye) return true;
  const double r = 0.5 * std::min(k.width, k.height);
  return std::hypot(x - k.cx, y - k.cy) <= r;
}

// A bound on a pixel's angular size (radians).
double PixelAngle(const Intrinsics& k) {
  if (k.projection == Projection::kEquirect) return std::max(2 * kPi / k.width, kPi / k.height);
  return 1.0 / std::min(k.fx, k.fy);
}

}  // namespace

Image SimWorld::RenderRadiance(const Intrinsics& k, const Pose& pose) const {
  k.Validate();
  const Impl& im = *impl_;
  const State& s = im.S();
  Image img(k.width, k.height, 3, PixelUnits::kRadiance);
  const double near_sun = s.sun_radius + 3.0 * PixelAngle(k);
  const double limb_mean = 1.0 - kLimb / 3.0;  // disc average of the limb-darkening law
  const Eigen::Vector3d centre_radiance = s.sun_mean / limb_mean;
  const Eigen::Vector3d o = pose.position;
  tbb::parallel_for(tbb::blocked_range<int>(0, k.height, 4), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) {
      for (int x = 0; x < k.width; ++x) {
        if (!InsideImage(k, x + 0.5, y + 0.5)) continue;
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int q = 0; q < 4; ++q) {
          const uint64_t h = MixHash((static_cast<uint64_t>(y) * 65536 + x) * 4 + q);
          const double px = x + ((q & 1) + HashUniformHigh(h)) * 0.5,
                       py = y + ((q >> 1) + HashUniformLow(h)) * 0.5;
          const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(px, py));
          const uint64_t h2 = MixHash(h);
          sum += im.Shade(s, o, d, HashUniformHigh(h2), HashUniformLow(h2), nullptr);
        }
        Eigen::Vector3d value = sum / 4.0;
        // The sun's disc, supersampled where it may touch the pixel.
        const Eigen::Vector3d dc = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
        if (s.sun_irr.maxCoeff() > 0 &&
            std::atan2(dc.cross(s.sun_dir).norm(), dc.dot(s.sun_dir)) < near_sun) {
          double limb = 0;
          for (int q = 0; q < kDiscSuper * kDiscSuper; ++q) {
            const double px = x + ((q % kDiscSuper) + 0.5) / kDiscSuper;
            const double py = y + ((q / kDiscSuper) + 0.5) / kDiscSuper;
            const Eigen::Vector3d d =
                (pose.rotation * Unproject(k, Eigen::Vector2d(px, py))).normalized();
            const double g = std::atan2(d.cross(s.sun_dir).norm(), d.dot(s.sun_dir));
            if (g >= s.sun_radius || d.z() <= 0) continue;
            if (im.Occluded(o, d)) continue;
            const double rr = g / s.sun_radius;
            limb += 1.0 - kLimb * (1.0 - std::sqrt(std::max(0.0, 1.0 - rr * rr)));
          }
          value += centre_radiance * (limb / (kDiscSuper * kDiscSuper));
        }
        if (!value.allFinite()) throw Error("SimWorld: non-finite radiance while rendering");
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(value[c]);
      }
    }
  });
  return img;
}

Image SimWorld::RenderBlockIds(const Intrinsics& k, const Pose& pose) const {
  k.Validate();
  const Impl& im = *impl_;
  Image img(k.width, k.height, 1, PixelUnits::kOther, -1.0f);
  tbb::parallel_for(tbb::blocked_range<int>(0, k.height, 4), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) {
      for (int x = 0; x < k.width; ++x) {
        if (!InsideImage(k, x + 0.5, y + 0.5)) continue;
        const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
        const sim::RayHit h = im.Trace(pose.position, d);
        int id = -1;
        if (h.patch >= 0) {
          const sim::Patch& p = im.scene.patches[h.patch];
          id = d.dot(p.n) < 0 ? p.model_block : -1;
        } else if (d.z() > 0) {
          id = -2;
        }
        img.at(x, y) = static_cast<float>(id);
      }
    }
  });
  return img;
}

std::vector<SimView> SimWorld::ArchitectureViews(bool quick) const {
  struct Spot {
    double azimuth_deg, distance_m, eye_m;
  };
  // Around the tower: SSW, WNW, NNE, ESE; clear of the surrounding blocks.
  const Spot spots[] = {{200, 80, 1.7}, {290, 78, 6.0}, {20, 82, 9.0}, {110, 76, 3.5}};
  const int w = quick ? 320 : 480, h = quick ? 240 : 360;
  const double hfov = 60.0;
  std::vector<SimView> out;
  for (const Spot& sp : spots) {
    const double a = sp.azimuth_deg * kPi / 180;
    const Eigen::Vector3d eye(sp.distance_m * std::sin(a), sp.distance_m * std::cos(a), sp.eye_m);
    // Aim between the tower's foot and its apex as seen from the eye.
    const double top = std::atan2(66.0 - sp.eye_m, sp.distance_m - 5.0);
    const double bottom = std::atan2(-sp.eye_m, sp.distance_m - 7.0);
    const double mid = 0.5 * (top + bottom);
    const Eigen::Vector3d towards(-std::sin(a) * std::cos(mid), -std::cos(a) * std::cos(mid),
                                  std::sin(mid));
    out.push_back({Intrinsics::PinholeFov(w, h, hfov), Pose::LookAt(eye, eye + towards)});
  }
  return out;
}

SimView SimWorld::SkyView() const {
  SimView v;
  v.intrinsics = Intrinsics::FisheyeFov(320, 320, 180.0);
  v.pose.position = Eigen::Vector3d(0, 0, 67.0);
  // Looking up, image up = north, so image right = west.
  v.pose.rotation << -1, 0, 0, 0, -1, 0, 0, 0, 1;
  return v;
}

std::vector<SimView> SimWorld::LandscapeViews() const {
  const double a = 202.5 * kPi / 180;
  const Eigen::Vector3d tripod(35.0 * std::sin(a), 35.0 * std::cos(a), 1.6);
  const Eigen::Vector3d mast = SkyView().pose.position;
  std::vector<SimView> out;
  for (const Eigen::Vector3d& eye : {tripod, mast}) {
    out.push_back({Intrinsics::Equirect(512, 256), Pose::Level(eye, 0.0, 0.0)});
  }
  return out;
}

SimView SimWorld::SunView() const {
  const State& s = impl_->S();
  SimView v;
  v.intrinsics = Intrinsics::PinholeFov(256, 256, 6.0);
  const Eigen::Vector3d eye(0, 0, 67.0);
  v.pose = Pose::LookAt(eye, eye + s.sun_dir);
  return v;
}

}  // namespace rouen
