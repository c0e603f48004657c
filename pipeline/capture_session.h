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
  bool resume = false;    // continue the session in `out`
  bool new_slot = false;  // field rigs: add this run as a new time-of-day slot to the session
  std::filesystem::path from_session;  // replay source
  // Each frame's progress, and one-off events (camera lost or reconnected; USB devices
  // plugged in or pulled out, reported from another thread) with CaptureProgress::event set.
  std::function<void(const CaptureProgress&)> progress;
  // Checked before every frame: once true, the capture stops after the frame in flight and
  // everything journalled stays. Null: the capture runs to the end of its plan.
  const std::atomic<bool>* stop = nullptr;
};

// Creates (or resumes) the session folder `out` and runs the plan of `dev` (OpenRig of
// `rig`) in it. Throws rouen::Error naming `out` when --new-slot finds no session, when the
// session is in use by another writer, or when a write fails (the frames journalled so far
// are kept; the message says how to continue).
CaptureSummary CaptureToSession(const RigConfig& rig, RigDevices& dev,
                                const std::filesystem::path& out,
                                const CaptureSessionOptions& opts);

}  // namespace rouen
