#include "solve/environment.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/angles.h"
#include "core/error.h"
#include "solve/retro.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

Eigen::Vector3d Dir(double az_deg, double el_deg) {
  const double az = az_deg * kPi / 180, el = el_deg * kPi / 180;
  return {std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el)};
}

TEST(EnvironmentMapTest, RegionsCoverTheSphereConsistently) {
  EnvOptions o;
  const EnvironmentMap m = EnvironmentMap::Constant(o, {1, 2, 3}, {4, 5, 6});
  EXPECT_EQ(m.num_regions(), 18 * 24);
  for (int r = 0; r < m.num_regions(); ++r) {
    double el0, el1, az0, az1;
    m.RegionBounds(r, &el0, &el1, &az0, &az1);
    const double el = 0.5 * (el0 + el1), az = 0.5 * (az0 + az1);
    EXPECT_EQ(m.Region({std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el)}),
              r);
  }
  EXPECT_EQ(m.Radiance(Dir(10, 30)), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(m.Radiance(Dir(200, -30)), Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(m.Radiance({0, 0, 1}), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(m.Radiance({0, 0, -1}), Eigen::Vector3d(4, 5, 6));
  // Azimuth 0 is north, 90 east.
  EXPECT_EQ(m.Region(Dir(1, 5)) % m.sectors, 0);
  EXPECT_EQ(m.Region(Dir(91, 5)) % m.sectors, 6);
  // JSON round trip.
  const EnvironmentMap back = nlohmann::json(m).get<EnvironmentMap>();
  EXPECT_EQ(back.radiance, m.radiance);
  nlohmann::json bad = m;
  bad["radiance"].erase(0);
  EXPECT_THROW(bad.get<EnvironmentMap>(), Error);
}

// A synthetic panorama whose radiance is a known function of direction.
Image Panorama(const Intrinsics& k, const Pose& pose, const Eigen::Vector3d& sun) {
  Image img(k.width, k.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, {x + 0.5, y + 0.5});
      Eigen::Vector3d v = d.z() >= 0 ? Eigen::Vector3d(1, 2, 4) : Eigen::Vector3d(3, 3, 2);
      if (d.dot(sun) > std::cos(1.5 * kPi / 180)) v = Eigen::Vector3d::Constant(1e5);
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(v[c]);
    }
  }
  return img;
}

TEST(BuildEnvironmentMapTest, AveragesSkipsModelAndSunAndFills) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);
  const Pose pose = Pose::Level({0, 0, 1.6}, 0, 0);
  const Eigen::Vector3d sun = Dir(135, 40);
  Image pano = Panorama(k, pose, sun);
  // A few invalid pixels.
  pano.at(10, 100, 0) = NAN;
  pano.at(11, 100, 1) = -1;
  // The model: a wall due east that hides azimuths ~[63, 117] deg up to ~60 deg, and a
  // ground disc (square) around the camera that hides everything below -20 deg.
  Mesh m;
  const int b = m.AddBlock("wall");
  m.AddPolygon({{10, 5, -1}, {10, -5, -1}, {10, -5, 21}, {10, 5, 21}}, b);
  testing::AddHorizontalRect(&m, -4.4, 4.4, -4.4, 4.4, 0, true, b);
  const RayCaster rc(m);
  SkyModel sky;  // uniform Lz = 1 per channel with the default parameters
  for (auto& ch : sky.channel) ch.Lz = 7;
  EnvSummary s;
  const EnvironmentMap env =
      BuildEnvironmentMap({{&pano, k, pose}}, rc, {sun, 0.0047}, sky, EnvOptions(), &s);
  EXPECT_EQ(s.pixels_invalid, 2);
  EXPECT_GT(s.pixels_sun, 0);
  EXPECT_GT(s.pixels_model, 0);
  EXPECT_EQ(s.pixels_used + s.pixels_sun + s.pixels_model + s.pixels_invalid, 720 * 360);
  // Observed regions above the horizon hold exactly the sky value (the sun was skipped).
  for (int r = 0; r < env.num_regions(); ++r) {
    double el0, el1, az0, az1;
    env.RegionBounds(r, &el0, &el1, &az0, &az1);
    if (env.source[r] == EnvRegionSource::kObserved) {
      const Eigen::Vector3d expect = el0 >= 0 ? Eigen::Vector3d(1, 2, 4) : Eigen::Vector3d(3, 3, 2);
      EXPECT_NEAR((env.radiance[r] - expect).norm(), 0, 1e-5) << r;
    }
  }
  // Fully hidden by the wall above the horizon: the sky model (7) times its band's residual
  // (EnvOptions::fill_band_residual): the band's observed regions read 1 2 4 where the model
  // says 7, and so does the hidden one; without the residual, the model alone.
  const int hidden = env.Region(Dir(90, 30));
  EXPECT_EQ(env.source[hidden], EnvRegionSource::kSkyModel);
  EXPECT_NEAR((env.radiance[hidden] - Eigen::Vector3d(1, 2, 4)).norm(), 0, 1e-5);
  EnvOptions model_alone;
  model_alone.fill_band_residual = false;
  const EnvironmentMap plain =
      BuildEnvironmentMap({{&pano, k, pose}}, rc, {sun, 0.0047}, sky, model_alone);
  EXPECT_EQ(plain.source[hidden], EnvRegionSource::kSkyModel);
  EXPECT_NEAR((plain.radiance[hidden] - Eigen::Vector3d::Constant(7)).norm(), 0, 1e-9);
  // Every region of the sky the panorama did not see takes its band's residual.
  for (int r = 0; r < env.num_regions(); ++r) {
    if (env.source[r] == EnvRegionSource::kSkyModel) {
      EXPECT_NEAR((env.radiance[r] - Eigen::Vector3d(1, 2, 4)).norm(), 0, 1e-5) << r;
    }
  }
  // Below -20 deg everything hits the ground square: filled from nearer bands.
  const int low = env.Region(Dir(10, -60));
  EXPECT_EQ(env.source[low], EnvRegionSource::kNeighbour);
  EXPECT_NEAR((env.radiance[low] - Eigen::Vector3d(3, 3, 2)).norm(), 0, 1e-5);
  // Below the horizon behind the wall: neighbours in the band.
  const int behind = env.Region(Dir(90, -5));
  EXPECT_NE(env.source[behind], EnvRegionSource::kSkyModel);
  EXPECT_NEAR((env.radiance[behind] - Eigen::Vector3d(3, 3, 2)).norm(), 0, 1e-5);
  EXPECT_GT(env.ObservedFraction(), 0.5);
  EXPECT_LT(env.ObservedFraction(), 1.0);
  EXPECT_EQ(env.num_layers(), 1);
  EXPECT_NEAR(env.layer_z[0], 1.6, 1e-12);
  EXPECT_EQ(s.regions_observed + s.regions_sky + s.regions_neighbour, env.num_regions());
}

// A sky photo (EnvPanorama::sky_only) fills the sky regions the building hides from the
// landscape panorama with what it saw there, not the sky model; regions the landscape
// panorama saw keep its pixels, and the sky photo makes no layer. Sky photos alone are refused.
TEST(BuildEnvironmentMapTest, ASkyPhotoFillsTheSkyTheBuildingHides) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);
  const Pose ground = Pose::Level({0, 0, 1.6}, 0, 0), mast = Pose::Level({0, 0, 30}, 0, 0);
  const Eigen::Vector3d sun = Dir(135, 40);
  const Image pano = Panorama(k, ground, sun);
  // The sky photo's sky is 5 6 7 (the landscape panorama's 1 2 4): where a region holds it, it
  // came from the sky photo.
  Image photo = Panorama(k, mast, sun);
  for (int y = 0; y < k.height / 2; ++y)
    for (int x = 0; x < k.width; ++x)
      for (int c = 0; c < 3; ++c)
        if (photo.at(x, y, c) < 100) photo.at(x, y, c) = static_cast<float>(5 + c);
  // A wall due east that hides azimuths ~[63, 117] deg up to ~60 deg from the ground; the mast
  // at 30 m sees over it.
  Mesh m;
  const int b = m.AddBlock("wall");
  m.AddPolygon({{10, 5, -1}, {10, -5, -1}, {10, -5, 21}, {10, 5, 21}}, b);
  const RayCaster rc(m);
  SkyModel sky;
  for (auto& ch : sky.channel) ch.Lz = 7;
  EnvPanorama sky_photo{&photo, k, mast};
  sky_photo.sky_only = true;
  const EnvironmentMap env =
      BuildEnvironmentMap({{&pano, k, ground}, sky_photo}, rc, {sun, 0.0047}, sky, EnvOptions());
  EXPECT_EQ(env.num_layers(), 1);
  EXPECT_NEAR(env.layer_z[0], 1.6, 1e-12);
  const int hidden = env.Region(Dir(90, 30)), seen = env.Region(Dir(270, 30));
  EXPECT_EQ(env.source[hidden], EnvRegionSource::kObserved);
  EXPECT_NEAR((env.radiance[hidden] - Eigen::Vector3d(5, 6, 7)).norm(), 0, 1e-5);
  EXPECT_NEAR((env.radiance[seen] - Eigen::Vector3d(1, 2, 4)).norm(), 0, 1e-5);
  // Below the horizon the sky photo adds nothing: the ground behind the wall is filled from
  // the landscape panorama's neighbours.
  EXPECT_NEAR((env.radiance[env.Region(Dir(90, -5))] - Eigen::Vector3d(3, 3, 2)).norm(), 0, 1e-5);
  EXPECT_THROW(BuildEnvironmentMap({sky_photo}, rc, {sun, 0.0047}, sky, EnvOptions()), Error);
}

// A photographed sky with structure the model lacks -- its lowest 5 degrees twice as bright as
// the model says, half a band -- keeps it in the map's detail cells (EnvOptions::sky_detail):
// each cell's shape times its region's mean is the cell's photographed mean, where uniform
// regions miss it by a third; the detail survives scene.json exactly, and damaged detail is
// refused.
TEST(BuildEnvironmentMapTest, SkyDetailKeepsThePhotographedStructureInsideARegion) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);  // 0.5 deg per pixel
  const Pose pose = Pose::Level({0, 0, 1.6}, 0, 0);
  SkyModel sky;
  sky.channel[0] = SkyParams{1.0, -1.0, -0.32, 10, -3, 0.45, 1};
  sky.channel[1] = SkyParams{1.2, -1.0, -0.4, 12, -3.2, 0.5, 1};
  sky.channel[2] = SkyParams{1.5, -1.0, -0.5, 8, -2.5, 0.3, 1};
  sky.sun_dir = Dir(135, 40);
  auto photographed = [&](const Eigen::Vector3d& d) -> Eigen::Vector3d {
    const double el = std::asin(std::clamp(d.z(), -1.0, 1.0)) / kDeg;
    return sky.Radiance(d) * (el < 5 ? 2.0 : 1.0);
  };
  Image pano(k.width, k.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, {x + 0.5, y + 0.5});
      const Eigen::Vector3d v = d.z() >= 0 ? photographed(d) : Eigen::Vector3d(0.2, 0.2, 0.2);
      for (int c = 0; c < 3; ++c) pano.at(x, y, c) = static_cast<float>(v[c]);
    }
  }
  Mesh m;  // a small block far off, below the camera's horizon
  testing::AddBox(&m, {200, 200, 0}, {201, 201, 1}, m.AddBlock("far"));
  const RayCaster rc(m);
  const EnvironmentMap env =
      BuildEnvironmentMap({{&pano, k, pose}}, rc, {sky.sun_dir, 0.0047}, sky, EnvOptions());
  ASSERT_EQ(env.detail, 4);
  ASSERT_EQ(env.sky_detail.size(), static_cast<size_t>(env.num_detail_cells()));
  const SkyShape shape(env, sky);
  const SkyShape uniform(EnvironmentMap::Constant(EnvOptions(), {1, 1, 1}, {1, 1, 1}), sky);
  double worst = 0, worst_uniform = 0;
  for (int c = 0; c < env.num_detail_cells(); ++c) {
    double el0, el1, az0, az1;
    env.CellBounds(c, &el0, &el1, &az0, &az1);
    const double el = 0.5 * (el0 + el1), az = 0.5 * (az0 + az1);
    const Eigen::Vector3d centre = Dir(az / kDeg, el / kDeg);
    if (centre.dot(sky.sun_dir) > std::cos(6 * kDeg)) continue;  // the sun's exclusion
    // The cell's photographed mean (its 5 x 5 to 5 x 8 pixels' solid-angle weighted mean).
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double w = 0;
    for (double e = el0 + 0.25 * kDeg; e < el1; e += 0.5 * kDeg) {
      for (double a = az0 + 0.25 * kDeg; a < az1; a += 0.5 * kDeg) {
        sum += std::cos(e) * photographed(Dir(a / kDeg, e / kDeg));
        w += std::cos(e);
      }
    }
    const Eigen::Vector3d truth = sum / w;
    const Eigen::Vector3d mean = env.radiance[env.RegionOfCell(c)];
    const auto rel = [&](const Eigen::Vector3d& v) {
      return (v - truth).cwiseQuotient(truth).cwiseAbs().maxCoeff();
    };
    worst = std::max(worst, rel(mean.cwiseProduct(shape.OfCell(c))));
    worst_uniform = std::max(worst_uniform, rel(mean));
    EXPECT_EQ(shape.OfCell(env.DetailCell(centre)), shape.OfCell(c));
    EXPECT_EQ(shape.InRegion(centre, env.RegionOfCell(c)), shape.OfCell(c));
  }
  // The model varies within a cell (2.5 x 3.75 deg) by a few per cent at most; the shape takes
  // its 4 x 4 sample mean against the pixels' (0.5 deg) mean.
  EXPECT_LT(worst, 0.02);
  EXPECT_GT(worst_uniform, 0.3);
  // Below the horizon the shape is 1, as it is everywhere for a uniform map.
  EXPECT_EQ(shape.OfCell(env.DetailCell(Dir(10, -20))), Eigen::Vector3d::Ones());
  EXPECT_TRUE(uniform.uniform());
  // scene.json keeps the detail exactly; damaged detail is refused.
  const EnvironmentMap back = nlohmann::json(env).get<EnvironmentMap>();
  EXPECT_EQ(back.detail, env.detail);
  EXPECT_EQ(back.sky_detail, env.sky_detail);
  EXPECT_EQ(back.sun_exclusion_rad, env.sun_exclusion_rad);
  nlohmann::json bad = env;
  bad["sky_detail"].erase(0);
  EXPECT_THROW(bad.get<EnvironmentMap>(), Error);
  bad = env;
  bad["sky_detail"].erase(0);
  bad["sky_detail"].erase(0);
  bad["sky_detail"].erase(0);
  EXPECT_THROW(bad.get<EnvironmentMap>(), Error);  // one cell short
  bad = env;
  bad["sky_detail"][5] = -1;
  EXPECT_THROW(bad.get<EnvironmentMap>(), Error);
  bad = env;
  bad["detail"] = 0;
  EXPECT_THROW(bad.get<EnvironmentMap>(), Error);
  // A detail grid too large to hold is refused before anything is allocated.
  EnvOptions huge;
  huge.sectors = 720;
  huge.sky_detail = 64;
  EXPECT_THROW(huge.Validate(), Error);
  huge.sky_detail = 4;
  EXPECT_NO_THROW(huge.Validate());
}

// Ground with radiance 1 within 100 m of the site and 5 beyond, seen from panoramas at
// 1.6 m and 50 m: from higher up the far ground reaches further below the horizon. Each
// panorama makes one layer; panoramas at nearly the same height share one.
Image GroundPanorama(const Intrinsics& k, const Pose& pose) {
  Image pano(k.width, k.height, 3, PixelUnits::kRadiance);
  const Eigen::Vector3d c = pose.position;
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, {x + 0.5, y + 0.5});
      double v = 2;  // sky
      if (d.z() < 0) {
        const Eigen::Vector3d g = c + (c.z() / -d.z()) * d;
        v = g.head<2>().norm() > 100 ? 5 : 1;
      }
      for (int ch = 0; ch < 3; ++ch) pano.at(x, y, ch) = static_cast<float>(v);
    }
  }
  return pano;
}

// A tower north-east of the panorama casts its shadow (sun from the north, 30 deg high) on
// rough ground that the panorama sees: sunlit, rho/pi (E_sky A(v) + E_sun sin 30 D(s, v)), in
// the shadow rho/pi E_sky A(v), under a uniform sky (A, D: solve/retro.h, 1 for Lambert). With
// the sun's irradiance and the ground's retro the map reads the panorama as the map of the same
// ground all sunlit; without them (or with lit_ground off) the regions over the shadow keep it.
TEST(BuildEnvironmentMapTest, GroundInTheModelsShadowIsReadAsSunlit) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);
  const Pose pose = Pose::Level({0, 0, 1.6}, 0, 0);
  Mesh m;
  testing::AddBox(&m, {8, -2, 0}, {12, 2, 20}, m.AddBlock("tower"));
  const RayCaster rc(m);
  EXPECT_EQ(GroundLevel(rc), 0);
  const Eigen::Vector3d sun = Dir(0, 30), sky_l(1, 2, 4), sun_e(30, 20, 10), up(0, 0, 1);
  SkyModel sky;
  for (int c = 0; c < 3; ++c) sky.channel[c] = SkyParams{sky_l[c], 0, 0, 0, 0, 0, 1};
  const Eigen::Vector3d e_sky = kPi * sky_l;  // a uniform sky on a horizontal plane
  for (const double retro : {0.0, 1.0}) {
    SCOPED_TRACE(retro);
    // The panorama with the shadow, and the same ground all sunlit.
    Image pano(k.width, k.height, 3, PixelUnits::kRadiance), all_lit = pano;
    int shaded_pixels = 0;
    for (int y = 0; y < k.height; ++y) {
      for (int x = 0; x < k.width; ++x) {
        const Eigen::Vector3d d = pose.rotation * Unproject(k, {x + 0.5, y + 0.5});
        Eigen::Vector3d v = sky_l, lit = sky_l;
        if (d.z() < 0) {
          const Eigen::Vector3d q = pose.position + (pose.position.z() / -d.z()) * d;
          const Eigen::Vector3d shaded = 0.1 * e_sky * AmbientRetroFactor(retro, up, -d);
          lit = shaded + 0.1 * sun_e * (0.5 * RetroFactor(retro, up, sun, -d));
          const bool in_shadow =
              !rc.Occluded(pose.position, d, 1e-9) &&
              rc.Occluded(q + Eigen::Vector3d(0, 0, rc.surface_offset()), sun, 0.0);
          shaded_pixels += in_shadow;
          v = in_shadow ? shaded : lit;
        }
        for (int c = 0; c < 3; ++c) {
          pano.at(x, y, c) = static_cast<float>(v[c]);
          all_lit.at(x, y, c) = static_cast<float>(lit[c]);
        }
      }
    }
    ASSERT_GT(shaded_pixels, 500);
    EnvOptions o;
    o.sun_exclusion_deg = 0;
    const EnvSun with_sun{sun, 0, sun_e, retro};
    EnvSummary s;
    const EnvironmentMap env = BuildEnvironmentMap({{&pano, k, pose}}, rc, with_sun, sky, o, &s);
    EXPECT_EQ(s.pixels_ground_shadow, shaded_pixels);
    EXPECT_EQ(env.ground_retro, retro);
    // (Read as it is: it has no shadow to read.)
    const EnvironmentMap want = BuildEnvironmentMap({{&all_lit, k, pose}}, rc, {sun, 0}, sky, o);
    int ground_regions = 0;
    for (int r = 0; r < env.bands_below * env.sectors; ++r) {
      ASSERT_EQ(env.source[r], want.source[r]);
      ground_regions += env.source[r] == EnvRegionSource::kObserved;
      // Float pixels: relative rounding 6e-8, summed over a region's pixels.
      EXPECT_NEAR((env.radiance[r] - want.radiance[r]).norm() / want.radiance[r].norm(), 0, 1e-6)
          << r;
    }
    EXPECT_GT(ground_regions, 150);
    // As seen: the region over the shadow (south-east, a few degrees below the horizon) is
    // darker, at least by its pixels' share of the shadow.
    const int over_shadow = env.Region(Eigen::Vector3d(10, -15, -1.6));
    o.lit_ground = false;
    for (const EnvironmentMap& seen :
         {BuildEnvironmentMap({{&pano, k, pose}}, rc, with_sun, sky, o, &s),
          BuildEnvironmentMap({{&pano, k, pose}}, rc, {sun, 0}, sky, EnvOptions(), &s)}) {
      EXPECT_EQ(s.pixels_ground_shadow, 0);
      ASSERT_EQ(seen.source[over_shadow], EnvRegionSource::kObserved);
      EXPECT_LT(seen.radiance[over_shadow][0], 0.95 * want.radiance[over_shadow][0]);
    }
  }
  // The ratio: Lambert's E_sky / (E_sky + E_sun sin(el)) for retro 0, whatever the view.
  const Eigen::Vector3d lambert = GroundShadowRatio(0, e_sky, sun_e, sun, Dir(200, 10));
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(lambert[c], e_sky[c] / (e_sky[c] + 0.5 * sun_e[c]), 1e-15);
}

TEST(BuildEnvironmentMapTest, OneLayerPerPanoramaHeight) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);
  const Pose low = Pose::Level({0, 0, 1.6}, 0, 0), high = Pose::Level({0, 0, 50}, 0, 0);
  const Pose low2 = Pose::Level({20, 0, 2.1}, 0, 0);  // within layer_merge_m of `low`
  const Image pano_low = GroundPanorama(k, low), pano_high = GroundPanorama(k, high);
  const Image pano_low2 = GroundPanorama(k, low2);
  // The model: a thin pole far away (only so that the caster has something).
  Mesh m;
  const int b = m.AddBlock("pole");
  m.AddPolygon({{300, 0, 0}, {300.1, 0, 0}, {300.1, 0, 50}, {300, 0, 50}}, b);
  const RayCaster rc(m);
  SkyModel sky;
  for (auto& ch : sky.channel) ch.Lz = 2;
  // Given in any order: sorted by height.
  EnvSummary s;
  const EnvironmentMap env = BuildEnvironmentMap({{&pano_high, k, high}, {&pano_low, k, low}}, rc,
                                                 {Dir(90, 45), 0.0047}, sky, EnvOptions(), &s);
  ASSERT_EQ(env.num_layers(), 2);
  EXPECT_NEAR(env.layer_z[0], 1.6, 1e-12);
  EXPECT_NEAR(env.layer_z[1], 50, 1e-12);
  EXPECT_EQ(s.regions_observed + s.regions_sky + s.regions_neighbour, 2 * env.num_regions());
  // -55 deg meets the ground 1.1 m (from 1.6 m) and 35 m (from 50 m) away; -15 deg meets it
  // 6 m and 187 m away.
  const Eigen::Vector3d steep = Dir(200, -55), shallow = Dir(200, -15);
  EXPECT_NEAR(env.Radiance(steep, 1.6).x(), 1, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, 1.6).x(), 1, 1e-5);
  EXPECT_EQ(env.Radiance(steep), env.Radiance(steep, 1.6));
  EXPECT_NEAR(env.Radiance(steep, 50).x(), 1, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, 50).x(), 5, 1e-5);
  // Clamped outside the layers, linear between them.
  EXPECT_NEAR(env.Radiance(shallow, 500).x(), 5, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, -3).x(), 1, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, 0.25 * 1.6 + 0.75 * 50).x(), 0.25 * 1 + 0.75 * 5, 1e-5);
  // The sky is the same in both layers.
  EXPECT_NEAR(env.Radiance(Dir(10, 20), 50).x(), 2, 1e-5);
  EXPECT_NEAR(env.Radiance(Dir(10, 20), 1.6).x(), 2, 1e-5);
  // Layers survive JSON.
  const EnvironmentMap back = nlohmann::json(env).get<EnvironmentMap>();
  EXPECT_EQ(back.layer_z, env.layer_z);
  EXPECT_EQ(back.Radiance(shallow, 30), env.Radiance(shallow, 30));

  // Two panoramas 0.5 m apart in height (less than layer_merge_m): one layer at their mean
  // height, pooling their pixels; a third one high up makes a second layer.
  const EnvironmentMap merged =
      BuildEnvironmentMap({{&pano_low, k, low}, {&pano_high, k, high}, {&pano_low2, k, low2}}, rc,
                          {Dir(90, 45), 0.0047}, sky, EnvOptions());
  ASSERT_EQ(merged.num_layers(), 2);
  EXPECT_NEAR(merged.layer_z[0], 0.5 * (1.6 + 2.1), 1e-12);
  EXPECT_NEAR(merged.layer_z[1], 50, 1e-12);
  const int r = merged.Region(steep);
  EXPECT_EQ(merged.pixel_count[r], 2 * env.pixel_count[r]);
  // With a smaller merge distance they stay apart.
  EnvOptions apart;
  apart.layer_merge_m = 0.25;
  EXPECT_EQ(BuildEnvironmentMap({{&pano_low, k, low}, {&pano_low2, k, low2}}, rc,
                                {Dir(90, 45), 0.0047}, sky, apart)
                .num_layers(),
            2);
}

// pixel_stride s reads one pixel per s x s block, on the block's diagonal, one step further
// along it from block to block: a sky striped row by row (1 and 3 alternately in the lowest band,
// as a haze band changes within a pixel or two of the horizon) keeps the mean of every row; the
// block's first pixel alone would read only the 1s.
TEST(BuildEnvironmentMapTest, AStrideReadsEveryRow) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);  // 0.5 deg per pixel
  const Pose pose = Pose::Level({0, 0, 1.6}, 0, 0);
  Image pano(720, 360, 3, PixelUnits::kRadiance);
  for (int y = 0; y < 360; ++y) {
    const double el = 90 - (y + 0.5) * 0.5;
    const double v = el < 0 ? 2.0 : el < 10 ? (y % 2 == 0 ? 1.0 : 3.0) : 5.0;
    for (int x = 0; x < 720; ++x)
      for (int c = 0; c < 3; ++c) pano.at(x, y, c) = static_cast<float>(v);
  }
  Mesh m;  // a thin pole far away (only so that the caster has something)
  const int b = m.AddBlock("pole");
  m.AddPolygon({{300, 0, 0}, {300.1, 0, 0}, {300.1, 0, 50}, {300, 0, 50}}, b);
  const RayCaster rc(m);
  SkyModel sky;
  const EnvSun below{Dir(90, -30), 0.0047};  // no sun above the horizon to skip
  EnvOptions o;
  o.sky_detail = 1;
  const EnvironmentMap full = BuildEnvironmentMap({{&pano, k, pose}}, rc, below, sky, o);
  const int horizon = full.Region(Dir(100, 5)), high = full.Region(Dir(100, 45));
  // Rows 0.5 deg apart weigh cos(el) each: within 0.1% of 2 below 10 deg.
  EXPECT_NEAR(full.radiance[horizon][0], 2, 2e-3);
  for (const int stride : {2, 4}) {
    o.pixel_stride = stride;
    const EnvironmentMap env = BuildEnvironmentMap({{&pano, k, pose}}, rc, below, sky, o);
    EXPECT_NEAR(env.radiance[horizon][0], full.radiance[horizon][0], 2e-3) << stride;
    EXPECT_NEAR(env.radiance[high][0], 5, 1e-6) << stride;
    EXPECT_NEAR(env.radiance[env.Region(Dir(100, -5))][0], 2, 1e-6) << stride;
  }
}

TEST(BuildEnvironmentMapTest, BadInputThrows) {
  const Intrinsics k = Intrinsics::Equirect(64, 32);
  const Pose pose;
  const RayCaster rc{Mesh()};
  const SkyModel sky;
  const Eigen::Vector3d up(0, 0, 1);
  Image small(32, 32, 3, PixelUnits::kRadiance);
  EXPECT_THROW(BuildEnvironmentMap({{&small, k, pose}}, rc, {up, 0.005}, sky, EnvOptions()), Error);
  Image ldr(64, 32, 3, PixelUnits::kDigital);
  EXPECT_THROW(BuildEnvironmentMap({{&ldr, k, pose}}, rc, {up, 0.005}, sky, EnvOptions()), Error);
  Image ok(64, 32, 3, PixelUnits::kRadiance, 1.f);
  EnvOptions bad;
  bad.sectors = 0;
  EXPECT_THROW(BuildEnvironmentMap({{&ok, k, pose}}, rc, {up, 0.005}, sky, bad), Error);
  EnvOptions bad_merge;
  bad_merge.layer_merge_m = 0;
  EXPECT_THROW(BuildEnvironmentMap({{&ok, k, pose}}, rc, {up, 0.005}, sky, bad_merge), Error);
  EXPECT_THROW(BuildEnvironmentMap({{&ok, k, pose}}, rc, {{0, 0, 0}, 0.005}, sky, EnvOptions()),
               Error);
  // No panorama, a missing image, one bad panorama among good ones.
  EXPECT_THROW(BuildEnvironmentMap({}, rc, {up, 0.005}, sky, EnvOptions()), Error);
  EXPECT_THROW(BuildEnvironmentMap({{nullptr, k, pose}}, rc, {up, 0.005}, sky, EnvOptions()),
               Error);
  EXPECT_THROW(
      BuildEnvironmentMap({{&ok, k, pose}, {&ldr, k, pose}}, rc, {up, 0.005}, sky, EnvOptions()),
      Error);
}

}  // namespace
}  // namespace rouen
