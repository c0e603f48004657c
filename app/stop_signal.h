// Ctrl-C and SIGTERM as a stop request for a long run (a capture): while a StopOnSignals
// lives, either signal sets its flag, which the run checks to stop after the step in flight,
// instead of ending the process.
#pragma once

#include <atomic>

namespace rouen {

class StopOnSignals {
 public:
  // Installs the handlers for SIGINT and SIGTERM (one StopOnSignals at a time).
  StopOnSignals();
  // Restores the handlers that were there before.
  ~StopOnSignals();
  StopOnSignals(const StopOnSignals&) = delete;
  StopOnSignals& operator=(const StopOnSignals&) = delete;

  // The flag to hand to the run: true once a signal came.
  const std::atomic<bool>* flag() const;
  // The signal that set the flag (SIGINT or SIGTERM), 0 while none came.
  int signal() const;
};

}  // namespace rouen
