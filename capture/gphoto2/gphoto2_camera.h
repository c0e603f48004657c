// Still cameras through libgphoto2 (DSLRs, mirrorless and 360° cameras over USB PTP, and over
// PTP/IP on a network) behind rouen's Camera interface.
//
// Settings go through libgphoto2's configuration widgets, as `gphoto2 --set-config` does:
// shutter speed ("shutterspeed", "shutterspeed2", "eos-shutterspeed"), ISO ("iso",
// "isospeed"), aperture ("f-number", "aperture"). A requested value becomes the nearest choice
// the camera offers (in stops); the widget is read back afterwards and that value is what the
// setter returns.
// Gain is ISO / base_iso (gain 1 = base ISO).
// Grab: libgphoto2 is asked to trigger a capture (gp_camera_trigger_capture) and its events
// are polled (gp_camera_wait_for_event) until the camera reports the new file; each file is
// downloaded as soon as it is reported, written into `download_dir`, deleted from the card
// (unless `delete_on_camera` is false), and the capture ends with the camera's capture-complete
// event. The frame is decoded from the downloaded file (JPEG/TIFF/PNG through OpenImageIO;
// a RAW-only capture is refused for now), and its EXIF exposure time and ISO are checked
// against the settings read back: a difference beyond `exif_tolerance_stops` is a DeviceError
// (a camera in an automatic mode, or one that ignored the change). The frame reports the EXIF
// values when the file has them, else the read-back settings; its time is the host's clock at
// the trigger plus half the exposure.
// Trigger rather than gp_camera_capture: in libgphoto2 2.5.30 the generic PTP capture ignores
// a Device Busy reply to InitiateCapture and then waits for events that never come (fixed
// upstream in 2.5.31); the trigger reports it.
// Failures: "Device Busy" (GP_ERROR_CAMERA_BUSY, or PTP code 0x2019 in libgphoto2's error
// text: 2.5.30 reports a busy property write as GP_ERROR_BAD_PARAMETERS) is retried on every
// operation, I/O errors and timeouts on every operation but the trigger (a trigger whose reply
// was lost may have fired: repeating it could take a second picture), with exponential
// backoff from `backoff_initial_s` doubling up to `backoff_max_s`, `max_attempts` tries in
// all; then a DeviceError naming the camera, the operation, the attempts and libgphoto2's
// error text. A camera that closed the connection (libgphoto2 logs "End of stream") is not
// retried: that call and every later one throw DeviceError saying so; reopen the camera
// (a file whose download was cut off stays on the card: it is deleted only once downloaded).
// PTP/IP: libgphoto2 writes to its sockets with write(), so a camera that closed the
// connection would raise SIGPIPE; and it closes file descriptor 0 whenever a PTP/IP camera
// disconnects (2.5.30 and upstream to date: an unused socket field left at 0). Every
// libgphoto2 call runs with SIGPIPE blocked in the calling thread (one it raised is
// discarded) and with fd 0 put back if the call closed it.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "capture/device.h"

namespace rouen {

struct Gphoto2Options {
  // libgphoto2's model name ("Canon EOS 5D Mark IV", "PTP/IP Camera"); empty = detect it on
  // `port` (a "ptpip:" port defaults to "PTP/IP Camera").
  std::string model;
  // libgphoto2's port path ("usb:001,004", "ptpip:192.168.1.1", "ptpip:HOST:PORT:EVENTPORT");
  // empty = the first camera libgphoto2 finds (or the one with `serial`).
  std::string port;
  // The camera's serial number (PTP DeviceInfo, libgphoto2's "serialnumber"): with a port, the
  // camera there must have it; without one, the cameras libgphoto2 detects (of `model`, when
  // given) are opened in turn and the one that has it is kept. Empty: any serial.
  std::string serial;
  int max_attempts = 5;                   // tries per operation (busy / I/O), 1..100
  double backoff_initial_s = 0.05;        // wait after the first failure, (0, 60]
  double backoff_max_s = 2.0;             // longest single wait, >= backoff_initial_s, <= 600
  double capture_timeout_s = 30;          // for the new file, beyond the exposure time, (0, 3600]
  double complete_timeout_s = 2;          // for capture-complete after the file, [0, 600]
  double exif_tolerance_stops = 1.0 / 6;  // EXIF vs settings, (0, 10]
  double base_iso = 100;                  // the ISO of gain 1, > 0
  bool delete_on_camera = true;           // delete each file from the card once downloaded
  // Where downloaded files are kept; empty = a private temporary folder removed at close.
  std::string download_dir;
  void Validate() const;  // throws rouen::Error explaining the problem
};

// Counters since the camera was opened.
struct Gphoto2Stats {
  int captures = 0;         // triggers the camera accepted
  int downloads = 0;        // files downloaded
  int busy_retries = 0;     // operations repeated after Device Busy
  int io_retries = 0;       // operations repeated after an I/O error or timeout
  int delete_failures = 0;  // files left on the card because deleting them failed
};

class Gphoto2Camera : public Camera {
 public:
  // Opens the camera (model and port as in the options). Throws DeviceError naming the port
  // and libgphoto2's error text (no camera, unknown model or port, connection refused), or
  // Error for invalid options.
  explicit Gphoto2Camera(const Gphoto2Options& options);
  // Closes the session (errors are ignored: the camera may be gone).
  ~Gphoto2Camera() override;
  Gphoto2Camera(const Gphoto2Camera&) = delete;
  Gphoto2Camera& operator=(const Gphoto2Camera&) = delete;

  std::string Id() const override;  // "gphoto2:<model>@<port>"
  // The serial number the camera reports ("" when it reports none).
  std::string Serial() const;
  // exposure_s, gain and aperture_f, each with the range the camera offers.
  std::vector<ControlInfo> Controls() const override;
  // Sets the nearest shutter speed the camera offers and returns the one it reports.
  double SetExposure(double seconds) override;
  // Sets the nearest ISO to gain * base_iso and returns the reported ISO / base_iso.
  double SetGain(double gain) override;
  void SetNdFilter(double density) override;  // remembered and reported; the operator fits it
  double NdFilter() const override { return nd_; }
  int ViewCount(Target) const override { return 1; }
  void Aim(Target, int) override {}  // the rig layer prompts the operator
  // Captures one frame with the current settings (see the file comment). Throws DeviceError.
  CapturedFrame Grab() override;
  // The battery level ("batterylevel"), the first card's free space and images
  // (gp_camera_get_storageinfo) and the camera's clock ("datetime", which libgphoto2 reads as
  // the host's local time; the same time zone on both gives UTC). Busy and I/O errors retried;
  // a field the camera does not report stays empty.
  CameraStatus Status() override;

  // Sets the nearest aperture the camera offers and returns the f-number it reports.
  double SetAperture(double f_number);
  // The shutter speeds the camera offers, in seconds, ascending (bulb and auto left out).
  std::vector<double> ShutterSpeeds() const;
  // The file the last Grab() downloaded (in download_dir), and every file of that capture.
  std::string LastFile() const;
  std::vector<std::string> LastFiles() const;
  const Gphoto2Stats& Stats() const { return stats_; }

  struct Impl;  // libgphoto2 objects

 private:
  Gphoto2Options options_;
  std::unique_ptr<Impl> impl_;
  double nd_ = 0;
  mutable Gphoto2Stats stats_;  // reading settings (const) may retry too
};

// A camera libgphoto2 detects on this machine's USB (and serial) ports.
struct Gphoto2CameraInfo {
  std::string model;  // libgphoto2's model name, e.g. "Canon EOS 5D Mark IV"
  std::string port;   // its port path, e.g. "usb:001,004"
};

// The cameras gp_camera_autodetect finds (PTP/IP cameras on a network are never detected: a
// rig names their "ptpip:" port). Throws DeviceError with libgphoto2's error text.
std::vector<Gphoto2CameraInfo> ListGphoto2Cameras();

// `rouen devices` entries for detected cameras: {"driver": "gphoto2", "rig_kind": "gphoto2",
// "id": port, "description": model and what to put in a rig's [camera] table}.
nlohmann::json DescribeGphoto2Cameras(const std::vector<Gphoto2CameraInfo>& cameras);

// Parses a shutter-speed choice as libgphoto2 drivers write them ("1/125", "0.0080s", "30",
// "2.5s", "1\"3", "1 1/2"): seconds, or nothing for "Bulb", "Time", "Auto" and the unparseable.
std::optional<double> ParseShutterSpeed(const std::string& text);
// Parses an aperture choice ("f/5.6", "5.6", "f5.6"): the f-number, or nothing.
std::optional<double> ParseAperture(const std::string& text);

}  // namespace rouen
