// What rouen hands to other tools from a solved scene: the building as binary glTF 2.0 with its
// two albedo sets, the sun, sky and environment of a time as a latitude-longitude EXR a renderer
// can light with, and renders with an alpha channel and their time, sun and camera in the EXR
// header.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/image.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"
#include "render/envmap.h"

namespace rouen {

// glTF is y-up: rouen's ENU metres (x east, y north, z up) are written as glTF (x, y, z) =
// (east, up, -north), a rotation (Blender's importer turns it back into x east, y north, z up).
Eigen::Vector3d EnuToGltf(const Eigen::Vector3d& enu);

struct GltfOptions {
  int texels_per_cell = 2;  // the albedo atlases' resolution (solve/atlas.h)
  void Validate() const;    // throws rouen::Error
};

struct GltfSummary {
  int blocks = 0;           // one node, mesh and material each
  int textured_blocks = 0;  // with grid points, so with albedo atlases
  int64_t vertices = 0;     // three per triangle (each triangle has its own atlas tile)
  int64_t triangles = 0;
  int64_t texels = 0;          // per albedo set
  int64_t clipped_texels = 0;  // albedo above 1 in some channel, stored as 1
  size_t bytes = 0;
};

// The building as a binary glTF 2.0 file (GLB): per block of the model one node, one mesh and
// one material whose baseColorTexture is the block's sun albedo atlas (solve/atlas.h) as an
// 8-bit PNG: the linear albedo clamped to 0..1 and encoded with the sRGB transfer function, as
// glTF defines base colour. The material's extras.rouen hold the sky+environment albedo atlas
// (a texture index, encoded the same way) and the block's retro parameter (scene.json
// albedo.retro, solve/retro.h). `asset_extras` go into asset.extras.rouen.
std::string EncodeGlb(const Mesh& mesh, const SurfaceGrid& grid, const AlbedoResult& albedo,
                      const nlohmann::json& asset_extras, const GltfOptions& options = {},
                      GltfSummary* summary = nullptr);

// EncodeGlb of a scene, written to `out` atomically (core/files.h WriteFileAtomic).
GltfSummary WriteSceneGltf(const LoadedScene& scene, const std::filesystem::path& out,
                           const GltfOptions& options = {});

struct SceneEnvmap {
  Image map;  // RGB radiance, render/envmap.h's orientation
  Lighting lighting;
  std::vector<ImageAttribute> attributes;  // LightingAttributes and the orientation
  // Irradiance on an unoccluded level plane (at the map's height): from the map, and rouen's.
  Eigen::Vector3d horizontal_from_map = Eigen::Vector3d::Zero();
  Eigen::Vector3d horizontal_rouen = Eigen::Vector3d::Zero();
};

// The request's lighting (its slot's, or predicted for its time: RequestedLighting; the camera
// is not used) as a latitude-longitude map (BakeLatLong).
SceneEnvmap SceneEnvmapFor(const LoadedScene& scene, const RenderRequest& request,
                           const LatLongOptions& options,
                           const std::function<void(const std::string&)>& log = {});

}  // namespace rouen
