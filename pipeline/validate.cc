#include "pipeline/validate.h"

#include <algorithm>

#include "core/error.h"
#include "core/limits.h"
#include "pipeline/render_scene.h"
#include "render/render.h"

namespace rouen {
namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

// The model blocks scored: every block not excluded, less the ground the solve modelled.
std::vector<int> ScoredBlocks(const LoadedScene& scene, const std::vector<std::string>& exclude) {
  const std::vector<std::string>& names = scene.solved.mesh.block_names;
  for (const std::string& e : exclude) {
    if (std::find(names.begin(), names.end(), e) != names.end()) continue;
    std::string known;
    for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
    throw Error(scene.dir.string() + ": the model has no block named '" + e +
                "' (blocks: " + known + ")");
  }
  // The ground the solve modelled (ground.radius_m) and the session's surroundings are not the
  // building the paper scores.
  std::vector<std::string> left_out = exclude;
  if (scene.scene.ground.radius_m > 0) left_out.push_back(scene.scene.ground.block);
  const std::vector<std::string>& around = scene.scene.surrounding_blocks;
  left_out.insert(left_out.end(), around.begin(), around.end());
  std::vector<int> blocks;
  for (int b = 0; b < static_cast<int>(names.size()); ++b)
    if (std::find(left_out.begin(), left_out.end(), names[b]) == left_out.end())
      blocks.push_back(b);
  if (blocks.empty()) throw Error(scene.dir.string() + ": every block of the model is excluded");
  return blocks;
}

std::string Brief(const RenderMetrics& m) {
  return "relative RMSE " + FormatNumber(m.rel_rmse) + ", PSNR " + FormatNumber(m.psnr_db) +
         " dB, median relative error " + FormatNumber(m.median_rel_error);
}

}  // namespace

void ValidateOptions::Validate() const {
  if (erode_px < 0 || erode_px > 64)
    throw Error("validate: the mask erosion must be 0..64 pixels, not " + std::to_string(erode_px));
  relight.Validate();
}

namespace {

// ShadedTerms over every observed shaded point (not only those the slot's views show, so the
// direct light exact at all of them): the lighting's irradiance, and the sky's direct share from
// the same lighting with nothing below the horizon.
std::vector<ShadedTerms> ShadedTermsOf(const SolveResult& solved, const Lighting& measured,
                                       const std::vector<int>& blocks,
                                       const std::function<void(const std::string&)>& log) {
  Log(log,
      "the irradiance on the shaded faces by term (at every observed point, and the sky "
      "alone)");
  const std::vector<SlotIrradiance> both = IrradianceFor(solved, {measured, measured.SkyOnly()});
  const SlotIrradiance& irr = both[0];
  const SlotIrradiance& sky = both[1];
  std::vector<ShadedTerms> out(1);
  out[0].block = "all";
  for (int b : blocks) {
    out.emplace_back();
    out.back().block = solved.mesh.block_names[b];
  }
  for (int i = 0; i < solved.grid.size(); ++i) {
    const GridPoint& p = solved.grid.points[i];
    if (irr.sun[i].maxCoeff() > 0 || solved.albedo.observations[i] == 0) continue;
    const auto it = std::find(blocks.begin(), blocks.end(), p.block);
    if (it == blocks.end()) continue;
    for (ShadedTerms* t : {&out[0], &out[1 + (it - blocks.begin())]}) {
      ++t->points;
      t->irradiance += irr.se[i];
      t->sky += sky.direct_se[i];
      t->environment += irr.direct_se[i] - sky.direct_se[i];
      t->interreflection += irr.se[i] - irr.direct_se[i];
    }
  }
  std::vector<ShadedTerms> kept;
  for (ShadedTerms& t : out) {
    if (t.points == 0) continue;
    const Eigen::Vector3d total = t.irradiance.cwiseMax(1e-300);
    t.sky = t.sky.cwiseQuotient(total);
    t.environment = t.environment.cwiseQuotient(total);
    t.interreflection = t.interreflection.cwiseQuotient(total);
    t.irradiance /= t.points;
    kept.push_back(std::move(t));
  }
  return kept;
}

}  // namespace

Validation ValidateSlot(const LoadedScene& scene, const Session& session, int slot,
                        const ValidateOptions& options,
                        const std::function<void(const std::string&)>& log) {
  options.Validate();
  const SolveResult& solved = scene.solved;
  const int nslots = static_cast<int>(solved.slots.size());
  if (slot < 0 || slot >= nslots)
    throw Error(scene.dir.string() + ": slot " + std::to_string(slot) +
                " is not in the scene (it has slots 0.." + std::to_string(nslots - 1) + ")");
  std::vector<std::string> views;
  for (const auto& [name, v] : scene.scene.views)
    if (v.slot == slot && v.target == "architecture") views.push_back(name);
  if (views.empty())
    throw Error(scene.dir.string() + ": slot " + std::to_string(slot) +
                " has no architecture photo to validate against");
  if (options.predicted && nslots < 2)
    throw Error(scene.dir.string() +
                ": the scene has one slot; there is no other to predict its lighting from");
  const std::vector<int> blocks = ScoredBlocks(scene, options.exclude_blocks);

  Validation out;
  out.slot = slot;
  const std::vector<int>& held = scene.scene.holdout_slots;
  out.held_out = std::find(held.begin(), held.end(), slot) != held.end();
  if (!out.held_out)
    Log(log, "slot " + std::to_string(slot) +
                 " was not held out: its photos shaped the albedos, so these figures are a fit, "
                 "not a prediction (rouen solve --holdout-slot " +
                 std::to_string(slot) + ")");

  // Irradiance once per lighting, for every photo of the slot; both lightings in one pass.
  std::vector<Lighting> lightings = {solved.slots[slot].lighting};
  std::optional<Lighting> predicted;
  if (options.predicted) {
    RenderRequest request;
    request.time = solved.slots[slot].utc;
    request.relight = options.relight;
    request.predict_without_slots = {slot};
    request.intrinsics = scene.scene.views.at(views.front()).intrinsics;
    predicted = RequestedLighting(scene, request, log);
    lightings.push_back(*predicted);
  }
  Log(log, "irradiance under slot " + std::to_string(slot) + "'s measured lighting" +
               (predicted ? " and the lighting predicted from the other slots" : ""));
  // The direct light exact where the slot's views look, the rest only for what it bounces there.
  std::vector<uint8_t> in_views(solved.grid.size(), 0);
  for (const std::string& name : views) {
    const SceneView& view = scene.scene.views.at(name);
    const std::vector<uint8_t> seen =
        GridPointsInView(solved.grid, *solved.caster, view.intrinsics, view.pose);
    for (int i = 0; i < solved.grid.size(); ++i) in_views[i] |= seen[i];
  }
  std::vector<SlotIrradiance> irr = IrradianceFor(solved, lightings, &in_views);
  const Lighting& measured = lightings[0];
  const SlotIrradiance& irr_measured = irr[0];
  const SlotIrradiance irr_predicted = predicted ? std::move(irr[1]) : SlotIrradiance{};

  if (options.terms) out.shaded_terms = ShadedTermsOf(solved, measured, blocks, log);

  MetricsOptions mo;
  mo.response = &scene.scene.response;
  MetricsAccumulator all_measured(mo), all_predicted(mo);
  for (const std::string& name : views) {
    const SceneView& view = scene.scene.views.at(name);
    HdrGroup g = MergeSessionBracket(session, name, scene.scene.response, scene.config);
    if (g.radiance.width != view.intrinsics.width || g.radiance.height != view.intrinsics.height)
      throw Error(session.dir().string() + ": bracket " + name + " is " +
                  std::to_string(g.radiance.width) + "x" + std::to_string(g.radiance.height) +
                  " but the scene's view is " + std::to_string(view.intrinsics.width) + "x" +
                  std::to_string(view.intrinsics.height) +
                  ": was the scene solved from this session?");
    PhotoValidation p;
    p.view = name;
    const Image ids = RenderBlockIds(solved.mesh, *solved.caster, view.intrinsics, view.pose);
    p.mask = ErodeMask(BlockMask(ids, blocks), ids.width, ids.height, options.erode_px);
    size_t scored = 0;
    for (size_t i = 0; i < p.mask.size(); ++i) {
      p.mask[i] = p.mask[i] && g.valid[i];
      scored += p.mask[i];
    }
    if (scored == 0) {
      Log(log, name + ": skipped, no building pixel to score");
      out.skipped.push_back(name);
      continue;
    }
    p.photo = std::move(g.radiance);
    // §6: the re-rendering at the photo's camera.
    p.rendered_measured = RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo,
                                     measured, irr_measured, view.intrinsics, view.pose);
    p.measured = CompareRadiance(p.rendered_measured, p.photo, p.mask, mo);
    all_measured.Add(p.rendered_measured, p.photo, p.mask);
    std::string line = name + ": measured lighting " + Brief(p.measured);
    if (predicted) {
      p.rendered_predicted = RenderView(solved.mesh, solved.grid, *solved.caster, solved.albedo,
                                        *predicted, irr_predicted, view.intrinsics, view.pose);
      p.predicted = CompareRadiance(p.rendered_predicted, p.photo, p.mask, mo);
      all_predicted.Add(p.rendered_predicted, p.photo, p.mask);
      line += "; predicted " + Brief(*p.predicted);
    }
    Log(log, line);
    out.photos.push_back(std::move(p));
  }
  if (out.photos.empty())
    throw Error(scene.dir.string() + ": slot " + std::to_string(slot) +
                " has no building pixel to score in any photo (the model is not in view, or "
                "every pixel in view is excluded or unexposed)");
  out.measured = all_measured.Result();
  if (predicted) out.predicted = all_predicted.Result();
  out.measured_lighting = measured;
  out.predicted_lighting = std::move(predicted);
  return out;
}

namespace {
nlohmann::json MetricsJson(const RenderMetrics& m) {
  return {{"pixels", m.pixels},
          {"rel_rmse", m.rel_rmse},
          {"psnr_db", m.psnr_db},
          {"median_rel_error", m.median_rel_error},
          {"mean_ratio", m.mean_ratio}};
}
}  // namespace

nlohmann::json ValidationToJson(const Validation& v) {
  nlohmann::json j = {{"slot", v.slot}, {"held_out", v.held_out}};
  j["measured"] = MetricsJson(v.measured);
  if (v.predicted) j["predicted"] = MetricsJson(*v.predicted);
  j["photos"] = nlohmann::json::array();
  for (const PhotoValidation& p : v.photos) {
    nlohmann::json pj = {{"view", p.view}, {"measured", MetricsJson(p.measured)}};
    if (p.predicted) pj["predicted"] = MetricsJson(*p.predicted);
    j["photos"].push_back(pj);
  }
  if (!v.skipped.empty()) j["skipped"] = v.skipped;
  if (!v.shaded_terms.empty()) {
    auto rgb = [](const Eigen::Vector3d& x) { return nlohmann::json{x.x(), x.y(), x.z()}; };
    nlohmann::json terms = nlohmann::json::array();
    for (const ShadedTerms& t : v.shaded_terms) {
      terms.push_back({{"block", t.block},
                       {"points", t.points},
                       {"irradiance", rgb(t.irradiance)},
                       {"sky", rgb(t.sky)},
                       {"environment", rgb(t.environment)},
                       {"interreflection", rgb(t.interreflection)}});
    }
    j["shaded_terms"] = terms;
  }
  return j;
}

}  // namespace rouen
