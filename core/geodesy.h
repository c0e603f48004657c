// Geodetic <-> local east-north-up frame of a site (GeographicLib, WGS84).
#pragma once

#include <Eigen/Core>
#include <memory>

#include "core/solar.h"

namespace rouen {

class LocalFrame {
 public:
  explicit LocalFrame(const Site& origin);
  ~LocalFrame();
  LocalFrame(const LocalFrame&) = delete;
  LocalFrame& operator=(const LocalFrame&) = delete;

  const Site& origin() const { return origin_; }
  // Metres: x east, y north, z up, relative to the origin.
  Eigen::Vector3d ToEnu(const Site& p) const;
  Site ToGeodetic(const Eigen::Vector3d& enu) const;

 private:
  Site origin_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace rouen
