#include "capture/clock.h"

#include <algorithm>
#include <cmath>

namespace rouen {

void ClockOffsetEstimator::Add(const GpsFix& fix) {
  if (!fix.received_utc || !fix.valid()) return;
  double d = static_cast<double>(fix.utc.ns - fix.received_utc->ns) * 1e-9;
  if (std::isfinite(d)) diffs_.push_back(d);
}

std::optional<double> ClockOffsetEstimator::Offset() const {
  if (diffs_.empty()) return std::nullopt;
  // A receiver's cold-start time glitch (wrong second, wrong week) must not win the max:
  // only differences within 1 s of the median count.
  std::vector<double> sorted = diffs_;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  double best = median;
  for (double d : sorted)
    if (std::abs(d - median) <= 1.0) best = std::max(best, d);
  return best;
}

double ClockOffsetEstimator::Spread() const {
  if (diffs_.empty()) return 0;
  auto [lo, hi] = std::minmax_element(diffs_.begin(), diffs_.end());
  return *hi - *lo;
}

}  // namespace rouen
