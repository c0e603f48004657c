#include "solve/albedo.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/angles.h"
#include "core/error.h"
#include "core/stats.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

// A plaza with a box on it: faces in sun and shadow at different times.
struct World {
  Mesh mesh;
  SurfaceGrid grid;
  std::unique_ptr<RayCaster> rc;
  HemisphereCache cache;
  std::vector<Lighting> slots;
  std::vector<Eigen::Vector3d> rho_sun, rho_se;
};

// The world's hemisphere cache (64 directions) and one slot per sun azimuth at `el_deg`, under a
// constant blue sky over a warm environment.
void CacheAndSuns(World* w, const std::vector<double>& az_deg, double el_deg) {
  HemisphereOptions ho;
  ho.directions = 64;
  w->cache = BuildHemisphereCache(w->grid, *w->rc, ho);
  for (double az : az_deg) {
    Lighting l;
    const double a = az * kPi / 180, el = el_deg * kPi / 180;
    l.sun_dir =
        Eigen::Vector3d(std::cos(el) * std::sin(a), std::cos(el) * std::cos(a), std::sin(el));
    l.sun_radiance = Eigen::Vector3d(3e4, 2.8e4, 2.5e4);
    l.sun_solid_angle_sr = 6.8e-5;
    l.env = EnvironmentMap::Constant(EnvOptions(), {0.25, 0.35, 0.6}, {0.1, 0.1, 0.08});
    w->slots.push_back(l);
  }
}

World MakeWorld() {
  World w;
  const int plaza = w.mesh.AddBlock("plaza");
  const int box = w.mesh.AddBlock("box");
  testing::AddHorizontalRect(&w.mesh, -6, 6, -6, 6, 0, true, plaza);
  testing::AddBox(&w.mesh, {-1, -1, 0}, {1, 1, 3}, box);
  GridOptions go;
  go.spacing_m = 0.8;
  go.block_spacing_m["plaza"] = 2.0;
  w.grid = BuildSurfaceGrid(w.mesh, go);
  w.rc = std::make_unique<RayCaster>(w.mesh);
  CacheAndSuns(&w, {100, 160, 220, 260}, 35);
  // Smoothly varying true albedos; rho_sun differs from rho_se (pseudo-BRDFs differ).
  for (const auto& p : w.grid.points) {
    const Eigen::Vector3d base(0.3 + 0.1 * std::sin(p.position.x()),
                               0.4 + 0.05 * p.position.z() / 3,
                               0.5 + 0.1 * std::cos(p.position.y()));
    w.rho_se.push_back(base);
    w.rho_sun.push_back(base.cwiseProduct(Eigen::Vector3d(1.1, 1.0, 0.9)));
  }
  return w;
}

// Plaza points under the box receive no light at all (and no camera sees them).
bool Buried(const World& w, int i) {
  const Eigen::Vector3d& p = w.grid.points[i].position;
  return std::abs(p.x()) < 1 && std::abs(p.y()) < 1 && p.z() < 0.01;
}

// Observations consistent with eqs. 11-12 for the given irradiance: every point in every slot.
std::vector<Observation> Observe(const World& w, const std::vector<SlotIrradiance>& irr,
                                 bool include_buried = false) {
  std::vector<Observation> obs;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i) && !include_buried) continue;
    for (size_t s = 0; s < irr.size(); ++s) {
      Observation o;
      o.point = i;
      o.slot = static_cast<int>(s);
      o.photo = static_cast<int>(s);
      const Eigen::Vector3d I =
          (w.rho_se[i].cwiseProduct(irr[s].se[i]) + w.rho_sun[i].cwiseProduct(irr[s].sun[i])) / kPi;
      o.radiance = I.cast<float>();
      obs.push_back(o);
    }
  }
  return obs;
}

// The solve's default options, with the world's model for the exact (vector-flux) irradiance.
AlbedoOptions OptionsFor(const World& w) {
  AlbedoOptions o;
  o.irradiance.mesh = &w.mesh;
  return o;
}

// The irradiance as the solve computes it (the photos below are made with it).
std::vector<SlotIrradiance> Irradiance(const World& w) {
  std::vector<SlotIrradiance> irr;
  for (const auto& l : w.slots)
    irr.push_back(ComputeIrradiance(w.grid, w.cache, *w.rc, l, OptionsFor(w).irradiance));
  return irr;
}

TEST(AlbedoTest, RecoversBothPseudoAlbedosFromConsistentData) {
  const World w = MakeWorld();
  const auto irr = Irradiance(w);
  const auto obs = Observe(w, irr);
  const AlbedoResult r = SolveAlbedoFixedIrradiance(w.grid, obs, irr);
  ASSERT_EQ(r.rho_se.size(), static_cast<size_t>(w.grid.size()));
  int good = 0, buried = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i)) {
      ++buried;
      EXPECT_EQ(r.observations[i], 0);
      continue;
    }
    EXPECT_EQ(r.observations[i], 4);
    // rho_se is determined (eq. 11 or diverse sun ratios) except when the point is never in
    // the sun; then rho_sun comes from the block ratio.
    EXPECT_NEAR((r.rho_se[i] - w.rho_se[i]).norm(), 0, 1e-4 * w.rho_se[i].norm()) << i;
    if (!(r.flags[i] & (kAlbedoSunUnobserved | kAlbedoNeverShadowed))) {
      EXPECT_NEAR((r.rho_sun[i] - w.rho_sun[i]).norm(), 0, 1e-4 * w.rho_sun[i].norm()) << i;
      ++good;
    }
  }
  EXPECT_GT(good, w.grid.size() / 3);
  EXPECT_LT(r.summary.residual_rms_rel, 1e-4);
  EXPECT_LT(r.summary.residual_p90_rel, 1e-4);
  EXPECT_LE(r.summary.residual_median_rel, r.summary.residual_p90_rel);
  EXPECT_GT(buried, 0);
  EXPECT_EQ(r.summary.points_observed, w.grid.size() - buried);
  // Observations of points that receive no light at all carry no information: unobserved.
  const AlbedoResult r2 = SolveAlbedoFixedIrradiance(w.grid, Observe(w, irr, true), irr);
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i)) {
      EXPECT_TRUE(r2.flags[i] & kAlbedoNoObservations);
    }
  }
  // Block ratio for never-sunlit points: 1.1, 1.0, 0.9 per channel.
  for (int i = 0; i < w.grid.size(); ++i) {
    if (r.flags[i] & kAlbedoSunUnobserved) {
      EXPECT_NEAR(r.rho_sun[i].x() / r.rho_se[i].x(), 1.1, 1e-3);
      EXPECT_NEAR(r.rho_sun[i].z() / r.rho_se[i].z(), 0.9, 1e-3);
    }
  }
}

// Observations of a world whose `rough` block reflects the sun with RetroFactor(retro) (the
// others Lambertian), seen from four cameras around it at every slot.
std::vector<Observation> ObserveRetro(const World& w, const std::vector<SlotIrradiance>& irr,
                                      int rough, double retro) {
  const Eigen::Vector3d cams[] = {{12, -9, 2}, {-10, -11, 6}, {-12, 8, 3}, {9, 12, 9}};
  std::vector<Observation> obs;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i)) continue;
    const GridPoint& gp = w.grid.points[i];
    for (size_t s = 0; s < irr.size(); ++s) {
      for (int c = 0; c < 4; ++c) {
        const Eigen::Vector3d v = (cams[c] - gp.position).normalized();
        if (gp.normal.dot(v) < 0.05) continue;
        const double r = gp.block == rough ? retro : 0.0;
        const double d = RetroFactor(r, gp.normal, w.slots[s].sun_dir, v);
        // The sky's light reflected as the rough surface reflects it from where it arrives.
        const double a =
            AmbientRetroFactor(r, gp.normal, v, LightAt(irr[s].se_light, i, gp.normal));
        Observation o;
        o.point = i;
        o.slot = static_cast<int>(s);
        o.photo = static_cast<int>(s * 4 + c);
        o.view_dir = v.cast<float>();
        o.radiance = ((a * w.rho_se[i].cwiseProduct(irr[s].se[i]) +
                       d * w.rho_sun[i].cwiseProduct(irr[s].sun[i])) /
                      kPi)
                         .cast<float>();
        obs.push_back(o);
      }
    }
  }
  return obs;
}

// §4.2.2 inside the albedo solve: observations of a world whose box carries a sun lobe, from
// cameras some of which catch the highlights. The lobe is found on the box only, and the
// diffuse albedos come back without the highlights in them.
TEST(AlbedoTest, FitsTheGlossyBlocksSunLobeAndNotTheMatteOnes) {
  World w = MakeWorld();
  const int box = 1, plaza = 0;
  SpecularLobe truth;
  truth.rho_s = Eigen::Vector3d::Constant(0.08);
  truth.kappa = 1;
  truth.n = 12;
  const auto irr = Irradiance(w);
  // Eight cameras around the box at two heights: the walls' mirror directions of the 35 deg
  // suns point down at 35 deg, so some views see each wall near its highlight.
  std::vector<Eigen::Vector3d> cams;
  for (int k = 0; k < 8; ++k) {
    const double a = 2 * kPi * (k + 0.5) / 8;
    cams.emplace_back(9 * std::sin(a), 9 * std::cos(a), k % 2 ? 0.5 : 5.5);
  }
  std::vector<Observation> obs;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i)) continue;
    const GridPoint& gp = w.grid.points[i];
    for (size_t s = 0; s < irr.size(); ++s) {
      for (size_t c = 0; c < cams.size(); ++c) {
        const Eigen::Vector3d v = (cams[c] - gp.position).normalized();
        if (gp.normal.dot(v) < 0.05) continue;
        Observation o;
        o.point = i;
        o.slot = static_cast<int>(s);
        o.photo = static_cast<int>(s * cams.size() + c);
        o.view_dir = v.cast<float>();
        Eigen::Vector3d I =
            (w.rho_se[i].cwiseProduct(irr[s].se[i]) + w.rho_sun[i].cwiseProduct(irr[s].sun[i])) /
            kPi;
        if (gp.block == box)
          I += truth.Eval(gp.normal, w.slots[s].sun_dir, v).cwiseProduct(irr[s].sun[i]);
        o.radiance = I.cast<float>();
        obs.push_back(o);
      }
    }
  }
  AlbedoOptions opt = OptionsFor(w);
  opt.outer_iterations = 1;  // the photos carry no interreflection
  opt.fit_retro = false;
  // These photos reflect the sun and no sky, which no material does: by default the sky's
  // reflection the box's lobe would make contradicts them, and the lobe goes.
  const AlbedoResult one_material = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  for (const SpecularLobe& l : one_material.sun_lobes) EXPECT_TRUE(l.IsZero());
  EXPECT_GT(one_material.summary.sky_lobe_cost_fitted[box],
            one_material.summary.sky_lobe_cost_zero[box]);
  // The paper's pseudo-BRDFs: a sky lobe of its own (§4.2.1), the sun's found alone.
  opt.sky_lobe.source = SkyLobeOptions::Source::kFit;
  const AlbedoResult fit = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  ASSERT_EQ(fit.sun_lobes.size(), 2u);
  EXPECT_TRUE(fit.sun_lobes[plaza].IsZero());
  ASSERT_FALSE(fit.sun_lobes[box].IsZero());
  // The photos reflect no sky: no block gets a sky/environment lobe (§4.2.1), and the one
  // tried (the box, which has a sun lobe) gained less than the threshold.
  for (const SpecularLobe& l : fit.sky_lobes) EXPECT_TRUE(l.IsZero());
  ASSERT_EQ(fit.summary.sky_lobe_samples.size(), 2u);
  EXPECT_GT(fit.summary.sky_lobe_samples[box], 0);
  EXPECT_EQ(fit.summary.sky_lobe_samples[plaza], 0);
  ASSERT_EQ(fit.summary.lobe_cost_zero.size(), 2u);
  EXPECT_LT(fit.summary.lobe_cost_fitted[box], 0.5 * fit.summary.lobe_cost_zero[box]);
  // The peak the photos saw (the mirror direction's f_s) within 20%: the diffuse albedos of
  // the first solve hold part of the highlight, which the lobe then misses.
  EXPECT_NEAR(fit.sun_lobes[box].rho_s[1], truth.rho_s[1], 0.2 * truth.rho_s[1]);
  opt.sun_lobe.fit = false;
  const AlbedoResult matte = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  EXPECT_TRUE(matte.sun_lobes.empty());
  // The box's diffuse sun albedo is closer to the truth with the lobe taken out.
  double e_fit = 0, e_matte = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (w.grid.points[i].block != box || fit.flags[i] != 0) continue;
    e_fit += (fit.rho_sun[i] - w.rho_sun[i]).norm() / w.rho_sun[i].norm();
    e_matte += (matte.rho_sun[i] - w.rho_sun[i]).norm() / w.rho_sun[i].norm();
  }
  EXPECT_LT(e_fit, 0.5 * e_matte);
}

// A block the photos saw too little to fit a retro (here the plaza, 40 sunlit observations left
// of its thousands) takes the retro of the blocks they could tell, not Lambert's law; with no
// block told, every one stays Lambertian.
TEST(AlbedoTest, ABlockSeenTooLittleTakesTheRetroOfTheBlocksSeenEnough) {
  World w = MakeWorld();
  const int box = 1, plaza = 0;
  const auto irr = Irradiance(w);
  std::vector<Observation> obs;
  int plaza_kept = 0;
  for (const Observation& o : ObserveRetro(w, irr, box, 0.8)) {
    if (w.grid.points[o.point].block == plaza && plaza_kept++ >= 40) continue;
    obs.push_back(o);
  }
  AlbedoOptions opt = OptionsFor(w);
  opt.outer_iterations = 1;
  opt.bounces = 1;
  const AlbedoResult fit = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  ASSERT_EQ(fit.retro.size(), 2u);
  EXPECT_GT(fit.retro[box], 0.5);
  EXPECT_EQ(fit.retro[plaza], fit.retro[box]);
  opt.retro_min_observations = 1000000;  // no block told
  const AlbedoResult none = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  EXPECT_TRUE(none.retro.empty() || (none.retro[box] == 0.0 && none.retro[plaza] == 0.0));
}

TEST(AlbedoTest, FitsEachBlocksRetroAndTheAlbedosWithIt) {
  World w = MakeWorld();
  // Lower suns too, where a rough surface departs most from Lambert.
  for (double el : {12.0, 20.0}) {
    Lighting l = w.slots[0];
    const double a = (el == 12 ? 250 : 110) * kPi / 180, e = el * kPi / 180;
    l.sun_dir = Eigen::Vector3d(std::cos(e) * std::sin(a), std::cos(e) * std::cos(a), std::sin(e));
    w.slots.push_back(l);
  }
  const int box = 1, plaza = 0;
  const double truth = 0.8;  // between the fit's candidates (multiples of 0.25)
  const auto irr = Irradiance(w);
  const auto obs = ObserveRetro(w, irr, box, truth);
  AlbedoOptions opt = OptionsFor(w);
  opt.outer_iterations = 1;  // the photos carry no interreflection
  opt.bounces = 1;
  const AlbedoResult fit = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  ASSERT_EQ(fit.retro.size(), 2u);
  // Exact data: the truth is the cost's unique zero. The candidates bracket it within half a
  // step and the parabola through the three nearest moves towards it.
  EXPECT_NEAR(fit.retro[box], truth, 0.125);
  EXPECT_EQ(fit.retro[plaza], 0.0);  // Lambertian and on a candidate: found exactly
  ASSERT_EQ(fit.summary.retro_cost_fitted.size(), 2u);
  EXPECT_LT(fit.summary.retro_cost_fitted[box], 0.5 * fit.summary.retro_cost_lambert[box]);
  opt.fit_retro = false;
  const AlbedoResult lambert = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  EXPECT_TRUE(lambert.retro.empty() || lambert.retro[box] == 0.0);
  // On the rough block's sunlit-and-shadowed points the fitted model recovers rho_sun better.
  double e_fit = 0, e_lambert = 0;
  int n = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (w.grid.points[i].block != box || fit.flags[i] != 0) continue;
    e_fit += (fit.rho_sun[i] - w.rho_sun[i]).norm() / w.rho_sun[i].norm();
    e_lambert += (lambert.rho_sun[i] - w.rho_sun[i]).norm() / w.rho_sun[i].norm();
    ++n;
  }
  ASSERT_GT(n, 10);
  EXPECT_LT(e_fit, 0.5 * e_lambert) << e_fit / n << " vs " << e_lambert / n;
}

TEST(AlbedoTest, RobustAgainstAShadowBoundaryOutlier) {
  World w = MakeWorld();
  // More slots so that one wrong observation per point is a minority.
  const std::vector<Lighting> base = w.slots;
  for (double az : {130.0, 190.0, 240.0}) {
    Lighting l = base[0];
    const double a = az * kPi / 180, el = 50 * kPi / 180;
    l.sun_dir =
        Eigen::Vector3d(std::cos(el) * std::sin(a), std::cos(el) * std::cos(a), std::sin(el));
    w.slots.push_back(l);
  }
  const auto irr = Irradiance(w);
  auto obs = Observe(w, irr);
  // Corrupt one observation of every 5th point: its pixel shows shadow although the grid
  // point is lit (or the reverse), as at a shadow edge.
  for (size_t k = 0; k < obs.size(); k += 5 * 7) {
    const auto& o = obs[k];
    obs[k].radiance = (w.rho_se[o.point].cwiseProduct(irr[o.slot].se[o.point]) / kPi +
                       w.rho_sun[o.point].cwiseProduct(Eigen::Vector3d::Constant(300)) / kPi)
                          .cast<float>();
  }
  AlbedoOptions opt = OptionsFor(w);
  const AlbedoResult r = SolveAlbedoFixedIrradiance(w.grid, obs, irr, opt);
  opt.loss = RobustLoss::kNone;
  const AlbedoResult plain = SolveAlbedoFixedIrradiance(w.grid, obs, irr, opt);
  opt.loss = RobustLoss::kPaper;
  const AlbedoResult paper = SolveAlbedoFixedIrradiance(w.grid, obs, irr, opt);
  double err = 0, err_plain = 0, err_paper = 0;
  int n = 0;
  for (size_t k = 0; k < obs.size(); k += 5 * 7) {
    const int i = obs[k].point;
    err += (r.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm();
    err_plain += (plain.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm();
    err_paper += (paper.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm();
    ++n;
  }
  EXPECT_LT(err / n, 0.25 * err_plain / n);
  EXPECT_LT(err_paper / n, 0.25 * err_plain / n);
  EXPECT_GT(r.summary.downweighted_fraction, 0);
}

// A highlight the fitted lobe over-explains leaves an observation of nothing (the diffuse
// albedos are solved again from what the lobes leave, never negative light). Its relative error
// is of what the photo measured, the highlight included: at 30 times the diffuse light it
// weighs 1/900 of a plain observation and leaves the albedo where the others put it. Taken as
// an exact zero, it would weigh more than the three others together and pull the albedo down.
TEST(AlbedoTest, AHighlightTheLobeOverExplainedPullsNoAlbedoDown) {
  World w = MakeWorld();
  const auto irr = Irradiance(w);
  std::vector<Observation> obs = Observe(w, irr);
  for (Observation& o : obs) {
    if (o.slot != 0) continue;
    const Eigen::Vector3f diffuse = o.radiance;
    o.measured = 31 * diffuse;  // a highlight of 30 x the diffuse light
    o.radiance = (o.measured - 1.05f * 30 * diffuse).cwiseMax(0.f);  // the lobe 5% too bright
  }
  AlbedoOptions opt = OptionsFor(w);
  auto median_error = [&](const AlbedoResult& r) {
    std::vector<double> e;
    for (int i = 0; i < w.grid.size(); ++i)
      if (!Buried(w, i)) e.push_back((r.rho_sun[i] - w.rho_sun[i]).norm() / w.rho_sun[i].norm());
    return Median(e);
  };
  EXPECT_LT(median_error(SolveAlbedoFixedIrradiance(w.grid, obs, irr, opt)), 0.01);
  for (Observation& o : obs) o.measured.setZero();
  EXPECT_GT(median_error(SolveAlbedoFixedIrradiance(w.grid, obs, irr, opt)), 0.2);
}

// Observations of photos made with one bounce from the true albedos.
std::vector<Observation> ObserveWithBounce(const World& w) {
  auto irr = Irradiance(w);
  for (auto& s : irr) AddInterreflection(w.grid, w.cache, w.rho_sun, w.rho_se, &s, 1);
  return Observe(w, irr);
}

TEST(AlbedoTest, OuterIterationConvergesToTheBounceConsistentAlbedo) {
  const World w = MakeWorld();
  const auto obs = ObserveWithBounce(w);
  AlbedoOptions opt = OptionsFor(w);
  opt.bounces = 1;  // as the photos were made
  opt.outer_iterations = 1;
  const AlbedoResult first = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  opt.outer_iterations = 6;
  opt.outer_tolerance = 0;  // all six
  std::vector<SlotIrradiance> final_irr;
  const AlbedoResult last = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt, &final_irr);
  ASSERT_EQ(last.summary.change_per_iteration.size(), 5u);
  EXPECT_EQ(last.summary.outer_iterations, 6);
  EXPECT_LT(last.summary.change_per_iteration[2], last.summary.change_per_iteration[0]);
  // With a tolerance the iterations stop at the first change below it.
  opt.outer_iterations = 20;
  opt.outer_tolerance =
      0.5 * (last.summary.change_per_iteration[1] + last.summary.change_per_iteration[2]);
  const AlbedoResult stopped = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  ASSERT_EQ(stopped.summary.change_per_iteration.size(), 3u);
  EXPECT_EQ(stopped.summary.outer_iterations, 4);
  EXPECT_LT(stopped.summary.change_per_iteration.back(), opt.outer_tolerance);
  ASSERT_EQ(final_irr.size(), w.slots.size());
  EXPECT_TRUE(final_irr[0].has_bounce);
  double e_first = 0, e_last = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i)) continue;
    e_first += (first.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm() / w.grid.size();
    e_last += (last.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm() / w.grid.size();
  }
  EXPECT_GT(e_first, 0.005);  // ignoring the bounce biases the albedo
  EXPECT_LT(e_last, 0.1 * e_first);
  EXPECT_LT(e_last, 1e-3);
}

// Started from albedos that already explain the photos with their bounce (a warm start, as the
// solve again after the ground field is read with the walls' light), the outer iteration's first
// step is already below a tolerance a cold start needs several steps to reach, and it ends at
// the same albedos. Albedos of another grid are refused.
TEST(AlbedoTest, AWarmStartFromTheAnswerStaysThere) {
  const World w = MakeWorld();
  const auto obs = ObserveWithBounce(w);
  AlbedoOptions opt = OptionsFor(w);
  opt.bounces = 1;
  opt.outer_iterations = 20;
  opt.outer_tolerance = 1e-3;
  const AlbedoResult cold = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  const AlbedoResult warm = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt, nullptr, &cold);
  EXPECT_GE(cold.summary.outer_iterations, 3);
  EXPECT_EQ(warm.summary.outer_iterations, 2);
  for (int i = 0; i < w.grid.size(); ++i) {
    if (Buried(w, i)) continue;
    EXPECT_LT((warm.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm(), 2e-3) << i;
  }
  AlbedoResult other = cold;
  other.rho_sun.pop_back();
  EXPECT_THROW(SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt, nullptr, &other), Error);
}

// A square well 2 x 2 m and 6 m deep, open to the sky, its walls and floor of albedo 0.8: most
// of the light inside has bounced (as in a belfry's open storey or a narrow court).
World MakeWell() {
  World w;
  const int well = w.mesh.AddBlock("well");
  testing::AddHorizontalRect(&w.mesh, -1, 1, -1, 1, 0, true, well);
  w.mesh.AddPolygon({{1, -1, 0}, {-1, -1, 0}, {-1, -1, 6}, {1, -1, 6}}, well);  // facing +y
  w.mesh.AddPolygon({{-1, 1, 0}, {1, 1, 0}, {1, 1, 6}, {-1, 1, 6}}, well);      // facing -y
  w.mesh.AddPolygon({{-1, -1, 0}, {-1, 1, 0}, {-1, 1, 6}, {-1, -1, 6}}, well);  // facing +x
  w.mesh.AddPolygon({{1, 1, 0}, {1, -1, 0}, {1, -1, 6}, {1, 1, 6}}, well);      // facing -x
  GridOptions go;
  go.spacing_m = 0.5;
  w.grid = BuildSurfaceGrid(w.mesh, go);
  w.rc = std::make_unique<RayCaster>(w.mesh);
  CacheAndSuns(&w, {120, 180, 240}, 60);
  for (const auto& p : w.grid.points) {
    const Eigen::Vector3d base(0.8, 0.75 + 0.02 * p.position.z(), 0.7);
    w.rho_se.push_back(base);
    w.rho_sun.push_back(base);
  }
  return w;
}

// Where the bounce carries most of the light, the plain update (the albedo that explains the
// photos under the last bounce) overshoots: an albedo too high brightens its neighbours' bounce,
// so their next albedo is too low, and where E grows faster than the albedos (eight bounces in a
// deep well) the swing grows. Newton's step on log rho, with E's growth measured by the
// interreflection's bounce order, converges there.
TEST(AlbedoTest, NewtonOuterIterationConvergesWhereTheBounceDominates) {
  const World w = MakeWell();
  ASSERT_GT(w.grid.size(), 100);
  AlbedoOptions opt = OptionsFor(w);
  opt.fit_retro = false;
  opt.sun_lobe.fit = false;
  auto irr = Irradiance(w);
  for (auto& s : irr) AddInterreflection(w.grid, w.cache, w.rho_sun, w.rho_se, &s, opt.bounces);
  // The bounce's share of the light at the wells' walls 2-4 m down, over the slots.
  double bounce = 0, all = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    const GridPoint& p = w.grid.points[i];
    if (p.normal.z() > 0.5 || p.position.z() < 2 || p.position.z() > 4) continue;
    for (const SlotIrradiance& s : irr) {
      bounce += (s.se[i] - s.direct_se[i]).sum();
      all += (s.se[i] + s.sun[i]).sum();
    }
  }
  ASSERT_GT(bounce / all, 0.5) << "not a cavity: the bounce is " << bounce / all << " of the light";
  const auto obs = Observe(w, irr);
  // Newton's step assumes every albedo off by one factor; an error local to a point converges by
  // s / (1 + s) per iteration (s ~ 1.9 here, E's elasticity with eight bounces): 0.66^12 = 7e-3
  // of the first iterations' error after 16.
  opt.outer_iterations = 16;
  opt.outer_tolerance = 0;
  auto error = [&](const AlbedoResult& r) {
    double e = 0;
    for (int i = 0; i < w.grid.size(); ++i)
      e += (r.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm() / w.grid.size();
    return e;
  };
  opt.outer_aitken = false;  // Newton's step against the plain update, each on its own
  const AlbedoResult newton = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  opt.outer_newton = false;
  const AlbedoResult plain = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  std::printf(
      "well: bounce share %.2f, albedo error after 16 iterations: Newton %.5f, plain %.5f\n",
      bounce / all, error(newton), error(plain));
  EXPECT_LT(error(newton), 0.01);
  EXPECT_GT(error(plain), 10 * error(newton));
}

// Where a point's error is its own, Newton's step goes s / (1 + s) of the way short each time
// (the well's walls: about 0.66). Aitken's extrapolation reads that rate from two steps and
// goes the rest of the way: the outer tolerance is reached in far fewer iterations, at the same
// albedos. Each run stops with its 99th-percentile step below the tolerance t, so each lies
// within t lambda / (1 - lambda) ~ 2 t of the fixed point there: they differ by at most 4 t.
TEST(AlbedoTest, AitkenExtrapolationReachesTheToleranceSooner) {
  const World w = MakeWell();
  AlbedoOptions opt = OptionsFor(w);
  opt.fit_retro = false;
  opt.sun_lobe.fit = false;
  const auto obs = Observe(w, Irradiance(w));
  const AlbedoResult aitken = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  opt.outer_aitken = false;
  const AlbedoResult newton = SolveAlbedo(w.grid, w.cache, *w.rc, w.slots, obs, opt);
  std::vector<double> difference;
  for (int i = 0; i < w.grid.size(); ++i) {
    for (int c = 0; c < 3; ++c)
      difference.push_back(std::abs(aitken.rho_se[i][c] / newton.rho_se[i][c] - 1));
  }
  const double p99 = Quantile(difference, 0.99);
  std::printf(
      "well: outer iterations %d with Aitken's extrapolation, %d without; albedos differ "
      "by %.4f at the 99th percentile\n",
      aitken.summary.outer_iterations, newton.summary.outer_iterations, p99);
  ASSERT_LT(newton.summary.outer_iterations, opt.outer_iterations) << "Newton did not converge";
  EXPECT_LT(aitken.summary.outer_iterations, 0.75 * newton.summary.outer_iterations);
  EXPECT_LT(p99, 4 * opt.outer_tolerance);
}

TEST(AlbedoTest, UnobservedPointsAreFilledAndFlagged) {
  const World w = MakeWorld();
  const auto irr = Irradiance(w);
  auto obs = Observe(w, irr);
  // Drop every observation of the box's top face.
  std::vector<Observation> kept;
  for (const auto& o : obs) {
    if (w.grid.points[o.point].normal.z() > 0.9 && w.grid.points[o.point].block == 1) continue;
    kept.push_back(o);
  }
  const AlbedoResult r = SolveAlbedoFixedIrradiance(w.grid, kept, irr);
  int filled = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (r.observations[i] == 0) {
      EXPECT_TRUE(r.flags[i] & kAlbedoNoObservations);
      EXPECT_TRUE(r.rho_se[i].allFinite());
      EXPECT_GT(r.rho_se[i].minCoeff(), 0.2);
      ++filled;
    }
  }
  EXPECT_GT(filled, 0);
  EXPECT_EQ(r.summary.points_observed, w.grid.size() - filled);
}

// A block no photo saw takes the median albedos of the observed blocks of its kind: two dark
// "trees" beside a box on a plaza, one unseen, which takes the seen tree's albedo rather than
// the median of every observed point (the plaza's and the box's).
TEST(AlbedoTest, ABlockNoPhotoSawTakesTheAlbedoOfItsKind) {
  World w;
  testing::AddHorizontalRect(&w.mesh, -8, 8, -8, 8, 0, true, w.mesh.AddBlock("plaza"));
  testing::AddBox(&w.mesh, {-1, -1, 0}, {1, 1, 3}, w.mesh.AddBlock("box"));
  testing::AddBox(&w.mesh, {4, -1, 0}, {5, 0, 2}, w.mesh.AddBlock("tree_seen"));
  testing::AddBox(&w.mesh, {-5, 4, 0}, {-4, 5, 2}, w.mesh.AddBlock("tree_unseen"));
  GridOptions go;
  go.spacing_m = 0.5;
  go.block_spacing_m["plaza"] = 2.0;
  w.grid = BuildSurfaceGrid(w.mesh, go);
  w.rc = std::make_unique<RayCaster>(w.mesh);
  CacheAndSuns(&w, {100, 160, 220, 260}, 35);
  const Eigen::Vector3d leaves(0.08, 0.15, 0.05), stone(0.45, 0.4, 0.35);
  for (const auto& p : w.grid.points) {
    w.rho_se.push_back(p.block >= 2 ? leaves : stone);
    w.rho_sun.push_back(p.block >= 2 ? leaves : stone);
  }
  const auto irr = Irradiance(w);
  std::vector<Observation> kept;
  for (const Observation& o : Observe(w, irr)) {
    if (w.grid.points[o.point].block != 3) kept.push_back(o);
  }
  AlbedoOptions kinds;
  kinds.block_kind = {0, 0, 1, 1};
  const AlbedoResult by_kind = SolveAlbedoFixedIrradiance(w.grid, kept, irr, kinds);
  const AlbedoResult by_all = SolveAlbedoFixedIrradiance(w.grid, kept, irr);
  int unseen = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (w.grid.points[i].block != 3) continue;
    ++unseen;
    EXPECT_TRUE(by_kind.flags[i] & kAlbedoNoObservations);
    // Consistent photos: the seen tree's points are its albedo to the solve's precision.
    EXPECT_LT((by_kind.rho_se[i] - leaves).cwiseAbs().maxCoeff(), 0.01) << i;
    EXPECT_LT((by_kind.rho_sun[i] - leaves).cwiseAbs().maxCoeff(), 0.01) << i;
    // Without kinds the stone's, which holds most observed points.
    EXPECT_LT((by_all.rho_se[i] - stone).cwiseAbs().maxCoeff(), 0.01) << i;
  }
  EXPECT_GT(unseen, 10);
}

TEST(AlbedoTest, GapsAreFilledFromTheSameFace) {
  const World w = MakeWorld();
  const auto irr = Irradiance(w);
  const auto obs = Observe(w, irr);
  // Hide a strip of the box's south face (normal -y, x in [-0.3, 0.3]).
  auto hidden = [&](int i) {
    const GridPoint& p = w.grid.points[i];
    return p.block == 1 && p.normal.y() < -0.9 && std::abs(p.position.x()) < 0.3;
  };
  std::vector<Observation> kept;
  for (const auto& o : obs) {
    if (!hidden(o.point)) kept.push_back(o);
  }
  const AlbedoResult r = SolveAlbedoFixedIrradiance(w.grid, kept, irr);
  int n = 0;
  for (int i = 0; i < w.grid.size(); ++i) {
    if (!hidden(i)) continue;
    ++n;
    EXPECT_TRUE(r.flags[i] & kAlbedoFilled);
    // The true field varies by at most ~0.1 * 0.6 m over the fill distance (sin x slope <= 0.1).
    EXPECT_NEAR((r.rho_se[i] - w.rho_se[i]).norm() / w.rho_se[i].norm(), 0, 0.1);
  }
  EXPECT_GT(n, 0);
  EXPECT_GE(r.summary.points_filled_neighbours, n);  // (and the plaza under the box)
}

TEST(AlbedoTest, BadInputThrows) {
  const World w = MakeWorld();
  const auto irr = Irradiance(w);
  EXPECT_THROW(SolveAlbedoFixedIrradiance(w.grid, {}, irr), Error);
  auto obs = Observe(w, irr);
  auto bad = obs;
  bad[0].slot = 9;
  EXPECT_THROW(SolveAlbedoFixedIrradiance(w.grid, bad, irr), Error);
  bad = obs;
  bad[0].point = -1;
  EXPECT_THROW(SolveAlbedoFixedIrradiance(w.grid, bad, irr), Error);
  bad = obs;
  bad[0].radiance.x() = NAN;
  EXPECT_THROW(SolveAlbedoFixedIrradiance(w.grid, bad, irr), Error);
  auto short_irr = irr;
  short_irr[1].sun.pop_back();
  EXPECT_THROW(SolveAlbedoFixedIrradiance(w.grid, obs, short_irr), Error);
  AlbedoOptions opt = OptionsFor(w);
  opt.outer_iterations = 0;
  EXPECT_THROW(SolveAlbedoFixedIrradiance(w.grid, obs, irr, opt), Error);
  EXPECT_THROW(SolveAlbedo(w.grid, w.cache, *w.rc, {}, obs), Error);
}

// Photos: a wall seen by a pinhole camera; a post in front hides part of it.
TEST(CollectObservationsTest, ProjectsChecksVisibilityMaskAndSamples) {
  Mesh m;
  const int wall = m.AddBlock("wall");
  const int post = m.AddBlock("post");
  m.AddPolygon({{-4, 0, 0}, {4, 0, 0}, {4, 0, 4}, {-4, 0, 4}}, wall);  // normal -y
  testing::AddBox(&m, {-0.5, -3.5, 0}, {0.5, -2.5, 5}, post);
  const SurfaceGrid g = BuildSurfaceGrid(m, GridOptions());
  const RayCaster rc(m);
  auto f = [](const Eigen::Vector3d& p) {
    return Eigen::Vector3d(1 + 0.1 * p.x(), 2 + 0.2 * p.z(), 3);
  };
  auto make_photo = [&](int w, int h) {
    ArchitecturePhoto ph;
    ph.intrinsics = Intrinsics::PinholeFov(w, h, 70);
    ph.pose = Pose::LookAt({0, -12, 2}, {0, 0, 2});
    ph.image = Image(w, h, 3, PixelUnits::kRadiance, 0.f);
    // Radiance on the wall: a linear function of the world point (bilinear sampling of a
    // linear field along a plane is exact only up to perspective: tolerance below).
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const Eigen::Vector3d d = ph.pose.rotation * Unproject(ph.intrinsics, {x + 0.5, y + 0.5});
        const RayHit hit = rc.Intersect(ph.pose.position, d.normalized());
        if (!hit.hit) continue;
        const Eigen::Vector3d v = f(ph.pose.position + hit.t * d.normalized());
        for (int c = 0; c < 3; ++c) ph.image.at(x, y, c) = static_cast<float>(v[c]);
      }
    }
    return ph;
  };
  ArchitecturePhoto ph = make_photo(320, 240);
  ph.mask.assign(320 * 240, 1);
  for (int y = 0; y < 240; ++y) {
    for (int x = 90; x < 110; ++x) ph.mask[y * 320 + x] = 0;  // a strip on the wall's left
  }
  ObservationSummary s;
  const auto obs = CollectObservations(g, rc, {ph}, ObservationOptions(), &s);
  EXPECT_GT(s.occluded, 0);
  EXPECT_GT(s.invalid_pixels, 0);
  EXPECT_EQ(s.observations, static_cast<int64_t>(obs.size()));
  ASSERT_GT(obs.size(), 20u);
  int wall_points = 0;
  for (const auto& o : obs) {
    const GridPoint& p = g.points[o.point];
    EXPECT_GT(p.normal.dot(ph.pose.position - p.position), 0);  // faces the camera
    EXPECT_NEAR((o.radiance.cast<double>() - f(p.position)).norm(), 0, 0.03);
    if (p.block != wall) continue;
    ++wall_points;
    // The post hides |x| < 0.59..0.71 m of the wall from this camera.
    EXPECT_GT(std::abs(p.position.x()), 0.55);
  }
  EXPECT_GT(wall_points, 20);
  // A photo told which blocks it observes (ArchitecturePhoto::blocks) reads those alone, with
  // the same samples there.
  ArchitecturePhoto post_only = ph;
  post_only.blocks.assign(m.block_names.size(), 0);
  post_only.blocks[post] = 1;
  const auto of_post = CollectObservations(g, rc, {post_only});
  ASSERT_FALSE(of_post.empty());
  EXPECT_EQ(of_post.size(),
            static_cast<size_t>(std::count_if(obs.begin(), obs.end(), [&](const Observation& o) {
              return g.points[o.point].block == post;
            })));
  for (const auto& o : of_post) EXPECT_EQ(g.points[o.point].block, post);
  // A coarse photo (25 cm pixels on the wall): 2x2-pixel footprints near the post's
  // silhouette and the wall's edges see other surfaces and are dropped.
  const ArchitecturePhoto coarse = make_photo(64, 48);
  ObservationSummary s1;
  const auto obs1 = CollectObservations(g, rc, {coarse}, ObservationOptions(), &s1);
  EXPECT_GT(s1.mixed_footprint, 0);
  ObservationOptions loose;
  loose.check_footprint = false;
  const auto all = CollectObservations(g, rc, {coarse}, loose);
  EXPECT_EQ(all.size(), obs1.size() + s1.mixed_footprint);
  // The nearest-pixel fallback takes back part of them (single clean pixels).
  ObservationOptions fallback;
  fallback.nearest_pixel_fallback = true;
  ObservationSummary s3;
  const auto near = CollectObservations(g, rc, {coarse}, fallback, &s3);
  EXPECT_GT(near.size(), obs1.size());
  EXPECT_LT(s3.mixed_footprint, s1.mixed_footprint);
  for (const auto& o : near) {
    EXPECT_NEAR((o.radiance.cast<double>() - f(g.points[o.point].position)).norm(), 0, 0.1);
  }
  // A sun in the south-east casts the post's shadow onto the wall: samples straddling the
  // shadow's edges are dropped when the slot's sun direction is given.
  const std::vector<Eigen::Vector3d> suns = {Eigen::Vector3d(0.3, -1, 0.4).normalized()};
  ObservationSummary s2;
  const auto lit = CollectObservations(g, rc, {coarse}, ObservationOptions(), &s2, &suns);
  EXPECT_GT(s2.shadow_edge, 0);
  EXPECT_EQ(lit.size() + s2.shadow_edge, obs1.size());
  const std::vector<Eigen::Vector3d> no_suns;
  EXPECT_THROW(CollectObservations(g, rc, {ph}, ObservationOptions(), nullptr, &no_suns), Error);
  // Bad input.
  ArchitecturePhoto wrong = ph;
  wrong.mask.pop_back();
  EXPECT_THROW(CollectObservations(g, rc, {wrong}), Error);
  wrong = ph;
  wrong.image = Image(100, 100, 3, PixelUnits::kRadiance);
  EXPECT_THROW(CollectObservations(g, rc, {wrong}), Error);
  wrong = ph;
  wrong.image.units = PixelUnits::kDigital;
  EXPECT_THROW(CollectObservations(g, rc, {wrong}), Error);
}

}  // namespace
}  // namespace rouen
