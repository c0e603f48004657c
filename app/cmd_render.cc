// rouen render: a solved scene's building under the lighting of one of its times of day, or
// under lighting predicted for another time (§5-6): interpolated sky, sunset, overcast.
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/outputs.h"
#include "core/time.h"
#include "pipeline/scene.h"
#include "render/tonemap.h"

namespace rouen {
namespace {

struct RenderArgs {
  std::string scene, out, png;
  int slot = 0;
  bool have_slot = false;
  std::string time;
  std::string view;
  std::string lens, pose;
  double pbs = 0;
  std::vector<double> overcast_colour;
  double overcast_brightness = 1;
  double exposure = 0;
};

void Run(const RenderArgs& a) {
  // Arguments first (CLI11 has checked each option's range and the options that exclude
  // each other), then the outputs, then the camera files and the scene: every mistake is told
  // before any work.
  if (a.have_slot == !a.time.empty())
    throw Error("give exactly one of --slot (a captured time of day) or --time (any other)");
  if (!a.lens.empty() != !a.pose.empty()) throw Error("--lens and --pose go together");
  if (!a.view.empty() && !a.lens.empty()) throw Error("give --view or --lens/--pose, not both");
  if (!a.overcast_colour.empty() && a.overcast_colour.size() != 3)
    throw Error("--overcast-colour takes three numbers R,G,B");
  RenderRequest request;
  if (a.have_slot) request.slot = a.slot;
  if (!a.time.empty()) {
    try {
      request.time = ParseIso8601(a.time);
    } catch (const Error& e) {
      throw Error(std::string("--time: ") + e.what());
    }
  }
  request.relight.pbs = a.pbs;
  if (!a.overcast_colour.empty())
    request.relight.overcast_colour =
        Eigen::Vector3d(a.overcast_colour[0], a.overcast_colour[1], a.overcast_colour[2]);
  request.relight.overcast_brightness = a.overcast_brightness;
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kRadiance);
  const std::string png = a.png.empty() ? "" : outputs.Add("--png", a.png, OutputKind::kImage);
  if (!a.lens.empty()) {
    request.intrinsics = ReadLensFile(a.lens).intrinsics;
    request.pose = ReadPoseFile(a.pose);
  }
  auto say = [](const std::string& s) { std::fprintf(stderr, "render: %s\n", s.c_str()); };

  const LoadedScene scene = LoadScene(a.scene, say);
  if (a.lens.empty()) {
    const SceneView& view = FindView(scene, a.view);
    request.intrinsics = view.intrinsics;
    request.pose = view.pose;
  }
  CheckRenderRequest(scene, request);
  const ResponseCurve& response = scene.scene.response;
  if (!a.png.empty() && !response.valid())
    throw Error(a.scene +
                ": the scene has no response curve (its photos were HDR), which --png "
                "needs; write the radiance only");
  const Image image = RenderScene(scene, request, say);
  WriteImage(out, image, StoredType::kFloat);
  double exposure = 0;
  if (!a.png.empty()) {
    exposure = a.exposure > 0 ? a.exposure : AutoExposure(image, response);
    WriteImage(png, ToDigital(image, response, exposure), StoredType::kUint8);
  }
  outputs.Commit();
  std::printf("%s: radiance %dx%d\n", a.out.c_str(), image.width, image.height);
  if (!a.png.empty())
    std::printf("%s: through the recovered response, exposure factor %.4g\n", a.png.c_str(),
                exposure);
}

}  // namespace

void RegisterRender(CLI::App& app) {
  auto a = std::make_shared<RenderArgs>();
  CLI::App* c = app.add_subcommand(
      "render", "Render a solved scene's building at a captured time of day or at any other time");
  c->footer(
      "Renders the building's radiance from a scene (written once by `rouen solve`; render never\n"
      "solves) with the recovered pseudo-albedos under the chosen lighting:\n"
      "  --slot N     the lighting measured at the session's N-th time of day;\n"
      "  --time ISO   lighting predicted for another time (paper §5): the sun's position from the\n"
      "               site and time, its radiance from the session's sun measurements against air\n"
      "               mass (sunrise/sunset reddening), the sky interpolated between the measured\n"
      "               skies by sun position, the environment from its recovered normals and\n"
      "               albedos; --pbs blocks that fraction of the sunlight and blends towards an\n"
      "               overcast sky (paper §6.3).\n"
      "The camera is one of the scene's views (--view, the names `rouen solve` lists), or a lens\n"
      "file and a pose file (as `rouen calib intrinsics` and `rouen calib pose` write them).\n"
      "Example: rouen render s.scene --time 2026-08-25T19:40:00-07:00 --out sunset.exr "
      "--png sunset.png");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  CLI::Option* slot = c->add_option("--slot", a->slot,
                                    "Render under the lighting of this captured slot (0, 1, ...)")
                          ->check(Within(0, INFINITY));
  c->add_option("--time", a->time,
                "Render at this time (ISO 8601 with offset, e.g. 2026-08-25T19:40:00-07:00)");
  c->add_option("--view", a->view,
                "Camera of this bracket (e.g. slot0/architecture/view1; default: the first)");
  c->add_option("--lens", a->lens, "Camera intrinsics JSON (with --pose)");
  c->add_option("--pose", a->pose, "Camera pose JSON (with --lens)");
  // The predicted sky's options have no meaning for a captured slot's lighting.
  c->add_option("--pbs", a->pbs, "Blocked sunlight fraction 0..1 (0 clear, 1 overcast)")
      ->check(Within(0, 1))
      ->excludes(slot)
      ->capture_default_str();
  c->add_option("--overcast-colour", a->overcast_colour, "Overcast sky colour R,G,B (relative)")
      ->delimiter(',')
      ->check(Positive())
      ->excludes(slot);
  c->add_option("--overcast-brightness", a->overcast_brightness,
                "Overcast sky's horizontal irradiance as a multiple of the clear sky's")
      ->check(Positive())
      ->excludes(slot)
      ->capture_default_str();
  c->add_option("--out", a->out, "Radiance to write (.exr, or .hdr, .pfm, .tif)")->required();
  CLI::Option* png =
      c->add_option("--png", a->png, "Also write an 8-bit PNG through the recovered response");
  c->add_option("--exposure", a->exposure, "Exposure factor for --png (default: automatic)")
      ->check(Positive())
      ->needs(png);
  c->callback([a, slot] {
    a->have_slot = slot->count() > 0;
    Run(*a);
  });
}

}  // namespace rouen
