// rouen validate: a solved scene rendered at the cameras and time of a slot's architecture
// photos and compared with them.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "app/render_options.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/outputs.h"
#include "pipeline/validate.h"

namespace rouen {
namespace {

struct ValidateArgs {
  std::string scene, session, json, images;
  int slot = 0;
  std::vector<std::string> exclude_blocks;
  int erode_px = 1;
  bool no_predicted = false;
  bool terms = false;
  PredictionArgs prediction;
};

std::string SafeName(std::string s) {
  std::replace(s.begin(), s.end(), '/', '_');
  return s;
}

void PrintRow(const std::string& what, const RenderMetrics& m) {
  std::printf("  %-44s %9.4f %8.2f %10.4f %8.4f %9lld\n", what.c_str(), m.rel_rmse, m.psnr_db,
              m.median_rel_error, m.mean_ratio, static_cast<long long>(m.pixels));
}

void Run(const ValidateArgs& a) {
  namespace fs = std::filesystem;
  ValidateOptions vo;
  vo.exclude_blocks = a.exclude_blocks;
  vo.erode_px = a.erode_px;
  vo.predicted = !a.no_predicted;
  vo.terms = a.terms;
  ApplyPrediction(a.prediction, &vo.relight);
  vo.Validate();
  // Outputs before any work: the JSON now, the images' folder now and its files once the
  // scene names the photos.
  OutputSet outputs;
  outputs.Protect("the scene", a.scene);
  outputs.Protect("--session", a.session);
  const std::string json = a.json.empty() ? "" : outputs.Add("--json", a.json, OutputKind::kFile);
  if (!a.images.empty()) CheckWritableFolder("--images", a.images);
  auto say = [](const std::string& s) { std::fprintf(stderr, "validate: %s\n", s.c_str()); };

  const Session session = Session::Load(a.session);
  const LoadedScene scene = LoadScene(a.scene, say);
  struct ImageFiles {
    std::string photo, rendered, difference, rendered_predicted, difference_predicted;
  };
  std::vector<ImageFiles> files;
  if (!a.images.empty()) {
    outputs.CreateFolder("--images", a.images);
    for (const auto& [name, v] : scene.scene.views) {
      if (v.slot != a.slot || v.target != "architecture") continue;
      const std::string base = (fs::path(a.images) / SafeName(name)).string();
      ImageFiles f;
      f.photo = outputs.Add("--images", base + "_photo.exr", OutputKind::kRadiance);
      f.rendered = outputs.Add("--images", base + "_render.exr", OutputKind::kRadiance);
      f.difference = outputs.Add("--images", base + "_difference.exr", OutputKind::kRadiance);
      if (vo.predicted) {
        f.rendered_predicted =
            outputs.Add("--images", base + "_render_predicted.exr", OutputKind::kRadiance);
        f.difference_predicted =
            outputs.Add("--images", base + "_difference_predicted.exr", OutputKind::kRadiance);
      }
      files.push_back(f);
    }
  }

  const Validation v = ValidateSlot(scene, session, a.slot, vo, say);

  MetricsOptions mo;
  mo.response = &scene.scene.response;
  nlohmann::json j = {{"scene", a.scene},
                      {"session", a.session},
                      {"exclude_blocks", vo.exclude_blocks},
                      {"erode_px", vo.erode_px}};
  j.update(ValidationToJson(v));
  for (size_t i = 0; i < files.size(); ++i) {
    const PhotoValidation& p = v.photos.at(i);
    const ImageFiles& f = files[i];
    WriteImage(f.photo, p.photo, StoredType::kFloat);
    WriteImage(f.rendered, p.rendered_measured, StoredType::kFloat);
    WriteImage(f.difference, RelativeDifference(p.rendered_measured, p.photo, p.mask, mo),
               StoredType::kFloat);
    if (p.predicted) {
      WriteImage(f.rendered_predicted, p.rendered_predicted, StoredType::kFloat);
      WriteImage(f.difference_predicted,
                 RelativeDifference(p.rendered_predicted, p.photo, p.mask, mo), StoredType::kFloat);
    }
  }
  if (!json.empty()) WriteFileAtomic(json, j.dump(2) + "\n");
  outputs.Commit();

  std::printf("%s, slot %d (%s): %zu photo(s)\n", a.scene.c_str(), v.slot,
              v.held_out ? "held out of the albedos" : "NOT held out: a fit, not a prediction",
              v.photos.size());
  std::printf("  %-44s %9s %8s %10s %8s %9s\n", "photo / lighting", "rel.RMSE", "PSNR dB",
              "median rel", "ratio", "pixels");
  for (const PhotoValidation& p : v.photos) {
    PrintRow(p.view + " measured", p.measured);
    if (p.predicted) PrintRow(p.view + " predicted", *p.predicted);
  }
  PrintRow("all photos, measured lighting", v.measured);
  if (v.predicted) PrintRow("all photos, predicted lighting", *v.predicted);
  if (!v.shaded_terms.empty()) {
    std::printf(
        "faces the sun does not reach (measured lighting), share of the irradiance, R G B:\n");
    std::printf("  %-12s %7s  %-17s  %-17s  %-17s\n", "block", "points", "sky", "environment",
                "interreflection");
    auto rgb = [](const Eigen::Vector3d& x) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%4.0f%% %4.0f%% %4.0f%%", 100 * x.x(), 100 * x.y(),
                    100 * x.z());
      return std::string(buf);
    };
    for (const ShadedTerms& t : v.shaded_terms) {
      std::printf("  %-12s %7d  %-17s  %-17s  %-17s\n", t.block.c_str(), t.points,
                  rgb(t.sky).c_str(), rgb(t.environment).c_str(), rgb(t.interreflection).c_str());
    }
  }
  if (!a.json.empty()) std::printf("wrote %s\n", a.json.c_str());
  if (!a.images.empty()) std::printf("wrote the images to %s\n", a.images.c_str());
}

}  // namespace

void RegisterValidate(CLI::App& app) {
  auto a = std::make_shared<ValidateArgs>();
  CLI::App* c = app.add_subcommand("validate", CommandSummary("validate"));
  c->footer(
      "Renders every architecture photo of slot N at its camera and time from the scene (as\n"
      "`rouen render` does; nothing is solved) and compares it with the photo merged to radiance\n"
      "through the scene's response curve, over the building's pixels (model blocks not\n"
      "excluded, eroded by --erode pixels, well exposed in the photo): twice, under the lighting\n"
      "measured at that slot and under lighting predicted from the other slots only (paper §5).\n"
      "Figures per photo and over all: relative RMSE, PSNR of the 8-bit images through the\n"
      "response curve (exposed so the photo's 99th percentile is digital 230), the median\n"
      "relative error |R - T| / T, and the brightness ratio sum R / sum T. A photo left with\n"
      "no pixel to score (the blocks it sees excluded) is skipped and named (\"skipped\" in\n"
      "--json); none left in any photo is an error.\n"
      "A fair test holds the slot out of the albedos: rouen solve SESSION --out SCENE\n"
      "--holdout-slot N.\n"
      "Example: rouen validate s.scene --session s --slot 4 --exclude-block plaza --json v.json");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  c->add_option("--session", a->session, "The session the scene was solved from")->required();
  c->add_option("--slot", a->slot, "The slot whose photos to compare with")
      ->required()
      ->check(Within(0, kMaxSlot));
  c->add_option("--exclude-block", a->exclude_blocks,
                "A model block (OBJ group) not scored, e.g. the ground (repeatable)");
  c->add_option("--erode", a->erode_px, "Pixels dropped along silhouettes and block edges")
      ->check(Within(0, 64))
      ->capture_default_str();
  c->add_flag("--no-predicted", a->no_predicted,
              "Only the slot's measured lighting (no prediction from the other slots)");
  c->add_flag("--terms", a->terms,
              "Also print what lights the faces the sun does not reach at that time, per block: "
              "the sky's, the environment's (below the horizon) and the interreflection's share "
              "of their irradiance under the measured lighting (one more irradiance pass)");
  c->add_option("--json", a->json, "Write the figures as JSON");
  AddPredictionOptions(c, &a->prediction, kSkyInterpOption);
  c->add_option("--images", a->images,
                "Folder for each photo's radiance, render and relative difference (EXR)");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
