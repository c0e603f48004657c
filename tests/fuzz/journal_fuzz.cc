// Session journal lines (core/session.h ParseJournalLine, frames.jsonl): each line of the
// input is one record. An accepted record has finite numbers, valid intrinsics and pose, a
// group (when it has one) of its own slot and target, and the line the writer journals for it
// reads back as the same record.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/session.h"
#include "tests/fuzz/fuzz_util.h"

namespace rouen {
namespace {

// An integer in the line reads as that integer, not another (e.g. truncated to 32 bits).
void CheckSameInteger(const nlohmann::json& j, int64_t parsed, const char* key) {
  FUZZ_CHECK(j.dump() == std::to_string(parsed),
             std::string(key) + " " + j.dump() + " read as " + std::to_string(parsed));
}

void CheckRecord(const FrameRecord& f, const nlohmann::json& j) {
  CheckSameInteger(j["id"], f.id, "id");
  if (j.contains("slot")) CheckSameInteger(j["slot"], f.slot, "slot");
  if (f.gps) {
    CheckSameInteger(j["gps"]["mode"], f.gps->mode, "gps mode");
    CheckSameInteger(j["gps"]["satellites"], f.gps->satellites, "gps satellites");
  }
  if (f.intrinsics) {
    CheckSameInteger(j["intrinsics"]["width"], f.intrinsics->width, "intrinsics width");
    CheckSameInteger(j["intrinsics"]["height"], f.intrinsics->height, "intrinsics height");
  }
  for (double v :
       {f.exposure_s, f.gain, f.aperture_f, f.nd_density, f.sun_azimuth_deg, f.sun_elevation_deg}) {
    FUZZ_CHECK(std::isfinite(v), "non-finite number in a record");
  }
  if (f.gps) {
    for (double v : {f.gps->lat_deg, f.gps->lon_deg, f.gps->height_m, f.gps->hdop})
      FUZZ_CHECK(std::isfinite(v), "non-finite GPS number");
  }
  if (f.intrinsics) FUZZ_CHECK(fuzz::Accepts([&] { f.intrinsics->Validate(); }), "intrinsics");
  if (f.pose) {
    FUZZ_CHECK(f.pose->rotation.allFinite() && f.pose->position.allFinite(), "pose");
  }
  // Consistency: a frame files into its group's bracket, so an accepted group names a view of
  // the frame's own slot and target (else the frame would merge into another time's bracket).
  if (!f.group.empty()) {
    BracketKey key;
    FUZZ_CHECK(fuzz::Accepts([&] { key = ParseBracketName(f.group); }),
               "accepted group " + f.group + " is not a bracket name");
    FUZZ_CHECK(key.slot == f.slot && key.target == f.target,
               "group " + f.group + " accepted for a frame of slot " + std::to_string(f.slot) +
                   ", target " + TargetName(f.target));
  }
}

}  // namespace
}  // namespace rouen

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  fuzz::ForEachLine(fuzz::Text(data, size), [](std::string_view line) {
    FrameRecord f;
    if (!fuzz::Accepts([&] { f = ParseJournalLine(line); })) return;
    CheckRecord(f, nlohmann::json::parse(line));
    // SessionWriter::Append journals json(record).dump(): Load and Resume must read it back.
    const std::string written = nlohmann::json(f).dump();
    FrameRecord back;
    FUZZ_CHECK(fuzz::Accepts([&] { back = ParseJournalLine(written); }),
               "the journalled form of an accepted record is refused: " + written);
    FUZZ_CHECK(nlohmann::json(back).dump() == written, "record changed on re-reading: " + written);
  });
  return 0;
}
