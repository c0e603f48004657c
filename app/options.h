// CLI11 validators for numeric options. CLI11's own ranges let NaN through (every comparison
// with NaN is false); these refuse NaN and infinities, and say the range.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

namespace rouen {

// A finite number within [lo, hi] (hi may be infinite); `unit` (e.g. "mbar") follows the
// range in the message.
CLI::Validator Within(double lo, double hi, const std::string& unit = "");
// A finite number above 0.
CLI::Validator Positive();
// A number one of core/limits.h's rules accepts (LatitudeProblem, HeightProblem, ...).
CLI::Validator Obeys(std::string (*problem)(double));

}  // namespace rouen
