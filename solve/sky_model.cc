#include "solve/sky_model.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"

namespace rouen {

double SkyBackground(const SkyParams& p, double xi) {
  return SkyGradationFactor(p.a, p.b, SkyInvCosXi(xi));
}

double SkyScattering(const SkyParams& p, double gamma) {
  const double cos_g = std::cos(gamma);
  return SkyScatteringFactor(p.c, p.d, p.e, p.h, SkyLogGamma(gamma), cos_g * cos_g);
}

// Eq. 9.
double SkyRadiance(const SkyParams& p, double xi, double gamma) {
  return p.Lz * SkyBackground(p, xi) * SkyScattering(p, gamma);
}

Eigen::Vector3d SkyModel::Radiance(const Eigen::Vector3d& dir) const {
  Eigen::Vector3d d = dir;
  if (d.z() < 0) {
    // Below the horizon: the value at the horizon in the same azimuth.
    d.z() = 0;
    if (d.squaredNorm() == 0) d = Eigen::Vector3d::UnitX();
  }
  const double n = d.norm();
  if (!(n > 0) || !std::isfinite(n)) return Eigen::Vector3d::Zero();
  d /= n;
  const Eigen::Vector3d s = sun_dir.normalized();
  const double xi = std::acos(std::clamp(d.z(), -1.0, 1.0));
  const double gamma = std::acos(std::clamp(d.dot(s), -1.0, 1.0));
  Eigen::Vector3d out;
  for (int c = 0; c < 3; ++c) out[c] = SkyRadiance(channel[c], xi, gamma);
  return out;
}

void to_json(nlohmann::json& j, const SkyModel& m) {
  nlohmann::json channels = nlohmann::json::array();
  for (const SkyParams& p : m.channel) {
    channels.push_back(
        {{"Lz", p.Lz}, {"a", p.a}, {"b", p.b}, {"c", p.c}, {"d", p.d}, {"e", p.e}, {"h", p.h}});
  }
  j = nlohmann::json{{"sun_dir", {m.sun_dir.x(), m.sun_dir.y(), m.sun_dir.z()}},
                     {"channels", channels}};
}

void from_json(const nlohmann::json& j, SkyModel& m) {
  auto number = [](const nlohmann::json& o, const char* key, const std::string& where) {
    if (!o.is_object() || !o.contains(key))
      throw Error("sky model: " + where + " lacks '" + key + "'");
    const nlohmann::json& v = o.at(key);
    if (!v.is_number()) throw Error("sky model: " + where + " '" + key + "' is not a number");
    const double x = v.get<double>();
    if (!std::isfinite(x)) throw Error("sky model: " + where + " '" + key + "' is not finite");
    return x;
  };
  if (!j.is_object()) throw Error("sky model: not a JSON object");
  if (!j.contains("sun_dir") || !j.at("sun_dir").is_array() || j.at("sun_dir").size() != 3) {
    throw Error("sky model: 'sun_dir' must be an array of 3 numbers");
  }
  Eigen::Vector3d s;
  for (int i = 0; i < 3; ++i) {
    const nlohmann::json& v = j.at("sun_dir")[i];
    if (!v.is_number()) throw Error("sky model: 'sun_dir' must be an array of 3 numbers");
    s[i] = v.get<double>();
  }
  if (!s.allFinite() || s.norm() < 1e-9) throw Error("sky model: 'sun_dir' is not a direction");
  if (!j.contains("channels") || !j.at("channels").is_array() || j.at("channels").size() != 3) {
    throw Error("sky model: 'channels' must be an array of 3 parameter sets");
  }
  SkyModel out;
  // Normalized once: a direction already unit to the last bits is kept as written, so a model
  // written and read again is the same model.
  out.sun_dir =
      std::abs(s.norm() - 1) <= 4 * std::numeric_limits<double>::epsilon() ? s : s.normalized();
  for (int c = 0; c < 3; ++c) {
    const nlohmann::json& o = j.at("channels")[c];
    const std::string where = "channel " + std::to_string(c);
    SkyParams& p = out.channel[c];
    p.Lz = number(o, "Lz", where);
    p.a = number(o, "a", where);
    p.b = number(o, "b", where);
    p.c = number(o, "c", where);
    p.d = number(o, "d", where);
    p.e = number(o, "e", where);
    p.h = number(o, "h", where);
    if (p.Lz < 0) throw Error("sky model: " + where + " has negative Lz");
  }
  m = out;
}

}  // namespace rouen
