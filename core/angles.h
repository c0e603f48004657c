// The angle constants of every layer, defined once.
#pragma once

#include <numbers>

namespace rouen {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kDeg = kPi / 180.0;  // radians per degree

}  // namespace rouen
