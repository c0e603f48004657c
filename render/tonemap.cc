#include "render/tonemap.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/stats.h"

namespace rouen {

Image ToDigital(const Image& radiance, const ResponseCurve& response, double exposure_factor) {
  if (!response.valid()) throw Error("tonemap: the response curve is not valid");
  if (!(exposure_factor > 0) || !std::isfinite(exposure_factor)) {
    throw Error("tonemap: exposure factor must be positive and finite");
  }
  if (radiance.units != PixelUnits::kRadiance) throw Error("tonemap: input is not radiance");
  if (radiance.channels < 3) throw Error("tonemap: input needs 3 channels");
  for (int y = 0; y < radiance.height; ++y) {
    for (int x = 0; x < radiance.width; ++x) {
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(radiance.at(x, y, c))) {
          throw Error("tonemap: non-finite radiance at pixel (" + std::to_string(x) + ", " +
                      std::to_string(y) + ")");
        }
      }
    }
  }
  Image out(radiance.width, radiance.height, 3, PixelUnits::kDigital, 0.f);
  tbb::parallel_for(
      tbb::blocked_range<int>(0, radiance.height, 16), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          for (int x = 0; x < radiance.width; ++x) {
            for (int c = 0; c < 3; ++c) {
              const double l = radiance.at(x, y, c);
              const double dn = response.DigitalValue(c, std::max(0.0, l) * exposure_factor);
              out.at(x, y, c) = static_cast<float>(std::clamp(std::round(dn), 0.0, 255.0));
            }
          }
        }
      });
  return out;
}

double AutoExposure(const Image& radiance, const ResponseCurve& response, double percentile,
                    double target_dn) {
  if (!response.valid()) throw Error("tonemap: the response curve is not valid");
  if (!(percentile > 0 && percentile <= 1) || !(target_dn > 0 && target_dn < 255)) {
    throw Error("tonemap: percentile must be in (0, 1] and target_dn in (0, 255)");
  }
  std::vector<float> v;
  v.reserve(radiance.data.size());
  for (float f : radiance.data) {
    if (std::isfinite(f) && f > 0) v.push_back(f);
  }
  if (v.empty()) return 1.0;
  // Green channel's exposure at the target digital number.
  const double exposure = std::exp(response.LogExposure(1, target_dn));
  return exposure / Quantile(std::move(v), percentile);
}

namespace {

// IEC 61966-2-1's encoding of a linear value in 0..1.
double SrgbEncode(double l) {
  return l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(l, 1 / 2.4) - 0.055;
}

}  // namespace

Image ToSrgbDigital(const Image& radiance, double exposure_factor) {
  if (!(exposure_factor > 0) || !std::isfinite(exposure_factor))
    throw Error("tonemap: exposure factor must be positive and finite");
  if (radiance.units != PixelUnits::kRadiance) throw Error("tonemap: input is not radiance");
  if (radiance.channels < 3) throw Error("tonemap: input needs 3 channels");
  Image out(radiance.width, radiance.height, 3, PixelUnits::kDigital, 0.f);
  for (int y = 0; y < radiance.height; ++y)
    for (int x = 0; x < radiance.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const double l = radiance.at(x, y, c);
        if (!std::isfinite(l))
          throw Error("tonemap: non-finite radiance at pixel (" + std::to_string(x) + ", " +
                      std::to_string(y) + ")");
        const double e = std::clamp(std::max(0.0, l) * exposure_factor, 0.0, 1.0);
        out.at(x, y, c) = static_cast<float>(std::round(255 * SrgbEncode(e)));
      }
  return out;
}

double AutoExposureSrgb(const Image& radiance, double percentile, double target) {
  if (!(percentile > 0 && percentile <= 1) || !(target > 0 && target <= 1))
    throw Error("tonemap: percentile and target must be in (0, 1]");
  std::vector<float> v;
  for (float f : radiance.data)
    if (std::isfinite(f) && f > 0) v.push_back(f);
  if (v.empty()) return 1.0;
  return target / Quantile(std::move(v), percentile);
}

}  // namespace rouen
