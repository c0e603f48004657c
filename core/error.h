// Expected failures (bad input files, malformed journals, device problems) are reported as
// rouen::Error whose message names the file, line or device. Programmer errors use checks.
#pragma once

#include <stdexcept>
#include <string>

namespace rouen {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace rouen
