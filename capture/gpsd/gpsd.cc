#include "capture/gpsd/gpsd.h"

#include <fcntl.h>
#include <gps.h>
#include <poll.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>

namespace rouen {
namespace {

UtcTime LaptopNow() {
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  return UtcTime{std::chrono::duration_cast<std::chrono::nanoseconds>(now).count()};
}

bool Finite(double v) { return std::isfinite(v); }

}  // namespace

struct GpsdGps::Impl {
  gps_data_t data{};
  bool open = false;
};

void GpsdOptions::Validate() const {
  if (host.empty()) throw Error("gpsd: empty host");
  const bool digits = !port.empty() && port.size() <= 5 &&
                      port.find_first_not_of("0123456789") == std::string::npos;
  const long p = digits ? std::stol(port) : 0;
  if (p < 1 || p > 65535) throw Error("gpsd: port '" + port + "' is not a number in 1..65535");
  if (!std::isfinite(timeout_s) || timeout_s < 0 || timeout_s > 60) {
    throw Error("gpsd " + host + ":" + port + ": timeout_s must be within [0, 60] s");
  }
}

GpsdGps::GpsdGps(const GpsdOptions& options) : impl_(new Impl), options_(options) {
  options_.Validate();
  errno = 0;
  if (gps_open(options_.host.c_str(), options_.port.c_str(), &impl_->data) != 0) {
    const int err = errno;
    throw DeviceError("gpsd at " + options_.host + ":" + options_.port +
                      " not reachable (is gpsd running?): " + gps_errstr(err));
  }
  impl_->open = true;
  if (gps_stream(&impl_->data, WATCH_ENABLE | WATCH_JSON, nullptr) != 0) {
    const std::string err = std::strerror(errno);
    gps_close(&impl_->data);
    impl_->open = false;
    throw DeviceError("gpsd at " + options_.host + ":" + options_.port +
                      ": cannot start the watch stream: " + err);
  }
  // Non-blocking socket (libgps 3.22 already makes it so; ensured here): gps_read() must
  // never wait for the rest of a report, since Poll() has a time limit; it returns 0 then
  // and Poll() waits with poll() instead.
  const int fd = impl_->data.gps_fd;
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0) ::fcntl(fd, F_SETFL, flags | O_NONBLOCK);
}

GpsdGps::~GpsdGps() {
  if (impl_ && impl_->open) {
    if (!gone_) gps_stream(&impl_->data, WATCH_DISABLE, nullptr);
    gps_close(&impl_->data);
  }
}

void GpsdGps::Lost(const std::string& detail) {
  gone_ = true;
  gone_reason_ = "gpsd at " + options_.host + ":" + options_.port +
                 ": connection lost (gpsd stopped?)" + (detail.empty() ? "" : ": " + detail);
  throw DeviceError(gone_reason_);
}

std::string GpsdGps::Id() const { return "gpsd:" + options_.host + ":" + options_.port; }

std::optional<GpsFix> GpsdGps::Poll() {
  if (gone_) throw DeviceError(gone_reason_);
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(options_.timeout_s));
  gps_data_t& d = impl_->data;
  bool new_fix = false;
  while (true) {
    // Wait for the first new fix; after that take only what is already queued.
    int wait_us = 0;
    if (!new_fix) {
      const auto left =
          std::chrono::duration_cast<std::chrono::microseconds>(deadline - Clock::now()).count();
      wait_us = static_cast<int>(std::max<int64_t>(0, std::min<int64_t>(left, 60000000)));
    }
    if (!gps_waiting(&d, wait_us)) break;
    d.set = 0;
    errno = 0;
    const int got = gps_read(&d, nullptr, 0);
    if (got < 0) {
      const int err = errno;
      Lost(err != 0 ? std::strerror(err) : "");
    }
    if (got == 0) {
      // Only part of a report is buffered (libgps then says "waiting" at once): wait on the
      // socket itself, and notice a peer that closed in the middle of a line.
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) break;
      pollfd p{d.gps_fd, POLLIN | POLLRDHUP, 0};
      const int r = ::poll(&p, 1, static_cast<int>(left));
      if (r > 0 && (p.revents & (POLLRDHUP | POLLHUP | POLLERR))) Lost("closed mid-report");
      continue;
    }
    ++stats_.messages;
    const UtcTime received = LaptopNow();
    if (d.set & MODE_SET) {  // a TPV report
      if (!(d.set & TIME_SET) || (d.fix.time.tv_sec == 0 && d.fix.time.tv_nsec == 0)) {
        ++stats_.untimed;  // gpsd does not trust the time yet
      } else {
        GpsFix f;
        f.utc.ns = static_cast<int64_t>(d.fix.time.tv_sec) * 1000000000 + d.fix.time.tv_nsec;
        f.received_utc = received;
        int mode = d.fix.mode >= MODE_2D ? d.fix.mode : 0;
        if (mode >= 2 &&
            (!(d.set & LATLON_SET) || !Finite(d.fix.latitude) || !Finite(d.fix.longitude) ||
             std::abs(d.fix.latitude) > 90 || std::abs(d.fix.longitude) > 180)) {
          mode = 0;
        }
        if (mode >= 2) {
          f.lat_deg = d.fix.latitude;
          f.lon_deg = d.fix.longitude;
          if (Finite(d.fix.altHAE)) {
            f.height_m = d.fix.altHAE;
          } else if (Finite(d.fix.altMSL)) {
            f.height_m = d.fix.altMSL + (Finite(d.fix.geoid_sep) ? d.fix.geoid_sep : 0.0);
          } else if (mode == 3) {
            mode = 2;  // no height after all
          }
        }
        f.mode = mode > 3 ? 3 : mode;
        f.satellites = d.satellites_used > 0 ? d.satellites_used : 0;
        f.hdop = Finite(d.dop.hdop) && d.dop.hdop > 0 ? d.dop.hdop : 99.0;
        latest_ = f;
        ++stats_.fixes;
        new_fix = true;
      }
    }
    if (Clock::now() >= deadline) break;
  }
  return latest_;
}

std::unique_ptr<Gps> OpenGpsdGps(const GpsdOptions& options) {
  return std::make_unique<GpsdGps>(options);
}

}  // namespace rouen
