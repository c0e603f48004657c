// Lens files (core/lens.h ParseLensFile, rigs/lenses/*.json) and pose files (core/camera.h
// ParsePose); every input is tried as both. An accepted lens has valid intrinsics, a field
// limit in 0..180 and a vignetting model that stays above 0.05; an accepted pose is a finite
// proper rotation.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/camera.h"
#include "core/lens.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  const std::string_view text = fuzz::Text(data, size);
  LensFile lens;
  if (fuzz::Accepts([&] { lens = ParseLensFile(text, "lens.json"); }, "lens.json")) {
    const Intrinsics& k = lens.intrinsics;
    // Sizes read as written, not truncated to another integer.
    const nlohmann::json j = nlohmann::json::parse(text);
    FUZZ_CHECK(j["width"].dump() == std::to_string(k.width), "width " + j["width"].dump());
    FUZZ_CHECK(j["height"].dump() == std::to_string(k.height), "height " + j["height"].dump());
    FUZZ_CHECK(fuzz::Accepts([&] { k.Validate(); }), "accepted lens has invalid intrinsics");
    FUZZ_CHECK(lens.max_field_deg >= 0 && lens.max_field_deg <= 180, "max_field_deg");
    if (lens.vignetting) {
      const VignettingModel& v = *lens.vignetting;
      const nlohmann::json& jv = j["vignetting"];
      FUZZ_CHECK(jv["width"].dump() == std::to_string(v.width), "vignetting width");
      FUZZ_CHECK(jv["height"].dump() == std::to_string(v.height), "vignetting height");
      FUZZ_CHECK(fuzz::Accepts([&] { v.Validate(); }), "accepted vignetting is invalid");
      for (double x : {0.0, double(v.width)})
        for (double y : {0.0, double(v.height)})
          FUZZ_CHECK(v.Falloff(x, y) > 0.05, "fall-off at a corner");
    }
  }
  Pose pose;
  if (fuzz::Accepts([&] { pose = ParsePose(text, "pose.json"); }, "pose.json")) {
    FUZZ_CHECK(pose.rotation.allFinite() && pose.position.allFinite(), "non-finite pose");
    const double ortho =
        (pose.rotation.transpose() * pose.rotation - Eigen::Matrix3d::Identity()).norm();
    FUZZ_CHECK(ortho <= 1e-6 && pose.rotation.determinant() > 0, "not a proper rotation");
  }
  return 0;
}
