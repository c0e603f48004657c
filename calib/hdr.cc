#include "calib/hdr.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <type_traits>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

#include "core/error.h"

namespace rouen {
namespace {

// Tables are indexed by digital number in steps of 1/16 so 16-bit inputs keep precision.
constexpr int kSteps = 16;
constexpr int kTable = 255 * kSteps + 1;
constexpr unsigned kLast = kTable - 1;
// ln of the largest finite float, minus a margin.
constexpr double kMaxLog = 88.0;

void CheckCurve(const ResponseCurve& curve) {
  for (int c = 0; c < 3; ++c) {
    const auto& g = curve.g[c];
    if (g.size() != 256) {
      throw Error("hdr merge: response curve channel " + std::to_string(c) + " has " +
                  std::to_string(g.size()) + " entries, expected 256");
    }
    for (int z = 0; z < 256; ++z) {
      if (!std::isfinite(g[z])) {
        throw Error("hdr merge: response curve channel " + std::to_string(c) +
                    " is not finite at z = " + std::to_string(z));
      }
      if (z > 0 && g[z] < g[z - 1]) {
        throw Error("hdr merge: response curve channel " + std::to_string(c) +
                    " decreases at z = " + std::to_string(z));
      }
    }
  }
}

// 0..255, with NaN mapped to 0 (std::clamp would pass NaN through to the index).
inline float Clamp255(float z) { return z > 0.f ? (z < 255.f ? z : 255.f) : 0.f; }

int Level(float z) { return static_cast<int>(Clamp255(z) * kSteps + 0.5f); }

// What the per-sample sums need, shared by all frames: at each 1/16-DN level k and channel c,
// {w(k), g_c(k)} (interleaved, entry k * nc + c: 98 KB for 3 channels, but integer inputs
// touch one cache line per DN, 16 KB, so it stays in L1). A frame's term is then
// w(k) (g_c(k) - ln X_j), with ln X_j one constant per frame pass.
struct Levels {
  struct Entry {
    float w;  // hat weight w(k)
    float g;  // g_c(k), ln exposure
  };
  std::vector<Entry> e;
  // For 8-bit codes: per frame j, g_c(z) - ln X_j at j * 256 nc + z nc + c (the float
  // g - ln X that the per-level path computes; the AVX2 kernel gathers it).
  std::vector<float> code_g;
  int nc = 3;
  float dark = 0, sat = 255;  // MergeOptions' levels, DN

  // w(k) = max(0, min(z - dark, sat - z)) at z = k / 16 DN, the table's w (the AVX2 kernel
  // computes it with these same float operations instead of loading it). z is exact in float;
  // for levels that are multiples of 1/16 DN (the defaults 5 and 250) so are both
  // differences, so this equals the double-precision hat; otherwise it differs only by the
  // rounding of the levels to float (relative 6e-8).
  float HatWeight(unsigned k) const {
    const float z = static_cast<float>(k) * (1.f / kSteps);
    return std::max(std::min(z - dark, sat - z), 0.f);
  }
  const Entry& At(unsigned k, int c) const { return e[static_cast<size_t>(k) * nc + c]; }
  float Weight(unsigned k) const { return e[static_cast<size_t>(k) * nc].w; }
  float G(unsigned k, int c) const { return At(k, c).g; }
  const float* CodeTable(int j) const { return code_g.data() + static_cast<size_t>(j) * 256 * nc; }
};

// Per-sample level: v = z * 16 + 0.5 truncated. The sample is valid when v lies in
// (-1, kTable), i.e. z in (-3/32, 255 + 1/32) DN (the half-step rounding margin, and the
// truncation toward zero at the bottom); NaN is invalid. Invalid samples use level 0 and set
// *bad. This is exactly what the AVX2 kernel's truncating conversion and unsigned clamp do.
inline unsigned SampleLevel(float z, unsigned* bad) {
  const float v = z * kSteps + 0.5f;
  const bool ok = v > -1.f && v < static_cast<float>(kTable);
  *bad |= !ok;
  return ok ? static_cast<unsigned>(static_cast<int>(v)) : 0u;
}
// An 8-bit code is always valid, and its level is what the float path gives the same number.
inline unsigned SampleLevel(uint8_t z, unsigned*) { return static_cast<unsigned>(z) * kSteps; }

// Adds one frame's row to the per-value sums num += w (g - ln X), den += w. Returns true when
// some value was outside 0..255 (see SampleLevel) or not finite.
template <int NC, typename T>
bool AccumulateRow(const T* s, const Levels& lv, float log_x, size_t row_len, float* num,
                   float* den) {
  unsigned bad = 0;
  for (size_t i = 0; i < row_len; i += NC) {
    for (int c = 0; c < NC; ++c) {
      const Levels::Entry& e = lv.At(SampleLevel(s[i + c], &bad), c);
      num[i + c] = num[i + c] + e.w * (e.g - log_x);
      den[i + c] = den[i + c] + e.w;
    }
  }
  return bad != 0;
}

// Adds the rows of frames 0..nf-1 (s[j], ln X_j = log_x[j]) to num/den, frame by frame in
// order; returns the last frame holding bad values, or -1. Portable kernel.
template <int NC, typename T>
int AccumulateRows(const T* const* s, const float* log_x, int nf, const Levels& lv, size_t row_len,
                   float* num, float* den) {
  int bad = -1;
  for (int j = 0; j < nf; ++j) {
    if (AccumulateRow<NC>(s[j], lv, log_x[j], row_len, num, den)) bad = j;
  }
  return bad;
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define ROUEN_HDR_AVX2 1
// F frames' rows at once, 8 values per instruction, for CPUs with AVX2 (checked at run time):
// each value's sums are loaded once, the F frames' terms added in frame order, and stored
// once. The operations are those of the portable kernel in the same order, without FMA
// contraction (the target is "avx2" only, without FMA, and the build is ISO C++ without GNU
// extensions, so the compiler does not contract across statements), so the results are the
// same floats. Whole groups of 24 values (8 pixels of 3 channels, or 24 of
// 1) go through the vector loop, the rest through the portable kernel. The weight is computed
// as Levels::HatWeight does, only g is gathered.
template <int NC, int F, typename T>
__attribute__((target("avx2"))) int AccumulatePassAvx2(const T* const* s, const float* log_x,
                                                       int j0, const Levels& lv, size_t row_len,
                                                       float* num, float* den) {
  const __m256 steps = _mm256_set1_ps(kSteps), half = _mm256_set1_ps(0.5f);
  const __m256 inv_steps = _mm256_set1_ps(1.f / kSteps);
  const __m256 dark = _mm256_set1_ps(lv.dark), sat = _mm256_set1_ps(lv.sat);
  const __m256 zero = _mm256_setzero_ps();
  const __m256i last = _mm256_set1_epi32(kLast);
  __m256 lx[F];
  for (int f = 0; f < F; ++f) lx[f] = _mm256_set1_ps(log_x[f]);
  const float* frame_g[F];
  for (int f = 0; f < F; ++f) {
    frame_g[f] = std::is_same_v<T, float> ? nullptr : lv.CodeTable(j0 + f);
  }
  // Channel of each lane in the three vectors of a 24-value group (phases 0, 2, 1 of 3).
  const __m256i ch[3] = {
      NC == 3 ? _mm256_setr_epi32(0, 1, 2, 0, 1, 2, 0, 1) : _mm256_setzero_si256(),
      NC == 3 ? _mm256_setr_epi32(2, 0, 1, 2, 0, 1, 2, 0) : _mm256_setzero_si256(),
      NC == 3 ? _mm256_setr_epi32(1, 2, 0, 1, 2, 0, 1, 2) : _mm256_setzero_si256()};
  // Largest raw level seen per frame, unsigned: NaN and values beyond int convert to
  // INT_MIN (0x80000000) and negative levels wrap, so all invalid samples exceed kLast.
  __m256i top[F];
  for (int f = 0; f < F; ++f) top[f] = _mm256_setzero_si256();
  const size_t vec_len = row_len - row_len % 24;
  for (size_t i = 0; i < vec_len; i += 24) {
    for (int v = 0; v < 3; ++v) {
      const size_t o = i + 8 * v;
      __m256 n = _mm256_loadu_ps(num + o), d = _mm256_loadu_ps(den + o);
      for (int f = 0; f < F; ++f) {
        if constexpr (!std::is_same_v<T, float>) {
          // 8-bit codes (always valid): z is the level's DN exactly, and the frame's own
          // table holds g_c(z) - ln X_j, the float the float path computes.
          const __m256i code =
              _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(s[f] + o)));
          const __m256i idx =
              NC == 3 ? _mm256_add_epi32(_mm256_add_epi32(_mm256_slli_epi32(code, 1), code), ch[v])
                      : code;
          const __m256 gx = _mm256_i32gather_ps(frame_g[f], idx, 4);
          const __m256 z = _mm256_cvtepi32_ps(code);
          const __m256 w =
              _mm256_max_ps(_mm256_min_ps(_mm256_sub_ps(z, dark), _mm256_sub_ps(sat, z)), zero);
          n = _mm256_add_ps(n, _mm256_mul_ps(w, gx));
          d = _mm256_add_ps(d, w);
        } else {
          const __m256 zf = _mm256_loadu_ps(s[f] + o);
          const __m256i raw = _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(zf, steps), half));
          top[f] = _mm256_max_epu32(top[f], raw);
          const __m256i k = _mm256_min_epu32(raw, last);
          const __m256i idx =
              NC == 3 ? _mm256_add_epi32(_mm256_add_epi32(_mm256_slli_epi32(k, 1), k), ch[v]) : k;
          // g from the {w, g} entries: 8-byte stride, 4 bytes in.
          const __m256 g = _mm256_i32gather_ps(&lv.e[0].g, idx, 8);
          const __m256 zk = _mm256_mul_ps(_mm256_cvtepi32_ps(k), inv_steps);
          const __m256 w =
              _mm256_max_ps(_mm256_min_ps(_mm256_sub_ps(zk, dark), _mm256_sub_ps(sat, zk)), zero);
          n = _mm256_add_ps(n, _mm256_mul_ps(w, _mm256_sub_ps(g, lx[f])));
          d = _mm256_add_ps(d, w);
        }
      }
      _mm256_storeu_ps(num + o, n);
      _mm256_storeu_ps(den + o, d);
    }
  }
  int bad = -1;
  for (int f = 0; f < F; ++f) {
    // Any lane above kLast (unsigned)?
    const __m256i ok = _mm256_cmpeq_epi32(_mm256_max_epu32(top[f], last), last);
    if (_mm256_movemask_epi8(ok) != -1) bad = f;
  }
  // Clear the upper register halves before SSE code runs again (GCC does not always insert
  // this for target-attribute functions; without it the caller's scalar code, expf in the
  // finishing pass, slows down several times).
  _mm256_zeroupper();
  for (int f = 0; f < F; ++f) {
    if (AccumulateRow<NC>(s[f] + vec_len, lv, log_x[f], row_len - vec_len, num + vec_len,
                          den + vec_len)) {
      bad = std::max(bad, f);
    }
  }
  return bad;
}

// All frames, kAvx2Frames per pass and the remainder one by one; the result as
// AccumulateRows.
constexpr int kAvx2Frames = 4;
template <int NC, typename T>
__attribute__((target("avx2"))) int AccumulateRowsAvx2(const T* const* s, const float* log_x,
                                                       int nf, const Levels& lv, size_t row_len,
                                                       float* num, float* den) {
  int bad = -1;
  int j = 0;
  for (; j + kAvx2Frames <= nf; j += kAvx2Frames) {
    const int b =
        AccumulatePassAvx2<NC, kAvx2Frames, T>(s + j, log_x + j, j, lv, row_len, num, den);
    if (b >= 0) bad = j + b;
  }
  for (; j < nf; ++j) {
    if (AccumulatePassAvx2<NC, 1, T>(s + j, log_x + j, j, lv, row_len, num, den) >= 0) bad = j;
  }
  return bad;
}
#endif

template <typename T>
using RowsKernel = int (*)(const T* const*, const float*, int, const Levels&, size_t, float*,
                           float*);

// The AVX2 kernel where the CPU has it and `simd` allows it, else the portable one.
template <typename T>
RowsKernel<T> ChooseKernel(int nc, bool simd) {
#ifdef ROUEN_HDR_AVX2
  if (simd && __builtin_cpu_supports("avx2")) {
    return nc == 3 ? AccumulateRowsAvx2<3, T> : AccumulateRowsAvx2<1, T>;
  }
#endif
  (void)simd;
  return nc == 3 ? AccumulateRows<3, T> : AccumulateRows<1, T>;
}

// e^x for the merge's |ln L| <= kMaxLog (88), in float operations that a vector unit does
// alike (ExpRowAvx2 gives the same floats): x = n ln 2 + r with |r| <= ln 2 / 2 (ln 2 in two
// parts, Cody & Waite), e^r by Cephes' degree-7 polynomial for expf (relative error below
// 2.4e-7, 2 float ulp, over that range), times 2^n applied as 2^(n/2) 2^(n - n/2) so both
// factors stay normal floats for n in -127..127 (e^-88 is a denormal).
constexpr float kLog2e = 1.44269504088896341f;
constexpr float kLn2Hi = 0.693359375f, kLn2Lo = -2.12194440e-4f;
constexpr float kExpP[6] = {1.9875691500e-4f, 1.3981999507e-3f, 8.3334519073e-3f,
                            4.1665795894e-2f, 1.6666665459e-1f, 5.0000001201e-1f};

inline float ExpPoly(float x) {
  const float n = std::floor(x * kLog2e + 0.5f);
  float r = x - n * kLn2Hi;
  r = r - n * kLn2Lo;
  const float r2 = r * r;
  float p = kExpP[0];
  for (int k = 1; k < 6; ++k) p = p * r + kExpP[k];
  p = p * r2 + r;
  p = p + 1.f;
  const int ni = static_cast<int>(n);
  const int a = ni >> 1, b = ni - a;
  const float sa = std::bit_cast<float>((a + 127) << 23);
  const float sb = std::bit_cast<float>((b + 127) << 23);
  return p * sa * sb;
}

// Replaces each ln L of a row by L = e^ln L; returns true when some |ln L| exceeded kMaxLog
// (or was NaN), whose entries are then set to 1.
bool ExpRow(float* l, size_t n) {
  bool over = false;
  for (size_t i = 0; i < n; ++i) {
    const bool ok = std::abs(l[i]) <= kMaxLog;
    over |= !ok;
    l[i] = ExpPoly(ok ? l[i] : 0.f);
  }
  return over;
}

using ExpRowFn = bool (*)(float*, size_t);

#ifdef ROUEN_HDR_AVX2
// ExpRow 8 values at a time with AVX2, the tail by ExpRow: the same operations.
__attribute__((target("avx2"))) bool ExpRowAvx2(float* l, size_t n) {
  const __m256 max_log = _mm256_set1_ps(static_cast<float>(kMaxLog));
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  __m256 over = _mm256_setzero_ps();
  const size_t vec = n - n % 8;
  for (size_t i = 0; i < vec; i += 8) {
    __m256 x = _mm256_loadu_ps(l + i);
    const __m256 ok = _mm256_cmp_ps(_mm256_and_ps(x, abs_mask), max_log, _CMP_LE_OQ);
    over = _mm256_or_ps(over, _mm256_xor_ps(ok, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
    x = _mm256_and_ps(x, ok);
    const __m256 nf = _mm256_floor_ps(
        _mm256_add_ps(_mm256_mul_ps(x, _mm256_set1_ps(kLog2e)), _mm256_set1_ps(0.5f)));
    __m256 r = _mm256_sub_ps(x, _mm256_mul_ps(nf, _mm256_set1_ps(kLn2Hi)));
    r = _mm256_sub_ps(r, _mm256_mul_ps(nf, _mm256_set1_ps(kLn2Lo)));
    const __m256 r2 = _mm256_mul_ps(r, r);
    __m256 p = _mm256_set1_ps(kExpP[0]);
    for (int k = 1; k < 6; ++k) p = _mm256_add_ps(_mm256_mul_ps(p, r), _mm256_set1_ps(kExpP[k]));
    p = _mm256_add_ps(_mm256_mul_ps(p, r2), r);
    p = _mm256_add_ps(p, _mm256_set1_ps(1.f));
    const __m256i ni = _mm256_cvttps_epi32(nf);
    const __m256i a = _mm256_srai_epi32(ni, 1), b = _mm256_sub_epi32(ni, a);
    const __m256i bias = _mm256_set1_epi32(127);
    const __m256 sa = _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(a, bias), 23));
    const __m256 sb = _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(b, bias), 23));
    _mm256_storeu_ps(l + i, _mm256_mul_ps(_mm256_mul_ps(p, sa), sb));
  }
  const bool any = _mm256_movemask_ps(over) != 0;
  _mm256_zeroupper();
  return ExpRow(l + vec, n - vec) || any;
}
#endif

ExpRowFn ChooseExpRow(bool simd) {
#ifdef ROUEN_HDR_AVX2
  if (simd && __builtin_cpu_supports("avx2")) return ExpRowAvx2;
#endif
  (void)simd;
  return ExpRow;
}

// Ghost removal over one row (see MergeOptions::ghost_removal): subtracts the contributions
// of frames that disagree with the pixel's reference frame from num/den. Returns the number
// of pixels where some frame was left out.
template <typename T>
int64_t RemoveGhosts(const std::vector<const T*>& src, const std::vector<int>& by_median,
                     const Levels& lv, const std::vector<float>& log_x,
                     const std::vector<float>& slope, int w, const MergeOptions& o, float* num,
                     float* den, uint8_t* ghost_row) {
  const int nc = lv.nc;
  int64_t count = 0;
  const float thr = static_cast<float>(o.ghost_threshold);
  const float noise = static_cast<float>(o.ghost_noise_dn);
  for (int x = 0; x < w; ++x) {
    const size_t off = static_cast<size_t>(x) * nc;
    int ref = -1;
    for (int j : by_median) {
      bool well = true;
      for (int c = 0; c < nc && well; ++c) well = lv.Weight(Level(src[j][off + c])) > 0;
      if (well) {
        ref = j;
        break;
      }
    }
    if (ref < 0) continue;
    bool any = false;
    for (int j : by_median) {
      if (j == ref) continue;
      bool differs = false;
      for (int c = 0; c < nc && !differs; ++c) {
        const int kj = Level(src[j][off + c]), kr = Level(src[ref][off + c]);
        // A clipped or dark reading says only "at least" / "at most": compare it one-sided
        // (a clipped frame contradicts the reference only when its lower bound lies above
        // it, a dark one only when its upper bound lies below it).
        const float d = (lv.G(kj, c) - log_x[j]) - (lv.G(kr, c) - log_x[ref]);
        const float allowed = thr + noise * (slope[static_cast<size_t>(kj) * nc + c] +
                                             slope[static_cast<size_t>(kr) * nc + c]);
        if (lv.Weight(kj) > 0) {
          differs = std::abs(d) > allowed;
        } else {
          const float z = src[j][off + c];
          differs = z >= 128.f ? d > allowed : d < -allowed;
        }
      }
      if (!differs) continue;
      any = true;
      for (int c = 0; c < nc; ++c) {
        const int kj = Level(src[j][off + c]);
        const float wj = lv.Weight(kj);
        num[off + c] -= wj * (lv.G(kj, c) - log_x[j]);
        den[off + c] -= wj;
      }
    }
    if (any) {
      ++count;
      if (ghost_row) ghost_row[x] = 1;
      // Cancellation may leave a tiny residue: a pixel whose only weights were removed
      // must not divide by it.
      for (int c = 0; c < nc; ++c) {
        if (den[off + c] < 1e-3f) den[off + c] = 0.f, num[off + c] = 0.f;
      }
    }
  }
  return count;
}

}  // namespace

void MergeOptions::Validate() const {
  if (!std::isfinite(dark_level) || !std::isfinite(saturation_level) || dark_level < 0 ||
      saturation_level > 255 || saturation_level - dark_level < 2) {
    throw Error("MergeOptions: need 0 <= dark_level < saturation_level - 2 <= 253, got " +
                std::to_string(dark_level) + " and " + std::to_string(saturation_level));
  }
  if (!std::isfinite(ghost_threshold) || ghost_threshold < 0 || !std::isfinite(ghost_noise_dn) ||
      ghost_noise_dn < 0) {
    throw Error("MergeOptions: ghost_threshold and ghost_noise_dn must be >= 0, got " +
                std::to_string(ghost_threshold) + " and " + std::to_string(ghost_noise_dn));
  }
}

Image MergeHdr(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
               const ResponseCurve& curve, const MergeOptions& options, MergeSummary* summary,
               std::vector<uint8_t>* valid_mask) {
  Image out;
  MergeHdrInto(frames, exposures, curve, options, &out, summary, valid_mask, nullptr);
  return out;
}

namespace {

// The merge proper, over frames' pixel data (w x h x nc values each) of type T: float for
// Image frames, uint8_t for CodeImage frames; the checks are the callers'.
template <typename T>
void MergeFrames(const std::vector<const T*>& frames, int w, int h, int nc,
                 const std::vector<double>& exposures, const ResponseCurve& curve,
                 const MergeOptions& options, Image* out_image, MergeSummary* summary,
                 std::vector<uint8_t>* valid_mask, std::vector<uint8_t>* ghost_mask,
                 std::chrono::steady_clock::time_point start) {
  const int nf = static_cast<int>(frames.size());
  const int shortest =
      static_cast<int>(std::min_element(exposures.begin(), exposures.end()) - exposures.begin());
  const int longest =
      static_cast<int>(std::max_element(exposures.begin(), exposures.end()) - exposures.begin());

  // w and g_c per 1/16-DN level (g linear between the curve's integer entries); see Levels.
  Levels lv;
  lv.nc = nc;
  lv.dark = static_cast<float>(options.dark_level);
  lv.sat = static_cast<float>(options.saturation_level);
  lv.e.resize(static_cast<size_t>(kTable) * nc);
  for (int k = 0; k < kTable; ++k) {
    const double z = static_cast<double>(k) / kSteps;
    const int z0 = std::min(254, k / kSteps);
    const double t = z - z0;
    for (int c = 0; c < nc; ++c) {
      const auto& g = curve.g[nc == 1 ? 1 : c];
      lv.e[static_cast<size_t>(k) * nc + c] = {lv.HatWeight(k),
                                               static_cast<float>((1 - t) * g[z0] + t * g[z0 + 1])};
    }
  }
  std::vector<float> log_x(nf);
  for (int j = 0; j < nf; ++j) log_x[j] = static_cast<float>(std::log(exposures[j]));
  if constexpr (std::is_same_v<T, uint8_t>) {
    lv.code_g.resize(static_cast<size_t>(nf) * 256 * nc);
    for (int j = 0; j < nf; ++j) {
      for (int z = 0; z < 256; ++z) {
        for (int c = 0; c < nc; ++c) {
          lv.code_g[(static_cast<size_t>(j) * 256 + z) * nc + c] = lv.G(z * kSteps, c) - log_x[j];
        }
      }
    }
  }
  const float sat_level = lv.sat;
  const float dark_level = lv.dark;
  const RowsKernel<T> accumulate = ChooseKernel<T>(nc, options.use_simd);
  const ExpRowFn exp_row = ChooseExpRow(options.use_simd);

  Image& out = *out_image;
  if (out.width != w || out.height != h || out.channels != nc ||
      out.data.size() != static_cast<size_t>(w) * h * nc) {
    out = Image(w, h, nc, PixelUnits::kRadiance);
  }
  out.units = PixelUnits::kRadiance;
  if (valid_mask) valid_mask->assign(static_cast<size_t>(w) * h, 1);
  if (ghost_mask) ghost_mask->assign(static_cast<size_t>(w) * h, 0);
  // Ghost removal: the slope g'(z) per table entry and channel, and the frames in order of
  // distance from the median exposure (the reference candidates).
  std::vector<float> slope;
  std::vector<int> by_median;
  if (options.ghost_removal) {
    slope.resize(lv.e.size());
    for (int k = 0; k < kTable; ++k) {
      const int z0 = std::clamp(k / kSteps, 1, 254);
      for (int c = 0; c < nc; ++c) {
        const auto& g = curve.g[nc == 1 ? 1 : c];
        slope[static_cast<size_t>(k) * nc + c] = static_cast<float>(0.5 * (g[z0 + 1] - g[z0 - 1]));
      }
    }
    std::vector<int> order(nf);
    for (int j = 0; j < nf; ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return exposures[a] < exposures[b]; });
    const int mid = (nf - 1) / 2;
    std::vector<int> rank(nf);
    for (int r = 0; r < nf; ++r) rank[r] = r;
    std::stable_sort(rank.begin(), rank.end(),
                     [&](int a, int b) { return std::abs(a - mid) < std::abs(b - mid); });
    for (int r : rank) by_median.push_back(order[r]);
  }
  std::atomic<int64_t> ghosts{0};
  std::atomic<int64_t> saturated{0}, dark{0};
  std::atomic<int> bad_frame{-1};
  std::atomic<bool> overflow{false};

  // Row by row: the kernel streams the frames through each row (a few frames per pass,
  // adding in the same frame order as a per-pixel loop, so the sums are the same floats),
  // then one pass per pixel finishes it.
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    int64_t local_sat = 0, local_dark = 0, local_ghosts = 0;
    const size_t row_len = static_cast<size_t>(w) * nc;
    std::vector<float> num(row_len), den(row_len);
    std::vector<const T*> src(nf);
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int j = 0; j < nf; ++j) src[j] = frames[j] + static_cast<size_t>(y) * w * nc;
      float* dst = out.data.data() + static_cast<size_t>(y) * w * nc;
      std::fill(num.begin(), num.end(), 0.f);
      std::fill(den.begin(), den.end(), 0.f);
      const int bad = accumulate(src.data(), log_x.data(), nf, lv, row_len, num.data(), den.data());
      if (bad >= 0) bad_frame.store(bad);
      if (options.ghost_removal) {
        local_ghosts +=
            RemoveGhosts(src, by_median, lv, log_x, slope, w, options, num.data(), den.data(),
                         ghost_mask ? ghost_mask->data() + static_cast<size_t>(y) * w : nullptr);
      }
      // ln L = num / den where some frame had weight (a loop that vectorises); pixels where
      // a channel had none take the fallbacks below, one pixel at a time.
      bool any_unweighted = false;
      for (size_t i = 0; i < row_len; ++i) {
        dst[i] = den[i] > 0 ? num[i] / den[i] : 0.f;
        any_unweighted |= !(den[i] > 0);
      }
      for (int x = 0; x < w && any_unweighted; ++x) {
        bool pixel_sat = false, pixel_dark = false, pixel_invalid = false;
        for (int c = 0; c < nc; ++c) {
          const size_t off = static_cast<size_t>(x) * nc + c;
          if (den[off] > 0) continue;
          pixel_invalid = true;
          float zmax = -1, zmin = 256;
          for (int j = 0; j < nf; ++j) {
            const float z = src[j][off];
            if (!(z >= 0.f && z <= 255.f)) continue;
            zmax = std::max(zmax, z);
            zmin = std::min(zmin, z);
          }
          const float zs = src[shortest][off];
          const float zl = src[longest][off];
          if (zs >= sat_level || zmin >= sat_level) {
            dst[off] = lv.G(kLast, c) - log_x[shortest];  // a lower bound
            pixel_sat = true;
          } else if (zl <= dark_level || zmax <= dark_level) {
            dst[off] = lv.G(Level(zl), c) - log_x[longest];
            pixel_dark = true;
          } else {
            // Saturated in long frames, dark in short ones, nothing in between: the
            // middle of the bracketing bounds.
            float lower = -1e30f, upper = 1e30f;
            for (int j = 0; j < nf; ++j) {
              const float z = Clamp255(src[j][off]);
              const float est = lv.G(Level(z), c) - log_x[j];
              if (z >= sat_level) lower = std::max(lower, est);
              if (z <= dark_level) upper = std::min(upper, est);
            }
            dst[off] = 0.5f * (lower + upper);
          }
        }
        local_sat += pixel_sat;
        local_dark += pixel_dark;
        if (valid_mask && pixel_invalid) (*valid_mask)[static_cast<size_t>(y) * w + x] = 0;
      }
      if (exp_row(dst, row_len)) overflow.store(true);
    }
    saturated += local_sat;
    dark += local_dark;
    ghosts += local_ghosts;
  });

  if (bad_frame.load() >= 0) {
    throw Error("hdr merge: frame " + std::to_string(bad_frame.load()) +
                " holds values outside 0..255 or not finite");
  }
  if (overflow.load()) {
    throw Error("hdr merge: radiance out of float range; are the exposures in seconds x gain?");
  }
  if (summary) {
    summary->pixels = static_cast<int64_t>(w) * h;
    summary->saturated_pixels = saturated.load();
    summary->dark_pixels = dark.load();
    summary->ghost_pixels = ghosts.load();
    summary->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
}

}  // namespace

namespace {

// The checks MergeHdrInto makes of its frames (Image or CodeImage) and exposures; returns the
// frames' pixel data.
template <typename Frame>
auto CheckFrames(const std::vector<const Frame*>& frames, const std::vector<double>& exposures,
                 const MergeOptions& options, const ResponseCurve& curve, Image* out_image) {
  options.Validate();
  CheckCurve(curve);
  if (out_image == nullptr) throw Error("hdr merge: no output image given");
  if (frames.empty()) throw Error("hdr merge: no frames given");
  if (frames.size() != exposures.size()) {
    throw Error("hdr merge: " + std::to_string(frames.size()) + " frames but " +
                std::to_string(exposures.size()) + " exposures");
  }
  for (size_t j = 0; j < frames.size(); ++j) {
    if (frames[j] == nullptr) throw Error("hdr merge: frame " + std::to_string(j) + " is null");
  }
  const Frame& f0 = *frames[0];
  const int w = f0.width, h = f0.height, nc = f0.channels;
  if (w <= 0 || h <= 0) throw Error("hdr merge: frame 0 is empty");
  if (nc != 1 && nc != 3) {
    throw Error("hdr merge: frames must have 1 or 3 channels, frame 0 has " + std::to_string(nc));
  }
  std::vector<const typename decltype(f0.data)::value_type*> data;
  for (size_t j = 0; j < frames.size(); ++j) {
    const Frame& f = *frames[j];
    const std::string fw = "hdr merge: frame " + std::to_string(j) + ": ";
    if constexpr (std::is_same_v<Frame, Image>) {
      if (f.units != PixelUnits::kDigital) {
        throw Error(fw + "is not in digital numbers (kDigital)");
      }
    }
    if (f.width != w || f.height != h || f.channels != nc) {
      throw Error(fw + std::to_string(f.width) + "x" + std::to_string(f.height) + "x" +
                  std::to_string(f.channels) + " differs from frame 0 (" + std::to_string(w) + "x" +
                  std::to_string(h) + "x" + std::to_string(nc) + ")");
    }
    if (f.data.size() != static_cast<size_t>(w) * h * nc) {
      throw Error(fw + "pixel buffer size does not match its dimensions");
    }
    if (!std::isfinite(exposures[j]) || exposures[j] <= 0) {
      throw Error(fw + "exposure " + std::to_string(exposures[j]) + " must be positive and finite");
    }
    data.push_back(f.data.data());
  }
  return data;
}

// MergeHdrInto for either frame type: the checks, then the one merge.
template <typename Frame>
void CheckAndMerge(const std::vector<const Frame*>& frames, const std::vector<double>& exposures,
                   const ResponseCurve& curve, const MergeOptions& options, Image* out_image,
                   MergeSummary* summary, std::vector<uint8_t>* valid_mask,
                   std::vector<uint8_t>* ghost_mask) {
  const auto start = std::chrono::steady_clock::now();
  const auto data = CheckFrames(frames, exposures, options, curve, out_image);
  MergeFrames(data, frames[0]->width, frames[0]->height, frames[0]->channels, exposures, curve,
              options, out_image, summary, valid_mask, ghost_mask, start);
}

}  // namespace

void MergeHdrInto(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
                  const ResponseCurve& curve, const MergeOptions& options, Image* out_image,
                  MergeSummary* summary, std::vector<uint8_t>* valid_mask,
                  std::vector<uint8_t>* ghost_mask) {
  CheckAndMerge(frames, exposures, curve, options, out_image, summary, valid_mask, ghost_mask);
}

void MergeHdrInto(const std::vector<const CodeImage*>& frames, const std::vector<double>& exposures,
                  const ResponseCurve& curve, const MergeOptions& options, Image* out_image,
                  MergeSummary* summary, std::vector<uint8_t>* valid_mask,
                  std::vector<uint8_t>* ghost_mask) {
  CheckAndMerge(frames, exposures, curve, options, out_image, summary, valid_mask, ghost_mask);
}

}  // namespace rouen

namespace rouen {

void RadianceMergeOptions::Validate() const {
  if (clip_min_pixels < 1 || clip_divisor < 1) {
    throw Error("RadianceMergeOptions: clip_min_pixels and clip_divisor must be >= 1, got " +
                std::to_string(clip_min_pixels) + " and " + std::to_string(clip_divisor));
  }
  if (!(clip_ramp > 0 && clip_ramp <= 1)) {
    throw Error("RadianceMergeOptions: clip_ramp must be in (0, 1], got " +
                std::to_string(clip_ramp));
  }
}

Image MergeRadiance(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
                    const std::vector<std::array<double, 3>>& transmission,
                    const RadianceMergeOptions& options, std::vector<uint8_t>* valid_mask) {
  options.Validate();
  if (frames.empty()) throw Error("radiance merge: no frames given");
  if (exposures.size() != frames.size() || transmission.size() != frames.size()) {
    throw Error("radiance merge: " + std::to_string(frames.size()) + " frames but " +
                std::to_string(exposures.size()) + " exposures and " +
                std::to_string(transmission.size()) + " transmissions");
  }
  for (size_t k = 0; k < frames.size(); ++k) {
    if (frames[k] == nullptr) {
      throw Error("radiance merge: frame " + std::to_string(k) + " is null");
    }
  }
  const Image& f0 = *frames[0];
  const int nc = f0.channels;
  if (nc != 3 && nc != 1) {
    throw Error("radiance merge: frames must have 1 or 3 channels, frame 0 has " +
                std::to_string(nc));
  }
  if (f0.width <= 0 || f0.height <= 0) throw Error("radiance merge: frame 0 is empty");
  const size_t npix = static_cast<size_t>(f0.width) * f0.height;
  for (size_t k = 0; k < frames.size(); ++k) {
    const Image& im = *frames[k];
    const std::string fk = "radiance merge: frame " + std::to_string(k) + ": ";
    if (im.units != PixelUnits::kRadiance) {
      throw Error(fk + "holds digital numbers, not radiance (kRadiance)");
    }
    if (im.width != f0.width || im.height != f0.height || im.channels != nc) {
      throw Error(fk + std::to_string(im.width) + "x" + std::to_string(im.height) + "x" +
                  std::to_string(im.channels) + " differs from frame 0 (" +
                  std::to_string(f0.width) + "x" + std::to_string(f0.height) + "x" +
                  std::to_string(nc) + ")");
    }
    if (im.data.size() != npix * nc) throw Error(fk + "pixel buffer size does not match");
    for (double t : transmission[k]) {
      if (!(std::isfinite(t) && t > 0)) {
        throw Error(fk + "transmission " + std::to_string(t) + " must be positive and finite");
      }
    }
  }
  // Clip level per frame and channel (infinite when the frame shows no clipping).
  const size_t min_clipped = std::max<size_t>(static_cast<size_t>(options.clip_min_pixels),
                                              npix / static_cast<size_t>(options.clip_divisor));
  std::vector<std::array<double, 3>> clip(frames.size());
  std::vector<double> weight(frames.size());
  for (size_t k = 0; k < frames.size(); ++k) {
    const std::vector<float>& data = frames[k]->data;
    for (int c = 0; c < nc; ++c) {
      double mx = 0;
      for (size_t i = 0; i < npix; ++i) {
        const double v = data[i * nc + c];
        if (std::isfinite(v)) mx = std::max(mx, v);
      }
      size_t at_max = 0;
      for (size_t i = 0; i < npix; ++i) {
        if (data[i * nc + c] >= 0.999 * mx) ++at_max;
      }
      clip[k][c] = mx > 0 && at_max >= min_clipped ? mx : HUGE_VAL;
    }
    const double t = (transmission[k][0] + transmission[k][1] + transmission[k][2]) / 3;
    weight[k] = (exposures[k] > 0 && std::isfinite(exposures[k]) ? exposures[k] : 1.0) * t;
  }
  Image out(f0.width, f0.height, nc, PixelUnits::kRadiance);
  if (valid_mask) valid_mask->assign(npix, 1);
  for (size_t i = 0; i < npix; ++i) {
    for (int c = 0; c < nc; ++c) {
      double sw = 0, swv = 0, fallback = 0, fallback_w = HUGE_VAL;
      for (size_t k = 0; k < frames.size(); ++k) {
        const double v = frames[k]->data[i * nc + c];
        if (!std::isfinite(v)) continue;
        const double l = v / transmission[k][nc == 3 ? c : 0];
        if (weight[k] < fallback_w) {
          fallback_w = weight[k];
          fallback = l;
        }
        const double top = clip[k][c];
        const double w =
            weight[k] * (std::isfinite(top)
                             ? std::clamp((top - v) / (options.clip_ramp * top), 0.0, 1.0)
                             : 1.0);
        sw += w;
        swv += w * l;
      }
      if (sw > 0) {
        out.data[i * nc + c] = static_cast<float>(swv / sw);
      } else {
        out.data[i * nc + c] = static_cast<float>(std::max(0.0, fallback));
        if (valid_mask) (*valid_mask)[i] = 0;
      }
    }
  }
  return out;
}

}  // namespace rouen
