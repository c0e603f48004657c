// rouen demo: the whole pipeline on the built-in simulated world. Captures a field session
// through the real capture controller, calibrates, solves, renders the held-out time and
// scores everything against the simulator's ground truth.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/progress.h"
#include "app/stop_signal.h"
#include "core/error.h"
#include "pipeline/capture_session.h"
#include "pipeline/demo.h"

namespace rouen {
namespace {

void Run(DemoOptions options) {
  options.log = [](const std::string& s) { std::fprintf(stderr, "demo: %s\n", s.c_str()); };
  CaptureSessionOptions capture;
  ProgressLine line(true);
  capture.progress = CaptureProgressPrinter(&line);
  DemoCapture demo;
  {
    // Ctrl-C and SIGTERM stop the capture after the frame in flight.
    StopOnSignals stop;
    capture.stop = stop.flag();
    try {
      demo = CaptureDemo(options, capture);
    } catch (...) {
      line.Done();
      throw;
    }
    line.Done();
  }
  for (const std::string& w : demo.summary.warnings) options.log("capture warning: " + w);
  if (demo.summary.stopped) throw Error("demo interrupted during capture");
  const DemoResult r = SolveAndScoreDemo(demo, options);
  const nlohmann::json& m = r.metrics;
  const auto f = [&](const char* key) { return m.at(key).get<double>(); };
  const std::filesystem::path& out = options.out;
  std::printf("rouen demo (%s): %d frames, %.1f s\n", options.quick ? "quick" : "full",
              m.at("frames_captured").get<int>(), f("wall_seconds"));
  std::printf("  response curve      max relative error  %.4f\n", f("response_max_rel_error"));
  std::printf("  sun direction       error               %.4f deg\n", f("sun_direction_error_deg"));
  std::printf("  sun radiance        relative error      %.4f\n", f("sun_radiance_rel_error"));
  std::printf("  sky                 relative error      median %.4f  p90 %.4f\n",
              f("sky_rel_error_median"), f("sky_rel_error_p90"));
  std::printf("  pseudo-albedo       relative error      sun %.4f  sky+env %.4f\n",
              f("albedo_sun_rel_error_mean"), f("albedo_skyenv_rel_error_mean"));
  std::printf("  held-out render     relative RMSE       %.4f  PSNR %.2f dB\n",
              f("heldout_render_rel_rmse"), f("heldout_render_psnr_db"));
  std::printf(
      "  held-out, predicted  relative RMSE       %.4f  PSNR %.2f dB  (sky median %.4f, "
      "sun %.4f)\n",
      f("heldout_predicted_render_rel_rmse"), f("heldout_predicted_render_psnr_db"),
      f("heldout_predicted_sky_rel_error_median"), f("heldout_predicted_sun_radiance_rel_error"));
  std::printf(
      "  held-out photographs relative RMSE       %.4f  PSNR %.2f dB  (predicted: %.4f, "
      "%.2f dB)\n",
      f("validate_measured_rel_rmse"), f("validate_measured_psnr_db"),
      f("validate_predicted_rel_rmse"), f("validate_predicted_psnr_db"));
  std::printf(
      "  the same figures:    rouen validate %s --session %s --slot %d --exclude-block plaza\n",
      r.scene_dir.c_str(), r.session_dir.c_str(), r.heldout_slot);
  std::printf("  wrote %s, %s, %s\n", (out / "metrics.json").c_str(), (out / "heldout.png").c_str(),
              (out / "heldout_truth.png").c_str());
  std::printf("  report: %s (%.1f MB, %.1f s)\n", (out / "report.html").c_str(),
              r.report.bytes / 1e6, r.report.seconds);
}

}  // namespace

void RegisterDemo(CLI::App& app) {
  auto a = std::make_shared<DemoOptions>();
  CLI::App* c = app.add_subcommand("demo", CommandSummary("demo"));
  c->footer(
      "No camera and no download needed. A campanile on a plaza in Berkeley is captured at five\n"
      "times of day by simulated devices through the real capture controller; the architecture\n"
      "views of one time are held out, rendered from the recovered lighting and reflectance, and\n"
      "compared with the simulator's truth: once under the lighting measured at that time, once\n"
      "under lighting predicted from the other times only (sun by extinction, sky interpolated,\n"
      "environment by photometric stereo). Writes DIR/metrics.json, DIR/heldout.png and\n"
      "DIR/heldout_predicted.png beside DIR/heldout_truth.png, the session (DIR/session), the\n"
      "solved scene (DIR/scene, as `rouen solve` writes it) and intermediate files (DIR/work).\n"
      "The held-out photographs are also compared as `rouen validate` compares them; the demo\n"
      "prints that command, which reproduces its figures. DIR/report.html shows it all on one\n"
      "page (as `rouen report` writes it).");
  c->add_option("--out", a->out, "Output folder")->capture_default_str();
  c->add_flag("--quick", a->quick, "Smaller images and fewer samples (about a minute)");
  c->add_flag("--true-response", a->true_response,
              "Diagnostic: give the solver the simulator's true response curve, to separate "
              "calibration error from the rest");
  c->add_option("--seed", a->seed, "Sensor/GPS noise seed")->capture_default_str();
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
