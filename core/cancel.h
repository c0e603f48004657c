// Stopping long work early: a Cancellation is the token a caller holds (Python's Ctrl-C, a
// GUI's stop button). It is requested from any thread, or from a signal handler (one
// lock-free atomic store), and the work polls it between pieces of a few milliseconds, then
// throws Cancelled. Work that is cancelled writes nothing more (outputs are written whole, at
// the end); the caller decides what the stop means to its user.
#pragma once

#include <atomic>

#include "core/error.h"

namespace rouen {

class Cancellation {
 public:
  void Request() noexcept { requested_.store(true, std::memory_order_relaxed); }
  bool requested() const noexcept { return requested_.load(std::memory_order_relaxed); }

 private:
  std::atomic<bool> requested_{false};
  static_assert(std::atomic<bool>::is_always_lock_free, "Request must be async-signal-safe");
};

// What cancelled work throws (a rouen::Error, so callers that only report errors still do).
class Cancelled : public Error {
 public:
  Cancelled() : Error("cancelled") {}
};

// The polls the work makes; `cancel` may be null (work nobody can stop).
inline bool IsCancelled(const Cancellation* cancel) {
  return cancel != nullptr && cancel->requested();
}
inline void ThrowIfCancelled(const Cancellation* cancel) {
  if (IsCancelled(cancel)) throw Cancelled();
}

}  // namespace rouen
