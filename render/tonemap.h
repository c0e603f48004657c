// Radiance -> 8-bit digital numbers through the recovered camera response (§6: "re-rendered
// radiance images are converted to ... pixel values with the inverse of the nonlinear mapping").
#pragma once

#include "core/image.h"
#include "core/response_curve.h"

namespace rouen {

// Digital number per pixel and channel: the response at exposure = radiance x
// exposure_factor (seconds x gain x ND transmission, in the response's exposure units),
// rounded to 0..255. Returns a kDigital image with the same channels (first 3 used).
// Throws rouen::Error for an invalid response, a non-positive factor or non-radiance input.
Image ToDigital(const Image& radiance, const ResponseCurve& response, double exposure_factor);

// The exposure factor that maps the given percentile of the radiance (all channels) to the
// digital number `target_dn` (e.g. 99th percentile -> 230): an auto exposure for previews.
double AutoExposure(const Image& radiance, const ResponseCurve& response, double percentile = 0.99,
                    double target_dn = 230);

// Without a recovered response (a scene solved from HDR photos only): radiance x
// exposure_factor clipped to 0..1 and encoded as sRGB (IEC 61966-2-1), 0..255.
Image ToSrgbDigital(const Image& radiance, double exposure_factor);
// The exposure factor that maps the given percentile of the radiance to `target` (of white)
// before the sRGB encoding.
double AutoExposureSrgb(const Image& radiance, double percentile = 0.99, double target = 0.9);

}  // namespace rouen
