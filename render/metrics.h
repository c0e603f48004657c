// Validation metrics between a rendered and a photographed (or ground-truth) radiance image.
#pragma once

#include <cstdint>
#include <vector>

#include "core/image.h"

namespace rouen {

struct RenderMetrics {
  int64_t pixels = 0;   // masked pixels compared
  double rel_rmse = 0;  // RMS(s R - T) / RMS(T) over masked pixels and all channels
  // PSNR in dB of s R against T, both divided by the 99th percentile of the masked truth
  // (all channels) and clipped to [0, 1]: 10 log10(1 / MSE).
  double psnr_db = 0;
  double mean_ratio = 0;  // sum(s R) / sum(T): overall brightness bias (1 = none)
  double scale = 1;       // s used
};

// Compares the first 3 channels over pixels with mask != 0 (empty mask: every pixel).
// Throws rouen::Error for mismatched sizes, an empty selection or non-finite values.
RenderMetrics CompareRadiance(const Image& rendered, const Image& truth,
                              const std::vector<uint8_t>& mask,
                              double scale_rendered_to_truth = 1.0);

// Keeps the pixels whose (2 radius + 1)^2 neighbourhood lies entirely in the mask: drops
// silhouette and block-edge pixels, whose value in a photograph mixes two surfaces.
std::vector<uint8_t> ErodeMask(const std::vector<uint8_t>& mask, int width, int height,
                               int radius = 1);

// Least-squares scale s minimising |s R - T|^2 over the mask (e.g. an unknown exposure).
double FitScale(const Image& rendered, const Image& truth, const std::vector<uint8_t>& mask);

}  // namespace rouen
