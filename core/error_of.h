// For tests: what a call throws, as text.
#pragma once

#include <string>

#include "core/error.h"

namespace rouen {

// The message of the rouen::Error `f` throws ("" when it throws none).
template <typename F>
std::string ErrorOf(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace rouen
