#include "core/geodesy.h"

#include <GeographicLib/Geocentric.hpp>
#include <GeographicLib/LocalCartesian.hpp>
#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {

struct LocalFrame::Impl {
  GeographicLib::LocalCartesian lc;
};

LocalFrame::LocalFrame(const Site& origin) : origin_(origin) {
  if (!std::isfinite(origin.lat_deg) || !std::isfinite(origin.lon_deg) ||
      !std::isfinite(origin.height_m) || std::abs(origin.lat_deg) > 90.0) {
    throw Error("local frame: invalid origin (lat " + std::to_string(origin.lat_deg) + ", lon " +
                std::to_string(origin.lon_deg) + ", height " + std::to_string(origin.height_m) +
                ")");
  }
  impl_ = std::make_unique<Impl>(Impl{GeographicLib::LocalCartesian(
      origin.lat_deg, origin.lon_deg, origin.height_m, GeographicLib::Geocentric::WGS84())});
}

LocalFrame::~LocalFrame() = default;

Eigen::Vector3d LocalFrame::ToEnu(const Site& p) const {
  double x = 0, y = 0, z = 0;
  impl_->lc.Forward(p.lat_deg, p.lon_deg, p.height_m, x, y, z);
  return Eigen::Vector3d(x, y, z);
}

Site LocalFrame::ToGeodetic(const Eigen::Vector3d& enu) const {
  Site s;
  impl_->lc.Reverse(enu.x(), enu.y(), enu.z(), s.lat_deg, s.lon_deg, s.height_m);
  return s;
}

}  // namespace rouen
