#include "capture/sim/ray_scene.h"

#include <embree3/rtcore.h>

#include "core/error.h"

namespace rouen::sim {

RayScene::RayScene(const std::vector<Patch>& patches) {
  device_ = rtcNewDevice(nullptr);
  if (!device_) throw Error("SimWorld: cannot create an Embree device");
  scene_ = rtcNewScene(device_);
  rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
  std::vector<Eigen::Vector3f> verts;
  std::vector<Eigen::Vector3i> tris;
  for (size_t i = 0; i < patches.size(); ++i) {
    const Patch& p = patches[i];
    const int b = static_cast<int>(verts.size());
    if (p.triangle) {
      verts.push_back(p.o.cast<float>());
      verts.push_back(p.Point(p.su, 0).cast<float>());
      verts.push_back(p.Point(p.apex_s, p.sv).cast<float>());
      tris.emplace_back(b, b + 1, b + 2);
      tri_patch_.push_back(static_cast<int>(i));
    } else {
      verts.push_back(p.o.cast<float>());
      verts.push_back(p.Point(p.su, 0).cast<float>());
      verts.push_back(p.Point(p.su, p.sv).cast<float>());
      verts.push_back(p.Point(0, p.sv).cast<float>());
      tris.emplace_back(b, b + 1, b + 2);
      tris.emplace_back(b, b + 2, b + 3);
      tri_patch_.push_back(static_cast<int>(i));
      tri_patch_.push_back(static_cast<int>(i));
    }
  }
  RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), verts.size()));
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), tris.size()));
  for (size_t i = 0; i < verts.size(); ++i) {
    for (int c = 0; c < 3; ++c) vb[3 * i + c] = verts[i][c];
  }
  for (size_t i = 0; i < tris.size(); ++i) {
    for (int c = 0; c < 3; ++c) ib[3 * i + c] = static_cast<unsigned>(tris[i][c]);
  }
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene_);
}

RayScene::~RayScene() {
  if (scene_) rtcReleaseScene(scene_);
  if (device_) rtcReleaseDevice(device_);
}

RayHit RayScene::Trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(o.x());
  rh.ray.org_y = static_cast<float>(o.y());
  rh.ray.org_z = static_cast<float>(o.z());
  rh.ray.dir_x = static_cast<float>(d.x());
  rh.ray.dir_y = static_cast<float>(d.y());
  rh.ray.dir_z = static_cast<float>(d.z());
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = std::numeric_limits<float>::infinity();
  rh.ray.mask = ~0u;
  rh.ray.flags = 0;
  rh.ray.time = 0.0f;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene_, &ctx, &rh);
  RayHit h;
  if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
    h.patch = tri_patch_[rh.hit.primID];
    h.t = rh.ray.tfar;
  }
  return h;
}

bool RayScene::Occluded(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay ray;
  ray.org_x = static_cast<float>(o.x());
  ray.org_y = static_cast<float>(o.y());
  ray.org_z = static_cast<float>(o.z());
  ray.dir_x = static_cast<float>(d.x());
  ray.dir_y = static_cast<float>(d.y());
  ray.dir_z = static_cast<float>(d.z());
  ray.tnear = 0.0f;
  ray.tfar = std::numeric_limits<float>::infinity();
  ray.mask = ~0u;
  ray.flags = 0;
  ray.time = 0.0f;
  rtcOccluded1(scene_, &ctx, &ray);
  return ray.tfar < 0;
}

void RayScene::TracePacket(const Eigen::Vector3d& o, const Eigen::Vector3d* d, int n,
                           RayHit* out) const {
  static_assert(kPacket == 8, "TracePacket uses Embree's 8-wide packets");
  if (n < 1 || n > kPacket) throw Error("RayScene: a packet holds 1 to 8 rays");
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  alignas(32) int valid[kPacket];
  RTCRayHit8 rh;
  for (int j = 0; j < kPacket; ++j) {
    const Eigen::Vector3d& dj = d[j < n ? j : 0];  // unused lanes repeat a valid ray
    valid[j] = j < n ? -1 : 0;
    rh.ray.org_x[j] = static_cast<float>(o.x());
    rh.ray.org_y[j] = static_cast<float>(o.y());
    rh.ray.org_z[j] = static_cast<float>(o.z());
    rh.ray.dir_x[j] = static_cast<float>(dj.x());
    rh.ray.dir_y[j] = static_cast<float>(dj.y());
    rh.ray.dir_z[j] = static_cast<float>(dj.z());
    rh.ray.tnear[j] = 0.0f;
    rh.ray.tfar[j] = std::numeric_limits<float>::infinity();
    rh.ray.mask[j] = ~0u;
    rh.ray.flags[j] = 0;
    rh.ray.time[j] = 0.0f;
    rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
  }
  rtcIntersect8(valid, scene_, &ctx, &rh);
  for (int j = 0; j < n; ++j) {
    out[j] = RayHit();
    if (rh.hit.geomID[j] != RTC_INVALID_GEOMETRY_ID) {
      out[j].patch = tri_patch_[rh.hit.primID[j]];
      out[j].t = rh.ray.tfar[j];
    }
  }
}

}  // namespace rouen::sim
