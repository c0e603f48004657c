#include "capture/nmea/nmea.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <utility>

namespace rouen {
namespace {

constexpr int64_t kMsPerDay = 86400000;
constexpr size_t kMaxSentence = 120;
constexpr unsigned kGga = 1, kRmc = 2, kZda = 4,
                   kGsa = 8;  // NMEA says 82; some receivers exceed it a little

bool IsDigits(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

std::vector<std::string_view> Split(std::string_view s) {
  std::vector<std::string_view> out;
  size_t start = 0;
  while (true) {
    const size_t comma = s.find(',', start);
    if (comma == std::string_view::npos) {
      out.push_back(s.substr(start));
      return out;
    }
    out.push_back(s.substr(start, comma - start));
    start = comma + 1;
  }
}

int DaysInMonth(int year, int month) {
  static const int kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
  return month == 2 && leap ? 29 : kDays[month - 1];
}

int64_t DayNumber(int year, int month, int day) {
  const UtcTime t = FromCivil(CivilTime{year, month, day, 0, 0, 0.0});
  return t.ns / (kMsPerDay * 1000000);
}

// One sentence's fields with error reporting. Each Get* returns false and fills `error` on a
// bad field; an empty field is "absent" (std::nullopt) unless Required is used.
class Fields {
 public:
  Fields(std::string_view address, std::vector<std::string_view> f)
      : address_(address), f_(std::move(f)) {}

  size_t size() const { return f_.size(); }
  std::string_view operator[](size_t i) const { return f_[i]; }
  bool Empty(size_t i) const { return f_[i].empty(); }

  bool Fail(NmeaErrorKind kind, size_t i, const char* name, const std::string& detail) {
    std::ostringstream os;
    os << address_ << " field " << i << " (" << name << ")";
    if (!f_[i].empty()) os << " '" << f_[i] << "'";
    os << ": " << detail;
    error = NmeaSentenceError{kind, os.str()};
    return false;
  }
  bool Require(size_t i, const char* name) {
    if (f_[i].empty()) return Fail(NmeaErrorKind::kMissingField, i, name, "empty");
    return true;
  }

  // A decimal number: digits, optional sign and point; finite; within [lo, hi].
  bool Number(size_t i, const char* name, double lo, double hi, std::optional<double>* out) {
    out->reset();
    const std::string_view s = f_[i];
    if (s.empty()) return true;
    const bool ok_chars = std::all_of(
        s.begin(), s.end(), [](char c) { return (c >= '0' && c <= '9') || c == '.' || c == '-'; });
    double v = 0;
    const char* end = s.data() + s.size();
    auto [ptr, ec] = std::from_chars(s.data(), end, v, std::chars_format::fixed);
    if (!ok_chars || ec != std::errc() || ptr != end || !std::isfinite(v)) {
      return Fail(NmeaErrorKind::kBadNumber, i, name, "not a decimal number");
    }
    if (v < lo || v > hi) {
      std::ostringstream os;
      os << "outside [" << lo << ", " << hi << "]";
      return Fail(NmeaErrorKind::kOutOfRange, i, name, os.str());
    }
    *out = v;
    return true;
  }
  bool Integer(size_t i, const char* name, int lo, int hi, std::optional<int>* out) {
    out->reset();
    const std::string_view s = f_[i];
    if (s.empty()) return true;
    if (!IsDigits(s) || s.size() > 6)
      return Fail(NmeaErrorKind::kBadNumber, i, name, "not an integer");
    int v = 0;
    std::from_chars(s.data(), s.data() + s.size(), v);
    if (v < lo || v > hi) {
      return Fail(NmeaErrorKind::kOutOfRange, i, name,
                  "outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
    }
    *out = v;
    return true;
  }
  bool Letter(size_t i, const char* name, std::string_view allowed, std::optional<char>* out) {
    out->reset();
    const std::string_view s = f_[i];
    if (s.empty()) return true;
    if (s.size() != 1 || allowed.find(s[0]) == std::string_view::npos) {
      return Fail(NmeaErrorKind::kBadNumber, i, name,
                  "expected one of '" + std::string(allowed) + "'");
    }
    *out = s[0];
    return true;
  }
  // hhmmss[.sss] -> ms since midnight.
  bool TimeOfDay(size_t i, std::optional<int64_t>* out) {
    out->reset();
    const std::string_view s = f_[i];
    if (s.empty()) return true;
    const std::string_view whole = s.substr(0, 6);
    const std::string_view frac = s.size() > 6 ? s.substr(6) : std::string_view();
    if (!IsDigits(whole) || whole.size() != 6 ||
        !(frac.empty() || (frac.size() >= 2 && frac[0] == '.' && IsDigits(frac.substr(1))))) {
      return Fail(NmeaErrorKind::kBadNumber, i, "time", "expected hhmmss[.sss]");
    }
    const int hh = (s[0] - '0') * 10 + (s[1] - '0');
    const int mm = (s[2] - '0') * 10 + (s[3] - '0');
    const int ss = (s[4] - '0') * 10 + (s[5] - '0');
    // Second 60 is a leap second; POSIX time cannot hold it, it folds onto the next second.
    if (hh > 23 || mm > 59 || ss > 60) {
      return Fail(NmeaErrorKind::kOutOfRange, i, "time", "hour, minute or second out of range");
    }
    double f = 0;
    if (!frac.empty()) {
      // At most millisecond resolution is kept; more digits are rounded.
      std::string digits(frac.substr(1, 9));
      f = std::strtod(("0." + digits).c_str(), nullptr);
    }
    int64_t ms = ((hh * 60 + mm) * 60 + ss) * 1000LL + std::llround(f * 1000.0);
    if (ms >= kMsPerDay) ms = kMsPerDay - 1;  // 23:59:60.x, kept inside the day
    *out = ms;
    return true;
  }
  // (d)ddmm.mmmm + hemisphere -> signed degrees.
  bool Angle(size_t i, size_t hemi_i, int deg_digits, const char* name,
             std::optional<double>* out) {
    out->reset();
    const std::string_view s = f_[i];
    const std::string_view h = f_[hemi_i];
    if (s.empty() && h.empty()) return true;
    if (s.empty()) return Fail(NmeaErrorKind::kMissingField, i, name, "empty but hemisphere given");
    const size_t dot = s.find('.');
    const std::string_view int_part = s.substr(0, dot);
    const std::string_view frac =
        dot == std::string_view::npos ? std::string_view() : s.substr(dot + 1);
    if (!IsDigits(int_part) || int_part.size() != static_cast<size_t>(deg_digits + 2) ||
        (dot != std::string_view::npos && !IsDigits(frac))) {
      return Fail(NmeaErrorKind::kBadNumber, i, name,
                  deg_digits == 2 ? "expected ddmm.mmmm" : "expected dddmm.mmmm");
    }
    int deg = 0;
    std::from_chars(s.data(), s.data() + deg_digits, deg);
    double minutes = 0;
    std::from_chars(s.data() + deg_digits, s.data() + s.size(), minutes, std::chars_format::fixed);
    const int max_deg = deg_digits == 2 ? 90 : 180;
    if (minutes >= 60.0) return Fail(NmeaErrorKind::kOutOfRange, i, name, "minutes >= 60");
    const double value = deg + minutes / 60.0;
    if (value > max_deg) {
      return Fail(NmeaErrorKind::kOutOfRange, i, name,
                  "more than " + std::to_string(max_deg) + " degrees");
    }
    const char* allowed = deg_digits == 2 ? "NS" : "EW";
    if (h.size() != 1 || std::string_view(allowed).find(h[0]) == std::string_view::npos) {
      return Fail(NmeaErrorKind::kBadNumber, hemi_i, "hemisphere",
                  std::string("expected ") + allowed[0] + " or " + allowed[1]);
    }
    *out = (h[0] == 'S' || h[0] == 'W') ? -value : value;
    return true;
  }

  NmeaSentenceError error;

 private:
  std::string_view address_;
  std::vector<std::string_view> f_;
};

}  // namespace

const char* NmeaErrorKindName(NmeaErrorKind kind) {
  switch (kind) {
    case NmeaErrorKind::kFraming:
      return "framing";
    case NmeaErrorKind::kMissingChecksum:
      return "missing checksum";
    case NmeaErrorKind::kBadChecksum:
      return "bad checksum";
    case NmeaErrorKind::kTruncated:
      return "truncated";
    case NmeaErrorKind::kBadNumber:
      return "bad number";
    case NmeaErrorKind::kOutOfRange:
      return "out of range";
    case NmeaErrorKind::kMissingField:
      return "missing field";
  }
  return "unknown";
}

std::string NmeaStats::Summary() const {
  std::ostringstream os;
  os << lines << " lines, " << accepted << " accepted, " << ignored << " ignored, " << rejected
     << " rejected";
  bool first = true;
  for (int k = 0; k < kNmeaErrorKinds; ++k) {
    if (by_kind[k] == 0) continue;
    os << (first ? " (" : ", ") << NmeaErrorKindName(static_cast<NmeaErrorKind>(k)) << " "
       << by_kind[k];
    first = false;
  }
  if (!first) os << ")";
  os << ", " << epochs << " epochs";
  if (missing_geoid > 0) os << ", " << missing_geoid << " GGA without geoid separation";
  return os.str();
}

uint8_t NmeaChecksum(std::string_view body) {
  uint8_t x = 0;
  for (char c : body) x ^= static_cast<uint8_t>(c);
  return x;
}

bool NmeaDecoder::Reject(NmeaErrorKind kind, std::string message, std::string* why) {
  ++stats_.rejected;
  ++stats_.by_kind[static_cast<int>(kind)];
  if (why) *why = message;
  stats_.last_error = NmeaSentenceError{kind, std::move(message)};
  return false;
}

void NmeaDecoder::EnterEpoch(int64_t tod_ms, std::optional<UtcTime> received) {
  if (cur_.open && cur_.tod_ms == tod_ms) return;
  if (cur_.open) CloseEpoch();
  cur_ = Epoch{};
  cur_.open = true;
  cur_.tod_ms = tod_ms;
  cur_.received = received;
}

void NmeaDecoder::CloseEpoch() {
  if (!cur_.open) return;
  if (auto fix = Build(cur_)) {
    last_epoch_fix_ = fix;
    last_epoch_types_ = cur_.types;
    ++stats_.epochs;
  }
  cur_ = Epoch{};
}

void NmeaDecoder::Flush() { CloseEpoch(); }

std::optional<GpsFix> NmeaDecoder::Build(const Epoch& e) const {
  if (!e.open || (!e.gga_quality && !e.rmc_status)) return std::nullopt;
  int64_t day = 0;
  if (e.day) {
    day = *e.day;
  } else if (anchor_day_) {
    // The candidate day whose instant is closest to the last dated sentence (midnight wrap).
    const int64_t anchor = *anchor_day_ * kMsPerDay + anchor_tod_ms_;
    int64_t best = 0, best_dist = -1;
    for (int64_t d = *anchor_day_ - 1; d <= *anchor_day_ + 1; ++d) {
      const int64_t dist = std::llabs(d * kMsPerDay + e.tod_ms - anchor);
      if (best_dist < 0 || dist < best_dist) best = d, best_dist = dist;
    }
    day = best;
  } else {
    return std::nullopt;
  }
  GpsFix f;
  f.utc.ns = (day * kMsPerDay + e.tod_ms) * 1000000;
  f.received_utc = e.received;
  int mode = 0;
  if (e.gga_quality) {
    mode = *e.gga_quality == 0 ? 0 : (e.alt_msl_m ? 3 : 2);
  } else if (e.rmc_status) {
    mode = *e.rmc_status == 'A' ? 2 : 0;
  }
  if (e.gsa_mode && mode != 0) mode = *e.gsa_mode == 1 ? 0 : *e.gsa_mode;
  if (e.rmc_status && *e.rmc_status != 'A' && !e.gga_quality) mode = 0;
  if (!e.has_position) mode = 0;
  if (mode == 3 && !e.alt_msl_m) mode = 2;
  f.mode = mode;
  if (mode >= 2) {
    f.lat_deg = e.lat_deg;
    f.lon_deg = e.lon_deg;
    if (e.alt_msl_m) f.height_m = *e.alt_msl_m + e.geoid_sep_m.value_or(0.0);
  }
  f.satellites = e.gga_satellites ? *e.gga_satellites : e.gsa_satellites;
  f.hdop = e.gga_hdop ? *e.gga_hdop : (e.gsa_hdop ? *e.gsa_hdop : 99.0);
  return f;
}

std::optional<GpsFix> NmeaDecoder::Fix() const {
  const bool complete = (cur_.types & last_epoch_types_) == last_epoch_types_;
  if (!last_epoch_fix_ || complete) {
    if (auto f = Build(cur_)) return f;
  }
  return last_epoch_fix_;
}

bool NmeaDecoder::Feed(std::string_view line, std::string* why, std::optional<UtcTime> received) {
  ++stats_.lines;
  while (!line.empty() && (line.back() == '\n' || line.back() == '\r' || line.back() == ' ' ||
                           line.back() == '\t')) {
    line.remove_suffix(1);
  }
  while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
  if (line.empty()) {
    ++stats_.blank;
    return true;
  }
  // Bytes before the last '$' are line noise ('$' is reserved and never inside a sentence).
  const size_t dollar = line.rfind('$');
  if (dollar == std::string_view::npos) {
    return Reject(NmeaErrorKind::kFraming, "no '$' in line", why);
  }
  line.remove_prefix(dollar);
  if (line.size() > kMaxSentence) {
    return Reject(NmeaErrorKind::kFraming,
                  "sentence of " + std::to_string(line.size()) + " characters (max " +
                      std::to_string(kMaxSentence) + ")",
                  why);
  }
  for (char c : line) {
    if (c < 0x20 || c > 0x7e) return Reject(NmeaErrorKind::kFraming, "non-printable byte", why);
  }
  const size_t star = line.find('*');
  if (star == std::string_view::npos) {
    return Reject(NmeaErrorKind::kMissingChecksum, "no '*HH' checksum", why);
  }
  const std::string_view body = line.substr(1, star - 1);
  const std::string_view sum = line.substr(star + 1);
  const std::string_view address_view = body.substr(0, body.find(','));
  const std::string address(address_view);
  if (sum.size() != 2 || HexValue(sum[0]) < 0 || HexValue(sum[1]) < 0) {
    return Reject(NmeaErrorKind::kBadChecksum,
                  address + ": checksum '" + std::string(sum) + "' is not two hex digits", why);
  }
  const int given = HexValue(sum[0]) * 16 + HexValue(sum[1]);
  const int computed = NmeaChecksum(body);
  if (given != computed) {
    char buf[80];
    std::snprintf(buf, sizeof(buf), ": checksum %02X, computed %02X", given, computed);
    return Reject(NmeaErrorKind::kBadChecksum, address + buf, why);
  }
  const bool alnum = std::all_of(address.begin(), address.end(), [](char c) {
    return (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
  });
  if (address.size() < 2 || !alnum) {
    return Reject(NmeaErrorKind::kFraming, "bad address field '" + address + "'", why);
  }
  if (address[0] == 'P' || address.size() != 5) {  // proprietary or unknown: valid, unused
    ++stats_.ignored;
    return true;
  }
  const std::string talker = address.substr(0, 2), type = address.substr(2);
  static const char* const kTalkers[] = {"GP", "GN", "GL", "GA", "GB"};
  const bool talker_ok = std::any_of(std::begin(kTalkers), std::end(kTalkers),
                                     [&](const char* t) { return talker == t; });
  if (!talker_ok || (type != "GGA" && type != "RMC" && type != "ZDA" && type != "GSA")) {
    ++stats_.ignored;
    return true;
  }

  Fields f(address_view, Split(body));
  auto need = [&](size_t n) {
    if (f.size() >= n) return true;
    f.error = NmeaSentenceError{NmeaErrorKind::kTruncated,
                                address + ": " + std::to_string(f.size() - 1) +
                                    " fields, expected at least " + std::to_string(n - 1)};
    return false;
  };
  auto fail = [&]() { return Reject(f.error.kind, f.error.message, why); };

  if (type == "GGA") {
    // time, lat, N/S, lon, E/W, quality, sats, hdop, alt, M, sep, M, age, station
    if (!need(15)) return fail();
    std::optional<int64_t> tod;
    std::optional<double> lat, lon, hdop, alt, sep;
    std::optional<int> quality, sats;
    std::optional<char> alt_unit, sep_unit;
    if (!f.Require(1, "time") || !f.TimeOfDay(1, &tod)) return fail();
    if (!f.Require(6, "quality") || !f.Integer(6, "quality", 0, 8, &quality)) return fail();
    if (!f.Angle(2, 3, 2, "latitude", &lat) || !f.Angle(4, 5, 3, "longitude", &lon)) return fail();
    if (*quality > 0 && (!lat || !lon)) {
      return Reject(NmeaErrorKind::kMissingField,
                    address + ": quality " + std::to_string(*quality) + " without a position", why);
    }
    if (!f.Integer(7, "satellites", 0, 99, &sats) || !f.Number(8, "hdop", 0, 100, &hdop) ||
        !f.Number(9, "altitude", -1500, 100000, &alt) ||
        !f.Letter(10, "altitude unit", "M", &alt_unit) ||
        !f.Number(11, "geoid separation", -200, 200, &sep) ||
        !f.Letter(12, "separation unit", "M", &sep_unit)) {
      return fail();
    }
    EnterEpoch(*tod, received);
    cur_.types |= kGga;
    cur_.gga_quality = *quality;
    if (*quality > 0) {
      cur_.has_position = true;
      cur_.lat_deg = *lat;
      cur_.lon_deg = *lon;
      cur_.alt_msl_m = alt;
      cur_.geoid_sep_m = sep;
      if (alt && !sep) ++stats_.missing_geoid;
    }
    cur_.gga_satellites = sats;
    cur_.gga_hdop = hdop;
  } else if (type == "RMC") {
    // time, status, lat, N/S, lon, E/W, speed kn, course, ddmmyy, magvar, E/W[, mode[, nav]]
    if (!need(12)) return fail();
    std::optional<int64_t> tod;
    std::optional<char> status, mode_ind;
    std::optional<double> lat, lon;
    if (!f.Require(1, "time") || !f.TimeOfDay(1, &tod)) return fail();
    if (!f.Require(2, "status") || !f.Letter(2, "status", "AV", &status)) return fail();
    if (!f.Angle(3, 4, 2, "latitude", &lat) || !f.Angle(5, 6, 3, "longitude", &lon)) return fail();
    if (f.size() > 12 && !f.Letter(12, "mode", "ADEFMNPRS", &mode_ind)) return fail();
    if (*status == 'A' && (!lat || !lon)) {
      return Reject(NmeaErrorKind::kMissingField, address + ": status A without a position", why);
    }
    std::optional<int64_t> day;
    const std::string_view d = f[9];
    if (!d.empty()) {
      if (!IsDigits(d) || d.size() != 6) {
        f.Fail(NmeaErrorKind::kBadNumber, 9, "date", "expected ddmmyy");
        return fail();
      }
      const int dd = (d[0] - '0') * 10 + (d[1] - '0');
      const int mm = (d[2] - '0') * 10 + (d[3] - '0');
      const int yy = (d[4] - '0') * 10 + (d[5] - '0');
      const int year = yy < 80 ? 2000 + yy : 1900 + yy;  // GPS dates start in 1980
      if (mm < 1 || mm > 12 || dd < 1 || dd > DaysInMonth(year, mm)) {
        f.Fail(NmeaErrorKind::kOutOfRange, 9, "date", "no such day");
        return fail();
      }
      day = DayNumber(year, mm, dd);
    }
    EnterEpoch(*tod, received);
    cur_.types |= kRmc;
    cur_.rmc_status = (mode_ind && *mode_ind == 'N') ? 'V' : *status;
    if (*cur_.rmc_status == 'A' && !cur_.has_position) {
      cur_.has_position = true;
      cur_.lat_deg = *lat;
      cur_.lon_deg = *lon;
    }
    if (day) {
      cur_.day = day;
      anchor_day_ = day;
      anchor_tod_ms_ = *tod;
    }
  } else if (type == "ZDA") {
    // time, day, month, year, zone hours, zone minutes
    if (!need(7)) return fail();
    std::optional<int64_t> tod;
    std::optional<int> dd, mm, yyyy;
    if (!f.Require(1, "time") || !f.TimeOfDay(1, &tod) || !f.Require(2, "day") ||
        !f.Integer(2, "day", 1, 31, &dd) || !f.Require(3, "month") ||
        !f.Integer(3, "month", 1, 12, &mm) || !f.Require(4, "year") ||
        !f.Integer(4, "year", 1980, 2200, &yyyy)) {
      return fail();
    }
    if (*dd > DaysInMonth(*yyyy, *mm)) {
      f.Fail(NmeaErrorKind::kOutOfRange, 2, "day", "no such day in that month");
      return fail();
    }
    EnterEpoch(*tod, received);
    cur_.types |= kZda;
    cur_.day = DayNumber(*yyyy, *mm, *dd);
    anchor_day_ = cur_.day;
    anchor_tod_ms_ = *tod;
  } else {  // GSA: M/A, mode, 12 satellite ids, PDOP, HDOP, VDOP[, system id]
    if (!need(18)) return fail();
    std::optional<char> sel;
    std::optional<int> mode;
    std::optional<double> pdop, hdop, vdop;
    if (!f.Letter(1, "selection", "MA", &sel) || !f.Require(2, "mode") ||
        !f.Integer(2, "mode", 1, 3, &mode)) {
      return fail();
    }
    int used = 0;
    for (size_t i = 3; i <= 14; ++i) {
      std::optional<int> prn;
      if (!f.Integer(i, "satellite id", 1, 999, &prn)) return fail();
      if (prn) ++used;
    }
    if (!f.Number(15, "pdop", 0, 100, &pdop) || !f.Number(16, "hdop", 0, 100, &hdop) ||
        !f.Number(17, "vdop", 0, 100, &vdop)) {
      return fail();
    }
    // Belongs to the open epoch (multi-constellation receivers send one GSA per system).
    cur_.types |= kGsa;
    cur_.gsa_mode = std::max(cur_.gsa_mode.value_or(1), *mode);
    cur_.gsa_satellites += used;
    if (hdop) cur_.gsa_hdop = hdop;
  }
  ++stats_.accepted;
  return true;
}

}  // namespace rouen
