// A capture as a stage: a rig's plan run into a session folder (created, resumed, or given a
// new time-of-day slot), with the building model, the lenses' vignetting and the site used
// recorded in session.json. Prints nothing: progress goes to a callback, and a flag the
// caller sets (the CLI: on Ctrl-C or SIGTERM) stops the capture after the frame in flight.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "capture/controller.h"
#include "capture/devices/devices.h"
#include "capture/rig.h"

namespace rouen {

struct CaptureSessionOptions {
  // Continue the session in `out`: it must exist (a folder left without session.json by a
  // crash at its creation is started afresh). A session whose plan is complete is left as it
  // is.
  bool resume = false;
  bool new_slot = false;  // field rigs: add this run as a new time-of-day slot to the session
  std::filesystem::path from_session;  // replay source
  // Each frame's progress, and one-off events (camera lost or reconnected; USB devices
  // plugged in or pulled out, reported from another thread) with CaptureProgress::event set.
  std::function<void(const CaptureProgress&)> progress;
  // Checked before every frame: once true, the capture stops after the frame in flight and
  // everything journalled stays. Null: the capture runs to the end of its plan.
  const std::atomic<bool>* stop = nullptr;
  SessionWriterOptions writer;  // how frames are stored (PNG compression level)
};

struct CaptureSessionSummary {
  CaptureSummary capture;  // this run: frames, slots, stopped, warnings
  // --resume of a session whose plan was complete: nothing was captured or written.
  bool already_complete = false;
  // This run's plan (slots x targets x views, as group names) and the brackets of it a
  // `--resume` would capture: those not journalled, and the one journalled last when the
  // capture stopped (it is captured again). Frames per bracket vary with the light.
  int brackets_planned = 0;
  std::vector<std::string> brackets_left;
  int slots_left = 0;    // slots with a bracket left
  int frames_total = 0;  // in the session's journal after this run
};

// Creates (or resumes) the session folder `out` and runs the plan of `dev` (OpenRig of
// `rig`) in it. Throws rouen::Error naming `out` when --resume finds no session folder, when
// --new-slot finds no session, when the session is in use by another writer, or when a
// write fails (the frames journalled so far are kept; the message says how to continue).
CaptureSessionSummary CaptureToSession(const RigConfig& rig, RigDevices& dev,
                                       const std::filesystem::path& out,
                                       const CaptureSessionOptions& opts);

}  // namespace rouen
