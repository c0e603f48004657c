// The CIE standard general skies (ISO 15469:2004 / CIE S 011/E:2003): 15 sky types built from
// six gradation groups (a, b) and six scattering-indicatrix groups (c, d, e). Relative
// luminance of a sky element at zenith angle Z and angle chi from the sun (sun at zenith
// angle Zs), normalised to the zenith:
//   L / Lz = f(chi) phi(Z) / (f(Zs) phi(0)),
//   phi(Z) = 1 + a exp(b / cos Z)  (phi(90 deg) = 1),
//   f(chi) = 1 + c [exp(d chi) - exp(d pi / 2)] + e cos^2 chi.
// Used as a comparison model for the sky fit (Yu & Malik 1998 §3.2 fits eq. 9 instead).
#pragma once

#include "solve/sky_model.h"

namespace rouen {

struct CieSkyType {
  int type = 0;                // 1..15
  const char* name = "";       // e.g. "V.4"
  double a = 0, b = 0;         // gradation group
  double c = 0, d = 0, e = 0;  // indicatrix group
};

constexpr int kNumCieSkyTypes = 15;

// Type 1..15; throws rouen::Error for any other number.
const CieSkyType& CieStandardSky(int type);

// L / Lz for a sky element at zenith angle `xi` and angle `gamma` from the sun, sun at zenith
// angle `sun_zenith` (all radians, xi and sun_zenith in [0, pi/2]).
double CieRelativeLuminance(const CieSkyType& t, double xi, double gamma, double sun_zenith);

// The same sky as eq. 9 parameters (h = 1): f(chi) is rewritten as
// k [1 + (c / k) exp(d chi) + (e / k) cos^2 chi] with k = 1 - c exp(d pi / 2) > 0, so
// SkyRadiance(CieAsSkyParams(t, Zs, Lz), xi, gamma) = Lz * CieRelativeLuminance(t, xi, gamma, Zs).
SkyParams CieAsSkyParams(const CieSkyType& t, double sun_zenith, double zenith_radiance);

}  // namespace rouen
