#include "solve/environment.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

constexpr double kPi = 3.14159265358979323846;

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
      BuildEnvironmentMap(pano, k, pose, rc, sun, 0.0047, sky, EnvOptions(), &s);
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
  // Fully hidden by the wall above the horizon: the sky model (7).
  const int hidden = env.Region(Dir(90, 30));
  EXPECT_EQ(env.source[hidden], EnvRegionSource::kSkyModel);
  EXPECT_NEAR((env.radiance[hidden] - Eigen::Vector3d::Constant(7)).norm(), 0, 1e-9);
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
}

// Ground with radiance 1 within 100 m of the panorama and 5 beyond: seen from higher up the
// far ground drops below the horizon, which the parallax layers reproduce.
TEST(BuildEnvironmentMapTest, ParallaxLayersReprojectTheGround) {
  const Intrinsics k = Intrinsics::Equirect(720, 360);
  const Pose pose = Pose::Level({0, 0, 1.6}, 0, 0);
  Image pano(k.width, k.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, {x + 0.5, y + 0.5});
      double v = 2;  // sky
      if (d.z() < 0) v = 1.6 / -d.z() * std::hypot(d.x(), d.y()) > 100 ? 5 : 1;
      for (int c = 0; c < 3; ++c) pano.at(x, y, c) = static_cast<float>(v);
    }
  }
  // The model: a thin pole far away, 50 m tall (sets the layers' range and the ground level).
  Mesh m;
  const int b = m.AddBlock("pole");
  m.AddPolygon({{300, 0, 0}, {300.1, 0, 0}, {300.1, 0, 50}, {300, 0, 50}}, b);
  const RayCaster rc(m);
  SkyModel sky;
  for (auto& ch : sky.channel) ch.Lz = 2;
  EnvOptions o;
  o.parallax_layers = 3;
  const EnvironmentMap env = BuildEnvironmentMap(pano, k, pose, rc, Dir(90, 45), 0.0047, sky, o);
  ASSERT_EQ(env.num_layers(), 3);
  EXPECT_NEAR(env.layer_z[0], 1.6, 1e-12);
  EXPECT_NEAR(env.layer_z[2], 50, 1e-12);
  const Eigen::Vector3d steep = Dir(200, -55), shallow = Dir(200, -15);
  // From 1.6 m both directions meet near ground (radiance 1) ...
  EXPECT_NEAR(env.Radiance(steep, 1.6).x(), 1, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, 1.6).x(), 1, 1e-5);
  EXPECT_EQ(env.Radiance(steep), env.Radiance(steep, 1.6));
  // ... from 50 m the shallow one (ground 137..284 m away) sees the far ground.
  EXPECT_NEAR(env.Radiance(steep, 50).x(), 1, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, 50).x(), 5, 1e-5);
  EXPECT_NEAR(env.Radiance(shallow, 500).x(), 5, 1e-5);  // clamped above the top layer
  // Linear between layers.
  const double l0 = env.Radiance(shallow, env.layer_z[0]).x();
  const double l1 = env.Radiance(shallow, env.layer_z[1]).x();
  EXPECT_EQ(l1, env.radiance[env.num_regions() + env.Region(shallow)].x());
  EXPECT_NEAR(env.Radiance(shallow, 0.25 * env.layer_z[0] + 0.75 * env.layer_z[1]).x(),
              0.25 * l0 + 0.75 * l1, 1e-9);
  // The sky is at infinity: the same in every layer.
  EXPECT_NEAR(env.Radiance(Dir(10, 20), 50).x(), 2, 1e-5);
  // Layers survive JSON.
  const EnvironmentMap back = nlohmann::json(env).get<EnvironmentMap>();
  EXPECT_EQ(back.layer_z, env.layer_z);
  EXPECT_EQ(back.Radiance(shallow, 50), env.Radiance(shallow, 50));
}

TEST(BuildEnvironmentMapTest, BadInputThrows) {
  const Intrinsics k = Intrinsics::Equirect(64, 32);
  const Pose pose;
  const RayCaster rc{Mesh()};
  const SkyModel sky;
  Image small(32, 32, 3, PixelUnits::kRadiance);
  EXPECT_THROW(BuildEnvironmentMap(small, k, pose, rc, {0, 0, 1}, 0.005, sky, EnvOptions()), Error);
  Image ldr(64, 32, 3, PixelUnits::kDigital);
  EXPECT_THROW(BuildEnvironmentMap(ldr, k, pose, rc, {0, 0, 1}, 0.005, sky, EnvOptions()), Error);
  Image ok(64, 32, 3, PixelUnits::kRadiance, 1.f);
  EnvOptions bad;
  bad.sectors = 0;
  EXPECT_THROW(BuildEnvironmentMap(ok, k, pose, rc, {0, 0, 1}, 0.005, sky, bad), Error);
  EXPECT_THROW(BuildEnvironmentMap(ok, k, pose, rc, {0, 0, 0}, 0.005, sky, EnvOptions()), Error);
}

}  // namespace
}  // namespace rouen
