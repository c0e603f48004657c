// Vignetting: the radial fall-off of a lens, calibrated from photographs of a uniform field
// (flat fields) and divided out of radiance images before they are merged or used.
#pragma once

#include <array>
#include <vector>

#include "core/image.h"
#include "core/lens.h"
#include "core/response_curve.h"

namespace rouen {

// The model (VignettingModel) and its removal (RemoveVignetting) live in core/lens.h.

struct VignettingOptions {
  // Flat frames are averaged over square bins of this many pixels on a side before the fit.
  int bin = 8;
  // Fit a linear illumination gradient per flat frame (a flat field is rarely perfectly even).
  bool fit_gradient = true;
  // Fit the optical centre too. To first order an offset of the centre and a linear gradient
  // are the same image, so both cannot be fitted: the centre is fitted only when
  // fit_gradient is false; otherwise it stays at `centre` (or the image centre).
  bool fit_centre = false;
  std::array<double, 2> centre = {-1, -1};  // pixels; negative = the image centre
  // Digital frames: values at or below / at or above these levels are not used.
  double dark_level = 5, saturation_level = 250;
  int max_iterations = 50;

  void Validate() const;  // throws rouen::Error explaining the bad field
};

struct VignettingSummary {
  int frames = 0;
  int bins_used = 0;
  int iterations = 0;
  double residual_rms = 0;    // relative (fraction of the frame's level), per bin
  double corner_falloff = 1;  // V at the farthest corner
  std::array<double, 3> gradient_max = {0, 0, 0};  // largest |gradient| fitted (per image width)
};

// Fits the model to flat-field frames of one lens: kRadiance images, or kDigital ones when
// `curve` is given (linearised through it). Every frame is scaled by its own level (and
// gradient), so frames of different brightness may be mixed. Throws rouen::Error for no
// frames, mismatched sizes, digital frames without a curve, too few usable bins, or a fit that
// does not give a valid model.
VignettingModel FitVignetting(const std::vector<const Image*>& flats,
                              const VignettingOptions& options, const ResponseCurve* curve,
                              VignettingSummary* summary = nullptr);

}  // namespace rouen
