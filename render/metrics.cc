#include "render/metrics.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/stats.h"
#include "render/tonemap.h"

namespace rouen {

namespace {

void Check(const Image& r, const Image& t, const std::vector<uint8_t>& mask) {
  if (r.width != t.width || r.height != t.height) {
    throw Error("metrics: rendered image is " + std::to_string(r.width) + "x" +
                std::to_string(r.height) + ", truth " + std::to_string(t.width) + "x" +
                std::to_string(t.height));
  }
  if (r.channels < 3 || t.channels < 3) throw Error("metrics: images need 3 channels");
  if (!mask.empty() && mask.size() != static_cast<size_t>(r.width) * r.height) {
    throw Error("metrics: mask has " + std::to_string(mask.size()) + " entries, expected " +
                std::to_string(static_cast<size_t>(r.width) * r.height));
  }
}

bool Selected(const std::vector<uint8_t>& mask, const Image& im, int x, int y) {
  return mask.empty() || mask[static_cast<size_t>(y) * im.width + x] != 0;
}

// An image's first 3 channels as kRadiance (ToDigital wants radiance units).
Image AsRadiance(const Image& im) {
  Image out(im.width, im.height, 3, PixelUnits::kRadiance, 0.f);
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = im.at(x, y, c);
  return out;
}

// Linear 8-bit display: radiance x exposure, rounded and clipped to 0..255.
Image ToLinearDigital(const Image& radiance, double exposure) {
  Image out(radiance.width, radiance.height, 3, PixelUnits::kDigital, 0.f);
  for (int y = 0; y < radiance.height; ++y)
    for (int x = 0; x < radiance.width; ++x)
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) = static_cast<float>(
            std::clamp(std::round(std::max(0.0f, radiance.at(x, y, c)) * exposure), 0.0, 255.0));
  return out;
}

}  // namespace

MetricsAccumulator::MetricsAccumulator(const MetricsOptions& options) : options_(options) {
  if (!(options.percentile > 0 && options.percentile <= 1) ||
      !(options.target_dn > 0 && options.target_dn < 255) || !(options.rel_error_floor >= 0))
    throw Error("metrics: percentile must be in (0, 1], target_dn in (0, 255), floor >= 0");
}

void MetricsAccumulator::Add(const Image& rendered, const Image& truth,
                             const std::vector<uint8_t>& mask) {
  Check(rendered, truth, mask);
  std::vector<double> green;
  double err_sq = 0, truth_sq = 0, sum_r = 0, sum_t = 0;
  int64_t n = 0;
  for (int y = 0; y < rendered.height; ++y) {
    for (int x = 0; x < rendered.width; ++x) {
      if (!Selected(mask, rendered, x, y)) continue;
      ++n;
      for (int c = 0; c < 3; ++c) {
        const double r = rendered.at(x, y, c), t = truth.at(x, y, c);
        if (!std::isfinite(r) || !std::isfinite(t))
          throw Error("metrics: non-finite value at pixel (" + std::to_string(x) + ", " +
                      std::to_string(y) + ")");
        err_sq += (r - t) * (r - t);
        truth_sq += t * t;
        sum_r += r;
        sum_t += t;
      }
      green.push_back(truth.at(x, y, 1));
    }
  }
  if (n == 0) throw Error("metrics: the mask selects no pixels");
  if (!(truth_sq > 0)) throw Error("metrics: the masked truth is all zero");
  const double high = std::max(1e-30, Quantile(green, options_.percentile));

  // §6: both images to 8 bits alike, exposed for the truth.
  const bool curve = options_.response && options_.response->valid();
  const double exposure =
      curve ? std::exp(options_.response->LogExposure(1, options_.target_dn)) / high
            : options_.target_dn / high;
  const Image rendered_rad = AsRadiance(rendered), truth_rad = AsRadiance(truth);
  const Image dn_r = curve ? ToDigital(rendered_rad, *options_.response, exposure)
                           : ToLinearDigital(rendered_rad, exposure);
  const Image dn_t = curve ? ToDigital(truth_rad, *options_.response, exposure)
                           : ToLinearDigital(truth_rad, exposure);
  const double floor = options_.rel_error_floor * high;
  for (int y = 0; y < rendered.height; ++y) {
    for (int x = 0; x < rendered.width; ++x) {
      if (!Selected(mask, rendered, x, y)) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = dn_r.at(x, y, c) - dn_t.at(x, y, c);
        dn_err_sq_ += d * d;
        const double t = truth.at(x, y, c);
        rel_errors_.push_back(
            static_cast<float>(std::abs(rendered.at(x, y, c) - t) / std::max<double>(t, floor)));
      }
    }
  }
  pixels_ += n;
  err_sq_ += err_sq;
  truth_sq_ += truth_sq;
  sum_rendered_ += sum_r;
  sum_truth_ += sum_t;
}

RenderMetrics MetricsAccumulator::Result() const {
  if (pixels_ == 0) throw Error("metrics: no image was compared");
  RenderMetrics m;
  m.pixels = pixels_;
  m.rel_rmse = std::sqrt(err_sq_ / truth_sq_);
  m.mean_ratio = sum_truth_ > 0 ? sum_rendered_ / sum_truth_ : 0.0;
  const double mse = dn_err_sq_ / (3.0 * static_cast<double>(pixels_));
  m.psnr_db = mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : 99.0;
  m.median_rel_error = Quantile(rel_errors_, 0.5);
  return m;
}

RenderMetrics CompareRadiance(const Image& rendered, const Image& truth,
                              const std::vector<uint8_t>& mask, const MetricsOptions& options) {
  MetricsAccumulator acc(options);
  acc.Add(rendered, truth, mask);
  return acc.Result();
}

Image RelativeDifference(const Image& rendered, const Image& truth,
                         const std::vector<uint8_t>& mask, const MetricsOptions& options) {
  Check(rendered, truth, mask);
  std::vector<double> green;
  for (int y = 0; y < truth.height; ++y)
    for (int x = 0; x < truth.width; ++x)
      if (Selected(mask, truth, x, y)) green.push_back(truth.at(x, y, 1));
  if (green.empty()) throw Error("metrics: the mask selects no pixels");
  const double floor =
      options.rel_error_floor * std::max(1e-30, Quantile(green, options.percentile));
  Image out(truth.width, truth.height, 3, PixelUnits::kRadiance, 0.f);
  for (int y = 0; y < truth.height; ++y)
    for (int x = 0; x < truth.width; ++x) {
      if (!Selected(mask, truth, x, y)) continue;
      for (int c = 0; c < 3; ++c) {
        const double t = truth.at(x, y, c);
        out.at(x, y, c) =
            static_cast<float>((rendered.at(x, y, c) - t) / std::max<double>(t, floor));
      }
    }
  return out;
}

std::vector<uint8_t> ErodeMask(const std::vector<uint8_t>& mask, int width, int height,
                               int radius) {
  if (width < 0 || height < 0 || mask.size() != static_cast<size_t>(width) * height) {
    throw Error("metrics: mask has " + std::to_string(mask.size()) + " entries for a " +
                std::to_string(width) + "x" + std::to_string(height) + " image");
  }
  if (radius < 0) throw Error("metrics: erosion radius must be >= 0");
  std::vector<uint8_t> out(mask.size(), 0);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      bool keep = true;
      for (int dy = -radius; dy <= radius && keep; ++dy) {
        for (int dx = -radius; dx <= radius && keep; ++dx) {
          const int xx = x + dx, yy = y + dy;
          keep = xx >= 0 && yy >= 0 && xx < width && yy < height &&
                 mask[static_cast<size_t>(yy) * width + xx] != 0;
        }
      }
      out[static_cast<size_t>(y) * width + x] = keep ? 1 : 0;
    }
  }
  return out;
}

}  // namespace rouen
