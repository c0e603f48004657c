// session.json (core/session.h ParseSessionInfo). Accepted info has a site in range and
// finite numbers, and what SessionWriter writes for it reads back the same.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/session.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  SessionInfo info;
  if (!fuzz::Accepts([&] { info = ParseSessionInfo(fuzz::Text(data, size), "session.json"); },
                     "session.json")) {
    return 0;
  }
  const nlohmann::json j = nlohmann::json::parse(fuzz::Text(data, size));
  FUZZ_CHECK(j["format_version"].dump() == std::to_string(info.format_version),
             "format_version " + j["format_version"].dump() + " read as " +
                 std::to_string(info.format_version));
  FUZZ_CHECK(std::abs(info.site.lat_deg) <= 90 && std::abs(info.site.lon_deg) <= 360, "site");
  FUZZ_CHECK(std::isfinite(info.site.height_m) && std::isfinite(info.clock_offset_s), "numbers");
  FUZZ_CHECK(info.extra.is_object(), "extra");
  const std::string written = nlohmann::json(info).dump(2) + "\n";
  SessionInfo back;
  FUZZ_CHECK(fuzz::Accepts([&] { back = ParseSessionInfo(written, "session.json"); }),
             "the written form of accepted info is refused: " + written);
  FUZZ_CHECK(nlohmann::json(back).dump(2) + "\n" == written, "info changed on re-reading");
  return 0;
}
