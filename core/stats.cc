#include "core/stats.h"

#include <algorithm>
#include <cassert>
#include <numeric>

namespace rouen {
namespace {

template <typename T>
T LowerRank(std::vector<T>& v, double p) {
  if (v.empty()) return 0;
  const size_t k = static_cast<size_t>(std::clamp(p, 0.0, 1.0) * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

template <typename T>
T MiddleValue(std::vector<T>& v) {
  if (v.empty()) return 0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  if (v.size() % 2 == 1) return v[mid];
  const T below = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid));
  return below + (v[mid] - below) / 2;
}

}  // namespace

double Median(std::vector<double> v) { return MiddleValue(v); }
float Median(std::vector<float> v) { return MiddleValue(v); }

double Quantile(std::vector<double> v, double p) { return LowerRank(v, p); }
float Quantile(std::vector<float> v, double p) { return LowerRank(v, p); }

double WeightedQuantile(const std::vector<double>& v, const std::vector<double>& w, double p) {
  assert(v.size() == w.size());
  if (v.empty()) return 0;
  std::vector<size_t> order(v.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return v[a] < v[b]; });
  const double total = std::accumulate(w.begin(), w.end(), 0.0);
  const double target = std::clamp(p, 0.0, 1.0) * (total - w[order.back()]);
  // Sums of equal weights round; 1e-12 of the total keeps equal weights on Quantile's rank.
  const double slack = 1e-12 * total;
  double before = 0;
  size_t k = 0;
  for (size_t i = 1; i < order.size(); ++i) {
    before += w[order[i - 1]];
    if (before > target + slack) break;
    k = i;
  }
  return v[order[k]];
}

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

}  // namespace rouen
