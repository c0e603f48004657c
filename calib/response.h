// Camera response recovery from bracketed exposures (Debevec & Malik 1997; Yu & Malik 1998 §3).
#pragma once

#include <cstdint>
#include <vector>

#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

// One static scene photographed at several exposures by the same camera.
struct Bracket {
  std::vector<Image> frames;      // kDigital 0..255, all the same size and channel count (1 or 3)
  std::vector<double> exposures;  // effective exposure factor = seconds x gain x 10^(-nd)
  // Optional, width x height: 0 marks pixels never to sample (padding, moving objects).
  std::vector<uint8_t> mask;
};

struct ResponseOptions {
  // Pixels sampled per bracket, stratified over brightness, preferring flat regions.
  int samples_per_bracket = 200;
  // Smoothness weight: ratio of the total squared weight of the 254 second-difference
  // equations to that of the data equations, so the bias does not change with the sample
  // count. Debevec-Malik's unnormalised lambda is about this x (samples x frames) / 254.
  // 1000 minimises the error on synthetic film-like and sRGB-like curves with 0.7 DN noise
  // and keeps the Memorial curve within 0.1 between 200 and 400 samples.
  double lambda = 1000.0;
  uint64_t seed = 1;
  // Added to the hat weight w(z) = min(z, 255 - z) so that z = 0 and z = 255 keep a trace.
  double weight_epsilon = 0.01;
  // Samples whose digital numbers fall by more than this (DN) as exposure grows are rejected
  // (misregistered or moving pixels, padding).
  double monotone_tolerance = 4.0;
  // Minimum slope enforced between adjacent entries after isotonic regression (ln units).
  double min_slope = 1e-4;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct ResponseSummary {
  int samples_used = 0;         // pixels, over all brackets
  int equations = 0;            // data equations per channel
  double residual_rms = 0;      // ln units, hat-weighted, over data with 0 < z < 255
  int monotone_violations = 0;  // adjacent pairs the isotonic step had to repair
  double seconds = 0;
};

// Recovers g(z) = ln(exposure) per channel by the Debevec-Malik linear least squares with a
// hat weight and a second-difference smoothness term, solved sparsely; then made strictly
// increasing (pool-adjacent-violators), lightly re-smoothed, and extended by extrapolation
// over values that never occurred.
//
// Scale: each channel is pinned at g_c(128) = 0, i.e. a pixel reading 128 in every channel
// is neutral (grey). The relative offset between channels is a white-balance choice that a
// bracket cannot determine; a later colour calibration may shift the channels.
// Single-channel frames give one curve copied to all three channels.
//
// Throws rouen::Error for fewer than two distinct exposures in a bracket, non-positive or
// non-finite exposures, mismatched frame counts or sizes, differing channel counts, frames
// that are not digital numbers, a mask of the wrong size, or too few usable samples.
ResponseCurve RecoverResponse(const std::vector<Bracket>& brackets, const ResponseOptions& options,
                              ResponseSummary* summary = nullptr);

}  // namespace rouen
