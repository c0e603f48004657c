#include "calib/response.h"

#include <tbb/parallel_for.h>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <numeric>
#include <random>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

constexpr int kLevels = 256;
constexpr int kPinned = 128;  // g_c(128) = 0 for every channel
constexpr int kBins = 32;     // brightness strata for sample selection
constexpr int kMinSamples = 8;

struct Sample {
  int bracket;
  size_t pixel;  // y * width + x
};

// Per-bracket validation; returns the channel count.
int CheckBracket(const Bracket& b, size_t index) {
  const std::string where = "response: bracket " + std::to_string(index) + ": ";
  if (b.frames.empty()) throw Error(where + "has no frames");
  if (b.frames.size() != b.exposures.size()) {
    throw Error(where + std::to_string(b.frames.size()) + " frames but " +
                std::to_string(b.exposures.size()) + " exposures");
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
  const Image& f0 = b.frames[0];
  if (f0.width <= 0 || f0.height <= 0) throw Error(where + "frame 0 is empty");
  if (f0.channels != 1 && f0.channels != 3) {
    throw Error(where + "frames must have 1 or 3 channels, frame 0 has " +
                std::to_string(f0.channels));
  }
  for (size_t j = 0; j < b.frames.size(); ++j) {
    const Image& f = b.frames[j];
    const std::string fw = where + "frame " + std::to_string(j) + ": ";
    if (f.units != PixelUnits::kDigital) throw Error(fw + "is not in digital numbers (kDigital)");
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
  if (!b.mask.empty() && b.mask.size() != static_cast<size_t>(f0.width) * f0.height) {
    throw Error(where + "mask has " + std::to_string(b.mask.size()) + " entries, expected " +
                std::to_string(static_cast<size_t>(f0.width) * f0.height));
  }
  return f0.channels;
}

// Stratified sampling over brightness (mean over frames and channels, monotone in radiance),
// preferring pixels of low local gradient; rejects pixels that darken as exposure grows.
std::vector<size_t> SelectSamples(const Bracket& b, size_t index, const ResponseOptions& o) {
  const int w = b.frames[0].width, h = b.frames[0].height, nc = b.frames[0].channels;
  const size_t np = static_cast<size_t>(w) * h;
  std::vector<int> order(b.frames.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int i, int j) { return b.exposures[i] < b.exposures[j]; });

  std::vector<float> key(np, 0.f);
  std::vector<uint8_t> usable(np, 1);
  std::vector<uint8_t> informative(np, 0);
  std::vector<float> running(np * nc, -1.f);
  const float tol = static_cast<float>(o.monotone_tolerance);
  const float inv = 1.f / static_cast<float>(b.frames.size() * nc);
  for (int j : order) {
    const float* d = b.frames[j].data.data();
    for (size_t p = 0; p < np; ++p) {
      float sum = 0;
      for (int c = 0; c < nc; ++c) {
        const float v = d[p * nc + c];
        if (!(v >= 0.f && v <= 255.f)) {
          throw Error("response: bracket " + std::to_string(index) + " frame " + std::to_string(j) +
                      ": pixel (" + std::to_string(p % w) + ", " + std::to_string(p / w) +
                      ") holds " + std::to_string(v) + ", outside 0..255");
        }
        float& r = running[p * nc + c];
        if (v < r - tol) usable[p] = 0;
        r = std::max(r, v);
        sum += v;
      }
      key[p] += sum * inv;
      const float mean = sum / nc;
      if (mean >= 2.f && mean <= 253.f && informative[p] < 2) ++informative[p];
    }
  }

  // Candidates per brightness stratum (interior pixels only, for the gradient).
  std::vector<std::vector<size_t>> bins(kBins);
  std::vector<float> grad(np, 0.f);
  for (int y = 1; y + 1 < h; ++y) {
    for (int x = 1; x + 1 < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      if (!usable[p] || informative[p] < 2) continue;
      if (!b.mask.empty() && b.mask[p] == 0) continue;
      grad[p] = std::abs(key[p + 1] - key[p - 1]) + std::abs(key[p + w] - key[p - w]);
      const int bin = std::min(kBins - 1, static_cast<int>(key[p] * kBins / 256.f));
      bins[bin].push_back(p);
    }
  }
  std::mt19937_64 rng(o.seed + 0x9E3779B97F4A7C15ull * (index + 1));
  const size_t quota = (o.samples_per_bracket + kBins - 1) / kBins;
  for (auto& bin : bins) {
    std::shuffle(bin.begin(), bin.end(), rng);
    // A random pool a few times the quota, flattest first; the rest stays random after it.
    const size_t pool = std::min(bin.size(), 4 * quota);
    std::stable_sort(bin.begin(), bin.begin() + pool,
                     [&](size_t a, size_t c) { return grad[a] < grad[c]; });
  }
  std::vector<size_t> chosen;
  std::vector<size_t> next(kBins, 0);
  bool any = true;
  while (chosen.size() < static_cast<size_t>(o.samples_per_bracket) && any) {
    any = false;
    for (int k = 0; k < kBins && chosen.size() < static_cast<size_t>(o.samples_per_bracket); ++k) {
      if (next[k] < bins[k].size()) {
        chosen.push_back(bins[k][next[k]++]);
        any = true;
      }
    }
  }
  return chosen;
}

struct Observation {
  int sample;
  uint8_t z;
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
};

ChannelResult SolveChannel(const std::vector<Observation>& obs, int num_samples,
                           const ResponseOptions& o) {
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

  std::vector<double> g(kLevels, 0.0), support(kLevels, 0.0);
  for (int z = 0; z < kLevels; ++z) g[z] = z == kPinned ? 0.0 : x[gi(z)];
  for (const Observation& ob : obs) {
    if (ob.z > 0 && ob.z < 255) support[ob.z] += HatWeight(ob.z, 0);
  }

  // Ends that no well-exposed observation reached: linear extrapolation with the slope of
  // the nearest supported stretch.
  int lo = 1, hi = kLevels - 2;
  while (lo < kLevels - 1 && support[lo] <= 0) ++lo;
  while (hi > 0 && support[hi] <= 0) --hi;
  if (lo < hi) {
    const int span = std::min(8, hi - lo);
    const double slope_lo = std::max(o.min_slope, (g[lo + span] - g[lo]) / span);
    const double slope_hi = std::max(o.min_slope, (g[hi] - g[hi - span]) / span);
    for (int z = 0; z < lo; ++z) g[z] = g[lo] - slope_lo * (lo - z);
    for (int z = hi + 1; z < kLevels; ++z) g[z] = g[hi] + slope_hi * (z - hi);
  }

  ChannelResult result;
  for (int z = 0; z + 1 < kLevels; ++z) {
    if (g[z + 1] < g[z] + o.min_slope) ++result.violations;
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
  result.g = std::move(g);
  return result;
}

}  // namespace

void ResponseOptions::Validate() const {
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
  for (size_t i = 0; i < brackets.size(); ++i) {
    for (size_t p : SelectSamples(brackets[i], i, options)) {
      samples.push_back({static_cast<int>(i), p});
    }
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
      for (size_t j = 0; j < b.frames.size(); ++j) {
        const float v = b.frames[j].data[samples[s].pixel * channels + c];
        const int z = std::clamp(static_cast<int>(std::lround(v)), 0, 255);
        obs[c].push_back({static_cast<int>(s), static_cast<uint8_t>(z),
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
  double sq = 0, wsum = 0;
  int violations = 0;
  for (int c = 0; c < channels; ++c) {
    violations += res[c].violations;
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
    summary->monotone_violations = violations;
    summary->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return curve;
}

}  // namespace rouen
