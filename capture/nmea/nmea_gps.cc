// NmeaGps: NMEA from a serial port (termios raw, poll()) or from a recorded log file.
#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>

#include "capture/nmea/nmea.h"

namespace rouen {
namespace {

constexpr size_t kMaxPartialLine = 4096;  // a longer run without '\n' is noise (binary data)
constexpr size_t kFileChunk = 65536;

speed_t BaudConstant(int baud) {
  switch (baud) {
    case 1200:
      return B1200;
    case 2400:
      return B2400;
    case 4800:
      return B4800;
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 921600:
      return B921600;
    default:
      return B0;
  }
}

// The laptop clock (system_clock), as GpsFix::received_utc wants it.
UtcTime LaptopNow() {
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  return UtcTime{std::chrono::duration_cast<std::chrono::nanoseconds>(now).count()};
}

std::string Errno() { return std::strerror(errno); }

}  // namespace

void NmeaOptions::Validate() const {
  if (path.empty()) throw Error("NMEA GPS: empty device/log path");
  if (baud != 0 && BaudConstant(baud) == B0) {
    throw Error("NMEA GPS " + path + ": unsupported baud rate " + std::to_string(baud) +
                " (1200..921600 standard rates, or 0 for a log file)");
  }
  if (!std::isfinite(timeout_s) || timeout_s < 0 || timeout_s > 60) {
    throw Error("NMEA GPS " + path + ": timeout_s must be within [0, 60] s");
  }
  if (!raw_log_path.empty() && raw_log_path == path) {
    throw Error("NMEA GPS " + path + ": raw_log_path must differ from the path read");
  }
}

NmeaGps::NmeaGps(const NmeaOptions& options) : options_(options) {
  options_.Validate();
  if (!options_.raw_log_path.empty()) {
    raw_fd_ =
        ::open(options_.raw_log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (raw_fd_ < 0) {
      throw DeviceError("NMEA raw log " + options_.raw_log_path + ": cannot open: " + Errno());
    }
  }
  try {
    OpenSource();
  } catch (...) {
    if (raw_fd_ >= 0) ::close(raw_fd_);
    throw;
  }
}

void NmeaGps::OpenSource() {
  const std::string& path = options_.path;
  if (options_.baud == 0) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw DeviceError("NMEA log " + path + ": cannot open: " + Errno());
    return;
  }
  fd_ = ::open(path.c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) throw DeviceError("NMEA GPS " + path + ": cannot open: " + Errno());
  termios t{};
  if (!::isatty(fd_) || ::tcgetattr(fd_, &t) != 0) {
    ::close(fd_);
    fd_ = -1;
    throw DeviceError("NMEA GPS " + path + ": not a serial port (use baud 0 for a log file)");
  }
  ::cfmakeraw(&t);
  t.c_cflag |= CLOCAL | CREAD;
  t.c_cflag &= ~(CSTOPB | PARENB | CRTSCTS);
  // VMIN 1 / VTIME 0 with O_NONBLOCK: read() gives EAGAIN when empty and 0/EIO on hang-up
  // (VMIN 0 would make "no data" and "hung up" look the same).
  t.c_cc[VMIN] = 1;
  t.c_cc[VTIME] = 0;
  const speed_t speed = BaudConstant(options_.baud);
  if (::cfsetispeed(&t, speed) != 0 || ::cfsetospeed(&t, speed) != 0 ||
      ::tcsetattr(fd_, TCSANOW, &t) != 0) {
    const std::string err = Errno();
    ::close(fd_);
    fd_ = -1;
    throw DeviceError("NMEA GPS " + path + ": cannot configure " + std::to_string(options_.baud) +
                      " baud raw mode: " + err);
  }
  ::tcflush(fd_, TCIFLUSH);  // drop whatever queued before we opened
}

NmeaGps::~NmeaGps() {
  if (fd_ >= 0) ::close(fd_);
  if (raw_fd_ >= 0) ::close(raw_fd_);
}

void NmeaGps::LogRaw(std::string_view line) {
  if (raw_fd_ < 0) return;
  std::string out(line);
  out.push_back('\n');
  size_t done = 0;
  while (done < out.size()) {
    const ssize_t n = ::write(raw_fd_, out.data() + done, out.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {  // the fix matters more than the raw copy: stop logging, keep reading
      raw_log_error_ = "NMEA raw log " + options_.raw_log_path + ": write failed: " + Errno();
      ::close(raw_fd_);
      raw_fd_ = -1;
      return;
    }
    done += static_cast<size_t>(n);
  }
}

std::string NmeaGps::Id() const { return "nmea:" + options_.path; }

std::optional<GpsFix> NmeaGps::Poll() { return options_.baud == 0 ? PollFile() : PollSerial(); }

int NmeaGps::FeedBuffered(UtcTime received) {
  int lines = 0;
  size_t start = 0;
  while (true) {
    const size_t nl = buffer_.find('\n', start);
    if (nl == std::string::npos) break;
    const std::string_view line = std::string_view(buffer_).substr(start, nl - start);
    LogRaw(line);
    decoder_.Feed(line, nullptr, received);
    ++lines;
    start = nl + 1;
  }
  buffer_.erase(0, start);
  if (buffer_.size() > kMaxPartialLine) {  // rejected (and counted) as an overlong line
    LogRaw(buffer_);
    decoder_.Feed(buffer_, nullptr, received);
    buffer_.clear();
    ++lines;
  }
  return lines;
}

std::optional<GpsFix> NmeaGps::PollSerial() {
  if (gone_) throw DeviceError(gone_reason_);
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(options_.timeout_s));
  int fed = 0;
  while (true) {
    bool got_data = false;
    // Drain what the tty holds now.
    while (!gone_) {
      char buf[4096];
      const ssize_t n = ::read(fd_, buf, sizeof(buf));
      if (n > 0) {
        got_data = true;
        buffer_.append(buf, static_cast<size_t>(n));
        fed += FeedBuffered(LaptopNow());
      } else if (n == 0) {
        gone_ = true;
        gone_reason_ = "NMEA GPS " + options_.path + ": device hung up (unplugged?)";
      } else if (errno == EINTR) {
        continue;
      } else if (errno == EAGAIN || errno == EWOULDBLOCK) {
        break;
      } else {
        gone_ = true;
        gone_reason_ = "NMEA GPS " + options_.path + ": read failed (device gone?): " + Errno();
      }
    }
    if (gone_) {
      if (fed > 0) return decoder_.Fix();  // deliver what arrived; the next Poll() throws
      throw DeviceError(gone_reason_);
    }
    if (fed > 0) break;
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    if (left.count() <= 0) break;
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, static_cast<int>(left.count()));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) throw DeviceError("NMEA GPS " + options_.path + ": poll failed: " + Errno());
    if (r == 0) break;  // timeout
    if (p.revents & POLLNVAL) {
      gone_ = true;
      gone_reason_ = "NMEA GPS " + options_.path + ": descriptor no longer valid";
      throw DeviceError(gone_reason_);
    }
    if ((p.revents & (POLLHUP | POLLERR)) && !(p.revents & POLLIN) && !got_data) {
      // Hang-up with nothing left to read; the read loop above confirms it next round, but a
      // tty that reports HUP yet EAGAIN would spin: treat it as gone here.
      char c;
      const ssize_t n = ::read(fd_, &c, 1);
      if (n == 1) {
        buffer_.push_back(c);
        continue;
      }
      gone_ = true;
      gone_reason_ = "NMEA GPS " + options_.path + ": device hung up (unplugged?)";
      throw DeviceError(gone_reason_);
    }
  }
  return decoder_.Fix();
}

std::optional<GpsFix> NmeaGps::PollFile() {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(options_.timeout_s));
  const int64_t epochs_before = decoder_.stats().epochs;
  while (!at_end_) {
    size_t nl = buffer_.find('\n');
    while (nl == std::string::npos) {
      char buf[kFileChunk];
      const ssize_t n = ::read(fd_, buf, sizeof(buf));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) throw DeviceError("NMEA log " + options_.path + ": read failed: " + Errno());
      if (n == 0) break;
      const size_t old = buffer_.size();
      buffer_.append(buf, static_cast<size_t>(n));
      nl = buffer_.find('\n', old);
    }
    if (nl == std::string::npos) {  // end of file: a last line without '\n', then flush
      if (!buffer_.empty()) {
        LogRaw(buffer_);
        decoder_.Feed(buffer_, nullptr, std::nullopt);
      }
      buffer_.clear();
      decoder_.Flush();
      at_end_ = true;
      break;
    }
    LogRaw(std::string_view(buffer_).substr(0, nl));
    // A recorded log is not live: its fixes carry no laptop time, so no clock offset.
    decoder_.Feed(std::string_view(buffer_).substr(0, nl), nullptr, std::nullopt);
    buffer_.erase(0, nl + 1);
    if (!options_.epoch_per_poll) break;
    if (decoder_.stats().epochs > epochs_before) break;
    if (Clock::now() >= deadline) break;
  }
  return options_.epoch_per_poll ? decoder_.LastEpochFix() : decoder_.Fix();
}

std::unique_ptr<Gps> OpenNmeaGps(const NmeaOptions& options) {
  return std::make_unique<NmeaGps>(options);
}

}  // namespace rouen
