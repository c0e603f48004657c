#include "app/stop_signal.h"

#include <csignal>

namespace rouen {
namespace {

std::atomic<bool> g_stop{false};
std::atomic<int> g_signal{0};
void (*g_old_int)(int) = SIG_DFL;
void (*g_old_term)(int) = SIG_DFL;

// Async-signal-safe: lock-free atomics only.
void OnSignal(int sig) {
  g_signal.store(sig);
  g_stop.store(true);
}

}  // namespace

StopOnSignals::StopOnSignals() {
  g_stop.store(false);
  g_signal.store(0);
  g_old_int = std::signal(SIGINT, OnSignal);
  g_old_term = std::signal(SIGTERM, OnSignal);
}

StopOnSignals::~StopOnSignals() {
  std::signal(SIGINT, g_old_int);
  std::signal(SIGTERM, g_old_term);
}

const std::atomic<bool>* StopOnSignals::flag() const { return &g_stop; }

int StopOnSignals::signal() const { return g_signal.load(); }

}  // namespace rouen
