// Environment photometric stereo (§5.2) on the simulated world: environment maps built from
// the simulator's landscape panoramas at the demo's slot times (as app/pipeline.cc builds
// them: fitted sky, sun from the simulator's truth), region normals and albedos recovered
// from the training times and compared with the world's geometry, and the environment
// predicted at the held-out time compared with the map built from that time's panoramas.
#include "solve/env_stereo.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "capture/sim/sim_scene.h"
#include "capture/sim/sim_world.h"
#include "core/angles.h"
#include "core/time.h"
#include "solve/environment.h"
#include "solve/raycast.h"
#include "solve/sky_fit.h"

namespace rouen {
namespace {

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  const size_t k = static_cast<size_t>(std::clamp(p, 0.0, 1.0) * (v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

struct Slot {
  UtcTime utc;
  EnvObservation obs;
};

// Per layer x region: what the panorama pixels of the region see in the world.
struct RegionTruth {
  Eigen::Vector3d normal_sum = Eigen::Vector3d::Zero();
  Eigen::Vector3d albedo_sum = Eigen::Vector3d::Zero();
  double surface_w = 0, sky_w = 0, model_w = 0;
  double purity() const { return surface_w > 0 ? normal_sum.norm() / surface_w : 0; }
  Eigen::Vector3d normal() const { return normal_sum.normalized(); }
  Eigen::Vector3d albedo() const { return albedo_sum / surface_w; }
  double sky_fraction() const { return sky_w / (sky_w + surface_w); }
};

// Nearest world patch hit by a ray (brute force over the scene's patches; the analytic ground
// z = 0 beyond them). Returns false for the sky.
bool TraceWorld(const sim::SceneGeometry& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                Eigen::Vector3d* p, Eigen::Vector3d* n, int* material, bool* in_model) {
  double best = 1e30;
  const sim::Patch* hit = nullptr;
  for (const sim::Patch& pa : g.patches) {
    const double dn = d.dot(pa.n);
    if (std::abs(dn) < 1e-12) continue;
    const double t = (pa.o - o).dot(pa.n) / dn;
    if (!(t > 1e-6) || t >= best) continue;
    const Eigen::Vector2d st = pa.Local(o + t * d);
    bool inside;
    if (!pa.triangle) {
      inside = st.x() >= 0 && st.x() <= pa.su && st.y() >= 0 && st.y() <= pa.sv;
    } else {
      const Eigen::Vector2d a(0, 0), b(pa.su, 0), c(pa.apex_s, pa.sv);
      auto cross = [](const Eigen::Vector2d& x, const Eigen::Vector2d& y) {
        return x.x() * y.y() - x.y() * y.x();
      };
      inside = cross(b - a, st - a) >= 0 && cross(c - b, st - b) >= 0 && cross(a - c, st - c) >= 0;
    }
    if (!inside) continue;
    best = t;
    hit = &pa;
  }
  if (hit) {
    *p = o + best * d;
    *n = hit->n;
    *material = hit->material;
    *in_model = hit->model_block >= 0;
    return true;
  }
  if (d.z() < 0) {
    *p = o - o.z() / d.z() * d;
    *n = Eigen::Vector3d::UnitZ();
    *material = sim::kGround;
    *in_model = false;
    return true;
  }
  return false;
}

class EnvStereoSimTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const auto t0 = std::chrono::steady_clock::now();
    SimWorldOptions wo;
    wo.quick = true;
    world_ = new SimWorld(wo);
    caster_ = new RayCaster(world_->Model());
    // The demo's slots (rigs/sim.toml): 07:45 10:30 13:30 [16:00 held out] 18:15 PDT.
    const char* times[] = {"07:45", "10:30", "13:30", "16:00", "18:15"};
    for (const char* hm : times) {
      Slot s;
      s.utc = ParseIso8601(std::string("2026-08-25T") + hm + ":00-07:00");
      world_->SetTime(s.utc);
      EnvLighting& l = s.obs.lighting;
      l.sun_dir = world_->TrueSunDirection();
      l.sun_radiance = world_->TrueSunRadiance();
      l.sun_solid_angle_sr = world_->TrueSunSolidAngle();
      // §3.2 as in app/pipeline.cc: the seven-parameter sky fitted to the sky camera's image.
      const SimView sv = world_->SkyView();
      const Image sky_img = world_->RenderRadiance(sv.intrinsics, sv.pose);
      SkySampleOptions so;
      so.max_samples = 3000;  // quicker than the pipeline's 20000; the sky is smooth
      const std::vector<SkySample> samples =
          ExtractSkySamples(sky_img, nullptr, sv.intrinsics, sv.pose, l.sun_dir, so);
      // The paper's fit (eq. 10's weights, least squares), as this test's figures were set
      // with; the solve's default (relative, L1) is scored by the demo.
      SkyFitOptions fo;
      fo.weighting = SkyWeighting::kPaper;
      fo.norm_p = 2;
      fo.multiple_starts = false;  // clear skies: the CIE clear start suffices
      FitSky(samples, l.sun_dir, fo, &l.sky);
      // §3.3: the environment from the two landscape panoramas (1.6 m and 67 m).
      std::vector<Image> panos;
      std::vector<SimView> views = world_->LandscapeViews();
      for (const SimView& v : views) panos.push_back(world_->RenderRadiance(v.intrinsics, v.pose));
      std::vector<EnvPanorama> ep;
      for (size_t i = 0; i < views.size(); ++i)
        ep.push_back({&panos[i], views[i].intrinsics, views[i].pose});
      const EnvSun sun{l.sun_dir, std::sqrt(l.sun_solid_angle_sr / kPi),
                       l.sun_radiance * l.sun_solid_angle_sr};
      s.obs.env = BuildEnvironmentMap(ep, *caster_, sun, l.sky, EnvOptions());
      slots_->push_back(std::move(s));
    }
    setup_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  static void TearDownTestSuite() {
    delete caster_;
    delete world_;
    slots_->clear();
  }

  // Truth per layer x region from the world's geometry (the panorama pixels of each layer).
  static std::vector<RegionTruth> Truth(const EnvironmentMap& m) {
    const sim::SceneGeometry g = sim::BuildScene(sim::TexelSizes{});
    const std::vector<SimView> views = world_->LandscapeViews();
    std::vector<RegionTruth> out(m.radiance.size());
    const int nreg = m.num_regions();
    for (size_t v = 0; v < views.size(); ++v) {
      const int layer =
          static_cast<int>(std::min_element(m.layer_z.begin(), m.layer_z.end(),
                                            [&](double a, double b) {
                                              return std::abs(a - views[v].pose.position.z()) <
                                                     std::abs(b - views[v].pose.position.z());
                                            }) -
                           m.layer_z.begin());
      const Intrinsics& k = views[v].intrinsics;
      for (int y = 0; y < k.height; y += 2) {
        for (int x = 0; x < k.width; x += 2) {
          const Eigen::Vector3d d =
              (views[v].pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5)))
                  .normalized();
          const double w = std::sqrt(std::max(0.0, 1 - d.z() * d.z()));  // equirect solid angle
          RegionTruth& t = out[static_cast<size_t>(layer) * nreg + m.Region(d)];
          Eigen::Vector3d p, n;
          int mat;
          bool in_model;
          if (!TraceWorld(g, views[v].pose.position, d, &p, &n, &mat, &in_model)) {
            t.sky_w += w;
          } else if (in_model) {
            t.model_w += w;
          } else {
            t.normal_sum += w * n;
            t.albedo_sum += w * sim::MaterialAlbedo(mat, p);
            t.surface_w += w;
          }
        }
      }
    }
    return out;
  }

  static SimWorld* world_;
  static RayCaster* caster_;
  static std::vector<Slot>* slots_;
  static double setup_seconds_;
};

SimWorld* EnvStereoSimTest::world_ = nullptr;
RayCaster* EnvStereoSimTest::caster_ = nullptr;
std::vector<Slot>* EnvStereoSimTest::slots_ = new std::vector<Slot>();
double EnvStereoSimTest::setup_seconds_ = 0;

// Relative errors of `pred` against `obs` over the regions `use` selects (per channel), and
// the aggregate sum |p - o| / sum o.
struct MapError {
  double median = 0, p90 = 0, aggregate = 0;
  int regions = 0;
};

MapError CompareMaps(const EnvironmentMap& pred, const EnvironmentMap& obs,
                     const std::vector<bool>& use) {
  std::vector<double> rel;
  double num = 0, den = 0;
  MapError e;
  for (size_t i = 0; i < use.size(); ++i) {
    if (!use[i]) continue;
    ++e.regions;
    for (int c = 0; c < 3; ++c) {
      const double o = obs.radiance[i][c], p = pred.radiance[i][c];
      rel.push_back(std::abs(p - o) / std::max(o, 1e-12));
      num += std::abs(p - o);
      den += o;
    }
  }
  e.median = Percentile(rel, 0.5);
  e.p90 = Percentile(rel, 0.9);
  e.aggregate = den > 0 ? num / den : 0;
  return e;
}

TEST_F(EnvStereoSimTest, RecoversRegionsAndPredictsTheHeldOutTime) {
  ASSERT_EQ(slots_->size(), 5u);
  const int heldout = 3;
  std::vector<EnvObservation> train;
  for (int i = 0; i < 5; ++i) {
    if (i != heldout) train.push_back((*slots_)[i].obs);
  }
  EnvStereoOptions o;
  const auto t0 = std::chrono::steady_clock::now();
  const EnvStereoResult res = SolveEnvStereo(train, o);
  const double solve_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("setup (world, 5 times, sky fits, maps) %.1f s; stereo %.2f s\n", setup_seconds_,
              solve_s);
  std::printf("%s\n", res.summary.BriefReport().c_str());
  EXPECT_GT(res.summary.regions_landscape, 100);

  // Recovered normals and albedos against the world, over landscape regions that see one
  // surface orientation (|mean normal| > 0.98) and hardly any sky or model.
  const EnvironmentMap& m0 = train[0].env;
  const std::vector<RegionTruth> truth = Truth(m0);
  std::vector<double> ang, rho_sun, rho_sky, ang_all;
  int pure = 0;
  for (size_t i = 0; i < res.regions.size(); ++i) {
    const EnvRegionFit& f = res.regions[i];
    const RegionTruth& t = truth[i];
    if (f.kind != EnvRegionKind::kLandscape || t.surface_w <= 0) continue;
    ang_all.push_back(std::acos(std::clamp(f.normal.dot(t.normal()), -1.0, 1.0)) * 180 / kPi);
    if (t.purity() < 0.98 || t.sky_fraction() > 0.02 || t.model_w > 0.02 * t.surface_w) continue;
    ++pure;
    ang.push_back(ang_all.back());
    for (int c = 0; c < 3; ++c) {
      rho_sun.push_back(std::abs(f.rho_sun[c] / t.albedo()[c] - 1));
      rho_sky.push_back(std::abs(f.rho_sky[c] / t.albedo()[c] - 1));
    }
  }
  std::printf(
      "landscape regions %d (pure %d): normal error median %.1f p90 %.1f deg "
      "(all landscape: median %.1f p90 %.1f)\n",
      res.summary.regions_landscape, pure, Percentile(ang, 0.5), Percentile(ang, 0.9),
      Percentile(ang_all, 0.5), Percentile(ang_all, 0.9));
  std::printf(
      "albedo relative error: rho_sun median %.3f p90 %.3f; rho_sky median %.3f p90 "
      "%.3f\n",
      Percentile(rho_sun, 0.5), Percentile(rho_sun, 0.9), Percentile(rho_sky, 0.5),
      Percentile(rho_sky, 0.9));
  ASSERT_GE(pure, 30);
  // Stated figures. Most pure regions are recovered to about a degree and a few percent; the
  // tail is ground in moving cast shadows (blocks, and the tower's own shadow on the ground
  // seen from the mast on its top), which a Lambertian patch per region cannot explain
  // (§5.2 neglects shadows and interreflection within the environment): the fit then tilts
  // the normal towards the sun of the times the region was least shadowed.
  EXPECT_LT(Percentile(ang, 0.5), 5.0);
  EXPECT_LT(Percentile(rho_sun, 0.5), 0.1);

  // Held-out time: sun and fitted sky of that time, environment predicted from the model.
  const EnvObservation& held = (*slots_)[heldout].obs;
  const EnvironmentMap pred = PredictEnvironment(res, held.lighting);
  std::vector<bool> land(pred.radiance.size()), sky(pred.radiance.size());
  for (size_t i = 0; i < land.size(); ++i) {
    const bool observed = held.env.source[i] == EnvRegionSource::kObserved;
    land[i] = observed && (res.regions[i].kind == EnvRegionKind::kLandscape ||
                           res.regions[i].kind == EnvRegionKind::kSkyOnly);
    sky[i] = observed && res.regions[i].kind == EnvRegionKind::kSky;
  }
  const MapError e_land = CompareMaps(pred, held.env, land);
  const MapError e_sky = CompareMaps(pred, held.env, sky);
  // Baselines: the nearest training times' maps as they are, and their linear interpolation
  // in time (13:30 and 18:15 around 16:00).
  const EnvironmentMap& before = (*slots_)[2].obs.env;
  const EnvironmentMap& after = (*slots_)[4].obs.env;
  const double a = ((*slots_)[3].utc.UnixSeconds() - (*slots_)[2].utc.UnixSeconds()) /
                   ((*slots_)[4].utc.UnixSeconds() - (*slots_)[2].utc.UnixSeconds());
  EnvironmentMap lerp = before;
  for (size_t i = 0; i < lerp.radiance.size(); ++i) {
    lerp.radiance[i] = (1 - a) * before.radiance[i] + a * after.radiance[i];
  }
  const MapError e_before = CompareMaps(before, held.env, land);
  const MapError e_after = CompareMaps(after, held.env, land);
  const MapError e_lerp = CompareMaps(lerp, held.env, land);
  std::printf(
      "held-out 16:00, landscape regions (%d): relative error median %.3f p90 %.3f "
      "aggregate %.3f\n",
      e_land.regions, e_land.median, e_land.p90, e_land.aggregate);
  std::printf("  sky regions (%d): median %.3f p90 %.3f aggregate %.3f\n", e_sky.regions,
              e_sky.median, e_sky.p90, e_sky.aggregate);
  std::printf("  baselines (aggregate): 13:30 map %.3f, 18:15 map %.3f, linear in time %.3f\n",
              e_before.aggregate, e_after.aggregate, e_lerp.aggregate);
  EXPECT_GT(e_land.regions, 100);
  // The held-out landscape within 15% in aggregate (median region within 5%); the sky regions
  // carry the sky fit's own error (a few percent).
  EXPECT_LT(e_land.aggregate, 0.15);
  EXPECT_LT(e_land.median, 0.05);
  EXPECT_LT(e_sky.aggregate, 0.1);
  // The prediction must beat re-using or interpolating the neighbouring times' maps.
  EXPECT_LT(e_land.aggregate, e_before.aggregate);
  EXPECT_LT(e_land.aggregate, e_after.aggregate);
  EXPECT_LT(e_land.aggregate, e_lerp.aggregate);
}

}  // namespace
}  // namespace rouen
