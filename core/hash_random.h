// Counter-based random numbers: a key (a seed plus a pixel, frame or sample index) is mixed
// into a 64-bit hash, and uniform or normal numbers are read off the hash. A value depends on
// its key only, never on the order or thread that draws it, so simulated images and Monte
// Carlo estimates are reproducible under any parallel schedule.
#pragma once

#include <cmath>
#include <cstdint>

#include "core/angles.h"

namespace rouen {

// SplitMix64's finaliser (Steele, Lea & Flood 2014): every bit of `x` affects every bit out.
inline uint64_t MixHash(uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

// Two independent uniform numbers in (0, 1) from the high and the low 32 bits of a hash.
inline double HashUniformHigh(uint64_t h) { return ((h >> 32) + 0.5) * (1.0 / 4294967296.0); }
inline double HashUniformLow(uint64_t h) {
  return ((h & 0xffffffffULL) + 0.5) * (1.0 / 4294967296.0);
}
// One uniform number in [0, 1) with the 53 bits of a double.
inline double HashUniform53(uint64_t h) {
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

// Two independent standard normal numbers from a hash (Box-Muller).
inline void HashNormals(uint64_t h, double* n1, double* n2) {
  const double r = std::sqrt(-2.0 * std::log(HashUniformHigh(h)));
  const double phi = 2 * kPi * HashUniformLow(h);
  *n1 = r * std::cos(phi);
  *n2 = r * std::sin(phi);
}

}  // namespace rouen
