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

}  // namespace

double Quantile(std::vector<double> v, double p) { return LowerRank(v, p); }
float Quantile(std::vector<float> v, double p) { return LowerRank(v, p); }

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

}  // namespace rouen
