// The laptop's clock, and the offset between it and GPS time estimated from GPS fixes.
#pragma once

#include <optional>
#include <vector>

#include "capture/device.h"

namespace rouen {

// Frame times of field rigs: the laptop's real-time clock (it cannot jump to a planned slot).
class SystemClock : public Clock {
 public:
  UtcTime Now() override { return NowUtc(); }
  bool JumpTo(UtcTime) override { return false; }
  bool IsLaptopClock() const override { return true; }
};

// GPS time minus laptop clock, from fixes that carry the laptop time they arrived at
// (GpsFix::received_utc). Each fix gives utc - received_utc = offset - lag, where the lag
// (receiver epoch to the laptop reading it: serial transfer, gpsd) is >= 0 and varies; the
// largest difference seen has the smallest lag, so it is the estimate (within the smallest
// lag, typically 0.05-0.3 s with 1 Hz receivers), taken among differences within 1 s of their
// median so that a glitched fix cannot win. Fixes without received_utc are ignored.
class ClockOffsetEstimator {
 public:
  void Add(const GpsFix& fix);
  int count() const { return static_cast<int>(diffs_.size()); }
  // Seconds to add to the laptop clock to get GPS time; nothing before the first usable fix.
  std::optional<double> Offset() const;
  // Spread of the differences (max - min): an upper bound on the lag variation.
  double Spread() const;

 private:
  std::vector<double> diffs_;
};

}  // namespace rouen
