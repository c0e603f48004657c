// rouen status: what a session holds, slot by slot and bracket by bracket, and what its solve
// still lacks, each with the command that adds it. Exit 0 when `rouen solve` can run, 2 when
// it cannot.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "app/command_list.h"
#include "app/commands.h"
#include "core/error.h"
#include "core/files.h"
#include "pipeline/status.h"

namespace rouen {
namespace {

struct StatusArgs {
  std::string session, json;
  bool no_verify = false;
};

// Problems of one kind and fix print together, this many of them at most.
constexpr size_t kShownPerFix = 5;

// "1/4000-1/60 s" style exposure range, in seconds.
std::string Seconds(double lo, double hi) {
  char buf[64];
  if (lo == hi) {
    std::snprintf(buf, sizeof buf, "%.3g s", lo);
  } else {
    std::snprintf(buf, sizeof buf, "%.3g-%.3g s", lo, hi);
  }
  return buf;
}

void PrintBracket(const BracketStatus& b) {
  const int ldr = b.frames - b.hdr_frames;
  std::string kind = b.hdr_frames == 0 ? "LDR" : ldr == 0 ? "HDR" : "LDR+HDR";
  std::string exposures = Seconds(b.min_exposure_s, b.max_exposure_s);
  if (ldr > 0)
    exposures += " (" + std::to_string(b.ldr_exposures) +
                 (b.ldr_exposures == 1 ? " exposure)" : " exposures)");
  std::string nd;
  if (b.max_nd_density > 0) {
    char buf[48];
    if (b.min_nd_density == b.max_nd_density) {
      std::snprintf(buf, sizeof buf, "  ND %.3g", b.max_nd_density);
    } else {
      std::snprintf(buf, sizeof buf, "  ND %.3g-%.3g", b.min_nd_density, b.max_nd_density);
    }
    nd = buf;
  }
  std::printf("  %-28s %3d %-7s %-34s intrinsics %d/%d  pose %d/%d%s\n", b.group.c_str(), b.frames,
              kind.c_str(), exposures.c_str(), b.with_intrinsics, b.frames, b.with_pose, b.frames,
              nd.c_str());
}

// The problems, those with the same kind and fix together (a few named, the rest counted),
// each group followed by its fix.
void PrintProblems(const std::vector<const StatusProblem*>& problems) {
  for (size_t i = 0; i < problems.size();) {
    size_t j = i;
    while (j < problems.size() && problems[j]->kind == problems[i]->kind &&
           problems[j]->fix == problems[i]->fix)
      ++j;
    for (size_t k = i; k < j && k < i + kShownPerFix; ++k)
      std::printf("  - %s: %s\n", StatusProblemName(problems[k]->kind), problems[k]->what.c_str());
    if (j - i > kShownPerFix) std::printf("    ... and %zu more like it\n", j - i - kShownPerFix);
    std::printf("    fix: %s\n", problems[i]->fix.c_str());
    i = j;
  }
}

// " with surroundings FILE (N trees)", "" without surroundings.
std::string SurroundingsText(const SessionInfo& info) {
  if (info.surroundings.empty()) return "";
  const size_t n = info.trees.size();
  return " with surroundings " + info.surroundings +
         (n == 0 ? "" : " (" + std::to_string(n) + (n == 1 ? " tree)" : " trees)"));
}

void Run(const StatusArgs& a) {
  namespace fs = std::filesystem;
  const auto start = std::chrono::steady_clock::now();
  fs::path dir = fs::path(a.session).lexically_normal();
  if (!dir.has_filename()) dir = dir.parent_path();  // "s/" -> "s"
  StatusOptions options;
  options.verify_contents = !a.no_verify;
  const SessionStatus s = ReadSessionStatus(dir, options);
  if (!a.json.empty()) WriteFileAtomic(a.json, StatusToJson(s).dump(2) + "\n");

  std::printf(
      "%s: %d frames in %zu slot(s); rig %s; site %.5f, %.5f, %.0f m (%s); model %s%s\n",
      dir.c_str(), s.frames, s.slots.size(), s.info.rig.empty() ? "(none)" : s.info.rig.c_str(),
      s.info.site.lat_deg, s.info.site.lon_deg, s.info.site.height_m, s.info.site_source.c_str(),
      s.info.model.empty() ? "(none)" : s.info.model.c_str(), SurroundingsText(s.info).c_str());
  std::printf("capture: %s\n", !s.capture_complete   ? "not recorded in session.json"
                               : *s.capture_complete ? "complete"
                                                     : "unfinished");
  for (const SlotStatus& slot : s.slots) {
    std::printf("slot %d  %s%s\n", slot.slot,
                slot.utc ? slot.utc->Iso8601(0).c_str() : "(no frames)",
                slot.utc ? (slot.utc_from_sky ? "  (median of its sky frames)"
                                              : "  (median of its frames; no sky bracket)")
                         : "");
    for (const BracketStatus& b : slot.brackets) PrintBracket(b);
  }
  std::vector<const StatusProblem*> blocking, notes;
  for (const StatusProblem& p : s.problems) (p.blocking ? blocking : notes).push_back(&p);
  if (!notes.empty()) {
    std::printf("notes:\n");
    PrintProblems(notes);
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string verified =
      s.contents_verified ? "frame contents verified (sha256)" : "frame contents not verified";
  if (blocking.empty()) {
    std::printf("solvable: yes (%s; %.2f s)\n", verified.c_str(), seconds);
    return;
  }
  std::printf("solvable: no: %zu problem(s) stop `rouen solve` (%s; %.2f s):\n", blocking.size(),
              verified.c_str(), seconds);
  PrintProblems(blocking);
  throw ExitStatus{2};
}

}  // namespace

void RegisterStatus(CLI::App& app) {
  auto a = std::make_shared<StatusArgs>();
  CLI::App* c = app.add_subcommand("status", CommandSummary("status"));
  c->footer(
      "Per time-of-day slot (its time: the median of its sky frames, as the solve takes it)\n"
      "and bracket (slot<k>/<target>/view<v>): frames, LDR or HDR, exposure range, ND density,\n"
      "how many frames have intrinsics and a pose. Then what stops `rouen solve`, each with the\n"
      "command or edit that adds it: no building model, a slot without a sun, sky or landscape\n"
      "bracket, brackets without intrinsics or pose, no bracket to recover the response curve\n"
      "from, missing or changed frame files, exposure, ND or gain out of range, a damaged\n"
      "journal, a site out of range. Notes (not stopping the solve): a capture that stopped\n"
      "before the end of its plan, a journal line cut short by a crash.\n"
      "Reads session.json, frames.jsonl and the model; verifies every frame file's contents\n"
      "against its journalled sha256 (reading its bytes, never decoding its pixels) unless\n"
      "--no-verify. Image sizes and sky masks are checked by the solve itself.\n"
      "Exit status: 0 when the session can be solved, 2 when it cannot, 1 when it is not a\n"
      "session.\n"
      "Example: rouen status sessions/rouen-0930 --json status.json");
  c->add_option("session", a->session, "Session folder (from rouen capture or rouen import)")
      ->required();
  c->add_option("--json", a->json, "Also write the report as JSON to this file");
  c->add_flag("--no-verify", a->no_verify,
              "Do not read the frame files to compare their sha256 (faster on large sessions)");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
