// Industrial cameras through Aravis 0.8 (GigE Vision, USB3 Vision, and Aravis' in-process
// "Fake" camera) behind rouen's Camera interface, and a simulated camera whose frames travel
// through the Aravis driver.
//
// Exposure: `arv_camera_set_exposure_time` (Aravis maps it to ExposureTime or
// ExposureTimeAbs, in microseconds); the value is clamped to the camera's bounds and the value
// the camera holds afterwards is read back and reported.
// Gain: rouen's gain is linear (1 = unity). Cameras with a float "Gain" feature (SFNC: dB) get
// 20 log10(gain) dB; cameras with only "GainRaw" (vendor units) get round(20 log10(gain) /
// raw_gain_db_per_step) steps. The read-back value is converted back to linear.
// Fresh frames: after any setting change (exposure, gain, region), the next Grab() first pops
// every buffer already waiting in the stream and gives it back to the camera unread; then
//   - software-trigger mode (the default when the camera supports it): it triggers one frame,
//     which the camera can only expose after the register writes were acknowledged;
//   - free-running mode: it also discards `settle_frames` more buffers (the frames the
//     camera was exposing or reading out while the change arrived) and returns the next one.
// Timestamps: a buffer's system timestamp (host real-time clock, ns, when the buffer was
// complete) minus half the exposure is the frame's mid-exposure UTC. Readout and transfer
// latency (camera-specific, typically a few ms) is not subtracted.
// Frame ids: GigE Vision 1.x block ids are 16-bit and wrap 65535 -> 1 (0 is never used); a
// gap between consecutive delivered buffers counts as dropped frames. Free-running, frames
// the camera sent while all buffers were full (nobody grabbing) are not counted: the baseline
// restarts when a Grab() after a change gives the queued buffers back.
// Failures are DeviceErrors naming the device: unknown id (the message lists the cameras
// seen), no frame within exposure + timeout_s, a frame still incomplete after `retries`
// re-grabs (missing packets), a wrong pixel format or size. A control command that times out
// (camera unplugged) marks the camera lost: later calls throw at once, and destroying it hands
// Aravis' remaining timeouts (~10 s) to a background thread. Reopen the camera to recover.
// GigE Vision: packet socket disabled and socket buffer AUTO (frames are lost otherwise, see
// shared/NOTES.md).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "capture/device.h"

typedef struct _GError GError;  // glib

namespace rouen {

class SimWorld;
class SimClock;

enum class AravisTrigger {
  kAuto,      // software trigger when the camera offers TriggerSoftware, else free-running
  kSoftware,  // one frame per Grab(); fails at open when the camera cannot do it
  kFreeRun,   // continuous acquisition at the camera's frame rate
};

struct AravisOptions {
  std::string device_id;  // Aravis device id (see ListAravisDevices); empty = first found
  // "Mono8", "Mono16", "BayerRG8" / "BayerGR8" / "BayerGB8" / "BayerBG8", "RGB8", "BGR8";
  // empty = the camera's current format if it is one of these.
  std::string pixel_format;
  int buffers = 8;         // stream buffers, 2..256
  double timeout_s = 2.0;  // wait for a buffer beyond the exposure time, (0, 600] s
  AravisTrigger trigger = AravisTrigger::kAuto;
  int settle_frames = 2;              // free-running: frames discarded after a change, 0..16
  int retries = 2;                    // incomplete frames grabbed again before Grab() throws, 0..16
  double frame_rate = 0;              // AcquisitionFrameRate, frames per second (0 = leave as is)
  int width = 0, height = 0;          // region of interest from the sensor's top left (0 = leave)
  double raw_gain_db_per_step = 1.0;  // GainRaw-only cameras: dB per raw step, > 0
  bool enable_fake_interface = false;  // also discover Aravis' in-process "Fake" camera
  void Validate() const;               // throws rouen::Error explaining the problem
};

struct AravisDeviceInfo {
  std::string id;  // what AravisOptions::device_id takes
  std::string vendor, model, serial;
  std::string protocol;  // "GigEVision", "USB3Vision" or "Fake"
  std::string address;   // IP address (GigE) or bus address
};

// Counters since the camera was opened.
struct AravisStats {
  uint64_t delivered = 0;      // buffers returned by Grab()
  uint64_t discarded = 0;      // buffers dropped on purpose (in flight during a change)
  uint64_t dropped = 0;        // frame ids that never arrived (gaps, wrap-around aware)
  uint64_t incomplete = 0;     // buffers with a status other than success
  uint64_t timeouts = 0;       // Grab() calls that got no buffer in time
  uint64_t last_frame_id = 0;  // of the last buffer seen
  uint64_t stale = 0;          // OpenSimAravisCamera only: delivered frames that were not the
                               // simulated frame handed over (should stay 0)
};

class AravisCamera : public Camera {
 public:
  // Opens the device and starts acquisition. Throws DeviceError naming the device (unknown
  // id, no camera, unsupported pixel format, stream failure) or Error for invalid options.
  explicit AravisCamera(const AravisOptions& options);
  ~AravisCamera() override;
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  std::string Id() const override;  // "aravis:<device id>"
  std::vector<ControlInfo> Controls() const override;
  double SetExposure(double seconds) override;
  double SetGain(double gain) override;
  void SetNdFilter(double density) override;  // remembered and reported; the operator fits it
  double NdFilter() const override { return nd_; }
  int ViewCount(Target) const override { return 1; }
  void Aim(Target, int) override {}  // the rig layer prompts the operator
  CapturedFrame Grab() override;

  // Changes the region of interest (stops and restarts the stream with new buffers).
  void SetRegion(int width, int height);
  // Makes the next Grab() return a frame exposed after this call (see the file comment).
  void DiscardInFlight() { stale_ = true; }

  const AravisStats& Stats() const { return stats_; }
  uint64_t DroppedFrames() const { return stats_.dropped; }
  std::string PixelFormat() const { return pixel_format_; }
  bool SoftwareTriggered() const { return software_trigger_; }
  std::string Protocol() const { return protocol_; }

  struct Impl;  // Aravis objects (aravis_internal.h)
  Impl& impl() { return *impl_; }

 private:
  void StartStream();
  void StopStream();
  void ReleaseCamera();
  // The message of an Aravis error (freed); a timeout marks the camera as lost.
  std::string Take(GError*& error);
  void CheckAlive();  // throws DeviceError once the camera stopped answering
  [[noreturn]] void Fail(const std::string& what, const std::string& detail);

  AravisOptions options_;
  std::unique_ptr<Impl> impl_;
  std::string device_id_, protocol_, pixel_format_;
  bool software_trigger_ = false;
  bool gain_in_db_ = true;  // float "Gain" (dB) vs "GainRaw"
  bool gain_available_ = false;
  double exposure_s_ = 0, gain_ = 1, nd_ = 0;
  double exposure_min_s_ = 0, exposure_max_s_ = 0, gain_min_ = 1, gain_max_ = 1;
  bool stale_ = true;
  bool lost_ = false;  // a control command timed out: fail fast, skip camera commands
  std::string lost_reason_;
  bool have_last_id_ = false;
  uint64_t last_id_ = 0;
  AravisStats stats_;
};

std::unique_ptr<Camera> OpenAravisCamera(const AravisOptions& options);

// Cameras Aravis can see now (GigE Vision discovery broadcast, USB3 Vision enumeration; the
// in-process Fake camera only when `include_fake`). Throws nothing on an empty bus.
std::vector<AravisDeviceInfo> ListAravisDevices(bool include_fake = false);

// Frames between two consecutive frame ids that never arrived. 16-bit ids (both <= 65535)
// wrap 65535 -> 1, skipping 0; a 64-bit id going backwards means the camera restarted (0).
uint64_t MissingFrameIds(uint64_t previous, uint64_t next);

// A simulated camera whose frames pass through the Aravis driver: a SimCamera over `world`
// and `clock` renders each frame, Aravis' in-process Fake camera ("Fake_1", RGB8, free-running)
// carries it (fill-pattern callback), and an AravisCamera delivers it. Exposure and gain are
// set on the Fake camera and read back (exposure quantised to 1 us by its register); ND, aim
// and views delegate to the SimCamera. See sim_aravis_camera.cc for the details.
std::unique_ptr<Camera> OpenSimAravisCamera(std::shared_ptr<SimWorld> world, SimClock* clock,
                                            bool quick, uint64_t seed);

// Counters of an AravisCamera or of a camera from OpenSimAravisCamera; nothing for others.
std::optional<AravisStats> AravisStatsOf(const Camera& camera);

}  // namespace rouen
