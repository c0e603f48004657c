#include "capture/sim/sim_world.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "capture/sim/sim_test_world.h"
#include "core/angles.h"
#include "core/error.h"
#include "core/mesh.h"

namespace rouen {
namespace {

// The tower's solid (and the ground below z = 0), analytically, in world coordinates.
bool InsideSolid(const Eigen::Vector3d& p) {
  if (p.z() < 0) return true;
  const double a = -40.0 * kPi / 180;
  const double x = std::cos(a) * p.x() - std::sin(a) * p.y();
  const double y = std::sin(a) * p.x() + std::cos(a) * p.y();
  const double m = std::max(std::abs(x), std::abs(y));
  const double z = p.z();
  if (z < 8) return m < 7;
  if (z < 48) return m < 4.5;
  if (z < 58) {
    if (m >= 5) return false;
    if (m < 4.2) return false;  // the belfry's interior
    const double along = std::abs(x) > std::abs(y) ? std::abs(y) : std::abs(x);
    return !(along < 2 && z > 50 && z < 56);  // the openings
  }
  return m < 5.0 * (66.0 - z) / 8.0;
}

Eigen::Matrix3d LookAlong(const Eigen::Vector3d& n) {
  const Eigen::Vector3d z = n.normalized();
  const Eigen::Vector3d x = z.unitOrthogonal();
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = z.cross(x);
  r.col(2) = z;
  return r;
}

// Irradiance at `p` (normal n) from the rendered radiance of everything in its hemisphere
// (sky, sun disc, surfaces): an independent quadrature of the world's own light field.
Eigen::Vector3d RenderedIrradiance(const SimWorld& w, const Eigen::Vector3d& p,
                                   const Eigen::Vector3d& n) {
  const int size = 400;
  const Intrinsics k = Intrinsics::FisheyeFov(size, size, 180.0);
  Pose pose;
  pose.position = p + 0.01 * n;
  pose.rotation = LookAlong(n);
  const Image img = w.RenderRadiance(k, pose);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const double r = std::hypot(x + 0.5 - k.cx, y + 0.5 - k.cy);
      const double theta = r / k.fx;
      if (theta >= kPi / 2) continue;
      const double d_omega = (theta > 0 ? std::sin(theta) / theta : 1.0) / (k.fx * k.fy);
      for (int c = 0; c < 3; ++c) sum[c] += img.at(x, y, c) * std::cos(theta) * d_omega;
    }
  }
  return sum;
}

TEST(SimWorldTest, ModelHasTowerBlocksWithOutwardNormals) {
  const Mesh& m = SimTestWorld().Model();
  ASSERT_EQ(m.block_names, (std::vector<std::string>{"base", "shaft", "belfry", "roof", "plaza"}));
  ASSERT_EQ(m.triangles.size(), m.triangle_block.size());
  std::set<int> blocks;
  double plaza_area = 0;
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = m.triangles[t];
    const Eigen::Vector3d c = (m.vertices[tri[0]] + m.vertices[tri[1]] + m.vertices[tri[2]]) / 3;
    const Eigen::Vector3d n = m.Normal(static_cast<int>(t));
    EXPECT_FALSE(InsideSolid(c + 0.02 * n)) << "triangle " << t << " block " << m.triangle_block[t];
    EXPECT_TRUE(InsideSolid(c - 0.02 * n)) << "triangle " << t << " block " << m.triangle_block[t];
    blocks.insert(m.triangle_block[t]);
    if (m.triangle_block[t] == 4) plaza_area += m.Area(static_cast<int>(t));
  }
  EXPECT_EQ(blocks.size(), 5u);
  EXPECT_NEAR(plaza_area, 100.0 * 100.0 - 14.0 * 14.0, 1e-6);
}

TEST(SimWorldTest, ModelObjRoundTrips) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / "rouen_sim_world_test_model.obj";
  SimTestWorld().WriteModelObj(path.string());
  const Mesh back = ReadObj(path.string());
  std::filesystem::remove(path);
  EXPECT_EQ(back.block_names, SimTestWorld().Model().block_names);
  EXPECT_EQ(back.triangles.size(), SimTestWorld().Model().triangles.size());
}

TEST(SimWorldTest, AlbedoIsSmoothBoundedAndStoneLikeOnTheTower) {
  const SimWorld& w = SimTestWorld();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d mean2 = Eigen::Vector3d::Zero();
  int n = 0;
  for (double z = 1; z < 47; z += 0.7) {
    for (double s = -4.4; s <= 4.4; s += 0.55) {
      const double a = 40.0 * kPi / 180;
      const Eigen::Vector3d p(4.5 * std::cos(a) - s * std::sin(a),
                              4.5 * std::sin(a) + s * std::cos(a), z < 8 ? 0 : z);
      if (z < 8) continue;
      const Eigen::Vector3d rho = w.TrueAlbedo(p);
      EXPECT_GE(rho.minCoeff(), 0.05);
      EXPECT_LE(rho.maxCoeff(), 0.8);
      // Smooth: 1 cm away changes little (wavelengths are >= 3 m).
      const Eigen::Vector3d p2 = p + Eigen::Vector3d(0, 0, 0.01);
      EXPECT_LT((w.TrueAlbedo(p2) - rho).cwiseAbs().maxCoeff(), 0.01);
      mean += rho;
      mean2 += rho.cwiseProduct(rho);
      ++n;
    }
  }
  mean /= n;
  const Eigen::Vector3d sd = (mean2 / n - mean.cwiseProduct(mean)).cwiseSqrt();
  EXPECT_NEAR(mean[0], 0.55, 0.06);
  EXPECT_NEAR(mean[1], 0.50, 0.06);
  EXPECT_NEAR(mean[2], 0.42, 0.06);
  EXPECT_GT(sd[1], 0.02);  // it does vary
  // The plaza is grey paving, the far ground darker.
  const Eigen::Vector3d plaza = w.TrueAlbedo({-30, 20, 0});
  EXPECT_NEAR(plaza[1], 0.27, 0.12);
  EXPECT_LT(w.TrueAlbedo({1000, 2000, 0})[1], 0.3);
}

TEST(SimWorldTest, SkyIsBluerThanSunAndSunReddensTowardsEvening) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const Eigen::Vector3d sun_noon = w.TrueSunIrradiance();
  const Eigen::Vector3d zenith = w.TrueSkyRadiance(Eigen::Vector3d::UnitZ());
  EXPECT_GT(zenith[2] / zenith[0], 1.5 * sun_noon[2] / sun_noon[0]);
  const double el_noon = w.TrueSun().elevation_deg;
  w.SetTime(SimTestEvening());
  const Eigen::Vector3d sun_eve = w.TrueSunIrradiance();
  EXPECT_LT(w.TrueSun().elevation_deg, el_noon - 30);
  EXPECT_GT(sun_eve[0] / sun_eve[2], 1.3 * sun_noon[0] / sun_noon[2]);
  EXPECT_LT(sun_eve[1], sun_noon[1]);
  w.SetTime(SimTestNoon());
  // Mean disc radiance x solid angle = irradiance.
  EXPECT_NEAR((w.TrueSunRadiance() * w.TrueSunSolidAngle() - w.TrueSunIrradiance()).norm(), 0,
              1e-9 * w.TrueSunIrradiance().norm());
}

TEST(SimWorldTest, ShadowNorthOfTheTowerAtNoon) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  // Sun at azimuth ~190 deg, elevation ~62 deg: the shaft's shadow falls ~10 deg east of north.
  const Eigen::Vector3d shade = w.TrueIrradiance({2.5, 15, 0});
  const Eigen::Vector3d sunlit = w.TrueIrradiance({-2.5, -15, 0});
  for (int c = 0; c < 3; ++c) EXPECT_LT(shade[c], 0.5 * sunlit[c]);
  // Shade is lit by the sky: bluer than sunlit ground.
  EXPECT_GT(shade[2] / shade[0], sunlit[2] / sunlit[0]);
}

// The copper roof's lobe (MaterialSpecular): seen from the sun's mirror direction a sunlit
// roof point sends rho_s E_sun cos(i) more than its diffuse radiance (plus a little sky); seen
// from far off the mirror, only the sky's small share of the lobe.
TEST(SimWorldTest, RoofReflectsTheSunSpecularly) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const Mesh& model = w.Model();
  const int roof =
      static_cast<int>(std::find(model.block_names.begin(), model.block_names.end(), "roof") -
                       model.block_names.begin());
  ASSERT_LT(roof, static_cast<int>(model.block_names.size()));
  const Eigen::Vector3d sun = w.TrueSunDirection();
  int best = -1;
  for (size_t t = 0; t < model.triangles.size(); ++t) {
    if (model.triangle_block[t] != roof) continue;
    if (best < 0 || model.Normal(t).dot(sun) > model.Normal(best).dot(sun))
      best = static_cast<int>(t);
  }
  ASSERT_GE(best, 0);
  const Eigen::Vector3d n = model.Normal(best);
  const auto& tri = model.triangles[best];
  const Eigen::Vector3d x =
      (model.vertices[tri[0]] + model.vertices[tri[1]] + model.vertices[tri[2]]) / 3.0;
  const double c = n.dot(sun);
  ASSERT_GT(c, 0.3);
  const Eigen::Vector3d mirror = 2 * c * n - sun;
  // The sky's share is at most rho_s 2 pi / (n + 1) times the brightest sky radiance.
  double sky_max = 0;
  for (int i = 0; i < 400; ++i) {
    const double az = 2 * kPi * (i % 40) / 40, el = (0.5 + i / 40) * (kPi / 2) / 10;
    const Eigen::Vector3d d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
    sky_max = std::max(sky_max, w.TrueSkyRadiance(d).maxCoeff());
  }
  const double rho_s = 0.07, exponent = 20;  // sim_scene.cc MaterialSpecular(kRoofMetal)
  const double sky_bound = rho_s * 2 * kPi / (exponent + 1) * sky_max;
  auto seen_from = [&](const Eigen::Vector3d& dir) {
    Pose pose;
    pose.position = x + 20 * dir;
    pose.rotation = LookAlong(-dir);
    const Image img = w.RenderRadiance(Intrinsics::PinholeFov(9, 9, 0.5), pose);
    return Eigen::Vector3d(img.at(4, 4, 0), img.at(4, 4, 1), img.at(4, 4, 2));
  };
  const Eigen::Vector3d diffuse = w.TrueRadiance(x);
  const Eigen::Vector3d at_mirror = seen_from(mirror) - diffuse;
  const Eigen::Vector3d e_sun = w.TrueSunIrradiance() * c;
  for (int ch = 0; ch < 3; ++ch) {
    // Texel lighting noise of the diffuse part (~1%) is the tolerance below the sun's share.
    EXPECT_GT(at_mirror[ch], rho_s * e_sun[ch] - 0.01 * diffuse[ch]) << ch;
    EXPECT_LT(at_mirror[ch], rho_s * e_sun[ch] + sky_bound + 0.01 * diffuse[ch]) << ch;
  }
  // Off the mirror by ~50 degrees, towards the normal: cos^20 50deg = 1e-4 of the sun's share.
  const Eigen::Vector3d off = (n + 0.2 * (n - mirror)).normalized();
  ASSERT_LT(off.dot(mirror), std::cos(40 * kPi / 180));
  const Eigen::Vector3d away = seen_from(off) - diffuse;
  for (int ch = 0; ch < 3; ++ch) {
    EXPECT_GT(away[ch], -0.01 * diffuse[ch]) << ch;
    EXPECT_LT(away[ch], sky_bound + 1e-3 * rho_s * e_sun[ch] + 0.01 * diffuse[ch]) << ch;
  }
}

TEST(SimWorldTest, OpenGroundIrradianceIsSunPlusSky) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const Eigen::Vector3d p(-150, 160, 0);
  // Independent quadrature of the sky over the upper hemisphere (cosine-weighted strata).
  Eigen::Vector3d sky = Eigen::Vector3d::Zero();
  const int m = 300;
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < m; ++j) {
      const double u1 = (i + 0.5) / m, u2 = (j + 0.5) / m, r = std::sqrt(u1);
      sky += w.TrueSkyRadiance(Eigen::Vector3d(r * std::cos(2 * kPi * u2),
                                               r * std::sin(2 * kPi * u2), std::sqrt(1 - u1)));
    }
  }
  sky *= kPi / (m * m);
  const Eigen::Vector3d expected = w.TrueSunIrradiance() * w.TrueSunDirection().z() + sky;
  const Eigen::Vector3d got = w.TrueIrradiance(p);
  // Distant buildings hide < 0.3% of this point's sky and reflect about as much back.
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], expected[c], 0.01 * expected[c]);
}

TEST(SimWorldTest, IrradianceMatchesTheRenderedHemisphere) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const double a = 40.0 * kPi / 180;
  const Eigen::Vector3d sw(-std::cos(a), -std::sin(a), 0);  // sunlit at this time
  const Eigen::Vector3d ne(std::cos(a), std::sin(a), 0);    // in shade
  struct Probe {
    Eigen::Vector3d p, n;
  };
  const Probe probes[] = {{4.5 * sw + Eigen::Vector3d(0, 0, 20), sw},
                          {4.5 * ne + Eigen::Vector3d(0, 0, 12), ne},
                          {7.0 * sw + Eigen::Vector3d(0, 0, 0.5), sw},  // foot of the wall
                          {Eigen::Vector3d(-12, -8, 0), Eigen::Vector3d::UnitZ()}};
  for (const Probe& pr : probes) {
    const Eigen::Vector3d rendered = RenderedIrradiance(w, pr.p, pr.n);
    const Eigen::Vector3d truth = w.TrueIrradiance(pr.p);
    // The rendered hemisphere carries one more interreflection bounce, exact per-pixel sun
    // instead of texel averages, and its own sampling; quick-mode texel noise is ~0.5%
    // and the discretisation differences near corners ~1-2%: 3% covers both.
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(rendered[c], truth[c], 0.03 * truth[c]) << pr.p.transpose() << " channel " << c;
    }
  }
}

TEST(SimWorldTest, SunDiscIntegratesToTheSunIrradiance) {
  SimWorld& w = SimTestWorld();
  for (UtcTime t : {SimTestNoon(), SimTestEvening()}) {
    w.SetTime(t);
    const SimView v = w.SunView();
    const Image img = w.RenderRadiance(v.intrinsics, v.pose);
    const Intrinsics& k = v.intrinsics;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int y = 0; y < k.height; ++y) {
      for (int x = 0; x < k.width; ++x) {
        const double xn = (x + 0.5 - k.cx) / k.fx, yn = (y + 0.5 - k.cy) / k.fy;
        const double d_omega = 1.0 / (k.fx * k.fy) / std::pow(1 + xn * xn + yn * yn, 1.5);
        const Eigen::Vector3d d = v.pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
        const Eigen::Vector3d sky = w.TrueSkyRadiance(d);
        for (int c = 0; c < 3; ++c) sum[c] += (img.at(x, y, c) - sky[c]) * d_omega;
      }
    }
    const Eigen::Vector3d e = w.TrueSunIrradiance();
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(sum[c], e[c], 0.02 * e[c]);
    // The disc is resolved: its centre is brighter than its mean (limb darkening).
    const int cx = k.width / 2, cy = k.height / 2;
    EXPECT_GT(img.at(cx, cy, 1), 1.1 * w.TrueSunRadiance()[1]);
  }
  w.SetTime(SimTestNoon());
}

TEST(SimWorldTest, SunDiscInAWideViewConservesIrradiance) {
  // The 180-degree sky camera's pixels are ~0.56 deg: the disc covers about one pixel.
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const Eigen::Vector3d rendered = RenderedIrradiance(w, {0, 0, 67}, Eigen::Vector3d::UnitZ());
  Eigen::Vector3d sky = Eigen::Vector3d::Zero();
  const int m = 300;
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < m; ++j) {
      const double u1 = (i + 0.5) / m, u2 = (j + 0.5) / m, r = std::sqrt(u1);
      sky += w.TrueSkyRadiance(Eigen::Vector3d(r * std::cos(2 * kPi * u2),
                                               r * std::sin(2 * kPi * u2), std::sqrt(1 - u1)));
    }
  }
  const Eigen::Vector3d expected =
      w.TrueSunIrradiance() * w.TrueSunDirection().z() + sky * (kPi / (m * m));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(rendered[c], expected[c], 0.01 * expected[c]);
}

TEST(SimWorldTest, BlockIdsMarkModelSkyAndSurroundings) {
  SimWorld& w = SimTestWorld();
  const SimView sky = w.SkyView();
  const Image sky_ids = w.RenderBlockIds(sky.intrinsics, sky.pose);
  EXPECT_EQ(sky_ids.channels, 1);
  EXPECT_EQ(sky_ids.at(160, 160), -2.0f);
  for (const SimView& v : w.ArchitectureViews(true)) {
    const Image ids = w.RenderBlockIds(v.intrinsics, v.pose);
    const float centre = ids.at(ids.width / 2, ids.height / 2);
    EXPECT_GE(centre, 0.0f);
    EXPECT_LE(centre, 3.0f);
    std::set<int> seen(ids.data.begin(), ids.data.end());
    EXPECT_TRUE(seen.count(-2));  // sky above the tower
    EXPECT_TRUE(seen.count(4));   // the plaza
    EXPECT_TRUE(seen.count(0) && seen.count(1) && seen.count(3));
  }
  const std::vector<SimView> land = w.LandscapeViews();
  ASSERT_EQ(land.size(), 2u);
  EXPECT_LT(land[0].pose.position.z(), 2.0);   // the tripod
  EXPECT_GT(land[1].pose.position.z(), 66.0);  // the mast, above the roof apex (66 m)
  // From the tripod: ground, sky and the shaft; from the mast: ground, sky and the roof
  // below, but no longer the shaft (hidden by the roof and the belfry).
  const Image low = w.RenderBlockIds(land[0].intrinsics, land[0].pose);
  std::set<int> seen_low(low.data.begin(), low.data.end());
  EXPECT_TRUE(seen_low.count(-1) && seen_low.count(-2) && seen_low.count(1));
  const Image high = w.RenderBlockIds(land[1].intrinsics, land[1].pose);
  std::set<int> seen_high(high.data.begin(), high.data.end());
  EXPECT_TRUE(seen_high.count(-1) && seen_high.count(-2) && seen_high.count(3));
  EXPECT_FALSE(seen_high.count(1));
}

TEST(SimWorldTest, BelfryInteriorIsLitOnlyThroughItsOpenings) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const Eigen::Vector3d floor = w.TrueIrradiance({0, 0, 48});
  const Eigen::Vector3d ceiling = w.TrueIrradiance({0, 0, 58});
  const Eigen::Vector3d sky = w.TrueSkyIrradiance();
  const Eigen::Vector3d open = sky + w.TrueSunIrradiance() * w.TrueSunDirection().z();
  for (int c = 0; c < 3; ++c) {
    EXPECT_GT(floor[c], 0.02 * sky[c]);    // light comes in
    EXPECT_GT(ceiling[c], 0.02 * sky[c]);  // and is reflected up from the floor and walls
    EXPECT_LT(ceiling[c], 0.3 * open[c]);  // but far less than outside
  }
}

TEST(SimWorldTest, LightingIsCachedPerTime) {
  SimWorld& w = SimTestWorld();
  w.SetTime(SimTestNoon());
  const int before = w.stats().times_computed;
  w.SetTime(SimTestNoon());
  EXPECT_EQ(w.stats().times_computed, before);
  EXPECT_EQ(w.Time(), SimTestNoon());
}

TEST(SimWorldTest, ErrorsBeforeSetTimeAndForBadOptions) {
  SimWorldOptions o;
  o.quick = true;
  o.hemisphere_samples = 4;
  o.tower_texel_m = o.plaza_texel_m = o.block_texel_m = o.ground_texel_m = 10;
  SimWorld w(o);
  EXPECT_FALSE(w.HasTime());
  EXPECT_THROW(w.TrueSunRadiance(), Error);
  EXPECT_THROW(w.RenderRadiance(Intrinsics::PinholeFov(8, 8, 40), Pose{}), Error);
  o.hemisphere_samples = 10;  // not a square
  EXPECT_THROW(SimWorld{o}, Error);
  o.hemisphere_samples = 0;
  o.site.lat_deg = 95;
  EXPECT_THROW(SimWorld{o}, Error);
}

}  // namespace
}  // namespace rouen
