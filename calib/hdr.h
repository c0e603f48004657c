// Merging bracketed digital frames into one radiance image (Debevec & Malik 1997, eq. 6;
// Yu & Malik 1998 §3).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/code_image.h"
#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

struct MergeOptions {
  // Digital numbers at or below `dark_level` or at or above `saturation_level` get weight 0;
  // in between the weight is a hat peaking half-way.
  double dark_level = 5.0;
  double saturation_level = 250.0;

  // Ghost removal for moving content. Per pixel, the reference is the frame nearest the
  // median exposure in which every channel is well exposed. Another frame whose estimate
  // ln L_j,c = g(z_j,c) - ln X_j differs from the reference's in some channel by more than
  //   ghost_threshold + ghost_noise_dn * (g'(z_j,c) + g'(z_ref,c))   (ln units)
  // -- beyond its reading noise through the curve's slope -- is taken to see different
  // content and gets weight 0 at that pixel (all channels). Pixels where no frame is well
  // exposed in every channel are merged as usual.
  bool ghost_removal = false;
  double ghost_threshold = 0.15;  // ln units, besides the noise term
  double ghost_noise_dn = 3.0;    // reading noise allowance, DN

  // Use the AVX2 kernel when the CPU has it (checked at run time). It gives the same floats as
  // the portable kernel; false forces the portable one (tests compare the two).
  bool use_simd = true;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct MergeSummary {
  int64_t pixels = 0;
  int64_t saturated_pixels = 0;  // some channel saturated in every frame (value is a lower bound)
  int64_t dark_pixels = 0;       // some channel dark in every frame (value from the longest)
  int64_t ghost_pixels = 0;      // ghost_removal: pixels where some frame was left out
  double seconds = 0;
};

// Per channel ln L = sum_j w(z_j) (g(z_j) - ln X_j) / sum_j w(z_j), with X_j the effective
// exposure factor (seconds x gain x 10^-nd) of frame j. Returns a kRadiance image in the
// curve's units (relative radiance). A channel saturated in every frame takes the shortest
// exposure's g(255) - ln X_min (a lower bound); one dark in every frame takes the longest
// exposure's reading. `valid_mask`, when given, gets width x height entries: 1 where every
// channel had at least one well-exposed frame, 0 elsewhere.
// Throws rouen::Error for no frames, mismatched sizes or channel counts, frames that are not
// digital numbers, non-positive or non-finite exposures, values outside 0..255, or an
// invalid curve.
Image MergeHdr(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
               const ResponseCurve& curve, const MergeOptions& options,
               MergeSummary* summary = nullptr, std::vector<uint8_t>* valid_mask = nullptr);

// The same, into `out`, whose pixel buffer is reused when it already has the right size (no
// allocation or page faults when merging brackets of one size repeatedly). `ghost_mask`, when
// given, gets width x height entries: 1 where ghost removal left some frame out.
void MergeHdrInto(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
                  const ResponseCurve& curve, const MergeOptions& options, Image* out,
                  MergeSummary* summary = nullptr, std::vector<uint8_t>* valid_mask = nullptr,
                  std::vector<uint8_t>* ghost_mask = nullptr);

// MergeHdrInto over 8-bit frames: the same floats as over Image frames holding the same
// numbers (one implementation: a code z reads as the level 16 z that the float z does).
void MergeHdrInto(const std::vector<const CodeImage*>& frames, const std::vector<double>& exposures,
                  const ResponseCurve& curve, const MergeOptions& options, Image* out,
                  MergeSummary* summary = nullptr, std::vector<uint8_t>* valid_mask = nullptr,
                  std::vector<uint8_t>* ghost_mask = nullptr);

// Merging frames that already hold radiance (kRadiance: imported RAW/EXR divided by seconds x
// gain), which need no response curve.
struct RadianceMergeOptions {
  // A frame's channel counts as clipped at its maximum M (a RAW white level) when at least
  // max(clip_min_pixels, pixels / clip_divisor) pixels are >= 0.999 M; its weight then falls
  // linearly from 1 to 0 over the top clip_ramp x M.
  int64_t clip_min_pixels = 16;
  int64_t clip_divisor = 2000;
  double clip_ramp = 0.1;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

// Per channel a weighted mean of value / transmission_j,c. The weight of frame j is its
// exposure (seconds x gain, or 1 when not positive and finite) times its mean transmission --
// the shot-noise-optimal choice for linear data -- times the clipping ramp above. Non-finite
// values are skipped. A value with no weight (clipped, or non-finite, in every frame) takes the
// least-weighted frame's finite value (a lower bound; 0 when none) and its pixel gets 0 in
// `valid_mask` (width x height entries, 1 elsewhere). `transmission` holds each frame's
// filter transmission per R, G, B (1-channel frames use R). Throws rouen::Error for no frames,
// mismatched sizes or channel counts, frames that are not kRadiance, list sizes that differ,
// non-positive or non-finite transmissions, or invalid options.
Image MergeRadiance(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
                    const std::vector<std::array<double, 3>>& transmission,
                    const RadianceMergeOptions& options,
                    std::vector<uint8_t>* valid_mask = nullptr);

}  // namespace rouen
