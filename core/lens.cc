#include "core/lens.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"
#include "core/files.h"
#include "core/json_text.h"

namespace rouen {

double VignettingModel::HalfDiagonal(int width, int height) {
  return 0.5 * std::hypot(double(width), double(height));
}

double VignettingModel::FalloffAtRadius(double r) const {
  const double p = r * r;
  return 1 + p * (a[0] + p * (a[1] + p * a[2]));
}

double VignettingModel::Falloff(double x, double y) const {
  return FalloffAtRadius(std::hypot(x - cx, y - cy) / HalfDiagonal(width, height));
}

double VignettingModel::MaxRadius() const {
  const double hd = HalfDiagonal(width, height);
  double r = 0;
  for (double x : {0.0, double(width)})
    for (double y : {0.0, double(height)}) r = std::max(r, std::hypot(x - cx, y - cy) / hd);
  return r;
}

void VignettingModel::Validate() const {
  if (width <= 0 || height <= 0) throw Error("vignetting: width and height must be positive");
  if (!std::isfinite(cx) || !std::isfinite(cy) || cx < 0 || cx > width || cy < 0 || cy > height)
    throw Error("vignetting: the optical centre must lie inside the image");
  for (double v : a)
    if (!std::isfinite(v)) throw Error("vignetting: coefficients must be finite");
  const double rmax = MaxRadius();
  for (int i = 0; i <= 200; ++i) {
    const double r = rmax * i / 200;
    if (!(FalloffAtRadius(r) > 0.05))
      throw Error("vignetting: the fall-off drops to " + std::to_string(FalloffAtRadius(r)) +
                  " at radius " + std::to_string(r) + " (must stay above 0.05)");
  }
}

void to_json(nlohmann::json& j, const VignettingModel& v) {
  j = {{"model", "radial-even-6"},
       {"width", v.width},
       {"height", v.height},
       {"cx", v.cx},
       {"cy", v.cy},
       {"a", {v.a[0], v.a[1], v.a[2]}}};
}

void from_json(const nlohmann::json& j, VignettingModel& v) {
  if (!j.is_object()) throw Error("vignetting: expected an object");
  if (j.contains("model") && j["model"] != "radial-even-6")
    throw Error("vignetting: unknown model (expected \"radial-even-6\")");
  // Sizes are integers that fit an int (a float or a huge number is not converted).
  auto size = [&](const char* key) {
    return JsonGet<int>(j.at(key), std::string("vignetting: \"") + key + "\" (pixels)");
  };
  VignettingModel r;
  try {
    r.width = size("width");
    r.height = size("height");
    r.cx = j.at("cx").get<double>();
    r.cy = j.at("cy").get<double>();
    const auto& a = j.at("a");
    if (!a.is_array() || a.size() != 3) throw Error("vignetting: \"a\" must be [a1, a2, a3]");
    for (int k = 0; k < 3; ++k) r.a[k] = a[k].get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("vignetting: missing or mistyped key (width, height, cx, cy, a): ") +
                e.what());
  }
  r.Validate();
  v = r;
}

void RemoveVignetting(const VignettingModel& model, Image* radiance) {
  if (radiance->units != PixelUnits::kRadiance)
    throw Error("vignetting: can only be removed from a radiance image");
  const int w = radiance->width, h = radiance->height;
  if (w <= 0 || h <= 0) return;
  const double sx = double(model.width) / w, sy = double(model.height) / h;
  if (std::abs(sx / sy - 1) > 0.01)
    throw Error("vignetting: the model is for " + std::to_string(model.width) + "x" +
                std::to_string(model.height) + " images, this one is " + std::to_string(w) + "x" +
                std::to_string(h) + " (another aspect ratio)");
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double v = model.Falloff((x + 0.5) * sx, (y + 0.5) * sy);
      const float inv = static_cast<float>(1 / std::max(v, 0.05));
      for (int c = 0; c < radiance->channels; ++c) radiance->at(x, y, c) *= inv;
    }
  }
}

LensFile ReadLensFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(path + ": no such lens file");
  return ParseLensFile(ReadFileToString(path), path);
}

Pose ReadPoseFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(path + ": no such pose file");
  return ParsePose(ReadFileToString(path), path);
}

LensFile ParseLensFile(std::string_view text, const std::string& path) {
  LensFile lens;
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    if (!j.is_object()) throw Error("a lens file is a JSON object");
    lens.intrinsics = j.get<Intrinsics>();
    lens.intrinsics.Validate();
    if (j.contains("max_field_deg")) {
      const nlohmann::json& f = j["max_field_deg"];
      if (!f.is_number() || !(f.get<double>() >= 0 && f.get<double>() <= 180))
        throw Error("\"max_field_deg\" must be a number of degrees in 0..180");
      lens.max_field_deg = f.get<double>();
    }
    if (j.contains("vignetting")) lens.vignetting = j["vignetting"].get<VignettingModel>();
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not a valid lens file (" + e.what() + ")");
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  return lens;
}

}  // namespace rouen
