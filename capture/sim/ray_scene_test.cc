#include "capture/sim/ray_scene.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/hash_random.h"

namespace rouen::sim {
namespace {

// Packets give each ray the hit Trace gives it alone: the same patch, and the same distance
// up to Embree's single-precision arithmetic (float t, a few ulps relative).
TEST(RaySceneTest, PacketsHitWhatSingleRaysHit) {
  const SceneGeometry scene = BuildScene(TexelSizes{});
  const RayScene rays(scene.patches);
  int hits = 0, misses = 0;
  for (int o = 0; o < 200; ++o) {
    // Origins around the tower and over the plaza, 8 directions of every kind each (the last
    // packet of an origin part full).
    const uint64_t h = MixHash(o);
    const Eigen::Vector3d origin(60 * (HashUniformHigh(h) - 0.5), 60 * (HashUniformLow(h) - 0.5),
                                 0.5 + 70 * HashUniformHigh(MixHash(h)));
    Eigen::Vector3d dirs[RayScene::kPacket];
    const int n = o % 5 == 0 ? 3 : RayScene::kPacket;
    for (int j = 0; j < n; ++j) {
      double a = 0, b = 0, c = 0;
      HashNormals(MixHash(h + 1 + j), &a, &b);
      HashNormals(MixHash(h + 100 + j), &c, &a);
      dirs[j] = Eigen::Vector3d(a, b, c).normalized();
    }
    RayHit packet[RayScene::kPacket];
    rays.TracePacket(origin, dirs, n, packet);
    for (int j = 0; j < n; ++j) {
      const RayHit single = rays.Trace(origin, dirs[j]);
      ASSERT_EQ(packet[j].patch, single.patch) << "origin " << o << " ray " << j;
      if (single.patch < 0) {
        EXPECT_TRUE(std::isinf(packet[j].t));
        ++misses;
        continue;
      }
      EXPECT_NEAR(packet[j].t, single.t, 1e-5 * single.t);
      ++hits;
    }
  }
  EXPECT_GT(hits, 300);
  EXPECT_GT(misses, 100);
}

}  // namespace
}  // namespace rouen::sim
