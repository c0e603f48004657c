// A camera on the other end of a PTP/IP connection, for tests: a loopback TCP server speaking
// the PTP/IP transport (CIPA DC-X005 over ISO 15740 operations) well enough for libgphoto2's
// ptp2 driver to open it, set its exposure, capture, download and delete, exactly as it would
// a DSLR on Wi-Fi. It listens on 127.0.0.1 and takes the command and the event connection on
// the same port (libgphoto2 is told "ptpip:127.0.0.1:PORT:PORT"; without the third field
// libgphoto2 2.5.30 would connect its event channel to 15740).
//
// Protocol, as served here (all integers little-endian; every packet starts with its length
// u32 and type u32):
//   command connection: Init_Command_Request (1) -> Init_Command_Ack (2: connection number,
//     GUID, friendly name, version 1.0), then Operation_Request (6) -> [Start_Data (9),
//     Data (10)..., End_Data (12)] -> Operation_Response (7); data from the host to the camera
//     (SetDevicePropValue) arrives between the request and the response the same way.
//   event connection: Init_Event_Request (3, with the connection number) -> Init_Event_Ack (4);
//     afterwards Event (8) packets: ObjectAdded (0x4002, the new handle) and CaptureComplete
//     (0x400D, the InitiateCapture transaction) after each capture.
// Operations: GetDeviceInfo, OpenSession, CloseSession, GetStorageIDs, GetStorageInfo,
// GetObjectHandles, GetObjectInfo, GetObject, DeleteObject, InitiateCapture,
// GetDevicePropDesc, GetDevicePropValue, SetDevicePropValue (ExposureTime 0x500D in 0.1 ms,
// ExposureIndex/ISO 0x500F, FNumber 0x5007 in 1/100, all enumerations; BatteryLevel 0x5001
// and DateTime 0x5011, "YYYYMMDDThhmmss", read-only); anything else is answered
// Operation_Not_Supported. GetStorageInfo reports a 32 GiB card less what its objects take.
//
// Each capture stores a JPEG whose pixel values scale with the exposure set (by default a
// gradient scene; `frame` can supply any image) and whose EXIF carries the exposure time, ISO
// and f-number the camera held. Faults are injected per operation code: "Device Busy" replies,
// a dropped connection (also halfway through a data phase), and a corrupt object. After a drop
// the responder accepts a new connection (a camera that comes back).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"

namespace rouen {

// PTP operation codes the responder serves (ISO 15740).
namespace ptp_op {
constexpr uint16_t kGetDeviceInfo = 0x1001, kOpenSession = 0x1002, kCloseSession = 0x1003,
                   kGetStorageIds = 0x1004, kGetStorageInfo = 0x1005, kGetObjectHandles = 0x1007,
                   kGetObjectInfo = 0x1008, kGetObject = 0x1009, kDeleteObject = 0x100B,
                   kInitiateCapture = 0x100E, kGetDevicePropDesc = 0x1014,
                   kGetDevicePropValue = 0x1015, kSetDevicePropValue = 0x1016;
}  // namespace ptp_op

// The settings a capture is taken with, as the host set them over PTP.
struct PtpShot {
  double exposure_s = 0;  // ExposureTime / 10000
  int iso = 0;            // ExposureIndex
  double f_number = 0;    // FNumber / 100
  int index = 0;          // 1 for the first capture since the responder started
};

struct PtpIpResponderOptions {
  uint16_t port = 0;  // 0: an ephemeral port chosen by the OS
  std::string manufacturer = "rouen";
  std::string model = "PTP/IP double";
  std::string serial = "RPT0001";
  int width = 64, height = 48;  // of the built-in scene
  // The shutter speeds offered (ExposureTime in units of 0.1 ms, the PTP standard's), shortest
  // first; the camera starts at 1/125 s (80) when offered, else at the first.
  std::vector<uint32_t> exposure_times = {5,     10,    20,    40,     80,    167,
                                          333,   667,   1250,  2500,   5000,  10000,
                                          20000, 40000, 80000, 150000, 300000};
  // The picture a capture stores, as digital numbers 0..255 (1 or 3 channels), for `shot`;
  // called on the responder's thread with its lock held (it must not call the responder).
  // Empty: the built-in scene, 120 * (exposure_s * 30) * (iso / 100) * (8 / f_number)^2
  // times a horizontal ramp from 0.5 to 1 (green 0.9, blue 0.8 of red), clamped to 0..255.
  std::function<Image(const PtpShot&)> frame;
  double io_timeout_s = 5;  // a host silent this long in the middle of a packet is dropped
  // The camera's clock (DateTime) is UTC plus this many seconds (a camera set a little off,
  // or to local time).
  double clock_offset_s = 0;
};

// Counters since the responder started.
struct PtpIpResponderStats {
  int connections = 0;                 // command connections initialised
  int captures = 0;                    // InitiateCapture calls that took a picture
  int downloads = 0;                   // GetObject calls whose data was sent in full
  int deletes = 0;                     // objects deleted
  int busy_replies = 0;                // injected Device Busy responses
  int drops = 0;                       // injected connection drops
  std::map<uint16_t, int> operations;  // requests received, by operation code
};

class PtpIpResponder {
 public:
  static constexpr int kForever = -1;

  // Binds 127.0.0.1 (`options.port`, 0 = ephemeral) and starts serving on a thread. Throws
  // rouen::Error when the port cannot be bound.
  explicit PtpIpResponder(PtpIpResponderOptions options = {});
  // Closes every connection and stops the thread.
  ~PtpIpResponder();
  PtpIpResponder(const PtpIpResponder&) = delete;
  PtpIpResponder& operator=(const PtpIpResponder&) = delete;

  uint16_t Port() const { return port_; }
  // The libgphoto2 port path: "ptpip:127.0.0.1:<port>:<port>" (command port, event port).
  std::string PortPath() const;

  // The next `times` requests of `operation` are answered Device Busy (0x2019) without being
  // carried out; kForever for every one; 0 ends an earlier injection.
  void ReplyBusy(uint16_t operation, int times);
  // The `operations`-th request from now (1 = the next) is read and then both connections are
  // closed, without a response; an operation that sends data first sends half of it.
  void DropAfter(int operations);
  // Like DropAfter, at the next request of `operation`.
  void DropDuring(uint16_t operation);
  // The next capture stores bytes that are not a JPEG (its size and name stay plausible).
  void CorruptNextObject();
  // The EXIF of the following captures states this exposure time instead of the one applied
  // (a camera whose file disagrees with its settings); nullopt restores the truth.
  void SetExifExposure(std::optional<double> seconds);
  // The battery level the camera reports from now on (BatteryLevel, percent, 0..100).
  void SetBatteryLevel(int percent);

  // Counters so far.
  PtpIpResponderStats Stats() const;
  // The settings the camera holds now.
  PtpShot Settings() const;
  // Protocol violations seen from the host (malformed packets, wrong transaction ids ...).
  std::vector<std::string> ProtocolErrors() const;

 private:
  struct State;
  void Run();

  PtpIpResponderOptions options_;
  uint16_t port_ = 0;
  std::unique_ptr<State> state_;
};

}  // namespace rouen
