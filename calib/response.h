// Camera response recovery from bracketed exposures (Debevec & Malik 1997; Yu & Malik 1998 §3).
#pragma once

#include <cstdint>
#include <vector>

#include "core/code_image.h"
#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

// One static scene photographed at several exposures by the same camera.
struct Bracket {
  std::vector<Image> frames;  // kDigital 0..255, all the same size and channel count (1 or 3)
  // Or, instead of `frames` (then empty), the same frames as 8-bit codes: a quarter of the
  // memory, scanned for samples several times faster; the same curve.
  std::vector<CodeImage> codes;
  std::vector<double> exposures;  // effective exposure factor = seconds x gain x 10^(-nd)
  // Optional, width x height: 0 marks pixels never to sample (padding, moving objects).
  std::vector<uint8_t> mask;
};

// How the curve is recovered from the sampled pixels (the sample choice is shared).
enum class ResponseMethod {
  // Linear least squares on ln exposure with a second-difference smoothness term (Debevec &
  // Malik 1997), solved sparsely.
  kDebevecMalik,
  // Robertson, Borman & Stevenson 2003: alternates the irradiance of each sample,
  //   x_s = sum_j w_sj t_j I(z_sj) / sum_j w_sj t_j^2,
  // and the exposure of each level, I(m) = mean of t_j x_s over readings z_sj = m, until no
  // level's ln I moves by more than `convergence_tolerance`. Two changes from the paper, each
  // the cause of a bias of 0.1-0.8 ln on synthetic curves without noise:
  //  - Weight w = hat(z) / (dI/dz)^2 (the inverse variance of I(z) under +-0.5 DN
  //    quantisation, dI/dz from the current curve), zero within 3 DN of clipping. A plain
  //    hat times t^2 lets the longest, nearly clipped readings -- where one DN spans a wide
  //    range of exposure -- decide every sample.
  //  - The level means are combined with the Debevec-Malik second-difference term (same
  //    `lambda`) when ln I is updated. With one exposure ratio r between frames, any
  //    function periodic in ln exposure with period ln r fits the data equally well; the
  //    plain iteration keeps whatever such ripple its starting curve had.
  // Needs more readings per level than Debevec-Malik (robertson_min_samples_per_bracket).
  // Robertson et al. 2003, eqs. 10-11.
  kRobertson,
  // Mitsunaga & Nayar 1999: exposure I = f(M) = sum_n c_n M^n, M = z / 255, fitted to
  // f(M_q) = R_q f(M_q+1) over consecutive exposures q, q+1 of a sample with both readings
  // in [mn_fit_low, mn_fit_high]; each equation is divided by the previous estimate of f(M_q)
  // (relative error), f(128/255) = 1. The order is the one with the smallest two-fold
  // cross-validated residual among those whose f is positive and increasing over the fitted
  // range. R_q starts at the given exposure ratio and is re-estimated when
  // mn_estimate_ratios is set. A polynomial cannot follow a response whose inverse has a pole
  // at z = 255 (film-like shoulders): when no order is increasing, the top of the fit range
  // is lowered (12 DN steps, down to 192) and the curve above it is extrapolated, so it is
  // accurate only below the shoulder (synthetic film curve: to z = 235 noise-free, fitted to
  // 240). On curves that clip at a finite exposure (digital cameras, sRGB-like) it holds over
  // z = 20..250 (the default fit range; below mn_fit_low the curve is extrapolated: Memorial's
  // toe admits no increasing polynomial from 10 DN).
  kMitsunagaNayar,
};

const char* ResponseMethodName(ResponseMethod method);

struct ResponseOptions {
  ResponseMethod method = ResponseMethod::kDebevecMalik;
  // Pixels sampled per bracket, stratified over brightness, preferring flat regions.
  int samples_per_bracket = 200;
  // Brackets with more pixels than this are scanned for samples on a regular grid with
  // stride ceil(sqrt(pixels / scan_pixels)) (the gradient taken between grid neighbours).
  // Opt-in for now: with 1.5e6 (stride 2 on St Louis' 6 MP frames) the St Louis curve moved
  // by 0.41 ln between 200 and 400 samples, against 0.105 with the full scan -- for seed 1;
  // over seeds 1..12 the full scan's figure ranges 0.10..0.36 (mean 0.24), so one seed does
  // not separate the two.
  int64_t scan_pixels = 40000000;
  // Smoothness weight: ratio of the total squared weight of the 254 second-difference
  // equations to that of the data equations, so the bias does not change with the sample
  // count. Debevec-Malik's unnormalised lambda is about this x (samples x frames) / 254.
  // 1000 minimises the error on synthetic film-like and sRGB-like curves with 0.7 DN noise
  // and keeps the Memorial curve within 0.1 between 200 and 400 samples.
  double lambda = 1000.0;
  uint64_t seed = 1;
  // Scan the frames for samples with the AVX2 kernel when the CPU has it (checked at run
  // time). It chooses the same samples as the portable kernel; false forces the portable one.
  bool use_simd = true;
  // Added to the hat weight w(z) = min(z, 255 - z) so that z = 0 and z = 255 keep a trace.
  double weight_epsilon = 0.01;
  // Samples whose digital numbers fall by more than this (DN) as exposure grows are rejected
  // (misregistered or moving pixels, padding).
  double monotone_tolerance = 4.0;
  // Minimum slope enforced between adjacent entries after isotonic regression (ln units).
  double min_slope = 1e-4;

  // Robertson: each level starts as the mean of its own readings, so it samples at least
  // this many pixels per bracket (by the same selection).
  int robertson_min_samples_per_bracket = 2000;
  // Robertson: iteration cap and the largest change of any level's ln I (ln units) between
  // iterations that counts as converged.
  int max_iterations = 500;
  double convergence_tolerance = 1e-6;
  // Mitsunaga-Nayar: orders 1..max_polynomial_order are tried; readings used for the ratio
  // equations (DN; the clipped ends are left out, the curve is extrapolated beyond them).
  int max_polynomial_order = 10;
  double mn_fit_low = 20.0;
  double mn_fit_high = 252.0;
  // Mitsunaga-Nayar: re-estimate the exposure ratios of consecutive frames from the data
  // (the paper's iteration) instead of trusting the given exposures. Off by default, because
  // the merge uses the given exposures and the curve must agree with them.
  bool mn_estimate_ratios = false;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct ResponseSummary {
  ResponseMethod method = ResponseMethod::kDebevecMalik;
  int samples_used = 0;  // pixels, over all brackets
  int equations = 0;     // readings per channel (samples x frames)
  // Fit residual of the final curve, the same measure for every method: ln units,
  // hat-weighted, over readings with 0 < z < 255, each sample's ln E re-estimated from the
  // curve (rms over channels).
  double residual_rms = 0;
  // The method's own objective at its solution (rms over channels): Debevec-Malik, the
  // weighted data rows (ln units); Robertson, (I(z) - t x) / I(z) over weighted readings;
  // Mitsunaga-Nayar, (f(M_q) - R_q f(M_q+1)) / f(M_q) over the pairs.
  double method_residual = 0;
  int monotone_violations = 0;          // adjacent pairs the isotonic step had to repair
  int iterations = 0;                   // Robertson: iterations run (max over channels)
  bool converged = true;                // Robertson: every channel met convergence_tolerance
  int polynomial_order = 0;             // Mitsunaga-Nayar: chosen order (max over channels)
  std::vector<double> exposure_ratios;  // Mitsunaga-Nayar with mn_estimate_ratios: R_q used
  double mn_fit_high = 0;  // Mitsunaga-Nayar: top of the fit range used (lowest over channels)
  int scan_stride = 1;     // grid stride of the sample scan (largest over brackets)
  double seconds = 0;
};

// Recovers g(z) = ln(exposure) per channel by options.method (default: the Debevec-Malik
// linear least squares with a hat weight and a second-difference smoothness term, solved
// sparsely); then, for every method, made strictly increasing (pool-adjacent-violators),
// lightly re-smoothed, and extended by linear extrapolation over values no usable reading
// reached. Samples are chosen in parallel (TBB) over the bracket's pixels.
//
// Scale: each channel is pinned at g_c(128) = 0, i.e. a pixel reading 128 in every channel
// is neutral (grey). The relative offset between channels is a white-balance choice that a
// bracket cannot determine; a later colour calibration may shift the channels.
// Single-channel frames give one curve copied to all three channels.
//
// Throws rouen::Error for fewer than two distinct exposures in a bracket, non-positive or
// non-finite exposures, mismatched frame counts or sizes, differing channel counts, frames
// that are not digital numbers, a mask of the wrong size, or too few usable samples; and, for
// Mitsunaga-Nayar, when no polynomial order gives an increasing curve.
ResponseCurve RecoverResponse(const std::vector<Bracket>& brackets, const ResponseOptions& options,
                              ResponseSummary* summary = nullptr);

}  // namespace rouen
