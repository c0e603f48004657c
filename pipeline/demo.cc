#include "pipeline/demo.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "core/angles.h"
#include "core/error.h"
#include "core/files.h"
#include "core/session.h"
#include "core/stats.h"
#include "core/temporaries.h"
#include "pipeline/scene.h"
#include "pipeline/session_solve.h"
#include "pipeline/validate.h"
#include "render/metrics.h"
#include "render/render.h"
#include "render/tonemap.h"

namespace rouen {
namespace {

const char* kSimRig =
#include "pipeline/sim_rig.inc"
    ;

// Evenly spread unit directions over the upper hemisphere (Fibonacci lattice).
std::vector<Eigen::Vector3d> HemisphereDirections(int n, double min_elevation_deg) {
  std::vector<Eigen::Vector3d> out;
  const double golden = kPi * (3 - std::sqrt(5.0));
  const double zmin = std::sin(min_elevation_deg * kPi / 180);
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
    for (const char* sub : {"session", "work", "scene"}) fs::remove_all(out / sub);
  }
  fs::create_directories(out);
  WatchForTemporaries(out);  // its images and reports: removed on Ctrl-C
  WriteFileAtomic(out / ".rouen-demo", "This folder was written by `rouen demo`.\n");
}

}  // namespace

DemoCapture CaptureDemo(const DemoOptions& options, const CaptureSessionOptions& capture) {
  DemoCapture demo;
  demo.start = std::chrono::steady_clock::now();
  const std::filesystem::path& out = options.out;
  PrepareOut(out);
  demo.rig = ParseRig(kSimRig, "rigs/sim.toml (built in)");
  demo.rig.quick = options.quick;
  demo.rig.seed = options.seed;
  if (options.log)
    options.log(std::string("capturing a simulated field session (") +
                (options.quick ? "quick" : "full") + ", " +
                std::to_string(demo.rig.plan.slots.size()) + " times of day) into " +
                (out / "session").string());
  demo.devices = OpenRig(demo.rig);
  demo.camera = dynamic_cast<SimCamera*>(demo.devices.camera.get());
  demo.world = std::static_pointer_cast<SimWorld>(demo.devices.keep_alive);
  if (!demo.camera || !demo.world) throw Error("demo: the built-in rig is not the simulator");
  demo.summary = CaptureToSession(demo.rig, demo.devices, out / "session", capture).capture;
  return demo;
}

DemoResult SolveAndScoreDemo(DemoCapture& demo, const DemoOptions& options) {
  namespace fs = std::filesystem;
  const fs::path& out = options.out;
  const auto say = [&](const std::string& s) {
    if (options.log) options.log(s);
  };
  DemoResult result;
  // Offline processing from the session folder, as for a field session.
  Session session = Session::Load(out / "session");
  PipelineOptions po;
  po.work_dir = out / "work";
  // As `rouen solve --quick` would: the defaults, then the rig's [solve] options.
  po.config = SessionSolveConfig(session.info(), (out / "session" / "session.json").string(),
                                 options.quick);
  po.log = say;
  const int heldout = demo.rig.heldout_slot;
  if (heldout >= 0) po.exclude_albedo_slots = {heldout};
  if (options.true_response) po.response = demo.camera->sensor().TrueResponse();
  const fs::path scene_dir = out / "scene";
  SolveToScene(session, po, scene_dir);
  // Everything below reads the scene back, as `rouen render` and `rouen validate` do.
  const LoadedScene scene = LoadScene(scene_dir, say);
  const SolveResult& solved = scene.solved;
  const ResponseCurve& response = scene.scene.response;

  // Score against the simulator's ground truth (never seen by the solver).
  nlohmann::json m;
  const SimSensor& sensor = demo.camera->sensor();
  // Response curve: recovered ln-exposure vs the true one, up to one offset per channel
  // (Debevec-Malik fixes g(128) = 0; the absolute scale is unobservable from brackets).
  std::array<double, 3> to_truth{};  // recovered relative radiance -> true radiance, per channel
  double resp_err = 0;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> diffs;
    for (int z = 10; z <= 245; ++z)
      diffs.push_back(sensor.TrueLogExposure(c, z) - response.g[c][z]);
    double offset = Quantile(diffs, 0.5);
    for (int z = 10; z <= 245; ++z)
      resp_err = std::max(
          resp_err,
          std::abs(std::exp(response.g[c][z] + offset - sensor.TrueLogExposure(c, z)) - 1));
    to_truth[c] = std::exp(offset);  // TrueLogExposure is ln(true radiance x exposure factor)
  }
  m["response_max_rel_error"] = resp_err;

  std::vector<double> sun_dir_err, sun_rad_err, sky_err;
  // The simulator lights each slot at the slot's planned instant (its frames follow within
  // seconds); the truth is taken there.
  for (const SlotSolve& ss : solved.slots) {
    demo.world->SetTime(demo.rig.plan.slots.at(ss.slot));
    Eigen::Vector3d truth_dir = demo.world->TrueSunDirection();
    sun_dir_err.push_back(std::acos(std::clamp(truth_dir.dot(ss.lighting.sun_dir), -1.0, 1.0)) *
                          180 / kPi);
    Eigen::Vector3d true_sun = demo.world->TrueSunRadiance();
    for (int c = 0; c < 3; ++c)
      sun_rad_err.push_back(std::abs(to_truth[c] * ss.lighting.sun_radiance[c] - true_sun[c]) /
                            true_sun[c]);
    for (const Eigen::Vector3d& d : HemisphereDirections(2000, 3.0)) {
      if (d.dot(truth_dir) > std::cos(3.0 * kPi / 180)) continue;  // the sun's own disc
      Eigen::Vector3d fit = ss.lighting.sky.Radiance(d), tru = demo.world->TrueSkyRadiance(d);
      for (int c = 0; c < 3; ++c)
        sky_err.push_back(std::abs(to_truth[c] * fit[c] - tru[c]) / tru[c]);
    }
  }
  m["sun_direction_error_deg"] = Mean(sun_dir_err);
  m["sun_radiance_rel_error"] = Mean(sun_rad_err);
  m["sky_rel_error_median"] = Quantile(sky_err, 0.5);
  m["sky_rel_error_p90"] = Quantile(sky_err, 0.9);

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
    Eigen::Vector3d truth = demo.world->TrueAlbedo(p.position);
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

  // The held-out time: render every architecture view and compare with the truth, first under
  // the lighting measured at that time, then under lighting predicted from the other times
  // only (§5: sun by extinction, sky interpolated, environment by photometric stereo).
  // Figures from render/metrics (as `rouen validate` computes them) against the simulator's
  // truth, in the recovered units (the truth divided by to_truth), over the building's pixels.
  if (heldout < 0) throw Error("demo: the rig names no held-out time");
  std::vector<std::string> heldout_views;
  for (const auto& [name, v] : scene.scene.views)
    if (v.slot == heldout && v.target == "architecture") heldout_views.push_back(name);
  if (heldout_views.empty()) throw Error("demo: the held-out time has no architecture photo");
  // First the held-out photographs themselves, as `rouen validate` compares them (no
  // truth). Its renders of every held-out view under the measured and the predicted lighting
  // are the ones scored against the truth below (one prediction fit, one irradiance per
  // lighting).
  say("validating the held-out photographs; predicting the held-out time's lighting from the "
      "other times");
  ValidateOptions vo;
  vo.exclude_blocks = {"plaza"};
  const Validation validation = ValidateSlot(scene, session, heldout, vo, say);
  if (!validation.predicted_lighting) throw Error("demo: the validation predicted no lighting");
  const Lighting& predicted = *validation.predicted_lighting;

  MetricsOptions mo;
  mo.response = &response;
  MetricsAccumulator acc_measured(mo), acc_predicted(mo);
  demo.world->SetTime(demo.rig.plan.slots.at(heldout));
  for (size_t v = 0; v < heldout_views.size(); ++v) {
    const SceneView& view = scene.scene.views.at(heldout_views[v]);
    auto photo = std::find_if(validation.photos.begin(), validation.photos.end(),
                              [&](const PhotoValidation& p) { return p.view == heldout_views[v]; });
    if (photo == validation.photos.end())
      throw Error("demo: the validation did not render " + heldout_views[v]);
    const Image& rendered = photo->rendered_measured;
    const Image& rendered_predicted = photo->rendered_predicted;
    // The simulator's radiance of the photographed view (rendered for its frames).
    Image truth =
        demo.camera->Radiance(Target::kArchitecture, ParseBracketName(heldout_views[v]).view,
                              demo.rig.plan.slots.at(heldout));
    for (size_t k = 0; k < truth.data.size(); ++k) truth.data[k] /= to_truth[k % 3];
    const Image ids = demo.world->RenderBlockIds(view.intrinsics, view.pose);
    std::vector<uint8_t> building(static_cast<size_t>(ids.width) * ids.height, 0);
    std::vector<double> green;
    for (int y = 0; y < ids.height; ++y)
      for (int x = 0; x < ids.width; ++x) {
        const int id = static_cast<int>(ids.at(x, y, 0));
        if (id < 0 || solved.mesh.block_names[id] == "plaza") continue;
        building[static_cast<size_t>(y) * ids.width + x] = 1;
        green.push_back(truth.at(x, y, 1));
      }
    acc_measured.Add(rendered, truth, building);
    acc_predicted.Add(rendered_predicted, truth, building);
    if (v == 0) {
      // 8-bit images through the recovered response, exposed as the metrics expose them.
      const double exposure =
          std::exp(response.LogExposure(1, mo.target_dn)) / Quantile(green, mo.percentile);
      for (const auto& [prefix, image] :
           {std::pair<std::string, const Image*>{"heldout", &rendered},
            std::pair<std::string, const Image*>{"heldout_predicted", &rendered_predicted}}) {
        WriteImage((out / (prefix + ".png")).string(), ToDigital(*image, response, exposure),
                   StoredType::kUint8);
        WriteImage((out / (prefix + ".exr")).string(), *image, StoredType::kFloat);
      }
      WriteImage((out / "heldout_truth.png").string(), ToDigital(truth, response, exposure),
                 StoredType::kUint8);
    }
  }
  const RenderMetrics measured = acc_measured.Result();
  m["heldout_render_rel_rmse"] = measured.rel_rmse;
  m["heldout_render_psnr_db"] = measured.psnr_db;
  m["heldout_render_median_rel_error"] = measured.median_rel_error;
  const int64_t npx = measured.pixels;
  const RenderMetrics pred = acc_predicted.Result();
  m["heldout_predicted_render_rel_rmse"] = pred.rel_rmse;
  m["heldout_predicted_render_psnr_db"] = pred.psnr_db;
  m["heldout_predicted_render_median_rel_error"] = pred.median_rel_error;
  {
    demo.world->SetTime(demo.rig.plan.slots.at(heldout));
    const Eigen::Vector3d true_sun = demo.world->TrueSunRadiance();
    double e = 0;
    for (int c = 0; c < 3; ++c)
      e += std::abs(to_truth[c] * predicted.sun_radiance[c] - true_sun[c]) / true_sun[c] / 3;
    m["heldout_predicted_sun_radiance_rel_error"] = e;
    std::vector<double> err;
    const Eigen::Vector3d truth_dir = demo.world->TrueSunDirection();
    for (const Eigen::Vector3d& d : HemisphereDirections(2000, 3.0)) {
      if (d.dot(truth_dir) > std::cos(3.0 * kPi / 180)) continue;
      Eigen::Vector3d fit = predicted.sky.Radiance(d), tru = demo.world->TrueSkyRadiance(d);
      for (int c = 0; c < 3; ++c) err.push_back(std::abs(to_truth[c] * fit[c] - tru[c]) / tru[c]);
    }
    m["heldout_predicted_sky_rel_error_median"] = Quantile(err, 0.5);
    m["heldout_predicted_sky_rel_error_p90"] = Quantile(err, 0.9);
  }
  m["validate_measured_rel_rmse"] = validation.measured.rel_rmse;
  m["validate_measured_psnr_db"] = validation.measured.psnr_db;
  m["validate_measured_median_rel_error"] = validation.measured.median_rel_error;
  m["validate_predicted_rel_rmse"] = validation.predicted->rel_rmse;
  m["validate_predicted_psnr_db"] = validation.predicted->psnr_db;
  m["validate_predicted_median_rel_error"] = validation.predicted->median_rel_error;
  m["heldout_building_pixels"] = npx;
  m["frames_captured"] = static_cast<int>(session.frames().size());
  m["wall_seconds"] =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - demo.start).count();
  m["quick"] = options.quick;
  for (auto& [k, v] : m.items())
    if (v.is_number_float() && !std::isfinite(v.get<double>()))
      throw Error("demo: metric " + k + " is not finite");
  WriteFileAtomic(out / "metrics.json", m.dump(2) + "\n");

  // The report of the demo's world, as `rouen report` writes it, with the held-out photos.
  ReportRequest report;
  report.scene = scene_dir;
  report.session = out / "session";
  report.work = out / "work";
  report.metrics = {out / "metrics.json"};
  report.validation = &validation;
  result.report = WriteReport(report, out / "report.html");

  result.metrics = std::move(m);
  result.scene_dir = scene_dir;
  result.session_dir = out / "session";
  result.heldout_slot = heldout;
  return result;
}

}  // namespace rouen
