// rouen capture: run a rig's capture plan into a session folder.
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/progress.h"
#include "app/stop_signal.h"
#include "capture/controller.h"
#include "capture/devices/devices.h"
#include "capture/rig.h"
#include "core/error.h"
#include "pipeline/capture_session.h"
#include "pipeline/plan.h"

namespace rouen {
namespace {

struct CaptureArgs {
  std::string rig, out, from, target = "all";
  bool resume = false, quick = false, no_prompt = false, new_slot = false, allow_night = false;
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

// A word of a shell command line, quoted when it holds more than plain path characters.
std::string ShellWord(const std::string& w) {
  const char* plain = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-./:=+,@%";
  if (!w.empty() && w.find_first_not_of(plain) == std::string::npos) return w;
  std::string q = "'";
  for (char c : w) {
    if (c == '\'') {
      q += "'\\''";
    } else {
      q += c;
    }
  }
  return q + "'";
}

// The command that continues this capture: the same rig, folder and options, with --resume
// (after --new-slot too: the new slot is the session's last, which --resume continues).
std::string ResumeCommand(const CaptureArgs& a) {
  std::string c = "rouen capture --rig " + ShellWord(a.rig) + " --out " + ShellWord(a.out);
  if (!a.from.empty()) c += " --from " + ShellWord(a.from);
  if (a.target != "all") c += " --target " + a.target;
  if (a.quick) c += " --quick";
  if (a.no_prompt) c += " --no-prompt";
  return c + " --resume";
}

// The coverage the session's slots achieve so far (rouen plan's measure: each grid point of the
// model seen both sunlit and in shadow), when the session has a model.
void PrintCoverage(const std::string& out) {
  try {
    const Session session = Session::Load(out);
    if (session.info().model.empty()) return;
    for (const SlotCoverage& c : SessionCoverage(session))
      std::fprintf(
          stderr,
          "coverage: after slot %d (%s): %.1f%% of the model's grid points both sunlit "
          "and in shadow (%d of %d seen by the architecture views, %d sunlit at this time)\n",
          c.slot, c.time.Iso8601(0).c_str(), c.CoveredPercent(), c.seen, c.points, c.sunlit);
  } catch (const Error& e) {
    std::fprintf(stderr, "coverage: not computed: %s\n", e.what());
  }
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
  dev.plan.allow_night = a.allow_night;
  CaptureSessionOptions opts;
  opts.resume = a.resume;
  opts.new_slot = a.new_slot;
  opts.from_session = a.from;
  ProgressLine line(true);
  opts.progress = CaptureProgressPrinter(&line);
  // Ctrl-C and SIGTERM stop the capture after the frame in flight; what is written stays.
  StopOnSignals stop;
  opts.stop = stop.flag();
  CaptureSessionSummary s;
  try {
    s = CaptureToSession(rig, dev, a.out, opts);
  } catch (...) {
    line.Done();
    throw;
  }
  line.Done();
  if (s.already_complete) {
    std::fprintf(stderr,
                 "%s: the session is complete (%d frames; all %d brackets of the plan are "
                 "journalled): nothing to capture, nothing changed\n",
                 a.out.c_str(), s.frames_total, s.brackets_planned);
    return;
  }
  const CaptureSummary& c = s.capture;
  std::fprintf(stderr, "\n%s: %d frames in %d slot(s)\n", a.out.c_str(), c.frames, c.slots_done);
  for (const std::string& w : c.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  PrintCoverage(a.out);
  if (!c.stopped) return;
  // Stopped: what of the plan is left, and the command that captures it.
  const int sig = stop.signal();
  const std::string why = sig == SIGINT    ? "stopped by Ctrl-C (SIGINT)"
                          : sig == SIGTERM ? "stopped by SIGTERM"
                          : c.camera_lost  ? "stopped: the camera was lost"
                                           : "stopped";
  std::string next;
  if (!s.brackets_left.empty()) next = " (next: " + s.brackets_left.front() + ")";
  std::fprintf(stderr,
               "%s: %s with %d frames journalled; left of the plan: %zu of %d brackets in %d "
               "slot(s)%s (frames per bracket depend on the light)\n"
               "continue with:\n  %s\n",
               a.out.c_str(), why.c_str(), s.frames_total, s.brackets_left.size(),
               s.brackets_planned, s.slots_left, next.c_str(), ResumeCommand(a).c_str());
  // A signal ends the process as a shell expects of one: 128 + the signal (130, 143).
  if (sig != 0) throw ExitStatus{128 + sig};
}

}  // namespace

std::function<void(const CaptureProgress&)> CaptureProgressPrinter(ProgressLine* line) {
  return [line](const CaptureProgress& p) {
    if (!p.event.empty()) {
      line->Message(p.event);
      return;
    }
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "slot %d/%d  %-12s view %d  frames %5d  exposure %9.6f s  saturated %5.2f%%  "
                  "GPS %s",
                  p.slot + 1, p.slots, TargetName(p.target), p.view, p.frames_total, p.exposure_s,
                  100 * p.saturated_fraction, p.gps_status.c_str());
    line->Update(p.camera_status.empty() ? std::string(buf)
                                         : std::string(buf) + "  camera " + p.camera_status);
  };
}

void RegisterCapture(CLI::App& app) {
  auto a = std::make_shared<CaptureArgs>();
  CLI::App* c = app.add_subcommand("capture", CommandSummary("capture"));
  c->footer(
      "Each view is bracketed until its brightest pixels of interest are unsaturated and its\n"
      "darkest are above the noise floor; the sun is shot through the rig's ND filter until the\n"
      "disc is unsaturated. Every frame is written durably and journalled (frames.jsonl) with its\n"
      "exposure, UTC time, GPS fix and sun position.\n"
      "Field rigs (uvc-webcam, rpi-libcamera, gige-aravis, gphoto2) shoot one time-of-day slot\n"
      "per run, now (--new-slot adds the next time of day to an existing session): the capture\n"
      "asks you to point the camera at each target and to fit or remove the ND\n"
      "filter, and waits for Enter. The line at the bottom shows the slot, target, view, frames,\n"
      "current exposure, saturated fraction and GPS status. Without a GPS fix the rig's [site]\n"
      "is used (stated in session.json). If the camera is unplugged the rig's [capture]\n"
      "on_device_lost decides: stop, or reconnect (plug it back in; the bracket is redone).\n"
      "Ctrl-C (or SIGTERM) stops after the frame in flight and keeps everything written, says\n"
      "how many brackets of the plan are left and the command that continues, and exits 130\n"
      "(SIGTERM: 143). --resume continues an interrupted session: the folder must exist; a\n"
      "session whose plan is complete is left untouched (exit 0). A session is written by one\n"
      "capture at a time (a lock): a second one is refused. `rouen status SESSION` says what a\n"
      "session holds and what its solve lacks; `rouen devices` lists cameras and GPS receivers.\n"
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
  c->add_flag("--allow-night", a->allow_night,
              "Capture though the sun is below the horizon (a rehearsal of the rig at night or "
              "indoors; its sun, sky and landscape frames serve no solve)");
  c->add_flag("--quick", a->quick, "Simulated rigs: smaller images, fewer lighting samples");
  c->add_flag("--no-prompt", a->no_prompt,
              "Field rigs: do not stop to ask the operator to aim or fit the ND filter");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
