#include "solve/sky_cie.h"

#include <cmath>
#include <string>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

struct Gradation {
  double a, b;
};
struct Indicatrix {
  double c, d, e;
};
// ISO 15469 groups I..VI and 1..6.
constexpr Gradation kGradation[6] = {{4.0, -0.70},  {1.1, -0.80},  {0.0, -1.0},
                                     {-1.0, -0.55}, {-1.0, -0.32}, {-1.0, -0.15}};
constexpr Indicatrix kIndicatrix[6] = {{0, -1, 0},       {2, -1.5, 0.15},  {5, -2.5, 0.30},
                                       {10, -3.0, 0.45}, {16, -3.0, 0.30}, {24, -2.8, 0.15}};

CieSkyType Make(int type, const char* name, int g, int i) {
  const Gradation& gr = kGradation[g - 1];
  const Indicatrix& in = kIndicatrix[i - 1];
  return {type, name, gr.a, gr.b, in.c, in.d, in.e};
}

const CieSkyType kTypes[kNumCieSkyTypes] = {
    Make(1, "I.1", 1, 1),   Make(2, "I.2", 1, 2),   Make(3, "II.1", 2, 1),  Make(4, "II.2", 2, 2),
    Make(5, "III.1", 3, 1), Make(6, "III.2", 3, 2), Make(7, "III.3", 3, 3), Make(8, "III.4", 3, 4),
    Make(9, "IV.2", 4, 2),  Make(10, "IV.3", 4, 3), Make(11, "IV.4", 4, 4), Make(12, "V.4", 5, 4),
    Make(13, "V.5", 5, 5),  Make(14, "VI.5", 6, 5), Make(15, "VI.6", 6, 6)};

double Phi(const CieSkyType& t, double z) {
  const double cz = std::cos(z);
  if (cz <= 1e-9) return 1.0;  // exp(b / cos Z) -> 0 at the horizon (b < 0)
  return 1 + t.a * std::exp(t.b / cz);
}

double F(const CieSkyType& t, double chi) {
  const double cc = std::cos(chi);
  return 1 + t.c * (std::exp(t.d * chi) - std::exp(t.d * kPi / 2)) + t.e * cc * cc;
}

}  // namespace

const CieSkyType& CieStandardSky(int type) {
  if (type < 1 || type > kNumCieSkyTypes) {
    throw Error("CIE standard sky: type must be 1..15, got " + std::to_string(type));
  }
  return kTypes[type - 1];
}

double CieRelativeLuminance(const CieSkyType& t, double xi, double gamma, double sun_zenith) {
  return F(t, gamma) * Phi(t, xi) / (F(t, sun_zenith) * Phi(t, 0));
}

SkyParams CieAsSkyParams(const CieSkyType& t, double sun_zenith, double zenith_radiance) {
  const double k = 1 - t.c * std::exp(t.d * kPi / 2);
  SkyParams p;
  p.Lz = zenith_radiance * k / (F(t, sun_zenith) * Phi(t, 0));
  p.a = t.a;
  p.b = t.b;
  p.c = t.c / k;
  p.d = t.d;
  p.e = t.e / k;
  p.h = 1;
  return p;
}

}  // namespace rouen
