#include "calib/hdr.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

// Tables are indexed by digital number in steps of 1/16 so 16-bit inputs keep precision.
constexpr int kSteps = 16;
constexpr int kTable = 255 * kSteps + 1;
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

struct WeightedLog {
  float weight;   // w(z)
  float log_sum;  // g_c(z) - ln X_j
};

// Adds F frames' rows to the per-value sums num += w (g - ln X), den += w; returns true when
// some value was outside 0..255 (by more than half a table step, 1/32 DN) or not finite.
template <int NC, int F>
bool AccumulateRows(const float* const* s, const WeightedLog* const* tables, size_t row_len,
                    float* num, float* den) {
  // Branch-free: the table index is clamped as an unsigned integer (negative values and NaN,
  // which converts to INT_MIN, become huge), and out-of-range values are flagged.
  constexpr unsigned kLast = kTable - 1;
  unsigned bad = 0;
  for (size_t i = 0; i < row_len; i += NC) {
    for (int c = 0; c < NC; ++c) {
      float n = num[i + c], d = den[i + c];
      for (int f = 0; f < F; ++f) {
        const unsigned k = static_cast<unsigned>(static_cast<int>(s[f][i + c] * kSteps + 0.5f));
        bad |= k > kLast;
        const WeightedLog e = tables[f][static_cast<size_t>(std::min(k, kLast)) * NC + c];
        n += e.weight * e.log_sum;
        d += e.weight;
      }
      num[i + c] = n;
      den[i + c] = d;
    }
  }
  return bad != 0;
}

// All frames, one streaming pass each (consecutive values are independent sums, so the
// lookups overlap; accumulating several frames per value instead chains the additions).
template <int NC>
bool AccumulateAll(const std::vector<const float*>& src, const std::vector<WeightedLog>& table,
                   size_t table_stride, size_t row_len, float* num, float* den, int* bad_frame) {
  bool any = false;
  for (size_t j = 0; j < src.size(); ++j) {
    const WeightedLog* t = &table[j * table_stride];
    if (AccumulateRows<NC, 1>(&src[j], &t, row_len, num, den)) {
      any = true;
      *bad_frame = static_cast<int>(j);
    }
  }
  return any;
}

int Level(float z) {
  return static_cast<int>(Clamp255(z) * kSteps + 0.5f);
}

// Ghost removal over one row (see MergeOptions::ghost_removal): subtracts the contributions
// of frames that disagree with the pixel's reference frame from num/den. Returns the number
// of pixels where some frame was left out.
int64_t RemoveGhosts(const std::vector<const float*>& src, const std::vector<int>& by_median,
                     const std::vector<WeightedLog>& table, size_t table_stride,
                     const std::vector<float>& slope, int nc, int w, const MergeOptions& o,
                     float* num, float* den, uint8_t* ghost_row) {
  int64_t count = 0;
  const float thr = static_cast<float>(o.ghost_threshold);
  const float noise = static_cast<float>(o.ghost_noise_dn);
  for (int x = 0; x < w; ++x) {
    const size_t off = static_cast<size_t>(x) * nc;
    int ref = -1;
    for (int j : by_median) {
      bool well = true;
      for (int c = 0; c < nc && well; ++c) {
        well = table[j * table_stride + static_cast<size_t>(Level(src[j][off + c])) * nc + c]
                   .weight > 0;
      }
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
        const size_t kj = static_cast<size_t>(Level(src[j][off + c])) * nc + c;
        const size_t kr = static_cast<size_t>(Level(src[ref][off + c])) * nc + c;
        const WeightedLog& ej = table[j * table_stride + kj];
        const WeightedLog& er = table[ref * table_stride + kr];
        // A clipped or dark reading says only "at least" / "at most": compare it one-sided.
        const float d = ej.log_sum - er.log_sum;
        const float allowed = thr + noise * (slope[kj] + slope[kr]);
        if (ej.weight > 0) {
          differs = std::abs(d) > allowed;
        } else {
          const float z = src[j][off + c];
          differs = z >= 128.f ? d < -allowed : d > allowed;
        }
      }
      if (!differs) continue;
      any = true;
      for (int c = 0; c < nc; ++c) {
        const size_t kj = static_cast<size_t>(Level(src[j][off + c])) * nc + c;
        const WeightedLog& ej = table[j * table_stride + kj];
        num[off + c] -= ej.weight * ej.log_sum;
        den[off + c] -= ej.weight;
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

void MergeHdrInto(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
                  const ResponseCurve& curve, const MergeOptions& options, Image* out_image,
                  MergeSummary* summary, std::vector<uint8_t>* valid_mask,
                  std::vector<uint8_t>* ghost_mask) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  CheckCurve(curve);
  if (frames.empty()) throw Error("hdr merge: no frames given");
  if (frames.size() != exposures.size()) {
    throw Error("hdr merge: " + std::to_string(frames.size()) + " frames but " +
                std::to_string(exposures.size()) + " exposures");
  }
  for (size_t j = 0; j < frames.size(); ++j) {
    if (frames[j] == nullptr) throw Error("hdr merge: frame " + std::to_string(j) + " is null");
  }
  const Image& f0 = *frames[0];
  const int w = f0.width, h = f0.height, nc = f0.channels;
  if (w <= 0 || h <= 0) throw Error("hdr merge: frame 0 is empty");
  if (nc != 1 && nc != 3) {
    throw Error("hdr merge: frames must have 1 or 3 channels, frame 0 has " + std::to_string(nc));
  }
  for (size_t j = 0; j < frames.size(); ++j) {
    const Image& f = *frames[j];
    const std::string fw = "hdr merge: frame " + std::to_string(j) + ": ";
    if (f.units != PixelUnits::kDigital) throw Error(fw + "is not in digital numbers (kDigital)");
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
  }
  const int nf = static_cast<int>(frames.size());
  const int shortest =
      static_cast<int>(std::min_element(exposures.begin(), exposures.end()) - exposures.begin());
  const int longest =
      static_cast<int>(std::max_element(exposures.begin(), exposures.end()) - exposures.begin());

  // Per-z tables: weight and g(z) per channel.
  std::vector<float> weight(kTable);
  std::vector<float> gtab(static_cast<size_t>(kTable) * nc);
  for (int k = 0; k < kTable; ++k) {
    const double z = static_cast<double>(k) / kSteps;
    weight[k] = static_cast<float>(
        std::max(0.0, std::min(z - options.dark_level, options.saturation_level - z)));
    const int z0 = std::min(254, k / kSteps);
    const double t = z - z0;
    for (int c = 0; c < nc; ++c) {
      const auto& g = curve.g[nc == 1 ? 1 : c];
      gtab[static_cast<size_t>(k) * nc + c] = static_cast<float>((1 - t) * g[z0] + t * g[z0 + 1]);
    }
  }
  std::vector<float> log_x(nf);
  for (int j = 0; j < nf; ++j) log_x[j] = static_cast<float>(std::log(exposures[j]));
  const float sat_level = static_cast<float>(options.saturation_level);
  const float dark_level = static_cast<float>(options.dark_level);
  std::vector<float> g255(nc);
  for (int c = 0; c < nc; ++c) g255[c] = gtab[static_cast<size_t>(kTable - 1) * nc + c];

  // Per frame, level and channel: {w(z), g_c(z) - ln X_j}, the same floats the sums use.
  const size_t table_stride = static_cast<size_t>(kTable) * nc;
  std::vector<WeightedLog> table(table_stride * nf);
  for (int j = 0; j < nf; ++j) {
    for (size_t e = 0; e < table_stride; ++e) {
      table[j * table_stride + e] = {weight[e / nc], gtab[e] - log_x[j]};
    }
  }

  if (out_image == nullptr) throw Error("hdr merge: no output image given");
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
    slope.resize(gtab.size());
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

  // Row by row: frames in the outer loop stream through each row (accumulating in the
  // same frame order as a per-pixel loop, so the sums are the same floats), then one pass
  // per pixel finishes it.
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    int64_t local_sat = 0, local_dark = 0, local_ghosts = 0;
    const size_t row_len = static_cast<size_t>(w) * nc;
    std::vector<float> num(row_len), den(row_len);
    std::vector<const float*> src(nf);
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int j = 0; j < nf; ++j)
        src[j] = frames[j]->data.data() + static_cast<size_t>(y) * w * nc;
      float* dst = out.data.data() + static_cast<size_t>(y) * w * nc;
      std::fill(num.begin(), num.end(), 0.f);
      std::fill(den.begin(), den.end(), 0.f);
      int bad_j = -1;
      const bool bad = nc == 3 ? AccumulateAll<3>(src, table, table_stride, row_len, num.data(),
                                                  den.data(), &bad_j)
                               : AccumulateAll<1>(src, table, table_stride, row_len, num.data(),
                                                  den.data(), &bad_j);
      if (bad) bad_frame.store(bad_j);
      if (options.ghost_removal) {
        local_ghosts += RemoveGhosts(src, by_median, table, table_stride, slope, nc, w,
                                     options, num.data(), den.data(),
                                     ghost_mask ? ghost_mask->data() + static_cast<size_t>(y) * w
                                                : nullptr);
      }
      for (int x = 0; x < w; ++x) {
        bool pixel_sat = false, pixel_dark = false, pixel_invalid = false;
        for (int c = 0; c < nc; ++c) {
          const size_t off = static_cast<size_t>(x) * nc + c;
          float log_l;
          if (den[off] > 0) {
            log_l = num[off] / den[off];
          } else {
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
              log_l = g255[c] - log_x[shortest];  // a lower bound
              pixel_sat = true;
            } else if (zl <= dark_level || zmax <= dark_level) {
              const int k = static_cast<int>(Clamp255(zl) * kSteps + 0.5f);
              log_l = gtab[static_cast<size_t>(k) * nc + c] - log_x[longest];
              pixel_dark = true;
            } else {
              // Saturated in long frames, dark in short ones, nothing in between: the
              // middle of the bracketing bounds.
              float lower = -1e30f, upper = 1e30f;
              for (int j = 0; j < nf; ++j) {
                const float z = Clamp255(src[j][off]);
                const int k = static_cast<int>(z * kSteps + 0.5f);
                const float est = gtab[static_cast<size_t>(k) * nc + c] - log_x[j];
                if (z >= sat_level) lower = std::max(lower, est);
                if (z <= dark_level) upper = std::min(upper, est);
              }
              log_l = 0.5f * (lower + upper);
            }
          }
          if (!(std::abs(log_l) <= kMaxLog)) {
            overflow.store(true);
            log_l = 0;
          }
          dst[off] = std::exp(log_l);
        }
        local_sat += pixel_sat;
        local_dark += pixel_dark;
        if (valid_mask && pixel_invalid) (*valid_mask)[static_cast<size_t>(y) * w + x] = 0;
      }
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

}  // namespace rouen
