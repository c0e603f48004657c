// `rouen demo` as library calls (app/cmd_demo.cc parses its options and prints the figures):
// a field session of the built-in simulated world (rigs/sim.toml) captured through the real
// capture controller, solved to a scene as `rouen solve --quick` or `rouen solve` would, its
// held-out time rendered and validated, and everything scored against the simulator's truth.
#pragma once

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "capture/devices/devices.h"
#include "capture/rig.h"
#include "capture/sim/sim_devices.h"
#include "pipeline/capture_session.h"
#include "pipeline/report.h"

namespace rouen {

struct DemoOptions {
  std::filesystem::path out = "rouen-demo";
  bool quick = false;          // smaller images, fewer samples
  bool true_response = false;  // give the solver the simulator's true response curve
  uint64_t seed = 1;           // sensor and GPS noise
  std::function<void(const std::string&)> log;
};

// The simulated rig a demo captured with, kept to score the solve against its truth.
struct DemoCapture {
  std::chrono::steady_clock::time_point start;
  RigConfig rig;
  RigDevices devices;
  SimCamera* camera = nullptr;
  std::shared_ptr<SimWorld> world;
  CaptureSummary summary;
};

// Prepares options.out (an empty or missing folder, or one an earlier demo wrote: its session,
// work and scene are replaced) and captures the session into out/session with `capture`'s
// progress and stop flag. Throws rouen::Error for another folder.
DemoCapture CaptureDemo(const DemoOptions& options, const CaptureSessionOptions& capture);

struct DemoResult {
  // As written to out/metrics.json: response, sun, sky and pseudo-albedo errors against the
  // truth, the held-out render's figures under measured and predicted lighting, the held-out
  // photographs' (as `rouen validate` gives them), frames and wall seconds.
  nlohmann::json metrics;
  std::filesystem::path scene_dir, session_dir;
  int heldout_slot = -1;
  ReportSummary report;  // out/report.html
};

// Solves the captured session to out/scene, reads it back, validates and scores its held-out
// time, writes out/metrics.json, out/heldout*.png|exr and out/report.html.
DemoResult SolveAndScoreDemo(DemoCapture& demo, const DemoOptions& options);

}  // namespace rouen
