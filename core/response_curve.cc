#include "core/response_curve.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/files.h"

namespace rouen {

bool ResponseCurve::valid() const {
  for (const auto& ch : g) {
    if (ch.size() != 256) return false;
    for (size_t i = 0; i < ch.size(); ++i) {
      if (!std::isfinite(ch[i])) return false;
      if (i > 0 && ch[i] < ch[i - 1]) return false;
    }
  }
  return true;
}

double ResponseCurve::LogExposure(int channel, double z) const {
  const std::vector<double>& c = g[channel];
  const double zc = std::clamp(z, 0.0, 255.0);
  const int i = std::min(static_cast<int>(std::floor(zc)), 254);
  const double a = zc - i;
  return (1 - a) * c[i] + a * c[i + 1];
}

double ResponseCurve::DigitalValue(int channel, double exposure) const {
  const std::vector<double>& c = g[channel];
  if (!(exposure > 0)) return 0.0;
  const double le = std::log(exposure);
  if (le <= c.front()) return 0.0;
  if (le >= c.back()) return 255.0;
  // First entry above le; c[i - 1] <= le < c[i], so the segment has positive slope.
  const size_t i = static_cast<size_t>(std::upper_bound(c.begin(), c.end(), le) - c.begin());
  const double a = (le - c[i - 1]) / (c[i] - c[i - 1]);
  return static_cast<double>(i - 1) + a;
}

void to_json(nlohmann::json& j, const ResponseCurve& r) {
  j = nlohmann::json{{"g", {r.g[0], r.g[1], r.g[2]}}};
}

void from_json(const nlohmann::json& j, ResponseCurve& r) {
  if (!j.is_object()) throw Error("response curve: expected a JSON object");
  auto it = j.find("g");
  if (it == j.end()) throw Error("response curve: missing key \"g\"");
  if (!it->is_array() || it->size() != 3) {
    throw Error("response curve: \"g\" must hold 3 channels");
  }
  ResponseCurve out;
  for (int c = 0; c < 3; ++c) {
    const auto& ch = (*it)[c];
    if (!ch.is_array() || ch.size() != 256) {
      throw Error("response curve: channel " + std::to_string(c) + " must have 256 entries");
    }
    out.g[c].resize(256);
    for (int z = 0; z < 256; ++z) {
      if (!ch[z].is_number()) {
        throw Error("response curve: channel " + std::to_string(c) + " entry " + std::to_string(z) +
                    " is not a number");
      }
      out.g[c][z] = ch[z].get<double>();
      if (!std::isfinite(out.g[c][z])) {
        throw Error("response curve: channel " + std::to_string(c) + " entry " + std::to_string(z) +
                    " is not finite");
      }
      if (z > 0 && out.g[c][z] < out.g[c][z - 1]) {
        throw Error("response curve: channel " + std::to_string(c) + " decreases at entry " +
                    std::to_string(z));
      }
    }
  }
  r = std::move(out);
}

ResponseCurve ReadResponseCurve(const std::string& path) {
  const std::string text = ReadFileToString(path);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not valid JSON: " + e.what());
  }
  try {
    return j.get<ResponseCurve>();
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": " + e.what());
  }
}

void WriteResponseCurve(const std::string& path, const ResponseCurve& r) {
  if (!r.valid()) throw Error(path + ": refusing to write an invalid response curve");
  WriteFileAtomic(path, nlohmann::json(r).dump() + "\n");
}

}  // namespace rouen
