#include "solve/raycast.h"

#include <embree3/rtcore.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/error.h"

namespace rouen {

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::vector<int> prim_to_triangle;  // Embree primitive id -> mesh triangle

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {

void CheckDevice(RTCDevice device, const char* what) {
  const RTCError err = rtcGetDeviceError(device);
  if (err != RTC_ERROR_NONE) {
    throw Error(std::string("Embree: ") + what + " failed (error " +
                std::to_string(static_cast<int>(err)) + ")");
  }
}

}  // namespace

RayCaster::RayCaster(const Mesh& mesh) : impl_(std::make_unique<Impl>()) {
  num_triangles_ = static_cast<int>(mesh.triangles.size());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (const auto& p : mesh.vertices) {
    if (!p.allFinite()) continue;
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  if (lo.allFinite() && hi.allFinite()) bounds_ = Eigen::AlignedBox3d(lo, hi);
  scale_ = mesh.vertices.empty() || !(hi - lo).allFinite() ? 1.0 : std::max((hi - lo).norm(), 1e-6);

  impl_->device = rtcNewDevice("threads=0");
  if (!impl_->device) throw Error("Embree: rtcNewDevice failed");
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);

  const int nv = static_cast<int>(mesh.vertices.size());
  std::vector<Eigen::Vector3i> tris;
  tris.reserve(mesh.triangles.size());
  for (int t = 0; t < num_triangles_; ++t) {
    const Eigen::Vector3i& f = mesh.triangles[t];
    bool ok = f.minCoeff() >= 0 && f.maxCoeff() < nv;
    if (ok) {
      const Eigen::Vector3d& a = mesh.vertices[f[0]];
      const Eigen::Vector3d& b = mesh.vertices[f[1]];
      const Eigen::Vector3d& c = mesh.vertices[f[2]];
      const double area2 = (b - a).cross(c - a).norm();
      ok = std::isfinite(area2) && area2 > 1e-12 * scale_ * scale_;
    }
    if (!ok) {
      ++num_degenerate_;
      continue;
    }
    impl_->prim_to_triangle.push_back(t);
    tris.push_back(f);
  }

  if (!tris.empty()) {
    RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    float* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), std::max(nv, 1)));
    for (int i = 0; i < nv; ++i) {
      for (int k = 0; k < 3; ++k) vb[3 * i + k] = static_cast<float>(mesh.vertices[i][k]);
    }
    unsigned* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), tris.size()));
    for (size_t i = 0; i < tris.size(); ++i) {
      for (int k = 0; k < 3; ++k) ib[3 * i + k] = static_cast<unsigned>(tris[i][k]);
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometry(impl_->scene, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(impl_->scene);
  CheckDevice(impl_->device, "building the scene");
}

RayCaster::~RayCaster() = default;
RayCaster::RayCaster(RayCaster&&) noexcept = default;
RayCaster& RayCaster::operator=(RayCaster&&) noexcept = default;

RayHit RayCaster::Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double tmin,
                            double tmax) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(origin.x());
  rh.ray.org_y = static_cast<float>(origin.y());
  rh.ray.org_z = static_cast<float>(origin.z());
  rh.ray.dir_x = static_cast<float>(dir.x());
  rh.ray.dir_y = static_cast<float>(dir.y());
  rh.ray.dir_z = static_cast<float>(dir.z());
  rh.ray.tnear = static_cast<float>(tmin);
  rh.ray.tfar = static_cast<float>(std::min(tmax, 1e30));
  rh.ray.time = 0;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  RayHit out;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  out.hit = true;
  out.t = rh.ray.tfar;
  out.triangle = impl_->prim_to_triangle[rh.hit.primID];
  out.u = rh.hit.u;
  out.v = rh.hit.v;
  return out;
}

bool RayCaster::Occluded(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double tmin,
                         double tmax) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray;
  ray.org_x = static_cast<float>(origin.x());
  ray.org_y = static_cast<float>(origin.y());
  ray.org_z = static_cast<float>(origin.z());
  ray.dir_x = static_cast<float>(dir.x());
  ray.dir_y = static_cast<float>(dir.y());
  ray.dir_z = static_cast<float>(dir.z());
  ray.tnear = static_cast<float>(tmin);
  ray.tfar = static_cast<float>(std::min(tmax, 1e30));
  ray.time = 0;
  ray.mask = 0xFFFFFFFFu;
  ray.id = 0;
  ray.flags = 0;
  rtcOccluded1(impl_->scene, &context, &ray);
  return ray.tfar < 0;  // Embree sets tfar = -inf on a hit
}

}  // namespace rouen
