// GPS through a running gpsd (libgps JSON watch stream). libgps stays private to this folder.
//
// GpsFix::height_m is gpsd's altHAE, the height above the WGS84 ellipsoid (same convention
// as the NMEA driver and Site::height_m); when gpsd reports only altMSL, altMSL + geoidSep
// is used, and altMSL alone when the separation is missing too.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "capture/device.h"

namespace rouen {

struct GpsdOptions {
  std::string host = "127.0.0.1";
  std::string port = "2947";  // TCP port number
  double timeout_s = 1.0;     // Poll() never blocks longer than this
  // Throws rouen::Error: empty host, port not a number in 1..65535, timeout outside [0, 60].
  void Validate() const;
};

struct GpsdStats {
  int64_t messages = 0;  // JSON reports read (TPV, SKY, VERSION, DEVICES, WATCH...)
  int64_t fixes = 0;     // TPV reports turned into fixes
  int64_t untimed = 0;   // TPV reports without TIME_SET (skipped: time not trusted)
};

// Connects on construction and starts a WATCH (JSON). Poll() waits up to timeout_s for a new
// TPV report, then drains what is already queued and returns the latest fix (mode from
// fix.mode; satellites and hdop from the latest SKY). gpsd unreachable at construction, or
// the connection lost later: DeviceError naming host:port (then every Poll() throws).
// Construction connects with libgps's blocking connect(): an unreachable remote host can
// take the system's TCP connect timeout; a local port without gpsd fails at once.
class GpsdGps : public Gps {
 public:
  explicit GpsdGps(const GpsdOptions& options);
  ~GpsdGps() override;
  GpsdGps(const GpsdGps&) = delete;
  GpsdGps& operator=(const GpsdGps&) = delete;

  std::string Id() const override;
  std::optional<GpsFix> Poll() override;
  const GpsdStats& stats() const { return stats_; }

 private:
  [[noreturn]] void Lost(const std::string& detail);

  struct Impl;  // holds the gps_data_t
  std::unique_ptr<Impl> impl_;
  GpsdOptions options_;
  std::optional<GpsFix> latest_;
  GpsdStats stats_;
  bool gone_ = false;
  std::string gone_reason_;
};

std::unique_ptr<Gps> OpenGpsdGps(const GpsdOptions& options);

}  // namespace rouen
