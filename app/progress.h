// A one-line progress display on stderr (only when stderr is a terminal or forced).
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>

namespace rouen {

class ProgressLine {
 public:
  explicit ProgressLine(bool enabled) : enabled_(enabled), tty_(isatty(2)) {}
  // Redraws at most 10 times a second on a terminal; elsewhere prints a line every 5 s.
  void Update(const std::string& text) {
    if (!enabled_) return;
    auto now = std::chrono::steady_clock::now();
    double dt = std::chrono::duration<double>(now - last_).count();
    if (dt < (tty_ ? 0.1 : 5.0)) return;
    last_ = now;
    if (tty_) {
      std::fprintf(stderr, "\r%s\033[K", text.c_str());
    } else {
      std::fprintf(stderr, "%s\n", text.c_str());
    }
    shown_ = true;
  }
  // A message that must not be throttled away (camera lost, reconnected): on its own line.
  void Message(const std::string& text) {
    if (!enabled_) return;
    std::fprintf(stderr, "%s%s\n", tty_ && shown_ ? "\r\033[K" : "", text.c_str());
  }
  void Done() {
    if (enabled_ && tty_ && shown_) std::fprintf(stderr, "\n");
  }

 private:
  bool enabled_, tty_;
  bool shown_ = false;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace rouen
