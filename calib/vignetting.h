// Vignetting: the radial fall-off of a lens, calibrated from photographs of a uniform field
// (flat fields) and divided out of radiance images before they are merged or used.
#pragma once

#include <array>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

// V(r) = 1 + a1 r^2 + a2 r^4 + a3 r^6, r = distance from the optical centre (cx, cy) divided
// by the half-diagonal of the calibration image (r = 1 at the corners of a centred lens).
// A measured radiance is L_true x V.
struct VignettingModel {
  int width = 0, height = 0;  // image size the model was calibrated at (pixels)
  double cx = 0, cy = 0;      // optical centre, pixels (pixel centres at integer + 0.5)
  std::array<double, 3> a = {0, 0, 0};

  // Fall-off at pixel (x, y) (continuous coordinates) of an image of the calibration size.
  double Falloff(double x, double y) const;
  double FalloffAtRadius(double r) const;
  // Largest normalised radius of any image corner from the centre.
  double MaxRadius() const;
  // Checks sizes, a finite centre inside the image, finite coefficients and V > 0.05 from the
  // centre out to the farthest corner; throws rouen::Error.
  void Validate() const;
};

void to_json(nlohmann::json& j, const VignettingModel& v);
void from_json(const nlohmann::json& j, VignettingModel& v);  // validates; throws rouen::Error

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
  double residual_rms = 0;       // relative (fraction of the frame's level), per bin
  double corner_falloff = 1;     // V at the farthest corner
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

// Divides a radiance image by the fall-off (an image of another size with the same aspect
// ratio is mapped by scaling). Throws rouen::Error for a different aspect ratio or a digital
// image.
void RemoveVignetting(const VignettingModel& model, Image* radiance);

}  // namespace rouen
