#include "app/options.h"

#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "core/error.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/limits.h"

namespace rouen {
namespace {

// The number in `text` as CLI11 converts it (NaN and infinities included), if it is one.
std::optional<double> Number(const std::string& text) {
  double v = 0;
  if (!CLI::detail::lexical_cast(text, v)) return std::nullopt;
  return v;
}

}  // namespace

CLI::Validator Within(double lo, double hi, const std::string& unit) {
  const std::string range =
      (std::isinf(hi) ? ">= " + FormatNumber(lo) : FormatNumber(lo) + ".." + FormatNumber(hi)) +
      (unit.empty() ? "" : " ") + unit;
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        const std::optional<double> v = Number(text);
        if (v && *v >= lo && *v <= hi) return {};  // false for NaN
        return "'" + text + "' is not a number within " + range;
      },
      "NUMBER in " + range);
}

CLI::Validator Positive() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        const std::optional<double> v = Number(text);
        if (v && *v > 0 && std::isfinite(*v)) return {};
        return "'" + text + "' is not a positive number";
      },
      "POSITIVE");
}

CLI::Validator Obeys(std::string (*problem)(double)) {
  return CLI::Validator(
      [problem](std::string& text) -> std::string {
        const std::optional<double> v = Number(text);
        return v ? problem(*v) : "'" + text + "' is not a number";
      },
      "");
}

std::vector<double> ParseNumberList(const std::string& text, size_t n, const std::string& option) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size()) throw std::invalid_argument("");
    } catch (const std::exception&) {
      throw Error(option + " '" + text + "': '" + item + "' is not a number");
    }
    if (!std::isfinite(v.back())) throw Error(option + " '" + text + "': not finite");
  }
  if (v.size() != n || (!text.empty() && text.back() == ','))
    throw Error(option + " '" + text + "': expected " + std::to_string(n) +
                " comma-separated numbers");
  return v;
}

SkyInterpMode ParseSkyInterp(const std::string& text) {
  if (text == "elevation") return SkyInterpMode::kElevation;
  if (text == "angular") return SkyInterpMode::kAngularDistance;
  throw Error("--sky-interp takes elevation or angular, not '" + text + "'");
}

UtcTime ParseTimeOption(const std::string& text, const std::string& option) {
  try {
    return ParseIso8601(text);
  } catch (const Error& e) {
    throw Error(option + ": " + e.what());
  }
}

double ParseDurationSeconds(const std::string& text, double max_s, const std::string& option) {
  const std::string where = option + " '" + text + "'";
  size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw Error(where + ": not a duration (e.g. 15min, 1h, 30s)");
  }
  const std::string unit = text.substr(used);
  double scale = 0;
  if (unit.empty() || unit == "s") scale = 1;
  if (unit == "min") scale = 60;
  if (unit == "h") scale = 3600;
  if (scale == 0) throw Error(where + ": unknown unit '" + unit + "' (s, min or h)");
  const double seconds = value * scale;
  if (!std::isfinite(seconds) || seconds <= 0 || seconds > max_s)
    throw Error(where + ": must be above 0 and at most " + FormatNumber(max_s) + " s");
  return seconds;
}

Site ParseSiteOption(const std::string& text, const std::string& option) {
  const std::string where = option + " '" + text + "'";
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) parts.push_back(item);
  if (parts.size() != 3 || text.back() == ',')
    throw Error(where +
                ": expected LAT,LON,H (degrees north, degrees east, metres), e.g. "
                "38.6247,-90.1848,147");
  double v[3];
  const char* names[3] = {"latitude", "longitude", "height"};
  for (int k = 0; k < 3; ++k) {
    try {
      size_t used = 0;
      v[k] = std::stod(parts[k], &used);
      if (used != parts[k].size() || !std::isfinite(v[k])) throw std::invalid_argument("");
    } catch (const std::exception&) {
      throw Error(where + ": " + names[k] + " '" + parts[k] + "' is not a number");
    }
  }
  const Site site{v[0], v[1], v[2]};
  CheckSite(site, where);
  return site;
}

void AddCameraOptions(CLI::App* c, CameraArgs* a) {
  c->add_option("--view", a->view,
                "Camera of this bracket (e.g. slot0/architecture/view1; default: the first)");
  c->add_option("--lens", a->lens, "Camera intrinsics JSON (with --pose)");
  c->add_option("--pose", a->pose, "Camera pose JSON (with --lens)");
  c->add_option("--look-at", a->look_at, "A new camera looking at this point X,Y,Z (metres, ENU)");
  c->add_option("--from-point", a->from_point, "... from this point X,Y,Z (with --look-at)");
  c->add_option("--fov", a->fov_deg, "Horizontal field of view of the --look-at camera (deg)")
      ->check(Within(1, 170, "deg"))
      ->capture_default_str();
  c->add_option("--size", a->size, "Image size WIDTHxHEIGHT of the --look-at camera")
      ->capture_default_str();
}

std::pair<int, int> ParseImageSize(const std::string& text, const std::string& option) {
  int w = 0, h = 0;
  char x = 0, rest = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || x != 'x' || w < 1 || h < 1 ||
      w > kMaxImageSide || h > kMaxImageSide || static_cast<int64_t>(w) * h > kMaxImagePixels)
    throw Error(option + " '" + text + "': expected WIDTHxHEIGHT, each 1.." +
                std::to_string(kMaxImageSide));
  return {w, h};
}

bool CameraFromArgs(const CameraArgs& a, Intrinsics* intrinsics, Pose* pose) {
  if (!a.lens.empty() != !a.pose.empty()) throw Error("--lens and --pose go together");
  if (a.look_at.empty() != a.from_point.empty())
    throw Error("--look-at and --from-point go together");
  if (static_cast<int>(!a.view.empty()) + static_cast<int>(!a.lens.empty()) +
          static_cast<int>(!a.look_at.empty()) >
      1)
    throw Error("give one camera: --view, --lens/--pose or --look-at/--from-point");
  if (!a.look_at.empty()) {
    const std::vector<double> target = ParseNumberList(a.look_at, 3, "--look-at");
    const std::vector<double> eye = ParseNumberList(a.from_point, 3, "--from-point");
    const Eigen::Vector3d t(target[0], target[1], target[2]), e(eye[0], eye[1], eye[2]);
    if ((t - e).norm() < 1e-6)
      throw Error("--look-at and --from-point are the same point: no direction to look in");
    const auto [w, h] = ParseImageSize(a.size, "--size");
    *intrinsics = Intrinsics::PinholeFov(w, h, a.fov_deg);
    *pose = Pose::LookAt(e, t);
    return true;
  }
  if (!a.lens.empty()) {
    *intrinsics = ReadLensFile(a.lens).intrinsics;
    *pose = ReadPoseFile(a.pose);
    return true;
  }
  return false;
}

}  // namespace rouen
