// Rig descriptions (rigs/*.toml): which devices, the fallback site, ND filters, the
// bracketing plan and the time-of-day slots. Malformed rigs are errors naming file and line.
// Opening the devices a rig names is capture/devices (it links every driver of the build).
#pragma once

#include <array>
#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "capture/controller.h"
#include "capture/device.h"

namespace rouen {

// The rig kinds this code knows (whether this build has the driver is decided when the rig is
// opened): sim, replay, uvc-webcam (V4L2), rpi-libcamera, gige-aravis, aravis-fake (the
// simulated world served through Aravis's in-process fake camera), gphoto2 (DSLR, mirrorless
// and 360-degree still cameras over USB PTP or PTP/IP, through libgphoto2).
const std::vector<std::string>& RigKinds();

// [camera] keys of gphoto2 rigs (capture/gphoto2's Gphoto2Options, whose defaults these are).
struct Gphoto2CameraConfig {
  std::string model;   // libgphoto2's model name; "" = whatever is on `port`
  std::string port;    // "usb:001,004", "ptpip:192.168.1.1"; "" = the first camera found
  std::string serial;  // the camera's serial number; "" = any
  // Where the camera's files are kept as it wrote them (relative: to the rig's folder); "" = a
  // temporary folder, removed when the camera is closed.
  std::string download_dir;
  double aperture_f = 0;  // set when the rig opens the camera; 0 = as the camera is set
  int max_attempts = 5;   // tries per operation after Device Busy / I/O errors
  double backoff_initial_s = 0.05, backoff_max_s = 2.0;
  double capture_timeout_s = 30;  // for the new file, beyond the exposure time
  double exif_tolerance_stops = 1.0 / 6;
  double base_iso = 100;  // the ISO of gain 1
  bool delete_on_camera = true;
};

struct CameraConfig {
  std::string id = "cam0";  // the name frames are journalled under
  // Which device: v4l2 a /dev/videoN path; libcamera a camera id; aravis a device id
  // ("" = the first one found).
  std::string device;
  int width = 0, height = 0;       // 0 = the largest the device offers
  std::string pixel_format;        // driver format name ("YUYV", "Mono8", ...), "" = best
  int buffers = 4;                 // streaming buffers / queued requests
  int control_latency_frames = 0;  // frames to discard after an exposure/gain change
  double timeout_s = 2.0;          // a frame that takes longer is a device error
  // Lens intrinsics (JSON as in session frames), resolved against the rig file's folder; a
  // target may use another lens (e.g. a fisheye for the sky). Empty: unknown.
  std::string lens;
  std::map<Target, std::string> target_lens;
  Gphoto2CameraConfig gphoto2;  // gphoto2 rigs only
};

struct GpsConfig {
  std::string source = "none";  // sim | replay | nmea | gpsd | none
  std::string device;           // nmea: serial port (/dev/ttyACM0) or a recorded log file
  int baud = 9600;              // nmea: serial speed; 0 reads `device` as a plain file
  std::string host = "127.0.0.1", port = "2947";  // gpsd
  double timeout_s = 1.0;
};

struct RigConfig {
  std::string path;  // the rig file, for messages
  std::string name;
  std::string kind;  // one of RigKinds()
  CameraConfig camera;
  GpsConfig gps;
  Site site;         // fallback site when there is no GPS fix (stated in session.json)
  CapturePlan plan;  // slots from [plan] date/timezone/times (simulated rigs)
  std::vector<std::string> slot_labels;  // "07:30", ...
  int heldout_slot = -1;                 // demo: the slot whose architecture views are held out
  // ND filter for the sun, optical density per channel (R, G, B); plan.sun_nd_density is
  // their mean (what the operator is asked to fit).
  std::array<double, 3> sun_nd_density_rgb = {4.5, 4.5, 4.5};
  // Field rigs: views the operator shoots per target (simulated rigs know their own mounts).
  std::map<Target, int> views;
  DeviceLostPolicy on_device_lost = DeviceLostPolicy::kStop;
  double reconnect_timeout_s = 60;
  bool quick = false;  // sim: smaller images, fewer samples
  uint64_t seed = 1;   // sim: noise seed
  // [solve]: options `rouen solve` starts from for this rig's sessions, keyed as
  // `rouen solve --print-config` shows them (e.g. a coarser grid on a large paved block);
  // copied into each session (SessionInfo::solve_config) and checked by the pipeline.
  nlohmann::json solve_config = nlohmann::json::object();

  bool simulated() const { return kind == "sim" || kind == "aravis-fake"; }
  // A lens file path resolved against the rig's folder ("" when none).
  std::string LensPath(Target target) const;
  // `file` resolved against the rig's folder (absolute paths and "" unchanged).
  std::string Resolve(const std::string& file) const;
};

// TOML text as JSON (tables as objects), the one conversion of rouen's TOML files (rigs, solve
// configurations). Throws rouen::Error "<name>:<line>: <problem>" for malformed TOML and for
// values JSON cannot hold (dates, non-finite numbers).
nlohmann::json ParseTomlAsJson(const std::string& text, const std::string& name);

// Throws rouen::Error "<file>:<line>: <problem>" for malformed rigs.
RigConfig LoadRig(const std::filesystem::path& path);
// Parses a rig from text (the name is used in messages).
RigConfig ParseRig(const std::string& text, const std::string& name);

}  // namespace rouen
