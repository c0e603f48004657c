// The simulated camera sensor: exposure, photon shot noise and read noise, full-well
// saturation, a film-like non-linear response (not a pure gamma; slightly different per
// channel) and 8-bit quantisation. Deterministic for a given seed.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

struct SensorParams {
  double full_well_e = 20000.0;  // electrons at saturation (gain 1)
  double read_noise_e = 5.0;     // electrons RMS, before the gain
  // Fraction of full scale per unit exposure (W m^-2 sr^-1 x s x gain x ND transmission):
  // a sunlit stone wall (radiance ~20) at 1/500 s lands near mid-grey (DN ~125).
  double sensitivity = 2.0;
  // Response curve per channel (monotone, film-like, not a pure gamma):
  //   u = ((x + b)^gamma - b^gamma) / ((1 + b)^gamma - b^gamma)   (gamma with a linear toe)
  //   y1 = u (1 + s) / (u + s)                                     (shoulder)
  //   y = (1 - w) y1 + w smoothstep(y1)                            (S-curve), DN = 255 y.
  std::array<double, 3> gamma = {0.46, 0.45, 0.47};
  std::array<double, 3> black = {0.006, 0.005, 0.007};  // b
  std::array<double, 3> shoulder = {0.55, 0.60, 0.65};
  std::array<double, 3> toe = {0.25, 0.30, 0.28};
  void Validate() const;  // throws rouen::Error naming the parameter
};

class SimSensor {
 public:
  explicit SimSensor(const SensorParams& params = {});
  const SensorParams& params() const { return p_; }
  double Sensitivity() const { return p_.sensitivity; }

  // Response of channel c: normalised signal x in [0, 1] -> digital value in [0, 255]
  // (continuous, before quantisation) and its inverse.
  double Curve(int c, double x) const;
  double InverseCurve(int c, double dn) const;
  // Noise-free digital value (continuous) for an exposure = radiance x s x gain x ND.
  double DigitalValue(int c, double exposure) const;
  // ln(exposure) that produces digital value `dn` without noise (the true g(z) of
  // Debevec-Malik); dn below 0.25 is treated as 0.25.
  double TrueLogExposure(int c, double dn) const;
  // The true curve as a ResponseCurve (g(z) for z = 0..255).
  ResponseCurve TrueResponse() const;

  // Captures a radiance image (kRadiance, 3 channels): returns kDigital 0..255 integers
  // stored as floats. `seed` makes the noise reproducible.
  Image Capture(const Image& radiance, double exposure_s, double gain, double nd_density,
                uint64_t seed) const;
  // The same up to the normalised linear signal (after noise and clipping, before the
  // curve and quantisation); for tests of the noise model.
  Image CaptureLinear(const Image& radiance, double exposure_s, double gain, double nd_density,
                      uint64_t seed) const;
  // Standard deviation of the normalised linear signal for a noise-free level x (unclipped).
  double LinearNoiseStd(double x, double gain) const;

 private:
  SensorParams p_;
  // Per channel, from p_: b^gamma and (1 + b)^gamma - b^gamma (the curve's toe and scale).
  std::array<double, 3> black_pow_{}, curve_scale_{};
  // Per channel, element k - 1: the least float signal whose digital value (the curve rounded
  // to an integer) is at least k, k = 1..255; the curve rises, so a signal's digital value is
  // the number of these it reaches.
  std::array<std::vector<float>, 3> dn_threshold_;
  // Per channel, per bin of signals in [0, 1] sharing the top 16 bits of their float pattern
  // (bins 0.8% wide, log-spaced): the digital value of the bin's least signal. A signal's value
  // is its bin's plus the few thresholds it passes within the bin.
  std::array<std::vector<uint8_t>, 3> dn_of_bin_;
  double Quantised(int c, float x) const;  // the curve rounded to 0..255
};

}  // namespace rouen
