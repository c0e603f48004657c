// rouen capture: run a rig's capture plan into a session folder.
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "app/commands.h"
#include "app/progress.h"
#include "capture/controller.h"
#include "capture/rig.h"
#include "core/error.h"
#include "core/files.h"
#include "core/lens.h"
#include "core/mesh.h"

namespace rouen {
namespace {

struct CaptureArgs {
  std::string rig, out, from, target = "all";
  bool resume = false, quick = false, no_prompt = false, new_slot = false;
};

// Field rigs: the operator aims the camera and fits the ND filter, then presses Enter.
void PromptOperator(const OperatorRequest& r) {
  std::fprintf(stderr, "\n>>> %s ", r.text.c_str());
  std::fflush(stderr);
  std::string line;
  if (!std::getline(std::cin, line))
    throw Error(
        "capture: the operator prompt needs a terminal (stdin closed); use --no-prompt "
        "when the camera is aimed by other means");
}

void Run(const CaptureArgs& a) {
  RigConfig rig = LoadRig(a.rig);
  if (a.quick) rig.quick = true;
  OpenRigOptions open;
  open.from_session = a.from;
  if (!a.no_prompt) open.prompt = PromptOperator;
  RigDevices dev = OpenRig(rig, open);
  for (const std::string& n : dev.notes) std::fprintf(stderr, "%s\n", n.c_str());
  if (a.target != "all") dev.plan.targets = {ParseTarget(a.target)};
  CaptureSessionOptions opts;
  opts.resume = a.resume;
  opts.new_slot = a.new_slot;
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
                                const std::filesystem::path& out, const CaptureSessionOptions& opts,
                                bool show_progress) {
  namespace fs = std::filesystem;
  const bool field = !rig.simulated() && rig.kind != "replay";
  if (opts.new_slot && !field)
    throw Error(
        "--new-slot adds a time of day to a field session; simulated and replay rigs "
        "capture all their slots in one run");
  if (opts.new_slot && !fs::exists(out / "session.json"))
    throw Error(out.string() + ": --new-slot needs an existing session (run without it first)");
  // The recorded session of a replay, read once for its site, notes and model.
  std::optional<Session> src;
  if (!opts.from_session.empty()) src.emplace(Session::Load(opts.from_session));
  std::optional<SessionWriter> writer;
  if ((opts.resume || opts.new_slot) && fs::exists(out / "session.json")) {
    writer.emplace(SessionWriter::Resume(out));
    if (field) {
      // A field run is one slot: --resume continues the session's last slot, --new-slot
      // starts the next one now.
      int last = -1;
      for (const FrameRecord& f : writer->frames()) last = std::max(last, f.slot);
      dev.plan.first_slot = opts.new_slot ? last + 1 : std::max(last, 0);
      if (opts.new_slot) {
        SessionInfo info = writer->info();
        if (info.extra.contains("plan") && info.extra["plan"].contains("slots"))
          info.extra["plan"]["slots"].push_back(dev.plan.slots.front().Iso8601(9));
        writer->UpdateInfo(info);
      }
    }
  } else {
    SessionInfo info;
    info.site = rig.site;
    info.site_source = "rig";
    info.rig = fs::path(rig.path).filename().string();
    info.created_utc = NowUtc().Iso8601(3);
    info.extra["plan"] = PlanToJson(dev.plan);
    info.extra["nd_filters"] = {{"sun", rig.sun_nd_density_rgb}};
    if (rig.heldout_slot >= 0) info.extra["heldout_slot"] = rig.heldout_slot;
    if (src) {
      info.site = src->info().site;
      info.site_source = src->info().site_source;
      info.clock_offset_s = src->info().clock_offset_s;
      info.notes = "replayed from " + opts.from_session.string();
      for (const char* key : {"heldout_slot", "nd_filters", "vignetting"})
        if (src->info().extra.contains(key)) info.extra[key] = src->info().extra[key];
    }
    writer.emplace(SessionWriter::Create(out, info));
  }
  // A lens file's vignetting model travels with the session too, keyed by the frames' device
  // and target (app/pipeline.cc divides it out); one already there (e.g. from `rouen calib
  // vignetting --session`) is kept.
  if (rig.kind != "replay" && dev.camera) {
    SessionInfo info = writer->info();
    bool changed = false;
    for (Target t : dev.plan.targets) {
      const std::string path = rig.LensPath(t);
      if (path.empty()) continue;
      const std::optional<VignettingModel> v = ReadLensFile(path).vignetting;
      const std::string key = dev.camera->Id() + "/" + TargetName(t);
      if (!v || (info.extra.contains("vignetting") && info.extra["vignetting"].contains(key)))
        continue;
      info.extra["vignetting"][key] = *v;
      changed = true;
    }
    if (changed) writer->UpdateInfo(info);
  }
  // The building model travels with the session (also after a crash before it was written).
  if (writer->info().model.empty() && (dev.model || (src && !src->info().model.empty()))) {
    if (dev.model) {
      WriteObj((out / "model.obj").string(), *dev.model);
    } else {
      WriteFileAtomic(out / "model.obj",
                      ReadFileToString(ResolveInside(src->dir(), src->info().model)));
    }
    SessionInfo info = writer->info();
    info.model = "model.obj";
    writer->UpdateInfo(info);
  }
  DeviceLossOptions loss;
  loss.policy = rig.on_device_lost;
  loss.reconnect_timeout_s = rig.reconnect_timeout_s;
  CaptureController controller(dev.Devices(), dev.plan, writer->info().site, loss);
  g_stop.store(false);
  auto old_int = std::signal(SIGINT, OnSignal);
  auto old_term = std::signal(SIGTERM, OnSignal);
  ProgressLine line(show_progress);
  // Field rigs: report USB cameras and receivers pulled out or plugged back in as it happens.
  std::shared_ptr<void> usb_watch;
  if (!rig.simulated() && rig.kind != "replay")
    usb_watch = WatchUsb([&line](const std::string& m) { line.Message(m); });
  CaptureSummary s;
  try {
    s = controller.Run(
        *writer,
        [&](const CaptureProgress& p) {
          if (!p.event.empty()) {
            line.Message(p.event);
            return;
          }
          char buf[256];
          std::snprintf(
              buf, sizeof buf,
              "slot %d/%d  %-12s view %d  frames %5d  exposure %9.6f s  saturated %5.2f%%  "
              "GPS %s",
              p.slot + 1, p.slots, TargetName(p.target), p.view, p.frames_total, p.exposure_s,
              100 * p.saturated_fraction, p.gps_status.c_str());
          line.Update(buf);
        },
        &g_stop);
  } catch (const Error& e) {
    // A full disk, a read-only disk: everything journalled so far is whole and stays.
    std::signal(SIGINT, old_int);
    std::signal(SIGTERM, old_term);
    line.Done();
    throw Error(std::string(e.what()) + "\n" + out.string() + ": the " +
                std::to_string(writer->frames().size()) +
                " frames journalled so far are kept; once the problem is fixed, continue with "
                "`rouen capture --rig ... --out " +
                out.string() + " --resume`");
  }
  usb_watch.reset();
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
      "capture",
      "Run a rig's capture plan (sun, aureole, sky, landscape, architecture) into a "
      "session folder");
  c->footer(
      "Each view is bracketed until its brightest pixels of interest are unsaturated and its\n"
      "darkest are above the noise floor; the sun is shot through the rig's ND filter until the\n"
      "disc is unsaturated. Every frame is written durably and journalled (frames.jsonl) with its\n"
      "exposure, UTC time, GPS fix and sun position.\n"
      "Field rigs (uvc-webcam, rpi-libcamera, gige-aravis) shoot one time-of-day slot per run,\n"
      "now (--new-slot adds the next time of day to an existing session): the capture asks you to "
      "point the camera at each target and to fit or remove the ND\n"
      "filter, and waits for Enter. The line at the bottom shows the slot, target, view, frames,\n"
      "current exposure, saturated fraction and GPS status. Without a GPS fix the rig's [site]\n"
      "is used (stated in session.json). If the camera is unplugged the rig's [capture]\n"
      "on_device_lost decides: stop, or reconnect (plug it back in; the bracket is redone).\n"
      "Ctrl-C stops after the frame in flight and keeps everything written; --resume continues\n"
      "an interrupted session. `rouen devices` lists cameras and GPS receivers.\n"
      "Examples:\n"
      "  rouen capture --rig rigs/uvc-webcam.toml --out sessions/rouen-0930\n"
      "  rouen capture --rig rigs/uvc-webcam.toml --out sessions/rouen-0930 --resume\n"
      "  rouen capture --rig rigs/uvc-webcam.toml --out sessions/rouen-0930 --new-slot   # 14:00\n"
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
  c->add_flag("--new-slot", a->new_slot,
              "Field rigs: add this run to the session in --out as a new time of day")
      ->excludes("--resume");
  c->add_flag("--quick", a->quick, "Simulated rigs: smaller images, fewer lighting samples");
  c->add_flag("--no-prompt", a->no_prompt,
              "Field rigs: do not stop to ask the operator to aim or fit the ND filter");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
