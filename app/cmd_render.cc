// rouen render: the building of a session under the lighting of one of its times of day, or
// under lighting predicted for another time (§5-6): interpolated sky, sunset, overcast.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "app/commands.h"
#include "app/options.h"
#include "app/pipeline.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/outputs.h"
#include "core/solar.h"
#include "core/time.h"
#include "render/render.h"
#include "render/tonemap.h"
#include "solve/relight.h"

namespace rouen {
namespace {

struct RenderArgs {
  std::string session, work, out, png;
  int slot = 0;
  bool have_slot = false;
  std::string time;
  std::string view;
  std::string lens, pose;
  double pbs = 0;
  std::vector<double> overcast_colour;
  double overcast_brightness = 1;
  double exposure = 0;
  bool quick = false;
};

void Run(const RenderArgs& a) {
  namespace fs = std::filesystem;
  // Arguments first (CLI11 has checked each option's range and the options that exclude
  // each other), then the outputs and the working folder, then the inputs: every mistake is
  // told before minutes of solving.
  if (a.have_slot == !a.time.empty())
    throw Error("give exactly one of --slot (a captured time of day) or --time (any other)");
  if (!a.lens.empty() != !a.pose.empty()) throw Error("--lens and --pose go together");
  if (!a.view.empty() && !a.lens.empty()) throw Error("give --view or --lens/--pose, not both");
  if (!a.overcast_colour.empty() && a.overcast_colour.size() != 3)
    throw Error("--overcast-colour takes three numbers R,G,B");
  UtcTime when;
  if (!a.time.empty()) {
    try {
      when = ParseIso8601(a.time);
    } catch (const Error& e) {
      throw Error(std::string("--time: ") + e.what());
    }
  }
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kRadiance);
  const std::string png = a.png.empty() ? "" : outputs.Add("--png", a.png, OutputKind::kImage);
  fs::path session_dir = fs::path(a.session).lexically_normal();
  if (!session_dir.has_filename()) session_dir = session_dir.parent_path();  // "s/" -> "s"
  const fs::path work =
      a.work.empty() ? fs::path(session_dir.string() + ".work") : fs::path(a.work);
  CheckWritableFolder(a.work.empty() ? "the working folder" : "--work", work.string());
  auto say = [](const std::string& s) { std::fprintf(stderr, "render: %s\n", s.c_str()); };

  Session session = Session::Load(a.session);
  const Site site = SessionSite(session);
  if (!a.time.empty()) {
    const SunPosition sun = ComputeSunPosition(when, site);
    if (!(sun.elevation_deg > 0))
      throw Error("--time " + a.time + ": the sun is below the horizon there (elevation " +
                  std::to_string(sun.elevation_deg) + " deg); rouen renders daylight only");
  }
  // The model and a camera from files are read before the long solve, so a bad file fails at
  // once (SolveSession reads the model again).
  ReadSessionModel(session);
  Intrinsics intrinsics;
  Pose pose;
  if (!a.lens.empty()) {
    intrinsics = ReadLensFile(a.lens).intrinsics;
    pose = ReadPose(a.pose);
  }
  PipelineOptions po;
  po.work_dir = work;
  po.quick = a.quick;
  po.log = say;
  CalibResult calib = CalibrateSession(session, po);
  SolveResult solved = SolveSession(session, calib, po);

  // Otherwise the camera of a view of the session.
  if (a.lens.empty()) {
    std::string name = a.view;
    if (name.empty()) {
      for (const auto& [n, g] : calib.groups)
        if (g.target == Target::kArchitecture) {
          name = n;
          break;
        }
    }
    auto it = calib.groups.find(name);
    if (it == calib.groups.end())
      throw Error(a.session + ": no bracket named '" + name +
                  "' (views are named like slot0/architecture/view0)");
    intrinsics = it->second.intrinsics;
    pose = it->second.pose;
  }

  Lighting lighting;
  SlotIrradiance irr;
  if (a.have_slot) {
    if (a.slot >= static_cast<int>(solved.slots.size()))
      throw Error(a.session + ": slot " + std::to_string(a.slot) +
                  " does not exist (the session has " + std::to_string(solved.slots.size()) + ")");
    lighting = solved.slots[a.slot].lighting;
    irr = solved.irradiance.at(a.slot);
  } else {
    RelightOptions ro;
    ro.pbs = a.pbs;
    if (!a.overcast_colour.empty())
      ro.overcast_colour =
          Eigen::Vector3d(a.overcast_colour[0], a.overcast_colour[1], a.overcast_colour[2]);
    ro.overcast_brightness = a.overcast_brightness;
    std::vector<Lighting> measured;
    for (const SlotSolve& ss : solved.slots) measured.push_back(ss.lighting);
    say("fitting the sun's extinction, the sky interpolation and the environment's normals");
    LightingPredictor predictor(std::move(measured), ro);
    say(predictor.environment().summary.BriefReport());
    RelightSummary rs;
    lighting = predictor.At(when, site, &rs);
    say(rs.Describe());
    irr = IrradianceFor(solved, lighting);
  }
  say("rendering " + std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height));
  Image image = RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo, lighting, irr,
                           intrinsics, pose, RenderOptions{});
  WriteImage(out, image, StoredType::kFloat);
  double exposure = 0;
  if (!a.png.empty()) {
    exposure = a.exposure > 0 ? a.exposure : AutoExposure(image, calib.response);
    WriteImage(png, ToDigital(image, calib.response, exposure), StoredType::kUint8);
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
      "render", "Render a session's building at a captured time of day or at any other time");
  c->footer(
      "Calibrates and solves the session (files in --work), then renders the building's radiance\n"
      "from the recovered pseudo-albedos under the chosen lighting:\n"
      "  --slot N     the lighting measured at the session's N-th time of day;\n"
      "  --time ISO   lighting predicted for another time (paper §5): the sun's position from the\n"
      "               site and time, its radiance from the session's sun measurements against air\n"
      "               mass (sunrise/sunset reddening), the sky interpolated between the measured\n"
      "               skies by sun position, the environment from its recovered normals and\n"
      "               albedos; --pbs blocks that fraction of the sunlight and blends towards an\n"
      "               overcast sky (paper §6.3).\n"
      "Example: rouen render --session s --time 2026-08-25T19:40:00-07:00 --out sunset.exr "
      "--png sunset.png");
  c->add_option("--session", a->session, "Session folder")->required();
  c->add_option("--work", a->work, "Working folder (default: SESSION.work)");
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
  c->add_flag("--quick", a->quick, "Fewer samples (faster, rougher)");
  c->callback([a, slot] {
    a->have_slot = slot->count() > 0;
    Run(*a);
  });
}

}  // namespace rouen
