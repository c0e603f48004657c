#include "core/stats.h"

#include <algorithm>
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

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

}  // namespace rouen
