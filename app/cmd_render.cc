// rouen render: a solved scene's building under the lighting of one of its times of day, or
// under lighting predicted for another time (§5-6): interpolated sky, sunset, overcast.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <utility>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "app/render_options.h"
#include "core/error.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/outputs.h"
#include "core/time.h"
#include "pipeline/export.h"
#include "pipeline/scene.h"
#include "pipeline/timelapse.h"
#include "render/tonemap.h"

namespace rouen {
namespace {

struct RenderArgs {
  std::string scene, out, png;
  int slot = 0;
  bool have_slot = false;
  std::string time, from, to, step;
  CameraArgs camera;
  PredictionArgs prediction;
  std::vector<double> overcast_colour;
  double overcast_brightness = 1;
  double exposure = 0;
};

// The longest sequence --from/--to/--step renders (a day at one frame a minute is 1440).
constexpr int kMaxSequenceFrames = 5000;

void Run(const RenderArgs& a) {
  namespace fs = std::filesystem;
  // Arguments first (CLI11 has checked each option's range and the options that exclude
  // each other), then the outputs, then the camera files and the scene: every mistake is told
  // before any work.
  const bool sequence = !a.from.empty();
  if (sequence && (a.to.empty() || a.step.empty()))
    throw Error("--from needs --to and --step (e.g. --step 15min)");
  if (static_cast<int>(a.have_slot) + static_cast<int>(!a.time.empty()) +
          static_cast<int>(sequence) !=
      1)
    throw Error(
        "give exactly one of --slot (a captured time of day), --time (any other) or "
        "--from/--to/--step (a sequence)");
  if (!a.overcast_colour.empty() && a.overcast_colour.size() != 3)
    throw Error("--overcast-colour takes three numbers R,G,B");
  RenderRequest request;
  if (a.have_slot) request.slot = a.slot;
  if (!a.time.empty()) request.time = ParseTimeOption(a.time, "--time");
  std::vector<UtcTime> times;
  if (sequence) {
    const UtcTime from = ParseTimeOption(a.from, "--from"), to = ParseTimeOption(a.to, "--to");
    if (to < from) throw Error("--to " + a.to + " is before --from " + a.from);
    const double step = ParseDurationSeconds(a.step, 86400, "--step");
    const double span = to.UnixSeconds() - from.UnixSeconds();
    if (span / step + 1 > kMaxSequenceFrames)
      throw Error("--from/--to/--step make " +
                  std::to_string(static_cast<int64_t>(span / step) + 1) + " frames, more than " +
                  std::to_string(kMaxSequenceFrames) + "; take a longer --step");
    for (double t = 0; t <= span + 1e-6; t += step) times.push_back(from.PlusSeconds(t));
  }
  ApplyPrediction(a.prediction, &request.relight);
  if (!a.overcast_colour.empty())
    request.relight.overcast_colour =
        Eigen::Vector3d(a.overcast_colour[0], a.overcast_colour[1], a.overcast_colour[2]);
  request.relight.overcast_brightness = a.overcast_brightness;
  request.use_held_out_lighting = a.prediction.use_held_out;
  const bool own_camera = CameraFromArgs(a.camera, &request.intrinsics, &request.pose);

  // Outputs: one image (and PNG), or folders of frames named by their times (declared once
  // the scene has accepted every time, so a refused sequence creates no folder).
  OutputSet outputs;
  std::vector<std::string> out_files, png_files;
  if (!sequence) {
    out_files.push_back(outputs.Add("--out", a.out, OutputKind::kRadiance));
    if (!a.png.empty()) png_files.push_back(outputs.Add("--png", a.png, OutputKind::kImage));
  } else {
    CheckWritableFolder("--out", a.out);
    if (!a.png.empty()) CheckWritableFolder("--png", a.png);
  }
  auto say = [](const std::string& s) { std::fprintf(stderr, "render: %s\n", s.c_str()); };

  const LoadedScene scene = LoadScene(a.scene, say);
  if (!own_camera) {
    const SceneView& view = FindView(scene, a.camera.view);
    request.intrinsics = view.intrinsics;
    request.pose = view.pose;
  }
  std::vector<RenderRequest> requests;
  if (!sequence) requests.push_back(request);
  for (UtcTime t : times) {
    RenderRequest r = request;
    r.time = t;
    requests.push_back(r);
  }
  for (const RenderRequest& r : requests) {
    try {
      CheckRenderRequest(scene, r);
    } catch (const Error& e) {
      if (!sequence) throw;
      throw Error("--from/--to: at " + r.time->Iso8601(0) + ": " + e.what());
    }
  }
  // PNGs go through the recovered response, or (photos that were HDR: no response) through
  // the sRGB encoding.
  const ResponseCurve& response = scene.scene.response;
  if (sequence) {
    fs::create_directories(a.out);
    if (!a.png.empty()) fs::create_directories(a.png);
    for (UtcTime t : times) {
      out_files.push_back(outputs.Add("--out",
                                      (fs::path(a.out) / (SequenceFrameName(t) + ".exr")).string(),
                                      OutputKind::kRadiance));
      if (!a.png.empty())
        png_files.push_back(
            outputs.Add("--png", (fs::path(a.png) / (SequenceFrameName(t) + ".png")).string(),
                        OutputKind::kImage));
    }
  }
  // One exposure for every frame of a sequence (so that it darkens towards sunset): --exposure,
  // else the first frame's automatic one.
  double exposure = a.exposure;
  Image image;
  for (size_t i = 0; i < requests.size(); ++i) {
    if (sequence)
      std::fprintf(stderr, "render: %zu/%zu %s\n", i + 1, requests.size(),
                   requests[i].time->Iso8601(0).c_str());
    RenderedView view = RenderSceneView(scene, requests[i],
                                        sequence ? std::function<void(const std::string&)>{}
                                                 : std::function<void(const std::string&)>(say));
    WriteImage(out_files[i], view.rgba, StoredType::kFloat, view.attributes);
    image = std::move(view.rgb);
    if (!a.png.empty()) {
      if (exposure <= 0)
        exposure = response.valid() ? AutoExposure(image, response) : AutoExposureSrgb(image);
      WriteImage(
          png_files[i],
          response.valid() ? ToDigital(image, response, exposure) : ToSrgbDigital(image, exposure),
          StoredType::kUint8);
    }
  }
  outputs.Commit();
  if (sequence)
    std::printf("%s: %zu frames %dx%d, %s to %s\n", a.out.c_str(), requests.size(), image.width,
                image.height, times.front().Iso8601(0).c_str(), times.back().Iso8601(0).c_str());
  else
    std::printf("%s: radiance %dx%d\n", a.out.c_str(), image.width, image.height);
  if (!a.png.empty())
    std::printf("%s: through %s, exposure factor %.4g\n", a.png.c_str(),
                response.valid() ? "the recovered response"
                                 : "the sRGB encoding (the scene has no response curve: its "
                                   "photos were HDR)",
                exposure);
}

}  // namespace

void RegisterRender(CLI::App& app) {
  auto a = std::make_shared<RenderArgs>();
  CLI::App* c = app.add_subcommand("render", CommandSummary("render"));
  c->footer(
      "Renders the building's radiance from a scene (written once by `rouen solve`; render never\n"
      "solves) with the recovered pseudo-albedos under the chosen lighting:\n"
      "  --slot N     the lighting measured at the session's N-th time of day;\n"
      "  --time ISO   lighting predicted for another time (paper §5): the sun's position from the\n"
      "               site and time, its radiance from the session's sun measurements against air\n"
      "               mass (sunrise/sunset reddening), the sky interpolated between the measured\n"
      "               skies by sun position, the environment from its recovered normals and\n"
      "               albedos; --pbs blocks that fraction of the sunlight and blends towards an\n"
      "               overcast sky (paper §6.3). Slots the scene holds out (rouen solve\n"
      "               --holdout-slot) are left out of the prediction unless --use-held-out.\n"
      "  --from ISO --to ISO --step 15min   a sequence under predicted lighting, one EXR per time\n"
      "               in the --out folder (and PNGs in the --png folder, all at one exposure:\n"
      "               --exposure, else the first frame's), named by the time (20260825T194000Z).\n"
      "The camera is one of the scene's views (--view, the names `rouen solve` lists), a lens\n"
      "file and a pose file (as `rouen calib intrinsics` and `rouen calib pose` write them), or\n"
      "a new pinhole camera at --from-point looking at --look-at (ENU metres, the model's frame)\n"
      "with --fov and --size.\n"
      "The radiance file is RGBA: alpha is the fraction of each pixel's rays that hit the\n"
      "building (1 on it, 0 where every ray escapes; the colours keep the sky, environment and\n"
      "sun there). Its header (EXR) holds rouen:time (ISO 8601 UTC), rouen:lighting and\n"
      "rouen:slot (the slot or 'predicted'), rouen:sun_azimuth_deg (from north through east) and\n"
      "rouen:sun_elevation_deg, rouen:camera (JSON: intrinsics and pose as the lens and pose\n"
      "files hold them) and rouen:site.\n"
      "Example: rouen render s.scene --time 2026-08-25T19:40:00-07:00 --out sunset.exr "
      "--png sunset.png\n"
      "         rouen render s.scene --from 2026-08-25T08:00:00-07:00 --to "
      "2026-08-25T19:00:00-07:00"
      " \\\n           --step 30min --look-at 0,0,10 --from-point 40,-30,5 --out day/ --png day/");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  CLI::Option* slot = c->add_option("--slot", a->slot,
                                    "Render under the lighting of this captured slot (0, 1, ...)")
                          ->check(Within(0, INFINITY));
  c->add_option("--time", a->time,
                "Render at this time (ISO 8601 with offset, e.g. 2026-08-25T19:40:00-07:00)");
  c->add_option("--from", a->from, "Render a sequence from this time (with --to and --step)");
  c->add_option("--to", a->to, "Last time of the sequence (ISO 8601)");
  c->add_option("--step", a->step, "Time between frames of the sequence (e.g. 15min, 1h, 30s)");
  AddCameraOptions(c, &a->camera);
  AddPredictionOptions(c, &a->prediction, kUseHeldOutOption | kSkyInterpOption | kPbsOption, slot);
  c->add_option("--overcast-colour", a->overcast_colour, "Overcast sky colour R,G,B (relative)")
      ->delimiter(',')
      ->check(Positive())
      ->excludes(slot);
  c->add_option("--overcast-brightness", a->overcast_brightness,
                "Overcast sky's horizontal irradiance as a multiple of the clear sky's")
      ->check(Positive())
      ->excludes(slot)
      ->capture_default_str();
  c->add_option("--out", a->out,
                "Radiance to write (.exr, or .hdr, .pfm, .tif); with --from a folder of EXRs")
      ->required();
  CLI::Option* png = c->add_option(
      "--png", a->png,
      "Also write an 8-bit PNG through the recovered response (sRGB when the photos were HDR); "
      "with --from a folder of PNGs");
  c->add_option("--exposure", a->exposure, "Exposure factor for --png (default: automatic)")
      ->check(Positive())
      ->needs(png);
  c->callback([a, slot] {
    a->have_slot = slot->count() > 0;
    Run(*a);
  });
}

}  // namespace rouen
