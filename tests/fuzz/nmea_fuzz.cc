// NMEA 0183 sentences (capture/nmea): every line of the input is fed to one decoder, as a
// log file or a serial port delivers them. The decoder never throws; a fix it reports has
// a position in range, a known mode and a plausible time.
#include <cmath>
#include <optional>
#include <string>

#include "capture/nmea/nmea.h"
#include "tests/fuzz/fuzz_util.h"

namespace rouen {
namespace {

void CheckFix(const GpsFix& f) {
  FUZZ_CHECK(f.mode == 0 || f.mode == 2 || f.mode == 3, "mode " + std::to_string(f.mode));
  FUZZ_CHECK(std::isfinite(f.lat_deg) && std::abs(f.lat_deg) <= 90, "latitude");
  FUZZ_CHECK(std::isfinite(f.lon_deg) && std::abs(f.lon_deg) <= 180, "longitude");
  FUZZ_CHECK(std::isfinite(f.height_m), "height");
  FUZZ_CHECK(std::isfinite(f.hdop) && f.hdop >= 0, "hdop");
  FUZZ_CHECK(f.satellites >= 0, "satellites");
  if (f.mode == 0) FUZZ_CHECK(f.lat_deg == 0 && f.lon_deg == 0, "a mode-0 fix has a position");
  // GPS dates: 1980 (RMC years 80..99 are 19xx) to the ZDA limit, 2200.
  const CivilTime c = ToCivil(f.utc);
  FUZZ_CHECK(c.year >= 1979 && c.year <= 2201, "fix year " + std::to_string(c.year));
}

}  // namespace
}  // namespace rouen

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  NmeaDecoder decoder;
  int64_t n = 0;
  fuzz::ForEachLine(fuzz::Text(data, size), [&](std::string_view line) {
    std::string why;
    // Every other line carries a laptop time, as a serial port gives it.
    std::optional<UtcTime> received;
    if (++n % 2 == 0) received = UtcTime{1780000000LL * 1000000000 + n * 100000000};
    const bool ok = decoder.Feed(line, &why, received);
    FUZZ_CHECK(ok || !why.empty(), "rejected without a reason");
    if (auto fix = decoder.Fix()) CheckFix(*fix);
  });
  decoder.Flush();
  if (auto fix = decoder.LastEpochFix()) CheckFix(*fix);
  const NmeaStats& s = decoder.stats();
  FUZZ_CHECK(s.lines == n, "lines counted");
  FUZZ_CHECK(s.blank + s.accepted + s.ignored + s.rejected == s.lines, s.Summary());
  int64_t by_kind = 0;
  for (int64_t k : s.by_kind) by_kind += k;
  FUZZ_CHECK(by_kind == s.rejected, s.Summary());
  return 0;
}
