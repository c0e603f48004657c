// rouen export and rouen envmap: a solved scene for other tools -- the building as binary glTF
// with its albedos, the lighting of a time as a latitude-longitude EXR.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "app/render_options.h"
#include "core/error.h"
#include "core/files.h"
#include "core/outputs.h"
#include "pipeline/export.h"

namespace rouen {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void Say(const std::string& s, const char* command) {
  std::fprintf(stderr, "%s: %s\n", command, s.c_str());
}

struct ExportArgs {
  std::string scene, gltf;
  int texels_per_cell = 2;
};

void RunExport(const ExportArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  // Binary glTF: a .gltf name promises JSON, which other tools would fail to parse.
  if (LowerExtension(a.gltf) != ".glb")
    throw Error("--gltf " + a.gltf + ": rouen writes binary glTF; name it .glb");
  OutputSet outputs;
  outputs.Protect("the scene", a.scene);
  const std::string tmp = outputs.Add("--gltf", a.gltf, OutputKind::kFile);
  GltfOptions options;
  options.texels_per_cell = a.texels_per_cell;
  options.Validate();
  const LoadedScene scene = LoadScene(a.scene, [](const std::string& s) { Say(s, "export"); });
  const GltfSummary s = WriteSceneGltf(scene, tmp, options);
  outputs.Commit();
  std::printf(
      "%s: %d blocks (%d with albedo atlases), %lld triangles, %lld texels per albedo set, "
      "%.1f MB, %.2f s\n",
      a.gltf.c_str(), s.blocks, s.textured_blocks, static_cast<long long>(s.triangles),
      static_cast<long long>(s.texels), s.bytes / 1e6, SecondsSince(start));
  if (s.clipped_texels > 0)
    std::printf("%s: %lld texels had an albedo above 1 in some channel, stored as 1\n",
                a.gltf.c_str(), static_cast<long long>(s.clipped_texels));
}

struct EnvmapArgs {
  std::string scene, out, time;
  int slot = 0;
  bool have_slot = false, sky_model = false;
  int width = 1024;
  double height = NAN;
  PredictionArgs prediction;
};

void RunEnvmap(const EnvmapArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  if (a.have_slot == !a.time.empty())
    throw Error("give exactly one of --slot (a captured time of day) or --time (any other)");
  if (a.width % 2 != 0) throw Error("--width " + std::to_string(a.width) + ": must be even");
  RenderRequest request;
  if (a.have_slot) request.slot = a.slot;
  if (!a.time.empty()) request.time = ParseTimeOption(a.time, "--time");
  ApplyPrediction(a.prediction, &request.relight);
  request.use_held_out_lighting = a.prediction.use_held_out;
  LatLongOptions options;
  options.width = a.width;
  options.sky_model = a.sky_model;
  options.height_m = a.height;
  OutputSet outputs;
  outputs.Protect("the scene", a.scene);
  const std::string tmp = outputs.Add("--out", a.out, OutputKind::kRadiance);
  auto say = [](const std::string& s) { Say(s, "envmap"); };
  const LoadedScene scene = LoadScene(a.scene, say);
  const SceneEnvmap env = SceneEnvmapFor(scene, request, options, say);
  WriteImage(tmp, env.map, StoredType::kFloat, env.attributes);
  outputs.Commit();
  std::printf("%s: %dx%d latitude-longitude radiance, %.2f s\n", a.out.c_str(), env.map.width,
              env.map.height, SecondsSince(start));
  const Eigen::Vector3d& m = env.horizontal_from_map;
  const Eigen::Vector3d& r = env.horizontal_rouen;
  std::printf(
      "horizontal irradiance (R G B): from the map %.5g %.5g %.5g, rouen's %.5g %.5g %.5g\n", m[0],
      m[1], m[2], r[0], r[1], r[2]);
}

}  // namespace

void RegisterExport(CLI::App& app) {
  auto a = std::make_shared<ExportArgs>();
  CLI::App* c = app.add_subcommand("export", CommandSummary("export"));
  c->footer(
      "Writes the scene's model (one node, mesh and material per block) as one binary glTF 2.0\n"
      "file, its textures inside it:\n"
      "  baseColorTexture          the block's sun albedo atlas (solve's atlas/ layout), an 8-bit\n"
      "                            PNG: the linear albedo clamped to 0..1 through the sRGB\n"
      "                            transfer function, as glTF defines base colour;\n"
      "  extras.rouen              albedo_sky_env_texture (the sky + environment albedo, encoded\n"
      "                            the same way), retro (the block's sun reflection, scene.json\n"
      "                            albedo.retro; 0 is Lambert).\n"
      "Coordinates: glTF is y-up, so ENU metres (x east, y north, z up) are written as glTF\n"
      "(x, y, z) = (east, up, -north); Blender's importer turns them back into x east, y north,\n"
      "z up. The file is written whole or not at all.\n"
      "Example: rouen export s.scene --gltf building.glb");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  c->add_option("--gltf", a->gltf, "Binary glTF file to write (.glb)")->required();
  c->add_option("--texels-per-cell", a->texels_per_cell,
                "Atlas texels along a grid cell's edge (solve/atlas.h)")
      ->check(Within(1, 64))
      ->capture_default_str();
  c->callback([a] { RunExport(*a); });
}

void RegisterEnvmap(CLI::App& app) {
  auto a = std::make_shared<EnvmapArgs>();
  CLI::App* c = app.add_subcommand("envmap", CommandSummary("envmap"));
  c->footer(
      "Writes the lighting rouen renders with -- a captured slot's measured lighting (--slot) or\n"
      "the lighting predicted for any daylight time (--time, as rouen render --time) -- as an\n"
      "equirectangular float EXR (width x width/2) for another renderer to light with:\n"
      "  every pixel the mean radiance over its solid angle of the environment's regions (what\n"
      "  rouen's irradiance integrates; --sky-model: the smooth sky model above the horizon);\n"
      "  the sun a disc of its measured solid angle and radiance spread over the pixels it\n"
      "  covers, so that its irradiance is kept.\n"
      "Orientation: Blender's Environment Texture (equirectangular), with the scene's ENU frame\n"
      "as Blender's world (x east, y north, z up): a direction (x, y, z) is at\n"
      "  u = 0.5 - atan2(y, x) / 2pi (from the left edge), v = 0.5 + atan2(z, hypot(x, y)) / pi\n"
      "  (from the bottom edge): north at a quarter of the width, east at the centre, south at\n"
      "  three quarters, west at the edges, the zenith along the top row.\n"
      "The header holds the time (rouen:time, UTC), the sun's azimuth and elevation and this\n"
      "orientation. Printed: the map's horizontal irradiance beside rouen's.\n"
      "Example: rouen envmap s.scene --time 2026-08-25T19:40:00-07:00 --out sky.exr");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  CLI::Option* slot =
      c->add_option("--slot", a->slot, "The lighting measured at this captured slot (0, 1, ...)")
          ->check(Within(0, INFINITY));
  c->add_option("--time", a->time,
                "The lighting predicted for this time (ISO 8601 with offset, e.g. "
                "2026-08-25T19:40:00-07:00)");
  c->add_option("--out", a->out, "Float EXR to write (.exr)")->required();
  c->add_option("--width", a->width, "Map width in pixels (even; the height is half of it)")
      ->check(Within(8, 16384))
      ->capture_default_str();
  c->add_flag("--sky-model", a->sky_model,
              "Above the horizon, the sky model (smooth) instead of the environment's regions");
  c->add_option("--height", a->height,
                "Height (ENU metres) the environment is seen from, between its layers (default: "
                "the lowest panorama's)")
      ->check(Within(-1e4, 1e4, "m"));
  AddPredictionOptions(c, &a->prediction, kUseHeldOutOption | kSkyInterpOption | kPbsOption, slot);
  c->callback([a, slot] {
    a->have_slot = slot->count() > 0;
    RunEnvmap(*a);
  });
}

}  // namespace rouen
