// rouen view: a solved scene as a static web page that relights the building in the browser.
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "core/error.h"
#include "pipeline/viewer.h"

namespace rouen {
namespace {

struct ViewArgs {
  std::string scene, out;
  ViewerOptions options;
};

void Run(const ViewArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  a.options.Validate();
  CheckViewerOutput(a.out);
  auto say = [](const std::string& s) { std::fprintf(stderr, "view: %s\n", s.c_str()); };
  const LoadedScene scene = LoadScene(a.scene, say);
  ProgressLine line(true);
  const ViewerSummary s = WriteViewer(scene, a.out, a.options, say, [&](int done, int total) {
    line.Update("view: lighting " + std::to_string(done) + "/" + std::to_string(total));
  });
  line.Done();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "%s/index.html: %d times, %lld triangles, atlas %dx%d, shadows %dx%d, %.1f MB (lighting "
      "%.1f s, baking %.1f s, %.1f s in all)\n",
      a.out.c_str(), s.times, static_cast<long long>(s.triangles), s.atlas_width, s.atlas_height,
      s.shadow_width, s.shadow_height, s.bytes / 1e6, s.seconds_lighting, s.seconds_baking,
      seconds);
}

}  // namespace

void RegisterView(CLI::App& app) {
  auto a = std::make_shared<ViewArgs>();
  CLI::App* c = app.add_subcommand("view", CommandSummary("view"));
  c->footer(
      "Writes the folder --out with index.html and viewer_data.js: open index.html in a browser\n"
      "(WebGL 2; no server, no network). The page shows the building lit by rouen's recovered\n"
      "sun, sky and environment, with sliders for the time of day (sunrise to sunset of the\n"
      "captured day), overcast (the blocked sunlight fraction, paper §6.3) and exposure; drag\n"
      "to orbit, wheel to zoom, shift-drag to pan. It starts from the scene's first\n"
      "architecture view.\n"
      "rouen computes, once, the lighting predicted for --times times evenly spaced from sunrise\n"
      "to sunset (the sun 1 deg high; as rouen render --time: held-out slots left out) and, for\n"
      "each, the sun's visibility and the sky + environment irradiance with its interreflection\n"
      "under the clear sky and under the fully overcast one; the page interpolates between the\n"
      "two nearest times and blends clear and overcast linearly (the irradiance is linear in the\n"
      "blocked fraction but for the refit of the blended sky). Per pixel it computes\n"
      "  L = (rho_sun E_sun D + rho_se E_se) / pi + f_s E_sun\n"
      "(as rouen render) with V, whether the sun reaches the point, ray-cast per texel of a finer\n"
      "atlas (--shadow-texels-per-cell), E_se from the grid; then exposure and the camera's\n"
      "recovered response (as rouen render --png; a checkbox, #response=0: the sRGB encoding).\n"
      "Textures are 8-bit PNGs (value = scale (stored/255)^2.2) in one atlas of all\n"
      "blocks; the size grows with --times and the texels per cell squared.\n"
      "The exposure is noon's for the whole day (so that sunset darkens), or each time's own\n"
      "(the checkbox): the 99th percentile of the building's radiance to 0.9 of white.\n"
      "The address can set the sliders: index.html#t=0.25&overcast=0.5&ev=1&auto=1&controls=0\n"
      "(t the fraction of the day from sunrise to sunset, overcast 0..1, ev in stops, auto the\n"
      "exposure of each time, no panel).\n"
      "page API (for scripts and tests): window.rouenViewer.setBase(i), setTime(unix s),\n"
      "setOvercast(0..1), setExposureEv(ev), setAutoExposure(bool), setCamera({eye, target,\n"
      "fov_x_deg}) in ENU metres, camera(), state(); .whenReady resolves once the textures are\n"
      "loaded.\n"
      "Example: rouen view s.scene --out s.view && xdg-open s.view/index.html");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  c->add_option("--out", a->out, "Folder to write (new, or an earlier rouen view folder)")
      ->required();
  c->add_option("--times", a->options.times, "Lighting bases from sunrise to sunset")
      ->check(Within(2, 96))
      ->capture_default_str();
  c->add_option("--texels-per-cell", a->options.texels_per_cell,
                "Atlas texels along a grid cell's edge (solve/atlas.h)")
      ->check(Within(1, 16))
      ->capture_default_str();
  c->add_option("--shadow-texels-per-cell", a->options.shadow_texels_per_cell,
                "Sun-visibility atlas texels along a grid cell's edge (ray-cast per texel)")
      ->check(Within(1, 16))
      ->capture_default_str();
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
