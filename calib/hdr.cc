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

struct WeightedLog {
  float weight;   // w(z)
  float log_sum;  // g_c(z) - ln X_j
};

// Adds one frame's row to the per-value sums num += w (g - ln X), den += w; returns true
// when some value was outside 0..255 or not finite (it is skipped).
template <int NC>
bool AccumulateRow(const float* s, size_t row_len, const WeightedLog* table, float* num,
                   float* den) {
  bool bad = false;
  for (size_t i = 0; i < row_len; i += NC) {
    for (int c = 0; c < NC; ++c) {
      const float z = s[i + c];
      if (!(z >= 0.f && z <= 255.f)) {
        bad = true;
        continue;
      }
      const int k = static_cast<int>(z * kSteps + 0.5f);
      const WeightedLog e = table[static_cast<size_t>(k) * NC + c];
      num[i + c] += e.weight * e.log_sum;
      den[i + c] += e.weight;
    }
  }
  return bad;
}

}  // namespace

void MergeOptions::Validate() const {
  if (!std::isfinite(dark_level) || !std::isfinite(saturation_level) || dark_level < 0 ||
      saturation_level > 255 || saturation_level - dark_level < 2) {
    throw Error("MergeOptions: need 0 <= dark_level < saturation_level - 2 <= 253, got " +
                std::to_string(dark_level) + " and " + std::to_string(saturation_level));
  }
}

Image MergeHdr(const std::vector<const Image*>& frames, const std::vector<double>& exposures,
               const ResponseCurve& curve, const MergeOptions& options, MergeSummary* summary,
               std::vector<uint8_t>* valid_mask) {
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

  Image out(w, h, nc, PixelUnits::kRadiance);
  if (valid_mask) valid_mask->assign(static_cast<size_t>(w) * h, 1);
  std::atomic<int64_t> saturated{0}, dark{0};
  std::atomic<int> bad_frame{-1};
  std::atomic<bool> overflow{false};

  // Row by row: frames in the outer loop stream through each row (accumulating in the
  // same frame order as a per-pixel loop, so the sums are the same floats), then one pass
  // per pixel finishes it.
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    int64_t local_sat = 0, local_dark = 0;
    const size_t row_len = static_cast<size_t>(w) * nc;
    std::vector<float> num(row_len), den(row_len);
    std::vector<const float*> src(nf);
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int j = 0; j < nf; ++j)
        src[j] = frames[j]->data.data() + static_cast<size_t>(y) * w * nc;
      float* dst = out.data.data() + static_cast<size_t>(y) * w * nc;
      std::fill(num.begin(), num.end(), 0.f);
      std::fill(den.begin(), den.end(), 0.f);
      for (int j = 0; j < nf; ++j) {
        const bool bad = nc == 3 ? AccumulateRow<3>(src[j], row_len, &table[j * table_stride],
                                                    num.data(), den.data())
                                 : AccumulateRow<1>(src[j], row_len, &table[j * table_stride],
                                                    num.data(), den.data());
        if (bad) bad_frame.store(j);
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
              const int k = static_cast<int>(std::clamp(zl, 0.f, 255.f) * kSteps + 0.5f);
              log_l = gtab[static_cast<size_t>(k) * nc + c] - log_x[longest];
              pixel_dark = true;
            } else {
              // Saturated in long frames, dark in short ones, nothing in between: the
              // middle of the bracketing bounds.
              float lower = -1e30f, upper = 1e30f;
              for (int j = 0; j < nf; ++j) {
                const float z = std::clamp(src[j][off], 0.f, 255.f);
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
    summary->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return out;
}

}  // namespace rouen
