// Synthetic brackets for the calib tests: a known response applied to a known radiance field;
// loaders of the real brackets in ../shared/data/hdr (also used by bench/calib_bench).
#pragma once

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "calib/response.h"
#include "core/image.h"
#include "core/response_curve.h"

namespace rouen::testing {

// Known synthetic responses. kFilm: z = 255 (x / (x + k_c))^0.8, a film-like curve with a
// toe and a shoulder whose inverse has a pole at z = 255 (it never clips). kSrgb: the sRGB
// encoding of g_c x, clipped at x g_c = 1 as a digital camera clips.
enum class CurveShape { kFilm, kSrgb };

inline double TrueDigital(int c, double x, CurveShape shape = CurveShape::kFilm) {
  static const double kK[3] = {0.25, 0.3, 0.4};
  static const double kGain[3] = {0.9, 1.0, 0.8};
  if (shape == CurveShape::kFilm) return 255.0 * std::pow(x / (x + kK[c]), 0.8);
  const double v = std::min(1.0, x * kGain[c]);
  return 255.0 * (v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055);
}

// Exact inverse: ln x for a (fractional) digital number 0 < z < 255.
inline double TrueLogExposure(int c, double z, CurveShape shape = CurveShape::kFilm) {
  static const double kK[3] = {0.25, 0.3, 0.4};
  static const double kGain[3] = {0.9, 1.0, 0.8};
  if (shape == CurveShape::kFilm) {
    const double u = std::pow(z / 255.0, 1.25);
    return std::log(kK[c] * u / (1 - u));
  }
  const double m = z / 255.0;
  const double v = m <= 0.04045 ? m / 12.92 : std::pow((m + 0.055) / 1.055, 2.4);
  return std::log(v / kGain[c]);
}

// d ln x / dz of the true curve (ln units per digital number).
inline double TrueSlope(int c, double z, CurveShape shape = CurveShape::kFilm) {
  return 0.5 * (TrueLogExposure(c, z + 1, shape) - TrueLogExposure(c, z - 1, shape));
}

// The film curve tabulated as a ResponseCurve; the open ends z = 0 and 255 (ln x = -inf and
// +inf) are extrapolated linearly from their neighbours.
inline ResponseCurve TrueCurve() {
  ResponseCurve r;
  for (int c = 0; c < 3; ++c) {
    r.g[c].resize(256);
    for (int z = 1; z < 255; ++z) r.g[c][z] = TrueLogExposure(c, z);
    r.g[c][0] = 2 * r.g[c][1] - r.g[c][2];
    r.g[c][255] = 2 * r.g[c][254] - r.g[c][253];
  }
  return r;
}

// Piecewise-constant random radiance (blocks of `block` pixels, log-uniform between
// exp(log_lo) and exp(log_hi)), with a smooth ramp inside each block so neighbours differ.
inline Image RadianceField(int w, int h, double log_lo, double log_hi, uint64_t seed,
                           int block = 6) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(log_lo, log_hi);
  const int bw = (w + block - 1) / block, bh = (h + block - 1) / block;
  std::vector<double> base(static_cast<size_t>(bw) * bh * 3);
  for (double& v : base) v = u(rng);
  Image img(w, h, 3, PixelUnits::kRadiance);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) {
        // Channels correlated (same block brightness) with a colour offset.
        const double l = base[(static_cast<size_t>(y / block) * bw + x / block) * 3 + 0] +
                         0.3 *
                             (base[(static_cast<size_t>(y / block) * bw + x / block) * 3 + c] -
                              0.5 * (log_lo + log_hi)) /
                             (log_hi - log_lo) +
                         0.01 * (x % block);
        img.at(x, y, c) = static_cast<float>(std::exp(l));
      }
    }
  }
  return img;
}

// One frame: z = round(TrueDigital(x * exposure) + noise), clamped to 0..255.
inline Image Expose(const Image& radiance, double exposure, double noise_dn, std::mt19937_64* rng,
                    CurveShape shape = CurveShape::kFilm) {
  std::normal_distribution<double> n(0.0, noise_dn);
  Image f(radiance.width, radiance.height, 3, PixelUnits::kDigital);
  for (int y = 0; y < radiance.height; ++y) {
    for (int x = 0; x < radiance.width; ++x) {
      for (int c = 0; c < 3; ++c) {
        double z = TrueDigital(c, radiance.at(x, y, c) * exposure, shape);
        if (noise_dn > 0) z += n(*rng);
        f.at(x, y, c) = static_cast<float>(std::clamp(std::round(z), 0.0, 255.0));
      }
    }
  }
  return f;
}

inline Bracket MakeBracket(const Image& radiance, const std::vector<double>& exposures,
                           double noise_dn, uint64_t seed, CurveShape shape = CurveShape::kFilm) {
  std::mt19937_64 rng(seed);
  Bracket b;
  b.exposures = exposures;
  for (double e : exposures) b.frames.push_back(Expose(radiance, e, noise_dn, &rng, shape));
  return b;
}

// ---- Real data under ROUEN_SHARED_DIR (tests and bench only): Debevec's Memorial Church. ----

// Two stops apart; radiance e^-5..e^4 is well exposed somewhere for both curve shapes.
inline const std::vector<double> kTwoStopExposures = {1.0 / 64, 1.0 / 16, 1.0 / 4, 1.0, 4.0, 16.0};

inline bool StrictlyIncreasing(const std::vector<double>& g) {
  for (size_t z = 1; z < g.size(); ++z) {
    if (!(g[z] > g[z - 1])) return false;
  }
  return true;
}

inline std::filesystem::path MemorialDir() {
  return std::filesystem::path(ROUEN_SHARED_DIR) / "data" / "hdr" / "memorial";
}

// Loads the bracket listed in `dir`/exposures.txt (lines "filename seconds"; '#' comments),
// each frame cropped by the given margins in pixels. Empty when the list cannot be read.
inline Bracket LoadBracket(const std::filesystem::path& dir, int top, int bottom, int left,
                           int right) {
  Bracket b;
  std::ifstream list(dir / "exposures.txt");
  std::string line;
  while (std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    std::string file;
    double seconds = 0;
    in >> file >> seconds;
    const Image full = ReadImage((dir / file).string());
    const int w = full.width - left - right, h = full.height - top - bottom;
    Image crop(w, h, full.channels, full.units);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < full.channels; ++c) crop.at(x, y, c) = full.at(x + left, y + top, c);
      }
    }
    b.frames.push_back(std::move(crop));
    b.exposures.push_back(seconds);
  }
  return b;
}

// Loads the 16 frames cropped as the data set's README says (top 30, bottom 20, left 3,
// right 4 px) to remove the blue registration padding.
inline Bracket LoadMemorial() { return LoadBracket(MemorialDir(), 30, 20, 3, 4); }

}  // namespace rouen::testing
