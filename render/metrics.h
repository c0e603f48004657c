// Validation metrics between a rendered and a photographed (or ground-truth) radiance image,
// one image or pooled over several: used by `rouen validate` and by the demo alike.
#pragma once

#include <cstdint>
#include <vector>

#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

// How radiance becomes the 8-bit image the PSNR is measured on (§6: re-rendered radiance is
// shown through the camera's response): both images of a pair are exposed alike, at the
// exposure that puts the `percentile` of the truth's green channel (over the mask) at digital
// `target_dn`.
struct MetricsOptions {
  const ResponseCurve* response = nullptr;  // none (or not valid): linear, clipped at 255
  double percentile = 0.99;
  double target_dn = 230;
  // The relative error's denominator is max(T, floor), floor = this fraction of the truth's
  // `percentile`: dark pixels of a photograph are mostly noise.
  double rel_error_floor = 0.01;
};

struct RenderMetrics {
  int64_t pixels = 0;           // masked pixels compared
  double rel_rmse = 0;          // RMS(R - T) / RMS(T) over masked pixels and the 3 channels
  double psnr_db = 0;           // of the 8-bit images (MetricsOptions); 99 when identical
  double median_rel_error = 0;  // median over masked pixels and channels of |R - T| / max(T, floor)
  double mean_ratio = 0;        // sum(R) / sum(T): the overall brightness bias (1 = none)
};

// Pools image pairs: the figures over every masked pixel of every pair added.
class MetricsAccumulator {
 public:
  explicit MetricsAccumulator(const MetricsOptions& options = {});
  // Compares the first 3 channels over pixels with mask != 0 (empty mask: every pixel).
  // Throws rouen::Error for mismatched sizes, an empty selection, non-finite values or a
  // truth that is zero over the mask.
  void Add(const Image& rendered, const Image& truth, const std::vector<uint8_t>& mask);
  // Throws rouen::Error when nothing was added.
  RenderMetrics Result() const;

 private:
  MetricsOptions options_;
  int64_t pixels_ = 0;
  double err_sq_ = 0, truth_sq_ = 0, sum_rendered_ = 0, sum_truth_ = 0, dn_err_sq_ = 0;
  std::vector<float> rel_errors_;
};

// One pair: MetricsAccumulator with a single Add.
RenderMetrics CompareRadiance(const Image& rendered, const Image& truth,
                              const std::vector<uint8_t>& mask, const MetricsOptions& options = {});

// (R - T) / max(T, floor) per pixel and channel over the mask, 0 elsewhere: the signed
// relative error as an image (floor as in MetricsOptions). Throws as MetricsAccumulator::Add.
Image RelativeDifference(const Image& rendered, const Image& truth,
                         const std::vector<uint8_t>& mask, const MetricsOptions& options = {});

// Keeps the pixels whose (2 radius + 1)^2 neighbourhood lies entirely in the mask: drops
// silhouette and block-edge pixels, whose value in a photograph mixes two surfaces.
std::vector<uint8_t> ErodeMask(const std::vector<uint8_t>& mask, int width, int height,
                               int radius = 1);

}  // namespace rouen
