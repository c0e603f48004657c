#include "core/time.h"

#include <chrono>
#include <cmath>
#include <cstdio>

#include "core/error.h"

namespace rouen {
namespace {

constexpr int64_t kNsPerSecond = 1000000000LL;
constexpr int64_t kNsPerDay = 86400LL * kNsPerSecond;
constexpr int kMinYear = 1678, kMaxYear = 2261;  // ParseIso8601

// Days since 1970-01-01 of a proleptic Gregorian date (Hinnant's days_from_civil).
int64_t DaysFromCivil(int64_t y, int m, int d) {
  y -= m <= 2;
  const int64_t era = (y >= 0 ? y : y - 399) / 400;
  const int64_t yoe = y - era * 400;                                   // [0, 399]
  const int64_t doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;  // [0, 365]
  const int64_t doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;           // [0, 146096]
  return era * 146097 + doe - 719468;
}

void CivilFromDays(int64_t z, int64_t* y, int* m, int* d) {
  z += 719468;
  const int64_t era = (z >= 0 ? z : z - 146096) / 146097;
  const int64_t doe = z - era * 146097;
  const int64_t yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const int64_t mp = (5 * doy + 2) / 153;
  *d = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
  *m = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
  *y = yoe + era * 400 + (*m <= 2);
}

bool IsLeap(int64_t y) { return (y % 4 == 0 && y % 100 != 0) || y % 400 == 0; }

int DaysInMonth(int64_t y, int m) {
  static const int kDays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  return m == 2 && IsLeap(y) ? 29 : kDays[m - 1];
}

int64_t FloorDiv(int64_t a, int64_t b) {
  int64_t q = a / b;
  if ((a % b != 0) && ((a < 0) != (b < 0))) --q;
  return q;
}

class Parser {
 public:
  explicit Parser(std::string_view text) : text_(text) {}

  [[noreturn]] void Fail(const std::string& problem) const {
    throw Error("bad ISO 8601 time \"" + std::string(text_) + "\": " + problem);
  }
  bool AtEnd() const { return pos_ >= text_.size(); }
  char Peek() const { return AtEnd() ? '\0' : text_[pos_]; }
  int Digits(int n, const char* what) {
    int v = 0;
    for (int i = 0; i < n; ++i) {
      if (AtEnd() || text_[pos_] < '0' || text_[pos_] > '9') {
        Fail(std::string("expected ") + std::to_string(n) + " digits for the " + what);
      }
      v = v * 10 + (text_[pos_++] - '0');
    }
    return v;
  }
  void Expect(char c, const char* what) {
    if (Peek() != c) Fail(std::string("expected '") + c + "' " + what);
    ++pos_;
  }
  size_t pos_ = 0;
  std::string_view text_;
};

}  // namespace

UtcTime UtcTime::FromUnixSeconds(double s) {
  return UtcTime{static_cast<int64_t>(std::llround(s * 1e9))};
}

UtcTime UtcTime::PlusSeconds(double s) const {
  return UtcTime{ns + static_cast<int64_t>(std::llround(s * 1e9))};
}

std::string UtcTime::Iso8601(int digits) const {
  if (digits < 0) digits = 0;
  if (digits > 9) digits = 9;
  int64_t pow10 = 1;
  for (int i = 0; i < 9 - digits; ++i) pow10 *= 10;
  // Round to the requested precision first so that carries reach the seconds.
  int64_t rounded = FloorDiv(ns + pow10 / 2, pow10) * pow10;
  const int64_t days = FloorDiv(rounded, kNsPerDay);
  int64_t rem = rounded - days * kNsPerDay;
  int64_t y;
  int m, d;
  CivilFromDays(days, &y, &m, &d);
  const int hh = static_cast<int>(rem / (3600 * kNsPerSecond));
  rem -= hh * 3600 * kNsPerSecond;
  const int mm = static_cast<int>(rem / (60 * kNsPerSecond));
  rem -= mm * 60 * kNsPerSecond;
  const int ss = static_cast<int>(rem / kNsPerSecond);
  rem -= ss * kNsPerSecond;
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%04lld-%02d-%02dT%02d:%02d:%02d", static_cast<long long>(y), m,
                d, hh, mm, ss);
  std::string out = buf;
  if (digits > 0) {
    char frac[16];
    std::snprintf(frac, sizeof(frac), "%09lld", static_cast<long long>(rem));
    out += '.';
    out.append(frac, digits);
  }
  out += 'Z';
  return out;
}

UtcTime ParseIso8601(std::string_view text) {
  Parser p(text);
  if (text.empty()) p.Fail("empty");
  const int year = p.Digits(4, "year");
  // Nanoseconds in an int64 span 1677-09-21 .. 2262-04-11; whole years inside that (an
  // offset moves the instant by less than a day).
  if (year < kMinYear || year > kMaxYear) {
    p.Fail("year " + std::to_string(year) + " is outside " + std::to_string(kMinYear) + ".." +
           std::to_string(kMaxYear) + " (the range of rouen's nanosecond times)");
  }
  p.Expect('-', "after the year");
  const int month = p.Digits(2, "month");
  p.Expect('-', "after the month");
  const int day = p.Digits(2, "day");
  if (p.Peek() != 'T' && p.Peek() != 't' && p.Peek() != ' ') {
    p.Fail("expected 'T' or a space between date and time");
  }
  ++p.pos_;
  const int hour = p.Digits(2, "hour");
  p.Expect(':', "after the hour");
  const int minute = p.Digits(2, "minute");
  p.Expect(':', "after the minute");
  const int second = p.Digits(2, "second");
  int64_t frac_ns = 0;
  if (p.Peek() == '.' || p.Peek() == ',') {
    ++p.pos_;
    int n = 0;
    int64_t scale = 100000000;
    while (!p.AtEnd() && p.Peek() >= '0' && p.Peek() <= '9') {
      if (n == 9) p.Fail("more than 9 fractional-second digits");
      frac_ns += (p.Peek() - '0') * scale;
      scale /= 10;
      ++n;
      ++p.pos_;
    }
    if (n == 0) p.Fail("no digits after the decimal point");
  }
  if (month < 1 || month > 12) p.Fail("month " + std::to_string(month) + " out of range");
  if (day < 1 || day > DaysInMonth(year, month)) {
    p.Fail("day " + std::to_string(day) + " out of range for the month");
  }
  if (hour > 23) p.Fail("hour " + std::to_string(hour) + " out of range");
  if (minute > 59) p.Fail("minute " + std::to_string(minute) + " out of range");
  // POSIX time has no leap seconds, so ":60" is refused rather than folded into the next minute.
  if (second == 60) p.Fail("leap second :60 is not representable (POSIX time scale)");
  if (second > 59) p.Fail("second " + std::to_string(second) + " out of range");
  int64_t offset_s = 0;
  if (p.AtEnd()) p.Fail("no UTC offset (add Z or +HH:MM)");
  if (p.Peek() == 'Z' || p.Peek() == 'z') {
    ++p.pos_;
  } else if (p.Peek() == '+' || p.Peek() == '-') {
    const int sign = p.Peek() == '-' ? -1 : 1;
    ++p.pos_;
    const int oh = p.Digits(2, "offset hours");
    if (p.Peek() == ':') ++p.pos_;
    const int om = p.Digits(2, "offset minutes");
    if (oh > 23 || om > 59) p.Fail("UTC offset out of range");
    offset_s = sign * (oh * 3600 + om * 60);
  } else {
    p.Fail("expected Z or a +HH:MM offset after the seconds");
  }
  if (!p.AtEnd()) p.Fail("unexpected text after the offset");
  const int64_t days = DaysFromCivil(year, month, day);
  const int64_t secs = days * 86400 + hour * 3600 + minute * 60 + second - offset_s;
  return UtcTime{secs * kNsPerSecond + frac_ns};
}

CivilTime ToCivil(UtcTime t) {
  const int64_t days = FloorDiv(t.ns, kNsPerDay);
  int64_t rem = t.ns - days * kNsPerDay;
  int64_t y;
  int m, d;
  CivilFromDays(days, &y, &m, &d);
  CivilTime c{};
  c.year = static_cast<int>(y);
  c.month = m;
  c.day = d;
  c.hour = static_cast<int>(rem / (3600 * kNsPerSecond));
  rem -= c.hour * 3600 * kNsPerSecond;
  c.minute = static_cast<int>(rem / (60 * kNsPerSecond));
  rem -= c.minute * 60 * kNsPerSecond;
  c.second = static_cast<double>(rem) * 1e-9;
  return c;
}

UtcTime FromCivil(const CivilTime& c) {
  // Months outside 1..12 are normalised into the year so that callers may do arithmetic.
  int64_t y = c.year + FloorDiv(c.month - 1, 12);
  const int m = static_cast<int>(c.month - 1 - FloorDiv(c.month - 1, 12) * 12) + 1;
  const int64_t days = DaysFromCivil(y, m, 1) + (c.day - 1);
  const int64_t whole =
      (days * 86400 + int64_t{c.hour} * 3600 + int64_t{c.minute} * 60) * kNsPerSecond;
  return UtcTime{whole + static_cast<int64_t>(std::llround(c.second * 1e9))};
}

UtcTime NowUtc() {
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  return UtcTime{std::chrono::duration_cast<std::chrono::nanoseconds>(now).count()};
}

}  // namespace rouen
