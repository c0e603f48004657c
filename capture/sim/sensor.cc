#include "capture/sim/sensor.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/hash_random.h"

namespace rouen {
namespace {}  // namespace

void SensorParams::Validate() const {
  auto fail = [](const std::string& m) { throw Error("sensor parameters: " + m); };
  if (!(full_well_e >= 100 && full_well_e < 1e7)) fail("full_well_e must be in [100, 1e7)");
  if (!(read_noise_e >= 0 && read_noise_e < 1000)) fail("read_noise_e must be in [0, 1000)");
  if (!(sensitivity > 0 && std::isfinite(sensitivity))) fail("sensitivity must be positive");
  for (int c = 0; c < 3; ++c) {
    if (!(gamma[c] > 0.1 && gamma[c] <= 1.5)) fail("gamma must be in (0.1, 1.5]");
    if (!(shoulder[c] > 0.05 && shoulder[c] < 100)) fail("shoulder must be in (0.05, 100)");
    if (!(toe[c] >= 0 && toe[c] < 1)) fail("toe must be in [0, 1)");
    if (!(black[c] >= 0 && black[c] < 0.5)) fail("black must be in [0, 0.5)");
  }
}

SimSensor::SimSensor(const SensorParams& params) : p_(params) {
  p_.Validate();
  for (int c = 0; c < 3; ++c) {
    black_pow_[c] = std::pow(p_.black[c], p_.gamma[c]);
    curve_scale_[c] = std::pow(1.0 + p_.black[c], p_.gamma[c]) - black_pow_[c];
  }
  // Bisection over the floats of [0, 1], ordered as their bit patterns.
  const uint32_t one = std::bit_cast<uint32_t>(1.0f);
  for (int c = 0; c < 3; ++c) {
    for (int k = 1; k <= 255; ++k) {
      uint32_t lo = 0, hi = one + 1;  // the answer is in [lo, hi]; hi: none reaches k
      while (lo < hi) {
        const uint32_t mid = lo + (hi - lo) / 2;
        if (Quantised(c, std::bit_cast<float>(mid)) >= k)
          hi = mid;
        else
          lo = mid + 1;
      }
      dn_threshold_[c].push_back(lo > one ? std::numeric_limits<float>::infinity()
                                          : std::bit_cast<float>(lo));
    }
    const std::vector<float>& t = dn_threshold_[c];
    for (uint32_t bin = 0; bin <= (one >> 16); ++bin) {
      const float least = std::bit_cast<float>(bin << 16);
      dn_of_bin_[c].push_back(
          static_cast<uint8_t>(std::upper_bound(t.begin(), t.end(), least) - t.begin()));
    }
  }
}

double SimSensor::Quantised(int c, float x) const {
  return std::clamp(std::floor(Curve(c, x) + 0.5), 0.0, 255.0);
}

double SimSensor::Curve(int c, double x) const {
  x = std::clamp(x, 0.0, 1.0);
  const double b = p_.black[c], g = p_.gamma[c];
  const double u = (std::pow(x + b, g) - black_pow_[c]) / curve_scale_[c];
  const double s = p_.shoulder[c];
  const double y1 = u * (1.0 + s) / (u + s);
  const double smooth = y1 * y1 * (3.0 - 2.0 * y1);
  return 255.0 * ((1.0 - p_.toe[c]) * y1 + p_.toe[c] * smooth);
}

double SimSensor::InverseCurve(int c, double dn) const {
  dn = std::clamp(dn, 0.0, 255.0);
  double lo = 0.0, hi = 1.0;
  for (int it = 0; it < 64; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (Curve(c, mid) < dn)
      lo = mid;
    else
      hi = mid;
  }
  return 0.5 * (lo + hi);
}

double SimSensor::DigitalValue(int c, double exposure) const {
  return Curve(c, p_.sensitivity * exposure);
}

double SimSensor::TrueLogExposure(int c, double dn) const {
  return std::log(InverseCurve(c, std::max(dn, 0.25)) / p_.sensitivity);
}

ResponseCurve SimSensor::TrueResponse() const {
  ResponseCurve r;
  for (int c = 0; c < 3; ++c) {
    r.g[c].resize(256);
    for (int z = 0; z < 256; ++z) r.g[c][z] = TrueLogExposure(c, z);
  }
  return r;
}

double SimSensor::LinearNoiseStd(double x, double gain) const {
  const double electrons = x * p_.full_well_e / gain;
  return gain / p_.full_well_e *
         std::sqrt(std::max(electrons, 0.0) + p_.read_noise_e * p_.read_noise_e);
}

Image SimSensor::CaptureLinear(const Image& radiance, double exposure_s, double gain,
                               double nd_density, uint64_t seed) const {
  if (radiance.channels != 3 || radiance.units != PixelUnits::kRadiance) {
    throw Error("sim sensor: expected a 3-channel radiance image");
  }
  if (!(exposure_s > 0) || !(gain >= 1) || !(nd_density >= 0) || !std::isfinite(exposure_s) ||
      !std::isfinite(gain) || !std::isfinite(nd_density)) {
    throw Error("sim sensor: exposure must be > 0, gain >= 1 and ND density >= 0");
  }
  Image out(radiance.width, radiance.height, 3, PixelUnits::kOther);
  // Electrons per unit radiance: the gain amplifies after the photodiode.
  const double e_per_radiance =
      p_.sensitivity * exposure_s * std::pow(10.0, -nd_density) * p_.full_well_e;
  const double fw = p_.full_well_e;
  const uint64_t base = MixHash(seed ^ 0xC0FFEE1234ULL);
  tbb::parallel_for(tbb::blocked_range<int>(0, radiance.height, 8),
                    [&](const tbb::blocked_range<int>& r) {
                      for (int y = r.begin(); y != r.end(); ++y) {
                        for (int x = 0; x < radiance.width; ++x) {
                          for (int c = 0; c < 3; ++c) {
                            const size_t idx = radiance.index(x, y, c);
                            const double l = std::max(0.0, static_cast<double>(radiance.data[idx]));
                            const double mean_e = l * e_per_radiance;
                            double n1, n2;
                            HashNormals(MixHash(base + idx), &n1, &n2);
                            // Shot noise (Gaussian approximation of Poisson), full well, read
                            // noise.
                            double e = std::clamp(mean_e + std::sqrt(mean_e) * n1, 0.0, fw);
                            e += p_.read_noise_e * n2;
                            out.data[idx] = static_cast<float>(std::clamp(gain * e / fw, 0.0, 1.0));
                          }
                        }
                      }
                    });
  return out;
}

Image SimSensor::Capture(const Image& radiance, double exposure_s, double gain, double nd_density,
                         uint64_t seed) const {
  Image out = CaptureLinear(radiance, exposure_s, gain, nd_density, seed);
  out.units = PixelUnits::kDigital;
  // The response and quantisation, pixel by pixel (rows in parallel, as the noise above):
  // Quantised(c, x), the number of thresholds x reaches, counted on from its bin's.
  const size_t row = static_cast<size_t>(out.width) * 3;
  tbb::parallel_for(tbb::blocked_range<int>(0, out.height, 8),
                    [&](const tbb::blocked_range<int>& r) {
                      for (size_t i = r.begin() * row; i < r.end() * row; ++i) {
                        const float x = out.data[i];  // in [0, 1] (CaptureLinear clamps)
                        const std::vector<float>& t = dn_threshold_[i % 3];
                        int dn = x > 0 ? dn_of_bin_[i % 3][std::bit_cast<uint32_t>(x) >> 16] : 0;
                        while (dn < 255 && t[dn] <= x) ++dn;
                        out.data[i] = static_cast<float>(dn);
                      }
                    });
  return out;
}

}  // namespace rouen
