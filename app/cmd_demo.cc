// rouen demo: the whole pipeline on the built-in simulated world. Captures a field session
// through the real capture controller, calibrates, solves, renders the held-out time and
// scores everything against the simulator's ground truth.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>

#include "app/commands.h"
#include "app/progress.h"
#include "app/stop_signal.h"
#include "capture/devices/devices.h"
#include "capture/sim/sim_devices.h"
#include "core/error.h"
#include "core/files.h"
#include "core/temporaries.h"
#include "pipeline/capture_session.h"
#include "pipeline/session_solve.h"
#include "render/metrics.h"
#include "render/render.h"
#include "render/tonemap.h"
#include "solve/relight.h"

namespace rouen {
namespace {

const char* kSimRig =
#include "app/sim_rig.inc"
    ;

struct DemoArgs {
  std::string out = "rouen-demo";
  bool quick = false;
  bool true_response = false;
  uint64_t seed = 1;
};

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  size_t k = static_cast<size_t>(std::clamp(p, 0.0, 1.0) * (v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
}

// Evenly spread unit directions over the upper hemisphere (Fibonacci lattice).
std::vector<Eigen::Vector3d> HemisphereDirections(int n, double min_elevation_deg) {
  std::vector<Eigen::Vector3d> out;
  const double golden = M_PI * (3 - std::sqrt(5.0));
  const double zmin = std::sin(min_elevation_deg * M_PI / 180);
  for (int i = 0; i < n; ++i) {
    double z = zmin + (1 - zmin) * (i + 0.5) / n;
    double r = std::sqrt(1 - z * z), phi = golden * i;
    out.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
  }
  return out;
}

void PrepareOut(const std::filesystem::path& out) {
  namespace fs = std::filesystem;
  if (fs::exists(out) && !fs::is_empty(out)) {
    if (!fs::exists(out / ".rouen-demo"))
      throw Error(out.string() + " exists and is not a rouen demo folder; choose another --out");
    for (const char* sub : {"session", "work"}) fs::remove_all(out / sub);
  }
  fs::create_directories(out);
  WatchForTemporaries(out);  // its images and reports: removed on Ctrl-C
  WriteFileAtomic(out / ".rouen-demo", "This folder was written by `rouen demo`.\n");
}

void Run(const DemoArgs& a) {
  namespace fs = std::filesystem;
  const auto t0 = std::chrono::steady_clock::now();
  const fs::path out = a.out;
  PrepareOut(out);
  auto say = [](const std::string& s) { std::fprintf(stderr, "demo: %s\n", s.c_str()); };

  // 1. Capture the simulated field session through the capture controller.
  RigConfig rig = ParseRig(kSimRig, "rigs/sim.toml (built in)");
  rig.quick = a.quick;
  rig.seed = a.seed;
  say(std::string("capturing a simulated field session (") + (a.quick ? "quick" : "full") + ", " +
      std::to_string(rig.plan.slots.size()) + " times of day) into " + (out / "session").string());
  RigDevices dev = OpenRig(rig);
  auto* sim_cam = dynamic_cast<SimCamera*>(dev.camera.get());
  auto world = std::static_pointer_cast<SimWorld>(dev.keep_alive);
  CaptureSessionOptions capture;
  ProgressLine line(true);
  capture.progress = CaptureProgressPrinter(&line);
  CaptureSummary cap;
  {
    // Ctrl-C and SIGTERM stop the capture after the frame in flight.
    StopOnSignals stop;
    capture.stop = stop.flag();
    try {
      cap = CaptureToSession(rig, dev, out / "session", capture).capture;
    } catch (...) {
      line.Done();
      throw;
    }
    line.Done();
  }
  for (const std::string& w : cap.warnings) say("capture warning: " + w);
  if (cap.stopped) throw Error("demo interrupted during capture");

  // 2. Offline processing from the session folder, as for a field session.
  Session session = Session::Load(out / "session");
  PipelineOptions po;
  po.work_dir = out / "work";
  po.quick = a.quick;
  po.log = say;
  const int heldout = rig.heldout_slot;
  if (heldout >= 0) po.exclude_albedo_slots = {heldout};
  if (a.true_response) po.response = sim_cam->sensor().TrueResponse();
  CalibResult calib = CalibrateSession(session, po);
  SolveResult solved = SolveSession(session, calib, po);

  // 3. Score against the simulator's ground truth (never seen by the solver).
  nlohmann::json m;
  const SimSensor& sensor = sim_cam->sensor();
  // Response curve: recovered ln-exposure vs the true one, up to one offset per channel
  // (Debevec-Malik fixes g(128) = 0; the absolute scale is unobservable from brackets).
  std::array<double, 3> to_truth{};  // recovered relative radiance -> true radiance, per channel
  double resp_err = 0;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> diffs;
    for (int z = 10; z <= 245; ++z)
      diffs.push_back(sensor.TrueLogExposure(c, z) - calib.response.g[c][z]);
    double offset = Percentile(diffs, 0.5);
    for (int z = 10; z <= 245; ++z)
      resp_err = std::max(
          resp_err,
          std::abs(std::exp(calib.response.g[c][z] + offset - sensor.TrueLogExposure(c, z)) - 1));
    to_truth[c] = std::exp(offset);  // TrueLogExposure is ln(true radiance x exposure factor)
  }
  m["response_max_rel_error"] = resp_err;

  std::vector<double> sun_dir_err, sun_rad_err, sky_err;
  // The simulator lights each slot at the slot's planned instant (its frames follow within
  // seconds); the truth is taken there.
  for (const SlotSolve& ss : solved.slots) {
    world->SetTime(rig.plan.slots.at(ss.slot));
    Eigen::Vector3d truth_dir = world->TrueSunDirection();
    sun_dir_err.push_back(std::acos(std::clamp(truth_dir.dot(ss.lighting.sun_dir), -1.0, 1.0)) *
                          180 / M_PI);
    Eigen::Vector3d true_sun = world->TrueSunRadiance();
    for (int c = 0; c < 3; ++c)
      sun_rad_err.push_back(std::abs(to_truth[c] * ss.sun_measured.radiance[c] - true_sun[c]) /
                            true_sun[c]);
    for (const Eigen::Vector3d& d : HemisphereDirections(2000, 3.0)) {
      if (d.dot(truth_dir) > std::cos(3.0 * M_PI / 180)) continue;  // the sun's own disc
      Eigen::Vector3d fit = ss.lighting.sky.Radiance(d), tru = world->TrueSkyRadiance(d);
      for (int c = 0; c < 3; ++c)
        sky_err.push_back(std::abs(to_truth[c] * fit[c] - tru[c]) / tru[c]);
    }
  }
  m["sun_direction_error_deg"] = Mean(sun_dir_err);
  m["sun_radiance_rel_error"] = Mean(sun_rad_err);
  m["sky_rel_error_median"] = Percentile(sky_err, 0.5);
  m["sky_rel_error_p90"] = Percentile(sky_err, 0.9);

  // Pseudo-albedos against the true per-channel albedo at each grid point (Lambertian RGB
  // world: the pseudo-albedos of eqs. 11-12 equal it there). The headline figures are over
  // the building; the plaza (seen at grazing angles) is reported beside them.
  // Per block, the signed relative errors rho/truth - 1 (their absolute values give the means).
  struct BlockErrors {
    std::vector<double> sun, se;
  };
  std::map<std::string, BlockErrors> by_block;
  std::vector<double> e_sun, e_se;
  int never_sunlit = 0;
  for (int i = 0; i < solved.grid.size(); ++i) {
    if (solved.albedo.observations[i] == 0) continue;
    const GridPoint& p = solved.grid.points[i];
    const std::string& block = solved.mesh.block_names[p.block];
    Eigen::Vector3d truth = world->TrueAlbedo(p.position);
    bool sun_ok = !(solved.albedo.flags[i] & (kAlbedoSunUnobserved | kAlbedoFilled));
    bool se_ok = !(solved.albedo.flags[i] & (kAlbedoNeverShadowed | kAlbedoFilled));
    if (!sun_ok) ++never_sunlit;
    BlockErrors& b = by_block[block];
    for (int c = 0; c < 3; ++c) {
      double ds = solved.albedo.rho_sun[i][c] / truth[c] - 1;
      double de = solved.albedo.rho_se[i][c] / truth[c] - 1;
      if (sun_ok) b.sun.push_back(ds);
      if (se_ok) b.se.push_back(de);
      if (block == "plaza") continue;
      if (sun_ok) e_sun.push_back(std::abs(ds));
      if (se_ok) e_se.push_back(std::abs(de));
    }
  }
  m["albedo_sun_rel_error_mean"] = Mean(e_sun);
  m["albedo_skyenv_rel_error_mean"] = Mean(e_se);
  m["albedo_points_scored_sun"] = e_sun.size() / 3;
  m["albedo_points_scored_skyenv"] = e_se.size() / 3;
  m["albedo_points_never_sunlit"] = never_sunlit;
  auto mean_abs = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += std::abs(x);
    return v.empty() ? 0.0 : s / v.size();
  };
  for (const auto& [block, b] : by_block)
    m["albedo_by_block"][block] = {
        {"sun_rel_error_mean", mean_abs(b.sun)}, {"skyenv_rel_error_mean", mean_abs(b.se)},
        {"sun_rel_bias", Mean(b.sun)},           {"skyenv_rel_bias", Mean(b.se)},
        {"points_sun", b.sun.size() / 3},        {"points_skyenv", b.se.size() / 3}};

  // 4. Held-out time: render every architecture view and compare with the truth, first under
  // the lighting measured at that time, then under lighting predicted from the other times
  // only (§5: sun by extinction, sky interpolated, environment by photometric stereo).
  struct HeldoutScore {
    double rel_rmse = 0, psnr_db = 0;
    int64_t pixels = 0;
  };
  auto score_heldout = [&](const Lighting& lighting, const SlotIrradiance& irr,
                           const std::string& prefix) {
    double sq = 0, tsq = 0, dn_sq = 0;
    int64_t npx = 0;
    world->SetTime(rig.plan.slots.at(heldout));
    for (int v = 0;; ++v) {
      auto it = calib.groups.find("slot" + std::to_string(heldout) + "/architecture/view" +
                                  std::to_string(v));
      if (it == calib.groups.end()) break;
      const HdrGroup& g = it->second;
      Image rendered = RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo, lighting,
                                  irr, g.intrinsics, g.pose, RenderOptions{});
      Image truth = world->RenderRadiance(g.intrinsics, g.pose);
      Image ids = world->RenderBlockIds(g.intrinsics, g.pose);
      // Truth in the recovered units, for tone mapping both the same way.
      Image truth_rel = truth;
      for (size_t k = 0; k < truth_rel.data.size(); ++k) truth_rel.data[k] /= to_truth[k % 3];
      std::vector<double> building;
      for (int y = 0; y < rendered.height; ++y)
        for (int x = 0; x < rendered.width; ++x) {
          int id = static_cast<int>(ids.at(x, y, 0));
          if (id < 0 || solved.mesh.block_names[id] == "plaza") continue;
          for (int c = 0; c < 3; ++c) {
            double r = to_truth[c] * rendered.at(x, y, c), t = truth.at(x, y, c);
            sq += (r - t) * (r - t);
            tsq += t * t;
          }
          building.push_back(truth_rel.at(x, y, 1));
          ++npx;
        }
      // LDR images through the recovered response, exposed for the building.
      double l99 = std::max(1e-12, Percentile(building, 0.99));
      double exposure = std::exp(calib.response.g[1][230]) / l99;
      Image ldr_r = ToDigital(rendered, calib.response, exposure);
      Image ldr_t = ToDigital(truth_rel, calib.response, exposure);
      for (int y = 0; y < rendered.height; ++y)
        for (int x = 0; x < rendered.width; ++x) {
          int id = static_cast<int>(ids.at(x, y, 0));
          if (id < 0 || solved.mesh.block_names[id] == "plaza") continue;
          for (int c = 0; c < 3; ++c) {
            double d = ldr_r.at(x, y, c) - ldr_t.at(x, y, c);
            dn_sq += d * d;
          }
        }
      if (v == 0) {
        WriteImage((out / (prefix + ".png")).string(), ldr_r, StoredType::kUint8);
        WriteImage((out / (prefix + ".exr")).string(), rendered, StoredType::kFloat);
        if (prefix == "heldout")
          WriteImage((out / "heldout_truth.png").string(), ldr_t, StoredType::kUint8);
      }
    }
    if (npx == 0 || tsq <= 0) throw Error("demo: no building pixels in the held-out views");
    HeldoutScore hs;
    hs.rel_rmse = std::sqrt(sq / tsq);
    hs.psnr_db = 10 * std::log10(255.0 * 255.0 / (dn_sq / (3.0 * npx)));
    hs.pixels = npx;
    return hs;
  };
  if (heldout < 0) throw Error("demo: the rig names no held-out time");
  const SlotSolve& hs = solved.slots.at(heldout);
  const HeldoutScore measured =
      score_heldout(hs.lighting, solved.irradiance.at(heldout), "heldout");
  m["heldout_render_rel_rmse"] = measured.rel_rmse;
  m["heldout_render_psnr_db"] = measured.psnr_db;
  const int64_t npx = measured.pixels;

  say("predicting the held-out time's lighting from the other times");
  std::vector<Lighting> training;
  for (const SlotSolve& ss : solved.slots)
    if (ss.slot != heldout) training.push_back(ss.lighting);
  LightingPredictor predictor(std::move(training), RelightOptions{});
  say("environment photometric stereo: " + predictor.environment().summary.BriefReport());
  RelightSummary rsum;
  const Lighting predicted = predictor.At(hs.lighting.utc, SessionSite(session), &rsum);
  say("predicted " + rsum.Describe());
  const HeldoutScore pred =
      score_heldout(predicted, IrradianceFor(solved, predicted), "heldout_predicted");
  m["heldout_predicted_render_rel_rmse"] = pred.rel_rmse;
  m["heldout_predicted_render_psnr_db"] = pred.psnr_db;
  {
    world->SetTime(rig.plan.slots.at(heldout));
    const Eigen::Vector3d true_sun = world->TrueSunRadiance();
    double e = 0;
    for (int c = 0; c < 3; ++c)
      e += std::abs(to_truth[c] * predicted.sun_radiance[c] - true_sun[c]) / true_sun[c] / 3;
    m["heldout_predicted_sun_radiance_rel_error"] = e;
    std::vector<double> err;
    const Eigen::Vector3d truth_dir = world->TrueSunDirection();
    for (const Eigen::Vector3d& d : HemisphereDirections(2000, 3.0)) {
      if (d.dot(truth_dir) > std::cos(3.0 * M_PI / 180)) continue;
      Eigen::Vector3d fit = predicted.sky.Radiance(d), tru = world->TrueSkyRadiance(d);
      for (int c = 0; c < 3; ++c) err.push_back(std::abs(to_truth[c] * fit[c] - tru[c]) / tru[c]);
    }
    m["heldout_predicted_sky_rel_error_median"] = Percentile(err, 0.5);
    m["heldout_predicted_sky_rel_error_p90"] = Percentile(err, 0.9);
  }
  m["heldout_building_pixels"] = npx;
  m["frames_captured"] = static_cast<int>(session.frames().size());
  m["wall_seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  m["quick"] = a.quick;
  for (auto& [k, v] : m.items())
    if (v.is_number_float() && !std::isfinite(v.get<double>()))
      throw Error("demo: metric " + k + " is not finite");
  WriteFileAtomic(out / "metrics.json", m.dump(2) + "\n");

  std::printf("rouen demo (%s): %d frames, %.1f s\n", a.quick ? "quick" : "full",
              m["frames_captured"].get<int>(), m["wall_seconds"].get<double>());
  std::printf("  response curve      max relative error  %.4f\n", resp_err);
  std::printf("  sun direction       error               %.4f deg\n", Mean(sun_dir_err));
  std::printf("  sun radiance        relative error      %.4f\n", Mean(sun_rad_err));
  std::printf("  sky                 relative error      median %.4f  p90 %.4f\n",
              m["sky_rel_error_median"].get<double>(), m["sky_rel_error_p90"].get<double>());
  std::printf("  pseudo-albedo       relative error      sun %.4f  sky+env %.4f\n", Mean(e_sun),
              Mean(e_se));
  std::printf("  held-out render     relative RMSE       %.4f  PSNR %.2f dB\n",
              m["heldout_render_rel_rmse"].get<double>(),
              m["heldout_render_psnr_db"].get<double>());
  std::printf(
      "  held-out, predicted  relative RMSE       %.4f  PSNR %.2f dB  (sky median %.4f, "
      "sun %.4f)\n",
      pred.rel_rmse, pred.psnr_db, m["heldout_predicted_sky_rel_error_median"].get<double>(),
      m["heldout_predicted_sun_radiance_rel_error"].get<double>());
  std::printf("  wrote %s, %s, %s\n", (out / "metrics.json").c_str(), (out / "heldout.png").c_str(),
              (out / "heldout_truth.png").c_str());
}

}  // namespace

void RegisterDemo(CLI::App& app) {
  auto a = std::make_shared<DemoArgs>();
  CLI::App* c = app.add_subcommand(
      "demo",
      "The whole pipeline on a built-in simulated world: capture, calibrate, solve, "
      "render a held-out time, score against ground truth");
  c->footer(
      "No camera and no download needed. A campanile on a plaza in Berkeley is captured at five\n"
      "times of day by simulated devices through the real capture controller; the architecture\n"
      "views of one time are held out, rendered from the recovered lighting and reflectance, and\n"
      "compared with the simulator's truth: once under the lighting measured at that time, once\n"
      "under lighting predicted from the other times only (sun by extinction, sky interpolated,\n"
      "environment by photometric stereo). Writes DIR/metrics.json, DIR/heldout.png and\n"
      "DIR/heldout_predicted.png beside DIR/heldout_truth.png, the session (DIR/session) and\n"
      "intermediate files (DIR/work).");
  c->add_option("--out", a->out, "Output folder")->capture_default_str();
  c->add_flag("--quick", a->quick, "Smaller images and fewer samples (about a minute)");
  c->add_flag("--true-response", a->true_response,
              "Diagnostic: give the solver the simulator's true response curve, to separate "
              "calibration error from the rest");
  c->add_option("--seed", a->seed, "Sensor/GPS noise seed")->capture_default_str();
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
