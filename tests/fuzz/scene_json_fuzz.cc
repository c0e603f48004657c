// A scene's scene.json, as a user or a broken disk may leave it (solve/scene.h ParseSceneJson,
// the part of ReadScene that reads the text). An accepted scene has its site in range, unit
// sun directions with finite non-negative radiances, valid environment maps, views of its own
// slots with valid cameras inside the site's frame, held-out and stereo slots in range, a
// stereo fit of as many regions as its grid; and each part the writer stores (sky, map, camera,
// stereo fit, ground field) reads back as written.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/limits.h"
#include "solve/scene.h"
#include "tests/fuzz/fuzz_util.h"

namespace rouen {
namespace {

// `value` written, read back and written again gives the same text.
template <typename T>
void CheckRoundTrip(const T& value, const char* what) {
  const nlohmann::json written = value;
  T back;
  FUZZ_CHECK(fuzz::Accepts([&] { back = written.get<T>(); }),
             std::string("the written ") + what + " is refused: " + written.dump());
  FUZZ_CHECK(nlohmann::json(back) == written, std::string(what) + " changed on re-reading");
}

void CheckScene(const SceneJson& parsed) {
  const SceneModel& s = parsed.scene;
  FUZZ_CHECK(std::abs(s.site.lat_deg) <= kMaxAbsLatitudeDeg &&
                 std::abs(s.site.lon_deg) <= kMaxAbsLongitudeDeg &&
                 s.site.height_m >= kMinHeightM && s.site.height_m <= kMaxHeightM,
             "site out of range");
  for (const SlotModel& slot : s.slots) {
    FUZZ_CHECK(std::abs(slot.sun_dir.norm() - 1) <= 1e-6, "sun direction not unit");
    FUZZ_CHECK(slot.sun_radiance.allFinite() && slot.sun_radiance.minCoeff() >= 0,
               "sun radiance negative or not finite");
    FUZZ_CHECK(slot.sun_solid_angle_sr > 0 && slot.sun_solid_angle_sr < 1, "sun size");
    FUZZ_CHECK(fuzz::Accepts([&] { slot.env.Validate(); }), "an accepted map is not valid");
    CheckRoundTrip(slot.sky, "sky");
    CheckRoundTrip(slot.env, "environment map");
  }
  const int slots = static_cast<int>(s.slots.size());
  for (const auto& [name, v] : s.views) {
    const SceneView& view = v;  // a binding, not capturable in C++20 by clang 14
    FUZZ_CHECK(view.slot >= 0 && view.slot < slots, "view " + name + " of no slot");
    FUZZ_CHECK(fuzz::Accepts([&] { view.intrinsics.Validate(); }), "view " + name + " intrinsics");
    FUZZ_CHECK(view.pose.position.allFinite() &&
                   view.pose.position.cwiseAbs().maxCoeff() <= kMaxCoordinateM,
               "view " + name + " outside the site's frame");
    CheckRoundTrip(view.intrinsics, "intrinsics");
    CheckRoundTrip(view.pose, "pose");
  }
  for (int h : s.holdout_slots) FUZZ_CHECK(h >= 0, "negative held-out slot");
  if (s.env_stereo) {
    const EnvStereoResult& st = *s.env_stereo;
    for (int slot : s.env_stereo_slots) FUZZ_CHECK(slot >= 0 && slot < slots, "stereo slot");
    FUZZ_CHECK(st.summary.times == static_cast<int>(s.env_stereo_slots.size()), "stereo times");
    FUZZ_CHECK(st.regions.size() == static_cast<size_t>(st.bands_below + st.bands_above) *
                                        st.sectors * st.layer_z.size(),
               "stereo regions");
    CheckRoundTrip(st, "stereo fit");
  }
  if (s.ground_field) CheckRoundTrip(*s.ground_field, "ground field");
  FUZZ_CHECK(
      parsed.retro.is_object() && parsed.sun_lobes.is_object() && parsed.sky_lobes.is_object(),
      "per-block albedo parts not objects");
}

}  // namespace
}  // namespace rouen

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  SceneJson parsed;
  if (!fuzz::Accepts([&] { parsed = ParseSceneJson(fuzz::Text(data, size), "scene.json"); },
                     "scene.json"))
    return 0;
  CheckScene(parsed);
  return 0;
}
