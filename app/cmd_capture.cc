// rouen capture: run a rig's capture plan into a session folder.
#include <csignal>
#include <cstdio>
#include <filesystem>

#include "app/commands.h"
#include "app/progress.h"
#include "capture/controller.h"
#include "capture/rig.h"
#include "core/error.h"
#include "core/files.h"
#include "core/mesh.h"

namespace rouen {
namespace {

struct CaptureArgs {
  std::string rig, out, from, target = "all";
  bool resume = false, quick = false;
};

void Run(const CaptureArgs& a) {
  RigConfig rig = LoadRig(a.rig);
  if (a.quick) rig.quick = true;
  RigDevices dev = OpenRig(rig, a.from);
  if (a.target != "all") dev.plan.targets = {ParseTarget(a.target)};
  CaptureSessionOptions opts;
  opts.resume = a.resume;
  opts.from_session = a.from;
  CaptureSummary s = CaptureToSession(rig, dev, a.out, opts, /*show_progress=*/true);
  std::fprintf(stderr, "\n%s: %d frames in %d slot(s)%s\n", a.out.c_str(), s.frames, s.slots_done,
               s.stopped ? " (stopped; run again with --resume to complete)" : "");
  for (const std::string& w : s.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
}

}  // namespace

namespace {
std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop.store(true); }
}  // namespace

CaptureSummary CaptureToSession(const RigConfig& rig, RigDevices& dev,
                                const std::filesystem::path& out,
                                const CaptureSessionOptions& opts, bool show_progress) {
  namespace fs = std::filesystem;
  std::optional<SessionWriter> writer;
  if (opts.resume && fs::exists(out / "frames.jsonl")) {
    writer.emplace(SessionWriter::Resume(out));
  } else {
    SessionInfo info;
    info.site = rig.site;
    info.site_source = "rig";
    info.rig = fs::path(rig.path).filename().string();
    info.created_utc = NowUtc().Iso8601(3);
    info.extra["plan"] = PlanToJson(dev.plan);
    if (rig.heldout_slot >= 0) info.extra["heldout_slot"] = rig.heldout_slot;
    if (!opts.from_session.empty()) {
      Session src = Session::Load(opts.from_session);
      info.site = src.info().site;
      info.site_source = src.info().site_source;
      info.clock_offset_s = src.info().clock_offset_s;
      info.notes = "replayed from " + opts.from_session.string();
      if (src.info().extra.contains("heldout_slot"))
        info.extra["heldout_slot"] = src.info().extra["heldout_slot"];
    }
    writer.emplace(SessionWriter::Create(out, info));
    // The building model travels with the session.
    if (dev.model) {
      WriteObj((out / "model.obj").string(), *dev.model);
      info.model = "model.obj";
      writer->UpdateInfo(info);
    } else if (!opts.from_session.empty()) {
      Session src = Session::Load(opts.from_session);
      if (!src.info().model.empty()) {
        fs::path m = ResolveInside(src.dir(), src.info().model);
        WriteFileAtomic(out / "model.obj", ReadFileToString(m));
        info.model = "model.obj";
        writer->UpdateInfo(info);
      }
    }
  }
  CaptureController controller({dev.camera.get(), dev.gps.get(), dev.clock.get()}, dev.plan,
                               writer->info().site);
  g_stop.store(false);
  auto old_int = std::signal(SIGINT, OnSignal);
  auto old_term = std::signal(SIGTERM, OnSignal);
  ProgressLine line(show_progress);
  CaptureSummary s = controller.Run(
      *writer,
      [&](const CaptureProgress& p) {
        char buf[256];
        std::snprintf(buf, sizeof buf,
                      "slot %d/%d  %-12s view %d  frames %5d  exposure %9.6f s  saturated %5.2f%%  "
                      "GPS %s",
                      p.slot + 1, p.slots, TargetName(p.target), p.view, p.frames_total,
                      p.exposure_s, 100 * p.saturated_fraction, p.gps_status.c_str());
        line.Update(buf);
      },
      &g_stop);
  std::signal(SIGINT, old_int);
  std::signal(SIGTERM, old_term);
  line.Done();
  // The site actually used: the GPS fix if one came, else the rig's fallback (stated).
  SessionInfo info = writer->info();
  for (const FrameRecord& f : writer->frames()) {
    if (f.gps && f.gps->valid()) {
      info.site = {f.gps->lat_deg, f.gps->lon_deg, f.gps->height_m};
      info.site_source = "gps";
    }
  }
  if (info.site_source != "gps")
    s.warnings.push_back("no GPS fix: sun positions use the rig's fallback site (" +
                         std::to_string(info.site.lat_deg) + ", " +
                         std::to_string(info.site.lon_deg) + ")");
  writer->UpdateInfo(info);
  return s;
}

void RegisterCapture(CLI::App& app) {
  auto a = std::make_shared<CaptureArgs>();
  CLI::App* c = app.add_subcommand(
      "capture", "Run a rig's capture plan (sun, aureole, sky, landscape, architecture) into a "
                 "session folder");
  c->footer(
      "Each view is bracketed until its brightest pixels of interest are unsaturated and its\n"
      "darkest are above the noise floor; the sun is shot through the rig's ND filter until the\n"
      "disc is unsaturated. Every frame is written durably and journalled (frames.jsonl) with its\n"
      "exposure, UTC time, GPS fix and sun position. Ctrl-C stops after the frame in flight and\n"
      "keeps everything written; --resume continues an interrupted session.\n"
      "Examples:\n"
      "  rouen capture --rig rigs/sim.toml --out sessions/sim1\n"
      "  rouen capture --rig rigs/replay.toml --from sessions/sim1 --out sessions/replayed");
  c->add_option("--rig", a->rig, "Rig description (rigs/*.toml)")->required();
  c->add_option("--out", a->out, "Session folder to create (or to continue with --resume)")
      ->required();
  c->add_option("--from", a->from, "Recorded session to replay (replay rigs)");
  c->add_option("--target", a->target, "Capture only one target")
      ->check(CLI::IsMember({"all", "sun", "aureole", "sky", "landscape", "architecture"}))
      ->capture_default_str();
  c->add_flag("--resume", a->resume, "Continue an interrupted session in --out");
  c->add_flag("--quick", a->quick, "Simulated rigs: smaller images, fewer lighting samples");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
