// A camera response curve per channel (Debevec & Malik 1997): g(z) = ln(exposure) for each
// 8-bit digital number z, where exposure = relative radiance x seconds x gain x ND
// transmission. Defined up to one scale shared by all channels.
#pragma once

#include <array>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

namespace rouen {

struct ResponseCurve {
  std::array<std::vector<double>, 3> g;  // 256 entries per channel, non-decreasing

  bool valid() const;
  // ln exposure for a (possibly fractional) digital number, linear between entries.
  double LogExposure(int channel, double z) const;
  // Digital number (0..255, fractional) that an exposure produces; clamps at the ends.
  double DigitalValue(int channel, double exposure) const;
};

void to_json(nlohmann::json& j, const ResponseCurve& r);
void from_json(const nlohmann::json& j, ResponseCurve& r);  // validates; throws rouen::Error
ResponseCurve ReadResponseCurve(const std::string& path);   // JSON file
void WriteResponseCurve(const std::string& path, const ResponseCurve& r);

}  // namespace rouen
