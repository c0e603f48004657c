// UTC instants with nanosecond resolution (no leap-second smearing: POSIX time scale).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace rouen {

struct UtcTime {
  int64_t ns = 0;  // nanoseconds since 1970-01-01T00:00:00Z

  static UtcTime FromUnixSeconds(double s);
  double UnixSeconds() const { return static_cast<double>(ns) * 1e-9; }
  // ISO 8601 with a Z suffix; `digits` fractional-second digits (0..9).
  std::string Iso8601(int digits = 3) const;
  UtcTime PlusSeconds(double s) const;
  friend auto operator<=>(const UtcTime&, const UtcTime&) = default;
};

// Parses "YYYY-MM-DDTHH:MM:SS[.fff...](Z|+HH:MM|-HH:MM|+HHMM)" (also a space instead of T).
// A time without an offset is refused: field times must say which zone they are in. Years
// outside 1678..2261 (beyond the int64 nanoseconds of UtcTime) are refused.
// Throws rouen::Error naming the string and the problem.
UtcTime ParseIso8601(std::string_view text);

// Civil date-time (proleptic Gregorian, UTC) from an instant and back.
struct CivilTime {
  int year, month, day, hour, minute;
  double second;
};
CivilTime ToCivil(UtcTime t);
UtcTime FromCivil(const CivilTime& c);

UtcTime NowUtc();

}  // namespace rouen
