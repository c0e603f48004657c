// rouen report: one self-contained HTML page of a solved scene (and its session), with plots.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/files.h"
#include "core/outputs.h"
#include "core/session.h"
#include "pipeline/report.h"
#include "pipeline/scene.h"
#include "pipeline/validate.h"

namespace rouen {
namespace {

struct ReportArgs {
  std::string scene, session, work, out;
  std::vector<std::string> metrics;
  int validate_slot = -1;
  std::vector<std::string> exclude_blocks;
};

void Run(const ReportArgs& a) {
  namespace fs = std::filesystem;
  if (a.validate_slot >= 0 && a.session.empty())
    throw Error("--validate needs --session: the photos to compare with are in the session");
  // The output before any work; the inputs named on the command line must exist.
  OutputSet outputs;
  outputs.Protect("the scene", a.scene);
  outputs.Protect("--session", a.session);
  outputs.Protect("--work", a.work);
  for (const std::string& m : a.metrics) outputs.Protect("--metrics", m);
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  std::error_code ec;
  for (const std::string& m : a.metrics)
    if (!fs::is_regular_file(m, ec)) throw Error("--metrics " + m + ": no such file");
  if (!a.work.empty() && !fs::is_directory(a.work, ec))
    throw Error("--work " + a.work + ": no such folder");
  if (!a.session.empty() && !fs::is_directory(a.session, ec))
    throw Error("--session " + a.session + ": no such folder");
  auto say = [](const std::string& s) { std::fprintf(stderr, "report: %s\n", s.c_str()); };

  ReportRequest request;
  request.scene = a.scene;
  request.session = a.session;
  request.work = a.work;
  for (const std::string& m : a.metrics) request.metrics.push_back(m);
  request.log = say;
  std::optional<Validation> validation;
  if (a.validate_slot >= 0) {
    const Session session = Session::Load(a.session);
    const LoadedScene scene = LoadScene(a.scene, say);
    ValidateOptions vo;
    vo.exclude_blocks = a.exclude_blocks;
    vo.Validate();
    validation = ValidateSlot(scene, session, a.validate_slot, vo, say);
    request.validation = &*validation;
  }
  ReportSummary summary;
  const std::string html = BuildReport(request, &summary);
  WriteFileAtomic(out, html);
  outputs.Commit();
  std::printf("wrote %s (%.1f MB, %d plots, %d images, %.1f s)\n", a.out.c_str(),
              summary.bytes / 1e6, summary.plots, summary.images, summary.seconds);
  for (const ReportSection& s : summary.sections)
    for (const std::string& absent : s.absent)
      std::printf("  %s: %s\n", s.title.c_str(), absent.c_str());
}

}  // namespace

void RegisterReport(CLI::App& app) {
  auto a = std::make_shared<ReportArgs>();
  CLI::App* c = app.add_subcommand("report", CommandSummary("report"));
  c->footer(
      "Writes a single HTML file (images inlined, plots as SVG drawn by rouen; no script, no\n"
      "network) with: the capture timeline (with --session), the sun's path and the capture\n"
      "times on a sky chart, the response curves, the sky fits per slot (and their error by\n"
      "elevation and by angle from the sun, with --work), the environment maps and their\n"
      "photometric-stereo normals, the albedo atlases of both sets per block with the flagged\n"
      "points, the validation (with --validate or --metrics) and the timings of the solve.\n"
      "A section whose data is missing says so; the command lists those at the end.\n"
      "Example: rouen report s.scene --session s --work s.scene.work --validate 3\n"
      "         --exclude-block plaza --out s.report/report.html");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  c->add_option("--out", a->out, "The HTML file to write (its folder must exist)")->required();
  c->add_option("--session", a->session,
                "The session the scene was solved from: capture timeline, sky masks, photos");
  c->add_option("--work", a->work,
                "The solve's work folder (rouen solve's --work, by default <scene>.work; the "
                "demo's DIR/work): its merged sky photos (calib/hdr) give the sky fit's error by "
                "elevation and by angle from the sun, and its residual maps");
  c->add_option("--metrics", a->metrics,
                "A JSON file of figures to show (rouen validate --json, rouen demo's "
                "metrics.json); repeatable");
  c->add_option("--validate", a->validate_slot,
                "Render the architecture photos of this slot and show them beside the photos "
                "with error maps, as rouen validate does (needs --session)")
      ->check(Within(0, kMaxSlot));
  c->add_option("--exclude-block", a->exclude_blocks,
                "With --validate: a model block not scored, e.g. the ground (repeatable)");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
