// Shared by the libFuzzer targets (tests/fuzz/*_fuzz.cc). A rouen::Error is an expected
// rejection of a malformed input; any other exception, a failed invariant (FUZZ_CHECK), a
// crash, a leak, undefined behaviour or a timeout is a finding.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <string_view>
#include <typeinfo>

#include "core/error.h"

// Aborts with `what` (a std::string or C string) when `cond` is false: libFuzzer reports
// the input as a crash.
#define FUZZ_CHECK(cond, what)                                                                \
  do {                                                                                        \
    if (!(cond)) {                                                                            \
      std::fprintf(stderr, "FUZZ_CHECK(%s) failed at %s:%d: %s\n", #cond, __FILE__, __LINE__, \
                   std::string(what).c_str());                                                \
      std::abort();                                                                           \
    }                                                                                         \
  } while (0)

namespace rouen::fuzz {

inline std::string_view Text(const uint8_t* data, size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

// Runs `parse`: true when it returns, false when it throws rouen::Error (whose message must
// then mention `must_name`, the file name given to the parser, when that is not empty).
// Any other exception aborts.
template <typename F>
bool Accepts(F&& parse, std::string_view must_name = {}) {
  try {
    parse();
    return true;
  } catch (const Error& e) {
    const std::string_view msg = e.what();
    FUZZ_CHECK(!msg.empty(), "empty rouen::Error message");
    FUZZ_CHECK(must_name.empty() || msg.find(must_name) != std::string_view::npos,
               "error does not name the file: " + std::string(msg));
    return false;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "uncaught %s (not rouen::Error): %s\n", typeid(e).name(), e.what());
    std::abort();
  }
}

// Calls `line` with each '\n'-separated line of `text` (the last one may lack its newline).
template <typename F>
void ForEachLine(std::string_view text, F&& line) {
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    line(text.substr(pos, end - pos));
    pos = end + 1;
  }
}

}  // namespace rouen::fuzz
