#include "calib/nd.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/hdr.h"
#include "core/error.h"
#include "core/stats.h"

namespace rouen {
namespace {

void CheckRadiance(const Image& im, const char* which) {
  if (im.units != PixelUnits::kRadiance)
    throw Error(std::string("nd calibration: the ") + which + "-filter image is not radiance");
  if (im.channels != 3 || im.empty())
    throw Error(std::string("nd calibration: the ") + which + "-filter image must be RGB");
}

}  // namespace

void NdOptions::Validate() const {
  if (!(min_relative_level >= 0 && min_relative_level < 1))
    throw Error("nd options: min_relative_level must be in [0, 1)");
  if (min_pixels < 1) throw Error("nd options: min_pixels must be at least 1");
}

double NdCalibration::MeanDensity() const {
  return (channel[0].density + channel[1].density + channel[2].density) / 3;
}

std::array<double, 3> NdCalibration::DensityRgb() const {
  return {channel[0].density, channel[1].density, channel[2].density};
}

void to_json(nlohmann::json& j, const NdCalibration& c) {
  nlohmann::json t = nlohmann::json::array(), d = t, ci = t, sp = t, n = t;
  for (const NdChannel& ch : c.channel) {
    t.push_back(ch.transmission);
    d.push_back(ch.density);
    ci.push_back(ch.density_ci95);
    sp.push_back(ch.density_spread);
    n.push_back(ch.pixels);
  }
  j = {{"density_rgb", d},         {"transmission_rgb", t}, {"density_ci95_rgb", ci},
       {"density_spread_rgb", sp}, {"pixels_rgb", n},       {"density_mean", c.MeanDensity()}};
}

void from_json(const nlohmann::json& j, NdCalibration& c) {
  auto it = j.find("density_rgb");
  if (!j.is_object() || it == j.end() || !it->is_array() || it->size() != 3)
    throw Error("nd calibration: expected \"density_rgb\": [r, g, b]");
  NdCalibration r;
  for (int k = 0; k < 3; ++k) {
    if (!(*it)[k].is_number()) throw Error("nd calibration: density_rgb holds a non-number");
    const double d = (*it)[k].get<double>();
    if (!std::isfinite(d) || d < 0 || d > 10)
      throw Error("nd calibration: density " + std::to_string(d) + " outside 0..10");
    r.channel[k].density = d;
    r.channel[k].transmission = std::pow(10.0, -d);
  }
  c = r;
}

NdCalibration EstimateNdTransmission(const Image& with, const std::vector<uint8_t>* with_valid,
                                     const Image& without,
                                     const std::vector<uint8_t>* without_valid,
                                     const NdOptions& options) {
  options.Validate();
  CheckRadiance(with, "with");
  CheckRadiance(without, "without");
  if (with.width != without.width || with.height != without.height)
    throw Error("nd calibration: image sizes differ (" + std::to_string(with.width) + "x" +
                std::to_string(with.height) + " with the filter, " + std::to_string(without.width) +
                "x" + std::to_string(without.height) + " without)");
  const size_t npix = static_cast<size_t>(with.width) * with.height;
  for (const auto* m : {with_valid, without_valid})
    if (m && m->size() != npix) throw Error("nd calibration: a valid mask has the wrong size");

  // Per image and channel, a level below which pixels are too dark to use.
  std::array<double, 3> floor_with{}, floor_without{};
  for (int c = 0; c < 3; ++c) {
    std::vector<double> a, b;
    a.reserve(npix);
    b.reserve(npix);
    for (size_t i = 0; i < npix; ++i) {
      a.push_back(with.data[i * 3 + c]);
      b.push_back(without.data[i * 3 + c]);
    }
    floor_with[c] = options.min_relative_level * Median(std::move(a));
    floor_without[c] = options.min_relative_level * Median(std::move(b));
  }

  NdCalibration out;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> lr;  // log10 ratios
    lr.reserve(npix);
    for (size_t i = 0; i < npix; ++i) {
      if ((with_valid && !(*with_valid)[i]) || (without_valid && !(*without_valid)[i])) continue;
      const double a = with.data[i * 3 + c], b = without.data[i * 3 + c];
      if (!std::isfinite(a) || !std::isfinite(b)) continue;
      if (!(a > floor_with[c]) || !(b > floor_without[c]) || a <= 0 || b <= 0) continue;
      lr.push_back(std::log10(a / b));
    }
    const int64_t n = static_cast<int64_t>(lr.size());
    if (n < options.min_pixels)
      throw Error("nd calibration: channel " + std::to_string(c) + " has " + std::to_string(n) +
                  " pixels well exposed in both images, fewer than " +
                  std::to_string(options.min_pixels) +
                  " (adjust the exposures so the same parts of the scene are neither dark nor "
                  "saturated with and without the filter)");
    std::sort(lr.begin(), lr.end());
    const double med = lr[n / 2];
    // Distribution-free 95% interval of the median: ranks n/2 -+ 1.96 sqrt(n)/2.
    const int64_t half = static_cast<int64_t>(std::ceil(1.96 * std::sqrt(double(n)) / 2));
    const double lo = lr[std::max<int64_t>(0, n / 2 - half)];
    const double hi = lr[std::min<int64_t>(n - 1, n / 2 + half)];
    std::vector<double> dev(lr.size());
    for (size_t i = 0; i < lr.size(); ++i) dev[i] = std::abs(lr[i] - med);
    NdChannel& ch = out.channel[c];
    ch.density = -med;
    ch.transmission = std::pow(10.0, med);
    ch.density_ci95 = std::max(med - lo, hi - med);
    ch.density_spread = 1.4826 * Median(std::move(dev));
    ch.pixels = n;
  }
  return out;
}

NdCalibration EstimateNdTransmission(const Bracket& with, const Bracket& without,
                                     const ResponseCurve& curve, const NdOptions& options) {
  auto merge = [&](const Bracket& b, const char* which, std::vector<uint8_t>* valid) {
    if (b.frames.empty())
      throw Error(std::string("nd calibration: no frames ") + which + " the filter");
    if (b.frames.size() != b.exposures.size())
      throw Error(std::string("nd calibration: frames and exposures differ in number ") + which +
                  " the filter");
    std::vector<const Image*> ptrs;
    for (const Image& im : b.frames) ptrs.push_back(&im);
    try {
      return MergeHdr(ptrs, b.exposures, curve, MergeOptions{}, nullptr, valid);
    } catch (const Error& e) {
      throw Error(std::string("nd calibration: frames ") + which + " the filter: " + e.what());
    }
  };
  std::vector<uint8_t> vw, vo;
  const Image lw = merge(with, "with", &vw);
  const Image lo = merge(without, "without", &vo);
  return EstimateNdTransmission(lw, &vw, lo, &vo, options);
}

}  // namespace rouen
