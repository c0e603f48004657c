// Neutral-density filter calibration: per-channel transmission from photographs of the same
// static scene with and without the filter (the sun frames of Yu & Malik 1998 §3.1 are taken
// through such a filter; its real transmission is rarely neutral).
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>
#include <vector>

#include "calib/response.h"
#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

struct NdOptions {
  // Pixels whose radiance (either image, any channel) is below this fraction of that image's
  // channel median are left out: their ratio is dominated by noise.
  double min_relative_level = 0.05;
  // Fewest usable pixels per channel; fewer is an error.
  int64_t min_pixels = 50;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct NdChannel {
  double transmission = 1;  // median of L_with / L_without over the usable pixels
  double density = 0;       // -log10(transmission)
  // Half-width of a distribution-free 95% confidence interval of the median density
  // (order statistics of the per-pixel log10 ratios).
  double density_ci95 = 0;
  // Robust spread of the per-pixel log10 ratios (1.4826 x median absolute deviation).
  double density_spread = 0;
  int64_t pixels = 0;
};

struct NdCalibration {
  std::array<NdChannel, 3> channel;
  double MeanDensity() const;
  std::array<double, 3> DensityRgb() const;
};

void to_json(nlohmann::json& j, const NdCalibration& c);
// Reads "density_rgb" (the rest is informative); throws rouen::Error.
void from_json(const nlohmann::json& j, NdCalibration& c);

// Per-channel transmission from two 3-channel radiance images (kRadiance) of the same static
// scene, each already divided by its exposure time and gain but not by the filter: `with` was
// taken through the filter, `without` not. Optional masks (width x height, 1 = well exposed,
// as MergeHdr gives) restrict the pixels used. Throws rouen::Error for mismatched sizes,
// images that are not radiance, masks of the wrong size, or too few usable pixels.
NdCalibration EstimateNdTransmission(const Image& with, const std::vector<uint8_t>* with_valid,
                                     const Image& without,
                                     const std::vector<uint8_t>* without_valid,
                                     const NdOptions& options);

// The same from two LDR brackets (a single frame each is enough): each is merged to radiance
// through `curve` (exposures = seconds x gain, without the filter), keeping only pixels well
// exposed in some frame.
NdCalibration EstimateNdTransmission(const Bracket& with, const Bracket& without,
                                     const ResponseCurve& curve, const NdOptions& options);

}  // namespace rouen
