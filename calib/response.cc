#include "calib/response.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <type_traits>
#include <unordered_map>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

#include "core/error.h"

namespace rouen {
namespace {

constexpr int kLevels = 256;
constexpr int kPinned = 128;  // g_c(128) = 0 for every channel
constexpr int kBins = 32;     // brightness strata for sample selection
constexpr int kMinSamples = 8;

int SamplesWanted(const ResponseOptions& o) {
  return o.method == ResponseMethod::kRobertson
             ? std::max(o.samples_per_bracket, o.robertson_min_samples_per_bracket)
             : o.samples_per_bracket;
}

struct Sample {
  int bracket;
  size_t pixel;  // y * width + x
};

size_t FrameCount(const Bracket& b) { return b.frames.empty() ? b.codes.size() : b.frames.size(); }

// The checks of one bracket's frames (Image or CodeImage); returns the channel count.
template <typename Frame>
int CheckFrames(const std::vector<Frame>& frames, const std::string& where) {
  const Frame& f0 = frames[0];
  if (f0.width <= 0 || f0.height <= 0) throw Error(where + "frame 0 is empty");
  if (f0.channels != 1 && f0.channels != 3) {
    throw Error(where + "frames must have 1 or 3 channels, frame 0 has " +
                std::to_string(f0.channels));
  }
  for (size_t j = 0; j < frames.size(); ++j) {
    const Frame& f = frames[j];
    const std::string fw = where + "frame " + std::to_string(j) + ": ";
    if constexpr (std::is_same_v<Frame, Image>) {
      if (f.units != PixelUnits::kDigital) {
        throw Error(fw + "is not in digital numbers (kDigital)");
      }
    }
    if (f.width != f0.width || f.height != f0.height) {
      throw Error(fw + "size " + std::to_string(f.width) + "x" + std::to_string(f.height) +
                  " differs from frame 0 (" + std::to_string(f0.width) + "x" +
                  std::to_string(f0.height) + ")");
    }
    if (f.channels != f0.channels) throw Error(fw + "channel count differs from frame 0");
    if (f.data.size() != static_cast<size_t>(f.width) * f.height * f.channels) {
      throw Error(fw + "pixel buffer size does not match its dimensions");
    }
  }
  return f0.channels;
}

// Per-bracket validation; returns the channel count.
int CheckBracket(const Bracket& b, size_t index) {
  const std::string where = "response: bracket " + std::to_string(index) + ": ";
  if (!b.frames.empty() && !b.codes.empty()) {
    throw Error(where + "holds both frames and codes; give one of them");
  }
  const size_t n = FrameCount(b);
  if (n == 0) throw Error(where + "has no frames");
  if (n != b.exposures.size()) {
    throw Error(where + std::to_string(n) + " frames but " + std::to_string(b.exposures.size()) +
                " exposures");
  }
  for (size_t j = 0; j < b.exposures.size(); ++j) {
    if (!std::isfinite(b.exposures[j]) || b.exposures[j] <= 0) {
      throw Error(where + "exposure " + std::to_string(j) + " is " +
                  std::to_string(b.exposures[j]) + "; exposures must be positive and finite");
    }
  }
  const auto [lo, hi] = std::minmax_element(b.exposures.begin(), b.exposures.end());
  if (*hi <= *lo * (1 + 1e-9)) {
    throw Error(where + "needs at least two distinct exposures (all are " + std::to_string(*lo) +
                ")");
  }
  const int nc = b.frames.empty() ? CheckFrames(b.codes, where) : CheckFrames(b.frames, where);
  const size_t np = b.frames.empty() ? static_cast<size_t>(b.codes[0].width) * b.codes[0].height
                                     : static_cast<size_t>(b.frames[0].width) * b.frames[0].height;
  if (!b.mask.empty() && b.mask.size() != np) {
    throw Error(where + "mask has " + std::to_string(b.mask.size()) + " entries, expected " +
                std::to_string(np));
  }
  return nc;
}

// One frame's pass over a grid row of the sample scan (SelectSamples): per grid point, the
// frame's channel sum, scaled by `inv`, is added to acc; whether some channel fell more than
// `tol` below its running maximum is or-ed into darkened; informative counts (up to 2) the
// frames whose channel mean lies in 2..253 DN. `step` is the distance between grid points in
// floats (NC when every pixel is a grid point). Returns nonzero when a value is outside
// 0..255 or not finite.
template <int NC, typename T>
unsigned ScanFrameRow(const T* d, size_t step, int gw, float tol, float inv, float* run, float* acc,
                      uint32_t* informative, uint32_t* darkened) {
  unsigned bad = 0;
  for (int i = 0; i < gw; ++i) {
    const T* p = d + static_cast<size_t>(i) * step;
    float sum = 0;
    unsigned dark = 0;
    for (int c = 0; c < NC; ++c) {
      const float v = p[c];
      bad |= !(v >= 0.f && v <= 255.f);
      float& m = run[static_cast<size_t>(i) * NC + c];
      dark |= v < m - tol;
      m = std::max(m, v);
      sum += v;
    }
    acc[i] += sum * inv;
    const float mean = sum / NC;
    informative[i] = std::min<uint32_t>(2, informative[i] + (mean >= 2.f && mean <= 253.f));
    darkened[i] |= dark;
  }
  return bad;
}

template <typename T>
using ScanFrameRowFn = unsigned (*)(const T*, size_t, int, float, float, float*, float*, uint32_t*,
                                    uint32_t*);

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
// 24 interleaved RGB values (a, b, c) as R, G and B vectors of points 0..7: each channel's
// lanes gathered by two blends, then put in point order by a permutation.
__attribute__((target("avx2"), always_inline)) inline void SplitRgb(__m256 a, __m256 b, __m256 c,
                                                                    __m256* r, __m256* g,
                                                                    __m256* bl) {
  *r = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(a, b, 0x92), c, 0x24),
                                _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5));
  *g = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(a, b, 0x24), c, 0x49),
                                _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6));
  *bl = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(a, b, 0x49), c, 0x92),
                                 _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7));
}

// One vector of values of the scan: or-s into *bad the lanes outside 0..255 or NaN, sets *dark
// where a value lies more than tol below the running maximum m, and updates m.
template <typename T>
__attribute__((target("avx2"), always_inline)) inline __m256 ScanValues(const T* p, float* m,
                                                                        __m256 tol, __m256* bad,
                                                                        __m256* dark) {
  __m256 v;
  if constexpr (std::is_same_v<T, float>) {
    v = _mm256_loadu_ps(p);
  } else {
    v = _mm256_cvtepi32_ps(
        _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
  }
  const __m256 ok = _mm256_and_ps(_mm256_cmp_ps(v, _mm256_setzero_ps(), _CMP_GE_OQ),
                                  _mm256_cmp_ps(v, _mm256_set1_ps(255.f), _CMP_LE_OQ));
  *bad = _mm256_or_ps(*bad, _mm256_xor_ps(ok, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
  const __m256 mv = _mm256_loadu_ps(m);
  *dark = _mm256_cmp_ps(v, _mm256_sub_ps(mv, tol), _CMP_LT_OQ);
  // std::max(m, v) is v when m < v, else m.
  _mm256_storeu_ps(m, _mm256_blendv_ps(mv, v, _mm256_cmp_ps(mv, v, _CMP_LT_OQ)));
  return v;
}

// ScanFrameRow for every pixel a grid point (step NC), 8 points at a time with AVX2 (checked
// at run time), the rest by ScanFrameRow: the same operations in the same order, so the same
// floats. RGB values are compared in their interleaved order, then gathered into R, G and B
// vectors (two blends and a permutation each) for the per-point sums.
template <int NC, typename T>
__attribute__((target("avx2"))) unsigned ScanFrameRowAvx2(const T* d, size_t step, int gw,
                                                          float tol, float inv, float* run,
                                                          float* acc, uint32_t* informative,
                                                          uint32_t* darkened) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 vtol = _mm256_set1_ps(tol), vinv = _mm256_set1_ps(inv);
  const __m256 lo = _mm256_set1_ps(2.f), hi = _mm256_set1_ps(253.f);
  const __m256 nc = _mm256_set1_ps(static_cast<float>(NC));
  const __m256i two = _mm256_set1_epi32(2);
  __m256 bad = _mm256_setzero_ps();
  const int vec = gw - gw % 8;
  for (int i = 0; i < vec; i += 8) {
    const T* p = d + static_cast<size_t>(i) * NC;
    float* m = run + static_cast<size_t>(i) * NC;
    __m256 sum, dark;
    if constexpr (NC == 3) {
      __m256 da, db, dc;
      const __m256 a = ScanValues(p, m, vtol, &bad, &da),
                   b = ScanValues(p + 8, m + 8, vtol, &bad, &db),
                   c = ScanValues(p + 16, m + 16, vtol, &bad, &dc);
      __m256 r, g, bl, dr, dg, dbl;
      SplitRgb(a, b, c, &r, &g, &bl);
      SplitRgb(da, db, dc, &dr, &dg, &dbl);
      sum = _mm256_add_ps(_mm256_add_ps(_mm256_add_ps(zero, r), g), bl);
      dark = _mm256_or_ps(_mm256_or_ps(dr, dg), dbl);
    } else {
      sum = _mm256_add_ps(zero, ScanValues(p, m, vtol, &bad, &dark));
    }
    _mm256_storeu_ps(acc + i, _mm256_add_ps(_mm256_loadu_ps(acc + i), _mm256_mul_ps(sum, vinv)));
    const __m256 mean = _mm256_div_ps(sum, nc);
    const __m256i info = _mm256_castps_si256(
        _mm256_and_ps(_mm256_cmp_ps(mean, lo, _CMP_GE_OQ), _mm256_cmp_ps(mean, hi, _CMP_LE_OQ)));
    auto* in = reinterpret_cast<__m256i*>(informative + i);
    _mm256_storeu_si256(in, _mm256_min_epu32(two, _mm256_sub_epi32(_mm256_loadu_si256(in), info)));
    auto* dk = reinterpret_cast<__m256i*>(darkened + i);
    _mm256_storeu_si256(
        dk, _mm256_or_si256(_mm256_loadu_si256(dk),
                            _mm256_and_si256(_mm256_castps_si256(dark), _mm256_set1_epi32(1))));
  }
  const bool any_bad = _mm256_movemask_ps(bad) != 0;
  _mm256_zeroupper();
  return ScanFrameRow<NC, T>(d + static_cast<size_t>(vec) * NC, step, gw - vec, tol, inv,
                             run + static_cast<size_t>(vec) * NC, acc + vec, informative + vec,
                             darkened + vec) |
         any_bad;
}
#endif

template <int NC, typename T>
ScanFrameRowFn<T> ChooseScan(int stride, bool simd) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (simd && stride == 1 && __builtin_cpu_supports("avx2")) return ScanFrameRowAvx2<NC, T>;
#endif
  (void)stride, (void)simd;
  return ScanFrameRow<NC, T>;
}

// Stratified sampling over brightness (mean over frames and channels, monotone in radiance),
// preferring pixels of low local gradient; rejects pixels that darken as exposure grows.
// Large brackets are scanned on a grid of stride `*stride` (see ResponseOptions::scan_pixels).
// The scan runs in parallel over grid rows, frame by frame through a row (AVX2 where the CPU
// has it and o.use_simd allows), and keeps per grid point only its stratum; the random draw
// from each stratum is made on per-row counts, so only the drawn points (and their
// neighbours, for the gradient) are read again.
// `frames` holds the bracket's pixel data (w x h x nc values each) as T: float for Image
// frames, uint8_t for CodeImage ones.
template <typename T>
std::vector<size_t> SelectSamples(const Bracket& b, const std::vector<const T*>& frames, int w,
                                  int h, int nc, size_t index, const ResponseOptions& o,
                                  int* stride) {
  const size_t np = static_cast<size_t>(w) * h;
  std::vector<int> order(frames.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int i, int j) { return b.exposures[i] < b.exposures[j]; });
  int s = 1;
  if (static_cast<int64_t>(np) > o.scan_pixels) {
    s = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(np) / o.scan_pixels)));
  }
  *stride = s;
  const int gw = (w + s - 1) / s, gh = (h + s - 1) / s;
  const size_t ng = static_cast<size_t>(gw) * gh;

  // Per grid point: its stratum by brightness key (-1 unless an interior point that is usable:
  // never darkens by more than the tolerance as exposure grows, informative in at least two
  // frames, not masked). Per grid row: how many points each stratum has there.
  std::vector<int8_t> bin_of(ng, -1);
  std::vector<uint32_t> row_count(static_cast<size_t>(gh) * kBins, 0);
  std::atomic<int> bad_row{-1};
  const float tol = static_cast<float>(o.monotone_tolerance);
  const float inv = 1.f / static_cast<float>(frames.size() * nc);
  std::vector<const T*> data_by_exposure;
  for (int j : order) data_by_exposure.push_back(frames[j]);
  const int nf = static_cast<int>(order.size());
  // One grid row: the running maximum per channel, the count of informative frames and
  // whether the point darkened are kept for the row, and the frames are added in order of
  // exposure (the key's float sum in the same order as a per-point loop).
  struct RowState {
    std::vector<float> running, key;
    std::vector<uint32_t> informative, darkened;
  };
  const ScanFrameRowFn<T> scan =
      nc == 3 ? ChooseScan<3, T>(s, o.use_simd) : ChooseScan<1, T>(s, o.use_simd);
  auto scan_row = [&](int k, RowState* st) {
    float* run = st->running.data();
    uint32_t* informative = st->informative.data();
    uint32_t* darkened = st->darkened.data();
    float* acc = st->key.data();
    std::fill(acc, acc + gw, 0.f);
    std::fill(run, run + static_cast<size_t>(gw) * nc, -1.f);
    std::fill(informative, informative + gw, 0);
    std::fill(darkened, darkened + gw, 0);
    const size_t row = static_cast<size_t>(k) * s * w;
    unsigned bad = 0;
    for (int r = 0; r < nf; ++r) {
      bad |= scan(data_by_exposure[r] + row * nc, static_cast<size_t>(s) * nc, gw, tol, inv, run,
                  acc, informative, darkened);
    }
    if (bad) {
      bad_row.store(k);
      return;
    }
    if (k == 0 || k + 1 >= gh) return;  // only interior points are candidates
    uint32_t* counts = row_count.data() + static_cast<size_t>(k) * kBins;
    for (int i = 1; i + 1 < gw; ++i) {
      const size_t p = row + static_cast<size_t>(i) * s;
      if (darkened[i] || informative[i] < 2 || (!b.mask.empty() && b.mask[p] == 0)) continue;
      const int bin = std::min(kBins - 1, static_cast<int>(acc[i] * kBins / 256.f));
      bin_of[static_cast<size_t>(k) * gw + i] = static_cast<int8_t>(bin);
      ++counts[bin];
    }
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, gh), [&](const tbb::blocked_range<int>& rows) {
    RowState st;
    st.running.resize(static_cast<size_t>(gw) * nc);
    st.key.resize(gw);
    st.informative.resize(gw);
    st.darkened.resize(gw);
    for (int k = rows.begin(); k != rows.end(); ++k) scan_row(k, &st);
  });
  if (bad_row.load() >= 0) {
    // Name the first offending value of that row, in order of exposure.
    const size_t row = static_cast<size_t>(bad_row.load()) * s * w;
    for (int r = 0; r < nf; ++r) {
      for (int i = 0; i < gw; ++i) {
        const size_t p = row + static_cast<size_t>(i) * s;
        for (int c = 0; c < nc; ++c) {
          const float v = data_by_exposure[r][p * nc + c];
          if (v >= 0.f && v <= 255.f) continue;
          throw Error("response: bracket " + std::to_string(index) + " frame " +
                      std::to_string(order[r]) + ": pixel (" + std::to_string(p % w) + ", " +
                      std::to_string(p / w) + ") holds a value outside 0..255 or not finite");
        }
      }
    }
  }

  // How many points each stratum gives: strata take turns, one point each, until `wanted`
  // are chosen or all are used.
  std::array<size_t, kBins> count{};
  for (int k = 0; k < gh; ++k) {
    for (int bin = 0; bin < kBins; ++bin)
      count[bin] += row_count[static_cast<size_t>(k) * kBins + bin];
  }
  const size_t wanted = static_cast<size_t>(SamplesWanted(o));
  std::array<size_t, kBins> take{};
  for (size_t total = 0, round = 0; total < wanted; ++round) {
    bool any = false;
    for (int bin = 0; bin < kBins && total < wanted; ++bin) {
      if (count[bin] > round) ++take[bin], ++total, any = true;
    }
    if (!any) break;
  }
  // Each stratum's draw: the first entries of a Fisher-Yates shuffle of its points (ranks in
  // scan order), as many as the pool of flat candidates (a few times the quota) and the
  // points the stratum gives need; only the displaced entries are stored. Each stratum has
  // its own random stream, so a larger sample count extends the draw of a smaller one.
  const size_t quota = (wanted + kBins - 1) / kBins;
  std::array<std::vector<size_t>, kBins> draw;
  for (int bin = 0; bin < kBins; ++bin) {
    std::mt19937_64 rng(o.seed + 0x9E3779B97F4A7C15ull * (index + 1) +
                        0xBF58476D1CE4E5B9ull * (bin + 1));
    const size_t n = count[bin];
    const size_t m = std::min(n, std::max(take[bin], 4 * quota));
    std::unordered_map<size_t, size_t> moved;  // position -> rank, where not the identity
    auto at = [&](size_t i) {
      const auto it = moved.find(i);
      return it == moved.end() ? i : it->second;
    };
    for (size_t i = 0; i < m; ++i) {
      const size_t j = std::uniform_int_distribution<size_t>(i, n - 1)(rng);
      const size_t vi = at(i), vj = at(j);
      moved[j] = vi;
      draw[bin].push_back(vj);
    }
  }
  // Ranks to grid points: the row holding each rank from the per-row counts, then one pass
  // over each such row.
  struct Want {
    int row, bin;
    size_t rank_in_row, slot;
  };
  std::vector<Want> wants;
  std::vector<size_t> before(gh);  // points of the stratum in rows above
  for (int bin = 0; bin < kBins; ++bin) {
    size_t acc = 0;
    for (int k = 0; k < gh; ++k) {
      before[k] = acc;
      acc += row_count[static_cast<size_t>(k) * kBins + bin];
    }
    for (size_t slot = 0; slot < draw[bin].size(); ++slot) {
      const size_t rank = draw[bin][slot];
      const int k =
          static_cast<int>(std::upper_bound(before.begin(), before.end(), rank) - before.begin()) -
          1;
      wants.push_back({k, bin, rank - before[k], slot});
    }
  }
  std::sort(wants.begin(), wants.end(), [](const Want& a, const Want& c) {
    return a.row != c.row   ? a.row < c.row
           : a.bin != c.bin ? a.bin < c.bin
                            : a.rank_in_row < c.rank_in_row;
  });
  std::array<std::vector<size_t>, kBins> points;
  for (int bin = 0; bin < kBins; ++bin) points[bin].resize(draw[bin].size());
  for (size_t q0 = 0; q0 < wants.size();) {
    const int k = wants[q0].row;
    size_t q1 = q0;
    while (q1 < wants.size() && wants[q1].row == k) ++q1;
    // This row's wants of each stratum are wants[next[bin]..end[bin]), by rank.
    std::array<size_t, kBins> next{}, end{}, seen{};
    for (size_t q = q1; q-- > q0;) next[wants[q].bin] = q;
    for (size_t q = q0; q < q1; ++q) end[wants[q].bin] = q + 1;
    const int8_t* bins_row = bin_of.data() + static_cast<size_t>(k) * gw;
    size_t left = q1 - q0;
    for (int i = 0; i < gw && left > 0; ++i) {
      const int bin = bins_row[i];
      if (bin < 0) continue;
      if (next[bin] < end[bin] && wants[next[bin]].rank_in_row == seen[bin]) {
        points[bin][wants[next[bin]].slot] = static_cast<size_t>(k) * gw + i;
        ++next[bin];
        --left;
      }
      ++seen[bin];
    }
    q0 = q1;
  }
  // The pool (flattest first, by the gradient between grid neighbours), then the rest of
  // the draw in its random order; strata take turns.
  // The key of a grid point again, the same float sum as the scan's.
  auto key = [&](size_t g) {
    const size_t p = (g / gw) * s * static_cast<size_t>(w) + (g % gw) * s;
    float acc = 0;
    for (int r = 0; r < nf; ++r) {
      float sum = 0;
      for (int c = 0; c < nc; ++c) sum += data_by_exposure[r][p * nc + c];
      acc += sum * inv;
    }
    return acc;
  };
  auto grad = [&](size_t g) {
    return std::abs(key(g + 1) - key(g - 1)) + std::abs(key(g + gw) - key(g - gw));
  };
  for (auto& bin : points) {
    const size_t pool = std::min(bin.size(), 4 * quota);
    std::vector<std::pair<float, size_t>> by_grad(pool);
    for (size_t j = 0; j < pool; ++j) by_grad[j] = {grad(bin[j]), bin[j]};
    std::stable_sort(by_grad.begin(), by_grad.end(),
                     [](const auto& a, const auto& c) { return a.first < c.first; });
    for (size_t j = 0; j < pool; ++j) bin[j] = by_grad[j].second;
  }
  std::vector<size_t> chosen;
  for (size_t round = 0; chosen.size() < wanted; ++round) {
    bool any = false;
    for (int bin = 0; bin < kBins && chosen.size() < wanted; ++bin) {
      if (round < take[bin]) {
        const size_t g = points[bin][round];
        chosen.push_back((g / gw) * s * static_cast<size_t>(w) + (g % gw) * s);
        any = true;
      }
    }
    if (!any) break;
  }
  return chosen;
}

struct Observation {
  int sample;
  uint8_t z;
  int16_t frame;  // frame id over all brackets
  float log_exposure;
};

double HatWeight(int z, double eps) { return std::min(z, 255 - z) + eps; }

// Pool-adjacent-violators: the weighted non-decreasing fit to v.
std::vector<double> IsotonicFit(const std::vector<double>& v, const std::vector<double>& wt) {
  struct Block {
    double sum, weight;
    int count;
  };
  std::vector<Block> blocks;
  for (size_t i = 0; i < v.size(); ++i) {
    blocks.push_back({v[i] * wt[i], wt[i], 1});
    while (blocks.size() > 1) {
      const Block& a = blocks[blocks.size() - 2];
      const Block& c = blocks.back();
      if (a.sum / a.weight <= c.sum / c.weight) break;
      Block merged{a.sum + c.sum, a.weight + c.weight, a.count + c.count};
      blocks.pop_back();
      blocks.back() = merged;
    }
  }
  std::vector<double> out;
  out.reserve(v.size());
  for (const Block& b : blocks) out.insert(out.end(), b.count, b.sum / b.weight);
  return out;
}

struct ChannelResult {
  std::vector<double> g;
  int violations = 0;
  int iterations = 0;
  bool converged = true;
  int order = 0;
  double method_residual = 0;
  std::vector<double> ratios;
  double fit_high = 0;
};

// Hat weight of the well-exposed readings (0 < z < 255) per level.
std::vector<double> LevelSupport(const std::vector<Observation>& obs) {
  std::vector<double> support(kLevels, 0.0);
  for (const Observation& ob : obs) {
    if (ob.z > 0 && ob.z < 255) support[ob.z] += HatWeight(ob.z, 0);
  }
  return support;
}

// First and last level with support (lo > hi when there is none).
std::pair<int, int> SupportedRange(const std::vector<double>& support) {
  int lo = 1, hi = kLevels - 2;
  while (lo < kLevels - 1 && support[lo] <= 0) ++lo;
  while (hi > 0 && support[hi] <= 0) --hi;
  return {lo, hi};
}

// Common to every method: extrapolates the ends no supported reading reached, makes the curve
// strictly increasing, smooths lightly and pins g(128) = 0.
void FinishCurve(std::vector<double> g, const std::vector<double>& support,
                 const ResponseOptions& o, ChannelResult* result) {
  // Ends: linear extrapolation with the slope of the nearest supported stretch.
  const auto [lo, hi] = SupportedRange(support);
  if (lo < hi) {
    const int span = std::min(8, hi - lo);
    const double slope_lo = std::max(o.min_slope, (g[lo + span] - g[lo]) / span);
    const double slope_hi = std::max(o.min_slope, (g[hi] - g[hi - span]) / span);
    for (int z = 0; z < lo; ++z) g[z] = g[lo] - slope_lo * (lo - z);
    for (int z = hi + 1; z < kLevels; ++z) g[z] = g[hi] + slope_hi * (z - hi);
  }
  result->violations = 0;
  for (int z = 0; z + 1 < kLevels; ++z) {
    if (g[z + 1] < g[z] + o.min_slope) ++result->violations;
  }
  // Strictly increasing: isotonic fit of g(z) - min_slope * z, then a [1 2 1]/4 pass (a
  // non-negative kernel keeps it monotone), then the ramp back.
  std::vector<double> v(kLevels), wt(kLevels);
  for (int z = 0; z < kLevels; ++z) {
    v[z] = g[z] - o.min_slope * z;
    wt[z] = support[z] + 1e-3;
  }
  std::vector<double> iso = IsotonicFit(v, wt);
  std::vector<double> smooth = iso;
  for (int z = 1; z + 1 < kLevels; ++z) smooth[z] = 0.25 * (iso[z - 1] + 2 * iso[z] + iso[z + 1]);
  for (int z = 0; z < kLevels; ++z) g[z] = smooth[z] + o.min_slope * z;
  const double pin = g[kPinned];
  for (double& gz : g) gz -= pin;
  result->g = std::move(g);
}

// Debevec & Malik 1997, eq. 3: hat-weighted least squares on g(z_ij) - ln E_i - ln t_j with
// lambda * w(z) g''(z) rows.
std::vector<double> SolveDebevecMalik(const std::vector<Observation>& obs, int num_samples,
                                      const ResponseOptions& o, ChannelResult* info) {
  // Unknowns: g(z) for z != 128 (255 of them), then ln E per sample.
  auto gi = [](int z) { return z < kPinned ? z : z - 1; };
  const int ng = kLevels - 1;
  const int n = ng + num_samples;
  double data_w2 = 0;
  for (const Observation& ob : obs) data_w2 += std::pow(HatWeight(ob.z, o.weight_epsilon), 2);
  double smooth_w2 = 0;
  for (int z = 1; z < kLevels - 1; ++z) smooth_w2 += std::pow(HatWeight(z, o.weight_epsilon), 2);
  const double smooth_scale = std::sqrt(o.lambda * data_w2 / smooth_w2);

  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(obs.size() * 2 + (kLevels - 2) * 3);
  Eigen::VectorXd rhs(obs.size() + kLevels - 2);
  int row = 0;
  for (const Observation& ob : obs) {
    const double wz = HatWeight(ob.z, o.weight_epsilon);
    if (ob.z != kPinned) trip.emplace_back(row, gi(ob.z), wz);
    trip.emplace_back(row, ng + ob.sample, -wz);
    rhs[row++] = wz * ob.log_exposure;
  }
  for (int z = 1; z < kLevels - 1; ++z) {
    const double s = smooth_scale * HatWeight(z, o.weight_epsilon);
    const int zs[3] = {z - 1, z, z + 1};
    const double cs[3] = {s, -2 * s, s};
    for (int k = 0; k < 3; ++k) {
      if (zs[k] != kPinned) trip.emplace_back(row, gi(zs[k]), cs[k]);
    }
    rhs[row++] = 0;
  }
  Eigen::SparseMatrix<double> a(row, n);
  a.setFromTriplets(trip.begin(), trip.end());
  const Eigen::SparseMatrix<double> at = a.transpose();
  const Eigen::SparseMatrix<double> ata = at * a;
  const Eigen::VectorXd atb = at * rhs;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(ata);
  if (ldlt.info() != Eigen::Success) throw Error("response: normal equations are singular");
  const Eigen::VectorXd x = ldlt.solve(atb);
  if (ldlt.info() != Eigen::Success || !x.allFinite()) {
    throw Error("response: least-squares solve failed");
  }
  std::vector<double> g(kLevels, 0.0);
  for (int z = 0; z < kLevels; ++z) g[z] = z == kPinned ? 0.0 : x[gi(z)];
  // Objective: the weighted data rows, normalised by their weights.
  double sq = 0, wsum = 0;
  for (const Observation& ob : obs) {
    const double wz = HatWeight(ob.z, o.weight_epsilon);
    const double r = g[ob.z] - x[ng + ob.sample] - ob.log_exposure;
    sq += wz * wz * r * r;
    wsum += wz * wz;
  }
  info->method_residual = wsum > 0 ? std::sqrt(sq / wsum) : 0.0;
  return g;
}

// Level nearest to 128 with support (the scale is fixed there while iterating).
int Anchor(const std::vector<double>& support) {
  for (int d = 0; d < kLevels; ++d) {
    if (kPinned - d >= 0 && support[kPinned - d] > 0) return kPinned - d;
    if (kPinned + d < kLevels && support[kPinned + d] > 0) return kPinned + d;
  }
  return -1;
}

// Robertson, Borman & Stevenson 2003, eqs. for x_j and I(m) (see ResponseMethod::kRobertson).
std::vector<double> SolveRobertson(const std::vector<Observation>& obs, int num_samples,
                                   const std::vector<double>& support, const ResponseOptions& o,
                                   ChannelResult* info) {
  const int anchor = Anchor(support);
  if (anchor < 0) throw Error("response: Robertson: no well-exposed readings");
  const auto [lo, hi] = SupportedRange(support);
  std::vector<double> t(obs.size());
  for (size_t i = 0; i < obs.size(); ++i) t[i] = std::exp(static_cast<double>(obs[i].log_exposure));
  // ln I(z), from a linear start; only supported levels are estimated.
  std::vector<double> lg(kLevels);
  for (int z = 0; z < kLevels; ++z) lg[z] = std::log((z + 0.5) / (anchor + 0.5));
  std::vector<double> level(kLevels), weight(kLevels, 0.0);
  std::vector<double> num(num_samples), den(num_samples), sum(kLevels), count(kLevels);
  // Weight per level: hat / (dI/dz)^2, dI/dz = I * d ln I / dz over +-3 levels.
  auto update_weights = [&]() {
    for (int z = 0; z < kLevels; ++z) level[z] = std::exp(lg[z]);
    for (int z = 0; z < kLevels; ++z) {
      weight[z] = 0;
      if (support[z] <= 0) continue;
      const int a = std::max(lo, z - 3), b = std::min(hi, z + 3);
      const double slope = b > a ? std::max((lg[b] - lg[a]) / (b - a), 1e-4) : 1e-2;
      const double d = level[z] * slope;
      // Readings within 3 DN of clipping get no weight: a clipped pixel with noise reads
      // 253-254, and its vastly larger exposure would be averaged into those levels.
      weight[z] = z < 3 || z > 252 ? 0.0 : HatWeight(z, 0) / (d * d);
    }
  };
  update_weights();
  info->converged = false;
  double objective = 0;
  for (int it = 1; it <= o.max_iterations; ++it) {
    std::fill(num.begin(), num.end(), 0.0);
    std::fill(den.begin(), den.end(), 0.0);
    for (size_t i = 0; i < obs.size(); ++i) {
      const double w = weight[obs[i].z];
      num[obs[i].sample] += w * t[i] * level[obs[i].z];
      den[obs[i].sample] += w * t[i] * t[i];
    }
    std::fill(sum.begin(), sum.end(), 0.0);
    std::fill(count.begin(), count.end(), 0.0);
    double sq = 0, wsum = 0;
    for (size_t i = 0; i < obs.size(); ++i) {
      const int s = obs[i].sample;
      if (den[s] <= 0) continue;
      const double tx = t[i] * num[s] / den[s];
      sum[obs[i].z] += tx;
      count[obs[i].z] += 1;
      if (weight[obs[i].z] > 0) {
        const double r = (level[obs[i].z] - tx) / level[obs[i].z];
        const double hw = HatWeight(obs[i].z, 0);
        sq += hw * r * r;
        wsum += hw;
      }
    }
    objective = wsum > 0 ? std::sqrt(sq / wsum) : 0.0;
    if (!(count[anchor] > 0 && sum[anchor] > 0)) {
      throw Error("response: Robertson: the scale level lost its readings");
    }
    // ln I over the supported levels: the level means, held together by the same
    // second-difference term as Debevec-Malik (see ResponseMethod::kRobertson).
    std::vector<double> next = lg;
    {
      const int n = hi - lo + 1;
      std::vector<Eigen::Triplet<double>> trip;
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
      double data_w2 = 0;
      std::vector<double> dw(n, 0.0);
      for (int z = lo; z <= hi; ++z) {
        if (support[z] > 0 && count[z] > 0 && sum[z] > 0) {
          dw[z - lo] = count[z] * std::pow(HatWeight(z, o.weight_epsilon), 2);
          data_w2 += dw[z - lo];
        }
      }
      double smooth_w2 = 0;
      for (int z = lo + 1; z < hi; ++z) smooth_w2 += std::pow(HatWeight(z, o.weight_epsilon), 2);
      const double s2 = smooth_w2 > 0 ? o.lambda * data_w2 / smooth_w2 : 0.0;
      for (int z = lo; z <= hi; ++z) {
        const double d = dw[z - lo];
        if (d > 0) {
          trip.emplace_back(z - lo, z - lo, d);
          rhs[z - lo] += d * std::log(sum[z] / count[z]);
        }
      }
      for (int z = lo + 1; z < hi; ++z) {
        const double hw2 = s2 * std::pow(HatWeight(z, o.weight_epsilon), 2);
        const int k[3] = {z - 1 - lo, z - lo, z + 1 - lo};
        const double cf[3] = {1, -2, 1};
        for (int a = 0; a < 3; ++a) {
          for (int b = 0; b < 3; ++b) trip.emplace_back(k[a], k[b], hw2 * cf[a] * cf[b]);
        }
      }
      Eigen::SparseMatrix<double> ata(n, n);
      ata.setFromTriplets(trip.begin(), trip.end());
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(ata);
      const Eigen::VectorXd x = ldlt.solve(rhs);
      if (ldlt.info() != Eigen::Success || !x.allFinite()) {
        throw Error("response: Robertson: the level update is singular");
      }
      for (int z = lo; z <= hi; ++z) next[z] = x[z - lo];
    }
    const double pin = next[anchor];
    double change = 0;
    for (int z = lo; z <= hi; ++z) {
      next[z] -= pin;
      if (support[z] > 0) change = std::max(change, std::abs(next[z] - lg[z]));
    }
    lg = std::move(next);
    update_weights();
    info->iterations = it;
    if (change < o.convergence_tolerance) {
      info->converged = true;
      break;
    }
  }
  info->method_residual = objective;
  return lg;
}

// Chebyshev polynomials T_0..T_order at u = 2M - 1 (the fit is a polynomial in M; this basis
// keeps the normal equations well conditioned).
void Chebyshev(double m, int order, double* out) {
  const double u = 2 * m - 1;
  out[0] = 1;
  if (order >= 1) out[1] = u;
  for (int n = 2; n <= order; ++n) out[n] = 2 * u * out[n - 1] - out[n - 2];
}

double EvalPoly(const Eigen::VectorXd& c, double m) {
  double basis[16];
  Chebyshev(m, static_cast<int>(c.size()) - 1, basis);
  double v = 0;
  for (int n = 0; n < c.size(); ++n) v += c[n] * basis[n];
  return v;
}

// Mitsunaga & Nayar 1999, eq. 6-8 (see ResponseMethod::kMitsunagaNayar).
// Returns false when no order gives an increasing f over the fitted range.
bool FitMitsunagaNayar(const std::vector<Observation>& obs, double fit_high,
                       std::vector<double>* support, const ResponseOptions& o, ChannelResult* info,
                       std::vector<double>* g_out) {
  struct Pair {
    double m0, m1;
    int key;  // which pair of frames (for the ratio)
    int sample;
  };
  std::vector<Pair> pairs;
  std::vector<std::pair<int, int>> keys;  // frame ids of each ratio
  std::vector<double> ratio;              // R = t_q / t_q+1 per key
  std::vector<double> pair_support(kLevels, 0.0);
  for (size_t begin = 0; begin < obs.size();) {
    size_t end = begin;
    while (end < obs.size() && obs[end].sample == obs[begin].sample) ++end;
    std::vector<Observation> group(obs.begin() + begin, obs.begin() + end);
    std::sort(group.begin(), group.end(), [](const Observation& a, const Observation& b) {
      return a.log_exposure < b.log_exposure;
    });
    for (size_t k = 0; k + 1 < group.size(); ++k) {
      const Observation &a = group[k], &b = group[k + 1];
      if (!(b.log_exposure > a.log_exposure)) continue;
      if (a.z < o.mn_fit_low || a.z > o.mn_fit_high || b.z < o.mn_fit_low || b.z > fit_high) {
        continue;
      }
      const std::pair<int, int> id(a.frame, b.frame);
      int key = static_cast<int>(std::find(keys.begin(), keys.end(), id) - keys.begin());
      if (key == static_cast<int>(keys.size())) {
        keys.push_back(id);
        ratio.push_back(std::exp(static_cast<double>(a.log_exposure - b.log_exposure)));
      }
      pairs.push_back({a.z / 255.0, b.z / 255.0, key, a.sample});
      pair_support[a.z] += 1;
      pair_support[b.z] += 1;
    }
    begin = end;
  }
  if (pairs.size() < 8) {
    throw Error("response: Mitsunaga-Nayar: only " + std::to_string(pairs.size()) +
                " pairs of consecutive readings inside the fit range");
  }
  const auto [lo, hi] = SupportedRange(pair_support);
  const double m_ref = kPinned / 255.0;

  // Equality-constrained least squares: min sum_p (r_p (f(M0) - R f(M1)))^2, f(m_ref) = 1,
  // r_p = 1 / previous f(M0); from a linear start, a few reweighting passes.
  auto fit = [&](int order, int parity, const std::vector<double>& rat) -> Eigen::VectorXd {
    Eigen::VectorXd c = Eigen::VectorXd::Zero(order + 1);
    // Linear start f(M) = M / m_ref, in the Chebyshev basis: M = (T0 + T1) / 2.
    c[0] = 0.5 / m_ref;
    if (order >= 1) c[1] = 0.5 / m_ref;
    double b0[16], b1[16], bref[16];
    Chebyshev(m_ref, order, bref);
    for (int pass = 0; pass < 4; ++pass) {
      Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(order + 1, order + 1);
      for (const Pair& p : pairs) {
        if (parity >= 0 && p.sample % 2 != parity) continue;
        const double prev = EvalPoly(c, p.m0);
        const double r = 1.0 / std::max(prev, 1e-6);
        Chebyshev(p.m0, order, b0);
        Chebyshev(p.m1, order, b1);
        Eigen::VectorXd row(order + 1);
        for (int n = 0; n <= order; ++n) row[n] = r * (b0[n] - rat[p.key] * b1[n]);
        ata.selfadjointView<Eigen::Lower>().rankUpdate(row);
      }
      ata = ata.selfadjointView<Eigen::Lower>();
      Eigen::MatrixXd kkt = Eigen::MatrixXd::Zero(order + 2, order + 2);
      kkt.topLeftCorner(order + 1, order + 1) = ata;
      for (int n = 0; n <= order; ++n) kkt(order + 1, n) = kkt(n, order + 1) = bref[n];
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(order + 2);
      rhs[order + 1] = 1;
      const Eigen::VectorXd sol = kkt.fullPivLu().solve(rhs);
      if (!sol.allFinite()) break;
      c = sol.head(order + 1);
    }
    return c;
  };
  // The run of levels around 128 over which f is positive and strictly increasing.
  auto valid_run = [&](const Eigen::VectorXd& c) -> std::pair<int, int> {
    auto f = [&](int z) { return EvalPoly(c, z / 255.0); };
    const int mid = std::clamp(kPinned, lo, hi);
    if (!c.allFinite() || !(f(mid) > 0)) return {kLevels, -1};
    int a = mid, b = mid;
    while (a > lo && f(a - 1) > 0 && f(a - 1) < f(a)) --a;
    while (b < hi && f(b + 1) > f(b)) ++b;
    return {a, b};
  };
  // An order must describe the curve over z = 20..235 (or the fitted part of it).
  const int need_lo = std::max(lo, 20), need_hi = std::min(hi, 235);
  auto increasing = [&](const Eigen::VectorXd& c) {
    const auto [a, b] = valid_run(c);
    return a <= need_lo && b >= need_hi;
  };
  // Relative residual of the ratio equations of the given parity (-1: all).
  auto score = [&](const Eigen::VectorXd& c, int parity, const std::vector<double>& rat) {
    double sq = 0;
    int n = 0;
    for (const Pair& p : pairs) {
      if (parity >= 0 && p.sample % 2 != parity) continue;
      const double f0 = EvalPoly(c, p.m0);
      const double r = (f0 - rat[p.key] * EvalPoly(c, p.m1)) / std::max(std::abs(f0), 1e-12);
      sq += r * r;
      ++n;
    }
    return n > 0 ? std::sqrt(sq / n) : 0.0;
  };
  const int rounds = o.mn_estimate_ratios ? 5 : 1;
  Eigen::VectorXd c;
  int best = 0;
  for (int round = 0; round < rounds; ++round) {
    best = 0;
    double best_score = std::numeric_limits<double>::infinity();
    for (int order = 1; order <= o.max_polynomial_order; ++order) {
      const Eigen::VectorXd even = fit(order, 0, ratio), odd = fit(order, 1, ratio);
      if (!increasing(even) || !increasing(odd)) continue;
      const double sc = score(even, 1, ratio) + score(odd, 0, ratio);
      if (sc < best_score) {
        best_score = sc;
        best = order;
      }
    }
    if (best == 0) break;
    c = fit(best, -1, ratio);
    if (!increasing(c)) {
      best = 0;
      break;
    }
    if (round + 1 < rounds) {
      // The paper's ratio update: R_q = mean over pairs of f(M_q) / f(M_q+1).
      std::vector<double> rsum(ratio.size(), 0.0), rcount(ratio.size(), 0.0);
      const auto [a, b] = valid_run(c);
      for (const Pair& p : pairs) {
        const int z0 = static_cast<int>(std::lround(p.m0 * 255)),
                  z1 = static_cast<int>(std::lround(p.m1 * 255));
        if (z0 < a || z0 > b || z1 < a || z1 > b) continue;
        rsum[p.key] += EvalPoly(c, p.m0) / EvalPoly(c, p.m1);
        rcount[p.key] += 1;
      }
      for (size_t k = 0; k < ratio.size(); ++k) {
        if (rcount[k] > 0) ratio[k] = rsum[k] / rcount[k];
      }
    }
  }
  if (best == 0) return false;
  info->order = best;
  info->method_residual = score(c, -1, ratio);
  if (o.mn_estimate_ratios) info->ratios = ratio;
  const auto [run_lo, run_hi] = valid_run(c);
  std::vector<double> g(kLevels, 0.0);
  for (int z = run_lo; z <= run_hi; ++z) g[z] = std::log(EvalPoly(c, z / 255.0));
  // Levels outside the fitted run are extrapolated by FinishCurve.
  for (int z = 0; z < kLevels; ++z) (*support)[z] = z >= run_lo && z <= run_hi ? 1.0 : 0.0;
  *g_out = std::move(g);
  return true;
}

// Mitsunaga-Nayar over [mn_fit_low, mn_fit_high]; when no order is increasing there (a
// shoulder too steep for a polynomial), the top of the range is lowered in 12 DN steps
// down to 192 and the levels above are extrapolated.
std::vector<double> SolveMitsunagaNayar(const std::vector<Observation>& obs,
                                        std::vector<double>* support, const ResponseOptions& o,
                                        ChannelResult* info) {
  std::vector<double> g;
  for (double high = o.mn_fit_high; high >= std::max(192.0, o.mn_fit_low + 64); high -= 12) {
    if (FitMitsunagaNayar(obs, high, support, o, info, &g)) {
      info->fit_high = high;
      return g;
    }
  }
  throw Error("response: Mitsunaga-Nayar: no polynomial order up to " +
              std::to_string(o.max_polynomial_order) +
              " gives an increasing response, even with the fit range lowered to 192 DN; use "
              "Debevec-Malik or Robertson");
}

ChannelResult SolveChannel(const std::vector<Observation>& obs, int num_samples,
                           const ResponseOptions& o) {
  std::vector<double> support = LevelSupport(obs);
  ChannelResult result;
  std::vector<double> g;
  switch (o.method) {
    case ResponseMethod::kDebevecMalik:
      g = SolveDebevecMalik(obs, num_samples, o, &result);
      break;
    case ResponseMethod::kRobertson:
      g = SolveRobertson(obs, num_samples, support, o, &result);
      break;
    case ResponseMethod::kMitsunagaNayar:
      g = SolveMitsunagaNayar(obs, &support, o, &result);
      break;
  }
  FinishCurve(std::move(g), support, o, &result);
  return result;
}

}  // namespace

const char* ResponseMethodName(ResponseMethod method) {
  switch (method) {
    case ResponseMethod::kDebevecMalik:
      return "Debevec-Malik";
    case ResponseMethod::kRobertson:
      return "Robertson";
    case ResponseMethod::kMitsunagaNayar:
      return "Mitsunaga-Nayar";
  }
  return "unknown";
}

void ResponseOptions::Validate() const {
  if (method != ResponseMethod::kDebevecMalik && method != ResponseMethod::kRobertson &&
      method != ResponseMethod::kMitsunagaNayar) {
    throw Error("ResponseOptions: unknown method " + std::to_string(static_cast<int>(method)));
  }
  if (scan_pixels < 10000) {
    throw Error("ResponseOptions: scan_pixels must be >= 10000, got " +
                std::to_string(scan_pixels));
  }
  if (robertson_min_samples_per_bracket < 0 || robertson_min_samples_per_bracket > 1000000) {
    throw Error("ResponseOptions: robertson_min_samples_per_bracket must be in [0, 1e6], got " +
                std::to_string(robertson_min_samples_per_bracket));
  }
  if (max_iterations < 1 || max_iterations > 100000) {
    throw Error("ResponseOptions: max_iterations must be in [1, 100000], got " +
                std::to_string(max_iterations));
  }
  if (!std::isfinite(convergence_tolerance) || convergence_tolerance <= 0 ||
      convergence_tolerance >= 1) {
    throw Error("ResponseOptions: convergence_tolerance must be in (0, 1), got " +
                std::to_string(convergence_tolerance));
  }
  if (max_polynomial_order < 1 || max_polynomial_order > 15) {
    throw Error("ResponseOptions: max_polynomial_order must be in [1, 15], got " +
                std::to_string(max_polynomial_order));
  }
  if (!std::isfinite(mn_fit_low) || !std::isfinite(mn_fit_high) || mn_fit_low < 1 ||
      mn_fit_high > 254 || mn_fit_high - mn_fit_low < 64) {
    throw Error(
        "ResponseOptions: need 1 <= mn_fit_low, mn_fit_low + 64 <= mn_fit_high <= 254, "
        "got " +
        std::to_string(mn_fit_low) + " and " + std::to_string(mn_fit_high));
  }
  if (samples_per_bracket < kMinSamples || samples_per_bracket > 1000000) {
    throw Error("ResponseOptions: samples_per_bracket must be in [8, 1e6], got " +
                std::to_string(samples_per_bracket));
  }
  if (!std::isfinite(lambda) || lambda <= 0) {
    throw Error("ResponseOptions: lambda must be positive and finite, got " +
                std::to_string(lambda));
  }
  if (!std::isfinite(weight_epsilon) || weight_epsilon <= 0 || weight_epsilon > 10) {
    throw Error("ResponseOptions: weight_epsilon must be in (0, 10], got " +
                std::to_string(weight_epsilon));
  }
  if (!std::isfinite(monotone_tolerance) || monotone_tolerance < 0) {
    throw Error("ResponseOptions: monotone_tolerance must be >= 0, got " +
                std::to_string(monotone_tolerance));
  }
  if (!std::isfinite(min_slope) || min_slope < 0 || min_slope > 0.01) {
    throw Error("ResponseOptions: min_slope must be in [0, 0.01], got " +
                std::to_string(min_slope));
  }
}

ResponseCurve RecoverResponse(const std::vector<Bracket>& brackets, const ResponseOptions& options,
                              ResponseSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  if (brackets.empty()) throw Error("response: no brackets given");
  int channels = 0;
  for (size_t i = 0; i < brackets.size(); ++i) {
    const int nc = CheckBracket(brackets[i], i);
    if (i > 0 && nc != channels) {
      throw Error("response: bracket " + std::to_string(i) + " has " + std::to_string(nc) +
                  " channels, bracket 0 has " + std::to_string(channels));
    }
    channels = nc;
  }

  std::vector<Sample> samples;
  std::vector<int> first_frame(brackets.size(), 0);
  int stride = 1;
  for (size_t i = 0; i < brackets.size(); ++i) {
    int s = 1;
    const Bracket& b = brackets[i];
    std::vector<size_t> chosen;
    if (b.frames.empty()) {
      std::vector<const uint8_t*> data;
      for (const CodeImage& f : b.codes) data.push_back(f.data.data());
      chosen =
          SelectSamples(b, data, b.codes[0].width, b.codes[0].height, channels, i, options, &s);
    } else {
      std::vector<const float*> data;
      for (const Image& f : b.frames) data.push_back(f.data.data());
      chosen =
          SelectSamples(b, data, b.frames[0].width, b.frames[0].height, channels, i, options, &s);
    }
    for (size_t p : chosen) {
      samples.push_back({static_cast<int>(i), p});
    }
    stride = std::max(stride, s);
    if (i + 1 < brackets.size()) {
      first_frame[i + 1] = first_frame[i] + static_cast<int>(FrameCount(brackets[i]));
    }
  }
  if (first_frame.back() + FrameCount(brackets.back()) > 32767) {
    throw Error("response: more than 32767 frames in all brackets");
  }
  if (samples.size() < static_cast<size_t>(kMinSamples)) {
    throw Error("response: only " + std::to_string(samples.size()) +
                " usable sample pixels (need " + std::to_string(kMinSamples) +
                "); are the frames registered and not all saturated or black?");
  }

  std::array<std::vector<Observation>, 3> obs;
  for (int c = 0; c < channels; ++c) {
    for (size_t s = 0; s < samples.size(); ++s) {
      const Bracket& b = brackets[samples[s].bracket];
      for (size_t j = 0; j < FrameCount(b); ++j) {
        const size_t at = samples[s].pixel * channels + c;
        const float v = b.frames.empty() ? b.codes[j].data[at] : b.frames[j].data[at];
        const int z = std::clamp(static_cast<int>(std::lround(v)), 0, 255);
        obs[c].push_back({static_cast<int>(s), static_cast<uint8_t>(z),
                          static_cast<int16_t>(first_frame[samples[s].bracket] + j),
                          static_cast<float>(std::log(b.exposures[j]))});
      }
    }
  }

  std::array<ChannelResult, 3> res;
  tbb::parallel_for(0, channels, [&](int c) {
    res[c] = SolveChannel(obs[c], static_cast<int>(samples.size()), options);
  });

  ResponseCurve curve;
  for (int c = 0; c < 3; ++c) curve.g[c] = res[channels == 1 ? 0 : c].g;

  // Residuals of the final curve, with each sample's ln E re-estimated from it.
  double sq = 0, wsum = 0, method_sq = 0;
  int violations = 0, iterations = 0, order = 0;
  bool converged = true;
  for (int c = 0; c < channels; ++c) {
    violations += res[c].violations;
    iterations = std::max(iterations, res[c].iterations);
    order = std::max(order, res[c].order);
    converged = converged && res[c].converged;
    method_sq += res[c].method_residual * res[c].method_residual;
    const std::vector<double>& g = res[c].g;
    std::vector<double> num(samples.size(), 0), den(samples.size(), 0);
    for (const Observation& ob : obs[c]) {
      if (ob.z == 0 || ob.z == 255) continue;
      const double wz = HatWeight(ob.z, 0);
      num[ob.sample] += wz * (g[ob.z] - ob.log_exposure);
      den[ob.sample] += wz;
    }
    for (const Observation& ob : obs[c]) {
      if (ob.z == 0 || ob.z == 255 || den[ob.sample] <= 0) continue;
      const double r = g[ob.z] - ob.log_exposure - num[ob.sample] / den[ob.sample];
      const double wz = HatWeight(ob.z, 0);
      sq += wz * r * r;
      wsum += wz;
    }
  }
  for (int c = 0; c < 3; ++c) {
    for (double v : curve.g[c]) {
      if (!std::isfinite(v)) throw Error("response: recovered curve is not finite");
    }
  }
  if (summary) {
    summary->samples_used = static_cast<int>(samples.size());
    summary->equations = static_cast<int>(obs[0].size());
    summary->residual_rms = wsum > 0 ? std::sqrt(sq / wsum) : 0.0;
    summary->method_residual = std::sqrt(method_sq / channels);
    summary->monotone_violations = violations;
    summary->method = options.method;
    summary->iterations = iterations;
    summary->converged = converged;
    summary->polynomial_order = order;
    summary->exposure_ratios = res[0].ratios;
    summary->mn_fit_high = 255;
    for (int c = 0; c < channels; ++c) {
      if (res[c].fit_high > 0)
        summary->mn_fit_high = std::min(summary->mn_fit_high, res[c].fit_high);
    }
    if (options.method != ResponseMethod::kMitsunagaNayar) summary->mn_fit_high = 0;
    summary->scan_stride = stride;
    summary->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return curve;
}

}  // namespace rouen
