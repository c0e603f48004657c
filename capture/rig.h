// Rig descriptions (rigs/*.toml): which devices, the fallback site, ND filters, the
// bracketing plan and the time-of-day slots. Malformed rigs are errors naming file and line.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "capture/controller.h"
#include "capture/device.h"
#include "core/mesh.h"

namespace rouen {

struct RigConfig {
  std::string path;         // the rig file, for messages
  std::string name;
  std::string kind;         // "sim" | "replay"
  std::string camera_id = "cam0";
  int control_latency_frames = 0;  // frames to discard after a control change
  std::string gps_source = "none";  // "sim" | "replay" | "none"
  Site site;                // fallback site when there is no GPS fix
  CapturePlan plan;         // slots from [plan] date/timezone/times
  std::vector<std::string> slot_labels;  // "07:30", ...
  int heldout_slot = -1;    // demo: the slot whose architecture views are held out
  bool quick = false;       // sim: smaller images, fewer samples
  uint64_t seed = 1;        // sim: noise seed
};

// Throws rouen::Error "<file>:<line>: <problem>" for malformed rigs.
RigConfig LoadRig(const std::filesystem::path& path);
// Parses a rig from text (the name is used in messages).
RigConfig ParseRig(const std::string& text, const std::string& name);

// The devices a rig names, opened. `from_session` is the recorded session for replay rigs.
struct RigDevices {
  std::shared_ptr<void> keep_alive;  // shared state the devices use (world, session)
  std::unique_ptr<Camera> camera;
  std::unique_ptr<Gps> gps;
  std::unique_ptr<Clock> clock;
  CapturePlan plan;  // possibly adjusted (replay: the recorded slots)
  std::optional<Mesh> model;  // the building model, when the rig knows it (sim)
};
RigDevices OpenRig(const RigConfig& rig, const std::filesystem::path& from_session = {});

}  // namespace rouen
