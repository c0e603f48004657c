// The scene folder written by solve and read by render (DESIGN.md): scene.json with the site,
// response curve, grid options, per-slot sun/sky/environment and the albedo summary;
// albedo_sun.exr, albedo_se.exr (RGB) and albedo_info.exr (observations, flags) hold one grid
// point per pixel, row-major, 1024 wide. The grid itself is rebuilt from the model OBJ.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/camera.h"
#include "core/mesh.h"
#include "core/response_curve.h"
#include "core/solar.h"
#include "core/time.h"
#include "solve/albedo.h"
#include "solve/env_stereo.h"
#include "solve/environment.h"
#include "solve/grid.h"
#include "solve/ground_apron.h"
#include "solve/ground_field.h"
#include "solve/irradiance.h"
#include "solve/sky_model.h"

namespace rouen {

// Recovered illumination at one capture time (§3).
struct SlotModel {
  UtcTime utc;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();      // unit ENU
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();  // relative radiance, RGB
  double sun_solid_angle_sr = 6.8e-5;
  SkyModel sky;
  EnvironmentMap env;

  Lighting ToLighting() const;
  static SlotModel FromLighting(const Lighting& l);
};

// The camera of one photographed bracket of the session (named slot<k>/<target>/view<v>), so a
// scene renders its views without the session.
struct SceneView {
  int slot = 0;
  std::string target;  // "architecture", "sky", "landscape", "sun"
  UtcTime utc;         // the bracket's median frame time
  Intrinsics intrinsics;
  Pose pose;
};

struct SceneModel {
  int format_version = 1;
  Site site;
  ResponseCurve response;  // may be empty (not valid()) when photos came in as HDR
  GridOptions grid_options;
  // The ground the solve modelled around the building: not in model_file, added to it when read
  // (WithGroundApron) before the grid is built.
  GroundApronOptions ground;
  HemisphereOptions hemisphere;  // the irradiance's gathering pattern over that grid
  std::vector<SlotModel> slots;
  AlbedoResult albedo;
  // The environment's ground reflects the sun with RetroFactor(this) when predicted for a novel
  // time (solve/env_stereo.h EnvStereoOptions::ground_retro; 0: Lambert).
  double env_ground_retro = 0;
  // The environment's photometric stereo (§5.2) as the solve fitted it from `env_stereo_slots`
  // (the slots the albedos used): a prediction from those slots reads it instead of fitting
  // again. Absent when the solve did not fit it (scenes from before, fit_ground_retro off).
  std::optional<EnvStereoResult> env_stereo;
  std::vector<int> env_stereo_slots;
  // The ground as a light field (SolveConfig::ground_field), every slot's lighting shares it;
  // null without it.
  std::shared_ptr<const GroundField> ground_field;
  std::string model_file;  // OBJ, relative to the scene folder
  // The surroundings the solve modelled with the building (an OBJ relative to the scene
  // folder; "" for none): appended to model_file's mesh (Mesh::Append) before the ground.
  std::string surroundings_file;
  std::vector<std::string> surrounding_blocks;  // their blocks (read from the file)
  std::map<std::string, SceneView> views;
  std::vector<int> holdout_slots;  // slots whose architecture photos the albedos did not use
  // Provenance: a hash of everything the solve read (the session's files, the model, the
  // options), which a later solve compares to know whether there is work; the version of
  // rouen that wrote the scene; the solve's options as the pipeline records them.
  std::string inputs_sha256;
  std::string session_dir;  // the session folder solved (absolute), "" for older scenes
  std::string rouen_version;
  nlohmann::json options = nlohmann::json::object();
  // Seconds per stage of the solve that wrote it: [{"stage": ..., "seconds": ...}] (or null).
  nlohmann::json timings;
};

constexpr int kAlbedoImageWidth = 1024;

// Writes scene.json and the albedo EXRs (atomically, through core), and for other tools the
// grid points' positions and normals (points.exr, normals.exr, packed as the albedos), each
// block's albedo atlases (atlas/<index>_<block>_sun.exr and _se.exr, solve/atlas.h) and the
// model with texture coordinates into them (model_textured.obj and .mtl). The model OBJ must
// already be at dir/model_file (or be given as `mesh`, which is then written there).
void WriteScene(const std::filesystem::path& dir, const SceneModel& scene,
                const Mesh* mesh = nullptr);
// The scene's mesh as the solve had it: dir/model_file (or `building`, when given), the
// surroundings appended (their block names in `surroundings`, which may be null), the ground
// added. Throws rouen::Error naming a file that is missing or malformed.
Mesh SceneMesh(const std::filesystem::path& dir, const SceneModel& scene,
               const Mesh* building = nullptr, std::vector<std::string>* surroundings = nullptr);
// scene.json's text parsed and checked on its own (what ReadScene reads first, before the
// folder's files): the scene without its albedos, and what the folder must then match. Throws
// rouen::Error starting with `name`.
struct SceneJson {
  SceneModel scene;  // albedo.rho_sun, rho_se, observations, flags, retro and lobes empty
  size_t points = 0;
  std::string albedo_files[3];  // sun, se, info: relative to the scene folder
  std::string model_sha256, surroundings_sha256;
  nlohmann::json retro, sun_lobes, sky_lobes;  // objects by block name
};
SceneJson ParseSceneJson(std::string_view text, const std::string& name);

// Reads and validates a scene folder; checks that the OBJ is the file the scene was written
// with (scene.json keeps its sha256: grid points are numbered by triangle), rebuilds the grid
// from it and checks that the albedo images hold exactly one value per grid point. Throws
// rouen::Error naming the file.
SceneModel ReadScene(const std::filesystem::path& dir, Mesh* mesh = nullptr,
                     SurfaceGrid* grid = nullptr);

// Per-point values <-> a float image `width` wide (rows padded with zeros).
Image PackPointValues(const std::vector<Eigen::Vector3d>& values, int width = kAlbedoImageWidth);
std::vector<Eigen::Vector3d> UnpackPointValues(const Image& image, int count);

}  // namespace rouen
