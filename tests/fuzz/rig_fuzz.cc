// Rig files (capture/rig.h ParseRig, strict TOML keys). A rig that parses is one the capture
// can use: site in range, camera and GPS settings in their ranges, a valid bracket and plan.
#include <cmath>
#include <string>

#include "capture/rig.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  const std::string text(fuzz::Text(data, size));
  RigConfig rig;
  if (!fuzz::Accepts([&] { rig = ParseRig(text, "fuzz-rig.toml"); }, "fuzz-rig.toml")) return 0;
  bool known = false;
  for (const std::string& k : RigKinds()) known |= k == rig.kind;
  FUZZ_CHECK(known, "kind " + rig.kind);
  FUZZ_CHECK(std::abs(rig.site.lat_deg) <= 90 && std::abs(rig.site.lon_deg) <= 180, "site");
  FUZZ_CHECK(std::isfinite(rig.site.height_m), "site height");
  FUZZ_CHECK(!rig.camera.id.empty(), "camera id");
  FUZZ_CHECK(rig.camera.timeout_s > 0 && rig.camera.timeout_s <= 600, "camera timeout");
  FUZZ_CHECK(rig.gps.timeout_s > 0 && rig.gps.timeout_s <= 60, "gps timeout");
  FUZZ_CHECK(rig.reconnect_timeout_s > 0 && rig.reconnect_timeout_s <= 3600, "reconnect");
  for (double d : rig.sun_nd_density_rgb) FUZZ_CHECK(d >= 0 && d < 10, "ND density");
  FUZZ_CHECK(rig.plan.slots.size() == rig.slot_labels.size(), "slots and labels");
  FUZZ_CHECK(rig.heldout_slot >= -1 && rig.heldout_slot < static_cast<int>(rig.slot_labels.size()),
             "heldout slot");
  for (const auto& [target, views] : rig.views) FUZZ_CHECK(views >= 1 && views <= 64, "views");
  // The plan must pass the checks the capture runs before its first frame (field rigs get
  // their one slot, "now", at capture time).
  CapturePlan plan = rig.plan;
  if (plan.slots.empty()) plan.slots.push_back(UtcTime{1780000000LL * 1000000000});
  FUZZ_CHECK(fuzz::Accepts([&] { plan.Validate(); }), "ParseRig accepted an invalid plan");
  for (Target t : {Target::kSun, Target::kSky, Target::kArchitecture}) (void)rig.LensPath(t);
  return 0;
}
