// NMEA 0183 GPS input: a sentence decoder (GGA, RMC, ZDA, GSA) that assembles fixes, a Gps
// driver reading a serial port or a recorded log (the clock offset is capture/clock.h).
//
// Heights: GpsFix::height_m is the height above the WGS84 ellipsoid (like Site::height_m),
// i.e. GGA altitude above mean sea level + GGA geoid separation. When a receiver leaves the
// separation empty, the MSL altitude is used as is (counted in NmeaStats::missing_geoid).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "capture/device.h"
#include "core/session.h"
#include "core/time.h"

namespace rouen {

// Why a line was rejected.
enum class NmeaErrorKind {
  kFraming = 0,      // no '$', too long, bad address field, non-printable bytes
  kMissingChecksum,  // no "*HH" at the end
  kBadChecksum,      // "*HH" present but does not match (or is not hex)
  kTruncated,        // fewer fields than the sentence type needs
  kBadNumber,        // a field that should be a number/letter is not
  kOutOfRange,       // a well-formed number outside its valid range (minutes >= 60, lat > 90...)
  kMissingField,     // an empty field that the sentence needs (position of a GGA with a fix)
};
constexpr int kNmeaErrorKinds = 7;
const char* NmeaErrorKindName(NmeaErrorKind kind);

struct NmeaSentenceError {
  NmeaErrorKind kind = NmeaErrorKind::kFraming;
  // Names the sentence and field: "GPGGA field 2 (latitude) '4861.038': minutes >= 60".
  std::string message;
};

struct NmeaStats {
  int64_t lines = 0;     // lines fed (blank lines included)
  int64_t blank = 0;     // empty lines (ignored, not errors)
  int64_t accepted = 0;  // GGA/RMC/ZDA/GSA decoded and merged into the fix
  int64_t ignored = 0;   // valid sentences of other types or talkers (GSV, VTG, $PUBX...)
  int64_t rejected = 0;  // sum of by_kind
  std::array<int64_t, kNmeaErrorKinds> by_kind{};
  int64_t missing_geoid = 0;  // GGA fixes without a geoid separation (height = MSL altitude)
  int64_t epochs = 0;         // completed epochs (a new time of day started, or Flush())
  std::optional<NmeaSentenceError> last_error;
  // One line: "1200 lines, 1180 accepted, 12 ignored, 8 rejected (bad checksum 5, ...)".
  std::string Summary() const;
};

// Assembles fixes from a stream of sentences. Sentences are grouped into epochs by their time
// of day (GGA, RMC, ZDA carry it; a GSA belongs to the epoch of the sentence before it). The
// date comes from RMC or ZDA; a GGA-only epoch takes the date of the last dated sentence,
// moved by a day when the time of day wrapped past midnight (the candidate date closest in
// time to the last dated sentence wins).
// Mode: 0 when GGA quality is 0 or RMC says V (or mode N) without a GGA; else the GSA mode
// (1 -> 0); without a GSA, 3 when the GGA has an altitude, else 2. A 3D claim without an
// altitude is reported as 2D. Mode-0 fixes carry no position (0, 0, 0). Satellites: GGA's
// count, else the ids listed by the epoch's GSAs; hdop: GGA's, else GSA's, else 99.
// A sentence is applied all or nothing: a rejected one never changes the fix.
class NmeaDecoder {
 public:
  // Decodes one line (with or without "\r\n"). Returns true when the line was valid (decoded,
  // or a valid sentence of a type not used here, or blank); false when it was rejected: then
  // `why` (if given) receives the reason and the stats count it. `received` is the laptop
  // clock when the line was read; an epoch keeps the time of its first line.
  bool Feed(std::string_view line, std::string* why = nullptr,
            std::optional<UtcTime> received = std::nullopt);
  // Closes the current epoch (end of a log).
  void Flush();

  // The latest fix: the current epoch once it holds every sentence type the previous epoch
  // had (so a half-received epoch -- RMC without its GGA, say -- never replaces a complete
  // one), else the last completed epoch. Before the first epoch completes, the current one
  // as soon as it has a GGA or RMC and a date. Nothing before the first dated epoch.
  std::optional<GpsFix> Fix() const;
  // The last completed epoch (stats().epochs counts them).
  std::optional<GpsFix> LastEpochFix() const { return last_epoch_fix_; }
  const NmeaStats& stats() const { return stats_; }

 private:
  struct Epoch {
    bool open = false;
    int64_t tod_ms = 0;               // time of day, ms since midnight
    std::optional<int64_t> day;       // days since 1970-01-01 when dated in this epoch
    std::optional<UtcTime> received;  // laptop clock at the first line of the epoch
    bool has_position = false;
    double lat_deg = 0, lon_deg = 0;
    std::optional<double> alt_msl_m, geoid_sep_m;
    std::optional<int> gga_quality;  // 0 = no fix
    std::optional<char> rmc_status;  // 'A' valid, 'V' warning
    std::optional<int> gsa_mode;     // 1 none, 2 2D, 3 3D
    std::optional<int> gga_satellites;
    int gsa_satellites = 0;  // satellite ids listed in this epoch's GSAs
    std::optional<double> gga_hdop, gsa_hdop;
    unsigned types = 0;  // kGga | kRmc | kZda | kGsa seen in this epoch
  };

  bool Reject(NmeaErrorKind kind, std::string message, std::string* why);
  // Starts a new epoch at `tod_ms` unless the open one has that time already.
  void EnterEpoch(int64_t tod_ms, std::optional<UtcTime> received);
  void CloseEpoch();
  std::optional<GpsFix> Build(const Epoch& e) const;

  Epoch cur_;
  std::optional<GpsFix> last_epoch_fix_;
  unsigned last_epoch_types_ = 0;
  // The last dated sentence: its day and time of day (anchor for GGA-only epochs).
  std::optional<int64_t> anchor_day_;
  int64_t anchor_tod_ms_ = 0;
  NmeaStats stats_;
};

// XOR of the bytes between '$' and '*' (the NMEA checksum).
uint8_t NmeaChecksum(std::string_view body);

struct NmeaOptions {
  std::string path;        // serial device (/dev/ttyACM0) or a recorded log file
  int baud = 9600;         // 0: `path` is a recorded log read line by line (no laptop time)
  double timeout_s = 0.5;  // Poll() never blocks longer than this
  // Log files: read a whole epoch per Poll() (up to the first line of the next epoch)
  // instead of one line.
  bool epoch_per_poll = false;
  // When set, every line read (valid or not) is appended to this file as received, e.g. the
  // session's gps.nmea. Opening it can throw DeviceError; a later write failure stops the
  // copy (NmeaGps::raw_log_error() says why) but not the fixes.
  std::string raw_log_path;
  // Throws rouen::Error: empty path, unsupported baud rate, timeout outside [0, 60] s.
  void Validate() const;
};

// Gps over NMEA. Serial: raw 8N1 termios at `baud`, non-blocking reads with poll(), partial
// lines kept across reads. Poll() reads what has arrived (waiting up to timeout_s for a
// complete line when nothing new is there) and returns the latest fix. A device that
// vanishes (unplugged, hung up) throws DeviceError naming the path; when that Poll() still
// decoded new lines it returns them and the next Poll() throws.
class NmeaGps : public Gps {
 public:
  explicit NmeaGps(const NmeaOptions& options);  // throws Error / DeviceError
  ~NmeaGps() override;
  NmeaGps(const NmeaGps&) = delete;
  NmeaGps& operator=(const NmeaGps&) = delete;

  std::string Id() const override;
  std::optional<GpsFix> Poll() override;

  const NmeaDecoder& decoder() const { return decoder_; }
  bool at_end() const { return at_end_; }  // log file: every line has been read
  const std::string& raw_log_error() const { return raw_log_error_; }  // empty when fine

 private:
  std::optional<GpsFix> PollFile();
  std::optional<GpsFix> PollSerial();
  // Feeds complete lines from buffer_; returns how many.
  int FeedBuffered(UtcTime received);

  NmeaOptions options_;
  NmeaDecoder decoder_;
  void OpenSource();
  void LogRaw(std::string_view line);

  int fd_ = -1;
  int raw_fd_ = -1;
  std::string buffer_;  // bytes after the last newline (serial) or the read-ahead (file)
  bool at_end_ = false;
  bool gone_ = false;
  std::string gone_reason_;
  std::string raw_log_error_;
};

std::unique_ptr<Gps> OpenNmeaGps(const NmeaOptions& options);

}  // namespace rouen
