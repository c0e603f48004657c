// For the export tests (not part of the library API): a small solved scene written without a
// session -- a tower on a plaza, one slot of lighting and one architecture view -- and a reader
// of binary glTF that checks its container.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/hash_random.h"
#include "core/solar.h"
#include "core/time.h"
#include "solve/scene.h"
#include "solve/test_scenes.h"

namespace rouen::testing {

// The lighting of the scene's slot: the sun at azimuth 130 deg, elevation 35 deg, a clear sky,
// and environment regions holding the sky's means and a ground radiance, each scaled by its own
// factor in 0.5..1.5 (an environment that is not symmetric, so orientation errors show).
inline SlotModel ExportTestSlot() {
  SlotModel s;
  s.utc = ParseIso8601("2026-06-21T16:00:00Z");
  s.sun_dir = EnuFromAzEl(130, 35);
  s.sun_radiance = Eigen::Vector3d(1.2e5, 1.0e5, 0.8e5);
  s.sun_solid_angle_sr = 6.8e-5;
  s.sky = ClearSky(s.sun_dir);
  s.env = EnvironmentMap::FromSky(EnvOptions{}, s.sky, Eigen::Vector3d(0.3, 0.25, 0.2));
  for (size_t r = 0; r < s.env.radiance.size(); ++r)
    s.env.radiance[r] *= 0.5 + HashUniform53(MixHash(r + 17));
  return s;
}

// The albedo a grid point of the test scene gets (sun; the sky+environment albedo is 0.9 x it).
inline Eigen::Vector3d ExportTestAlbedo(const GridPoint& p) {
  const double base = p.block == 0 ? 0.6 : 0.3;
  return Eigen::Vector3d(base, base * 0.7 + 0.01 * p.position.z(),
                         base * 0.5 + 0.004 * std::abs(p.position.x()));
}

// Writes the scene into `dir` (created): blocks "tower" (6 x 6 x 15 m, retro 0.4, a sun lobe)
// and "plaza" (40 x 40 m, matte), grid spacing 1 m (plaza 4 m).
inline void WriteExportTestScene(const std::filesystem::path& dir) {
  Mesh mesh;
  const int tower = mesh.AddBlock("tower");
  const int plaza = mesh.AddBlock("plaza");
  AddBox(&mesh, {-3, -3, 0}, {3, 3, 15}, tower);
  AddHorizontalRect(&mesh, -20, 20, -20, 20, 0, true, plaza);
  SceneModel scene;
  scene.grid_options.spacing_m = 1.0;
  scene.grid_options.block_spacing_m["plaza"] = 4.0;
  scene.hemisphere.directions = 16;
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, scene.grid_options);
  AlbedoResult& a = scene.albedo;
  for (const GridPoint& p : grid.points) {
    a.rho_sun.push_back(ExportTestAlbedo(p));
    a.rho_se.push_back(0.9 * ExportTestAlbedo(p));
  }
  a.observations.assign(grid.size(), 3);
  a.flags.assign(grid.size(), 0);
  a.retro = {0.4, 0.0};
  a.sun_lobes.resize(2);
  a.sun_lobes[tower].rho_s = Eigen::Vector3d(0.03, 0.04, 0.05);
  a.sun_lobes[tower].kappa = 0.9;
  a.sun_lobes[tower].n = 25;
  scene.slots.push_back(ExportTestSlot());
  scene.model_file = "model.obj";
  SceneView view;
  view.slot = 0;
  view.target = "architecture";
  view.utc = scene.slots[0].utc;
  view.intrinsics = Intrinsics::PinholeFov(160, 120, 60);
  view.pose = Pose::LookAt({30, -30, 10}, {0, 0, 6});
  scene.views["slot0/architecture/view0"] = view;
  std::filesystem::create_directories(dir);
  WriteScene(dir, scene, &mesh);
}

// A GLB split into its JSON and binary chunks; `error` says what is wrong with the container
// (empty when it is whole): the header's magic, version and length, the chunks' types, lengths
// and 4-byte alignment.
struct ParsedGlb {
  std::string error;
  nlohmann::json json;
  std::string bin;
  // The bytes of bufferView `view`.
  std::string View(int view) const {
    const nlohmann::json& v = json.at("bufferViews").at(view);
    return bin.substr(v.value("byteOffset", size_t{0}), v.at("byteLength").get<size_t>());
  }
};
inline ParsedGlb ReadGlb(const std::string& glb) {
  ParsedGlb r;
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    std::memcpy(&v, glb.data() + at, 4);  // little-endian machines only (x86, arm64)
    return v;
  };
  if (glb.size() < 28 || glb.compare(0, 4, "glTF") != 0) return {"no glTF magic", {}, {}};
  if (u32(4) != 2) return {"version " + std::to_string(u32(4)), {}, {}};
  if (u32(8) != glb.size()) return {"header length differs from the file's", {}, {}};
  const uint32_t json_len = u32(12);
  if (glb.compare(16, 4, "JSON") != 0 || json_len % 4 != 0 || 20 + json_len + 8 > glb.size())
    return {"bad JSON chunk", {}, {}};
  try {
    r.json = nlohmann::json::parse(glb.substr(20, json_len));
  } catch (const nlohmann::json::exception& e) {
    return {std::string("JSON chunk: ") + e.what(), {}, {}};
  }
  const size_t bin_at = 20 + json_len;
  const uint32_t bin_len = u32(bin_at);
  if (glb.compare(bin_at + 4, 4, std::string("BIN\0", 4)) != 0 || bin_len % 4 != 0 ||
      bin_at + 8 + bin_len != glb.size())
    return {"bad BIN chunk", {}, {}};
  r.bin = glb.substr(bin_at + 8, bin_len);
  return r;
}

}  // namespace rouen::testing
