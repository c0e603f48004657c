// The simulated world behind `rouen demo`, the project's ground truth: a campanile-like tower
// on a plaza (Berkeley, late August) with surrounding blocks and open ground, lit by a sun
// from the world's own almanac (capture/sim/almanac.h) through a Rayleigh + Mie atmosphere
// (capture/sim/atmosphere.h). Surfaces are Lambertian with smoothly varying RGB albedo; the
// copper roof adds a mild specular lobe (sim_scene.h MaterialSpecular).
// Lighting per time: exact direct sun with shadow rays; sky and interreflection (several
// bounces) gathered by stratified Monte Carlo on surface texels. Frame: ENU metres, origin at
// the site. Radiance units: W m^-2 sr^-1 per colour band (R, G, B ~ 680, 550, 440 nm).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "capture/sim/almanac.h"
#include "capture/sim/atmosphere.h"
#include "core/camera.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/solar.h"
#include "core/time.h"

namespace rouen {

struct SimWorldOptions {
  Site site;           // default: Berkeley (37.8722 N, -122.2578 E, 60 m)
  bool quick = false;  // coarser lighting texels and fewer samples
  uint64_t seed = 1;   // jitter of the lighting samples
  AtmosphereParams atmosphere;
  double pressure_mbar = 1010.0;  // for refraction of the sun's direction
  double temperature_c = 10.0;
  // Lighting resolution; 0 picks the mode's default (quick / full).
  double tower_texel_m = 0;    // 0.6 / 0.4
  double plaza_texel_m = 0;    // 2 / 1
  double block_texel_m = 0;    // 2 / 1
  double ground_texel_m = 0;   // 8 / 4 (ground beyond the plaza, to 200 m)
  int hemisphere_samples = 0;  // per texel, a square number: 400 / 1024
  int sun_samples = 0;         // shadow rays per texel (area x disc): 4 / 16
  int bounces = 0;             // interreflection bounces: 4 / 5
  // Throws rouen::Error naming the bad option.
  void Validate() const;
};

// A camera placement: intrinsics and pose.
struct SimView {
  Intrinsics intrinsics;
  Pose pose;
};

struct SimWorldStats {
  int texels = 0;                // lighting texels
  int invalid_texels = 0;        // inside solids (filled from neighbours)
  int64_t gather_records = 0;    // stored hemisphere hits (time independent)
  double setup_seconds = 0;      // geometry, ray tracing of the gather structure (once)
  double last_time_seconds = 0;  // the last SetTime that computed a new time
  int times_computed = 0;
};

class SimWorld {
 public:
  explicit SimWorld(const SimWorldOptions& options = {});
  ~SimWorld();
  SimWorld(const SimWorld&) = delete;
  SimWorld& operator=(const SimWorld&) = delete;

  const SimWorldOptions& options() const;
  const Site& site() const;
  const SimWorldStats& stats() const;

  // Computes (or takes from the cache) the lighting at instant t and makes it current. Renders
  // may run on several threads at once, and beside SetTime of the time already current.
  void SetTime(UtcTime t);
  bool HasTime() const;
  UtcTime Time() const;  // throws rouen::Error before the first SetTime

  // The building model a user would give the solver: blocks "base", "shaft", "belfry",
  // "roof", "plaza"; outward normals, counter-clockwise from outside.
  const Mesh& Model() const;
  void WriteModelObj(const std::string& path) const;

  // --- Ground truth (the current time where it depends on time) ---
  // Albedo of the surface nearest to the point (anywhere in the world, ground included).
  Eigen::Vector3d TrueAlbedo(const Eigen::Vector3d& point_on_surface) const;
  const AlmanacSun& TrueSun() const;
  Eigen::Vector3d TrueSunDirection() const;   // unit ENU, apparent (refracted)
  Eigen::Vector3d TrueSunIrradiance() const;  // at normal incidence at the site, W m^-2
  Eigen::Vector3d TrueSunRadiance() const;    // mean over the disc = irradiance / solid angle
  double TrueSunSolidAngle() const;           // sr
  // Sky radiance towards a unit ENU direction (no sun disc); below the horizon: the
  // horizon's value (the world has ground there).
  Eigen::Vector3d TrueSkyRadiance(const Eigen::Vector3d& dir_enu) const;
  // Irradiance on a horizontal plane from the unoccluded sky (no sun).
  Eigen::Vector3d TrueSkyIrradiance() const;
  // Total irradiance (sun with shadows + sky + interreflections) at a point on the
  // surface nearest to `point`, on that surface's outward side.
  Eigen::Vector3d TrueIrradiance(const Eigen::Vector3d& point) const;
  // Outgoing diffuse radiance there (albedo / pi x irradiance; the roof's lobe not included).
  Eigen::Vector3d TrueRadiance(const Eigen::Vector3d& point) const;

  // --- Rendering (the current time) ---
  // Radiance image (units kRadiance): surfaces, sky and the sun disc (supersampled near the
  // sun so that its integrated irradiance is conserved). 2x2 jittered samples per pixel.
  // Pixels outside a fisheye's image circle are 0.
  Image RenderRadiance(const Intrinsics& k, const Pose& pose) const;
  // One channel: model block index, -1 for anything not in the model, -2 for sky.
  Image RenderBlockIds(const Intrinsics& k, const Pose& pose) const;

  // --- Standard camera placements ---
  // Four pinhole views of the tower from different azimuths, ~76-82 m away, framing it.
  // 480x360 (quick: 320x240).
  std::vector<SimView> ArchitectureViews(bool quick) const;
  // 180-degree fisheye (320x320) looking straight up from a mast 1 m above the roof apex;
  // image up = north.
  SimView SkyView() const;
  // Level equirect panoramas 512x256 facing azimuth 0, for the environment at two heights
  // (paper §3.3: a large building may need maps from several places):
  // [0] on a tripod at 1.6 m, 35 m south-south-west of the tower;
  // [1] on the sky camera's mast, 67 m (1 m above the roof apex): the surroundings much as
  //     the belfry and the roof see them.
  std::vector<SimView> LandscapeViews() const;
  // 6-degree pinhole (256x256) on the mast aimed at the current true sun.
  SimView SunView() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace rouen
