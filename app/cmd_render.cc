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
#include "core/session.h"
#include "core/time.h"
#include "pipeline/export.h"
#include "pipeline/scene.h"
#include "pipeline/texture_render.h"
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
  // --texture-from (§6.4): the photograph, its session, the grid render beside it, a photo to
  // score both against.
  std::string texture_from, session, grid_out, grid_png, compare;
  PhotoTextureOptions texture;
};

// The longest sequence --from/--to/--step renders (a day at one frame a minute is 1440).
constexpr int kMaxSequenceFrames = 5000;

// The PNG of a radiance image: through the scene's response, else the sRGB encoding.
void WritePng(const std::string& path, const Image& image, const ResponseCurve& response,
              double exposure) {
  WriteImage(
      path,
      response.valid() ? ToDigital(image, response, exposure) : ToSrgbDigital(image, exposure),
      StoredType::kUint8);
}

void PrintMetrics(const std::string& what, const RenderMetrics& m) {
  std::printf("  %-22s PSNR %6.2f dB, relative RMSE %.4f, median relative error %.4f (%lld px)\n",
              what.c_str(), m.psnr_db, m.rel_rmse, m.median_rel_error,
              static_cast<long long>(m.pixels));
}

// rouen render --texture-from: one image from the photograph's camera (arguments checked).
void RunTextured(const RenderArgs& a, const RenderRequest& request) {
  OutputSet outputs;
  outputs.Protect("the scene", a.scene);
  outputs.Protect("--session", a.session);
  const std::string out = outputs.Add("--out", a.out, OutputKind::kRadiance);
  const std::string png = a.png.empty() ? "" : outputs.Add("--png", a.png, OutputKind::kImage);
  const std::string grid_out =
      a.grid_out.empty() ? "" : outputs.Add("--grid-out", a.grid_out, OutputKind::kRadiance);
  const std::string grid_png =
      a.grid_png.empty() ? "" : outputs.Add("--grid-png", a.grid_png, OutputKind::kImage);
  auto say = [](const std::string& s) { std::fprintf(stderr, "render: %s\n", s.c_str()); };
  const Session session = Session::Load(a.session);
  const LoadedScene scene = LoadScene(a.scene, say);
  TextureRenderRequest tr;
  tr.photo = a.texture_from;
  tr.lighting = request;
  tr.options = a.texture;
  tr.compare = a.compare;
  const TextureRender r = RenderSceneWithPhotoTexture(scene, session, tr, say);
  WriteImage(out, r.textured.rgba, StoredType::kFloat, r.textured.attributes);
  if (!grid_out.empty()) WriteImage(grid_out, r.grid.rgba, StoredType::kFloat, r.grid.attributes);
  // One exposure for both PNGs (--exposure, else the textured render's), so they compare.
  const ResponseCurve& response = scene.scene.response;
  double exposure = a.exposure;
  if (exposure <= 0 && !(png.empty() && grid_png.empty()))
    exposure = response.valid() ? AutoExposure(r.textured.rgb, response)
                                : AutoExposureSrgb(r.textured.rgb);
  if (!png.empty()) WritePng(png, r.textured.rgb, response, exposure);
  if (!grid_png.empty()) WritePng(grid_png, r.grid.rgb, response, exposure);
  outputs.Commit();
  std::printf(
      "%s: radiance %dx%d from %s's viewpoint, per-pixel albedo (§6.4) on %lld of %lld "
      "building pixels\n",
      a.out.c_str(), r.textured.rgb.width, r.textured.rgb.height, a.texture_from.c_str(),
      static_cast<long long>(r.textured_pixels), static_cast<long long>(r.building_pixels));
  if (!grid_out.empty())
    std::printf("%s: the grid-resolution render under the same lighting\n", a.grid_out.c_str());
  if (!png.empty() || !grid_png.empty())
    std::printf("PNGs through %s, exposure factor %.4g\n",
                response.valid() ? "the recovered response" : "the sRGB encoding", exposure);
  if (r.textured_metrics) {
    std::printf("against %s (building pixels, eroded 1 px):\n", a.compare.c_str());
    PrintMetrics("texture render", *r.textured_metrics);
    PrintMetrics("grid render", *r.grid_metrics);
  }
}

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
  if (a.exposure > 0 && a.png.empty() && a.grid_png.empty())
    throw Error("--exposure is the PNGs' exposure: it needs --png or --grid-png");
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
    CheckFrameCount(span / step + 1, kMaxSequenceFrames);
    for (double t = 0; t <= span + 1e-6; t += step) times.push_back(from.PlusSeconds(t));
  }
  ApplyPrediction(a.prediction, &request.relight);
  if (!a.overcast_colour.empty())
    request.relight.overcast_colour =
        Eigen::Vector3d(a.overcast_colour[0], a.overcast_colour[1], a.overcast_colour[2]);
  request.relight.overcast_brightness = a.overcast_brightness;
  request.use_held_out_lighting = a.prediction.use_held_out;
  const bool own_camera = CameraFromArgs(a.camera, &request.intrinsics, &request.pose);
  if (!a.texture_from.empty()) {
    if (sequence) throw Error("--texture-from renders one image: give --slot or --time");
    if (own_camera || !a.camera.view.empty())
      throw Error(
          "--texture-from renders from the photograph's camera: drop --view, --lens/--pose "
          "and --look-at");
    if (a.session.empty())
      throw Error("--texture-from " + a.texture_from +
                  " needs --session, the session the photograph belongs to");
    RunTextured(a, request);
    return;
  }

  // Outputs: one image (and PNG), or folders of frames named by their times (declared once
  // the scene has accepted every time, so a refused sequence creates no folder).
  OutputSet outputs;
  outputs.Protect("the scene", a.scene);
  outputs.Protect("--session", a.session);
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
    outputs.CreateFolder("--out", a.out);
    if (!a.png.empty()) outputs.CreateFolder("--png", a.png);
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
      "--texture-from PHOTO --session S (paper §6.4, eq. 19): the grid holds one albedo per grid\n"
      "point, so a close view is blurred; a photograph of the session (a view of the scene,\n"
      "e.g. slot0/architecture/view1) gives each building pixel its own. Its texture factor\n"
      "t = rho / rho~ = (I - S) / D, per pixel and channel, with I the photograph merged to\n"
      "radiance and D, S the diffuse and specular parts of the grid render under the lighting\n"
      "measured at the photograph's slot; the image is t D' + S' from the photograph's\n"
      "viewpoint under the --slot or --time lighting (D', S' its grid render): the photograph\n"
      "itself at its own slot. Pixels off the building, unexposed in the photograph, or where\n"
      "t exceeds --texture-max-gain or D is below --texture-min-diffuse of its median keep the\n"
      "grid render. --grid-out/--grid-png write that grid render beside it; --compare PHOTO2\n"
      "scores both against another photograph through the same camera (e.g. the same view at\n"
      "a held-out slot).\n"
      "Example: rouen render s.scene --time 2026-08-25T19:40:00-07:00 --out sunset.exr "
      "--png sunset.png\n"
      "         rouen render s.scene --from 2026-08-25T08:00:00-07:00 --to "
      "2026-08-25T19:00:00-07:00"
      " \\\n           --step 30min --look-at 0,0,10 --from-point 40,-30,5 --out day/ --png day/\n"
      "         rouen render s.scene --slot 3 --texture-from slot0/architecture/view1 --session s "
      "\\\n           --out tex.exr --png tex.png --grid-png grid.png "
      "--compare slot3/architecture/view1");
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
  c->add_option(
      "--png", a->png,
      "Also write an 8-bit PNG through the recovered response (sRGB when the photos were HDR); "
      "with --from a folder of PNGs");
  c->add_option("--exposure", a->exposure,
                "Exposure factor for --png and --grid-png (default: automatic)")
      ->check(Positive());
  CLI::Option* texture =
      c->add_option("--texture-from", a->texture_from,
                    "Per-pixel albedo from this photograph of --session (a view, e.g. "
                    "slot0/architecture/view1), rendered from its viewpoint (paper §6.4)");
  c->add_option("--session", a->session, "The session the --texture-from photograph belongs to")
      ->needs(texture);
  c->add_option("--grid-out", a->grid_out,
                "With --texture-from: also the grid-resolution render (radiance) for comparison")
      ->needs(texture);
  c->add_option("--grid-png", a->grid_png,
                "With --texture-from: the grid-resolution render as a PNG at --png's exposure")
      ->needs(texture);
  c->add_option("--compare", a->compare,
                "With --texture-from: score both renders against this photograph of the session "
                "(same camera, e.g. the view at a held-out slot)")
      ->needs(texture);
  c->add_option("--texture-max-gain", a->texture.max_texture_gain,
                "With --texture-from: pixels whose albedo would exceed the grid's by this factor "
                "keep the grid render (the photo and the model disagree there)")
      ->check(Positive())
      ->needs(texture)
      ->capture_default_str();
  c->add_option("--texture-min-diffuse", a->texture.min_diffuse_fraction,
                "With --texture-from: pixels whose grid render under the photo's lighting is "
                "below this fraction of its median keep the grid render")
      ->check(Within(0, 0.99))
      ->needs(texture)
      ->capture_default_str();
  c->callback([a, slot] {
    a->have_slot = slot->count() > 0;
    Run(*a);
  });
}

}  // namespace rouen
