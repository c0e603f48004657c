// The paper's revised seven-parameter sky model, one parameter set per colour channel
// (Yu & Malik 1998, eq. 9):
//   Ls(xi, gamma) = Lz [1 + a exp(b / cos xi)] [1 + c exp(d gamma^h) + e cos^2 gamma]
// xi: zenith angle of the sky element, gamma: its angle to the sun, both radians.
#pragma once

#include <Eigen/Core>
#include <array>
#include <nlohmann/json_fwd.hpp>

namespace rouen {

struct SkyParams {
  double Lz = 1, a = 0, b = 0, c = 0, d = 0, e = 0, h = 1;
};

// Eq. 9 for one channel. cos(xi) is clamped to >= 0.01 so the horizon stays finite.
double SkyRadiance(const SkyParams& p, double xi, double gamma);

struct SkyModel {
  std::array<SkyParams, 3> channel;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();  // unit, ENU

  // Radiance towards a unit ENU direction (upper hemisphere; below it, the horizon value).
  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir) const;
};

void to_json(nlohmann::json& j, const SkyModel& m);
void from_json(const nlohmann::json& j, SkyModel& m);

}  // namespace rouen
