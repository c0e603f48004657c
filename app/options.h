// CLI11 validators for numeric options. CLI11's own ranges let NaN through (every comparison
// with NaN is false); these refuse NaN and infinities, and say the range.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "core/solar.h"
#include "core/time.h"

namespace rouen {

// A finite number within [lo, hi] (hi may be infinite); `unit` (e.g. "mbar") follows the
// range in the message.
CLI::Validator Within(double lo, double hi, const std::string& unit = "");
// A finite number above 0.
CLI::Validator Positive();
// A number one of core/limits.h's rules accepts (LatitudeProblem, HeightProblem, ...).
CLI::Validator Obeys(std::string (*problem)(double));

// `n` comma-separated finite numbers ("1.5,2,3"); throws rouen::Error naming `option`.
std::vector<double> ParseNumberList(const std::string& text, size_t n, const std::string& option);

// A duration "15min", "1h", "30s" (units s, min, h; a bare number is seconds), above 0 and at
// most `max_s`; throws rouen::Error naming `option`.
double ParseDurationSeconds(const std::string& text, double max_s, const std::string& option);

// An ISO 8601 time with its offset (core/time.h); throws rouen::Error naming `option`.
UtcTime ParseTimeOption(const std::string& text, const std::string& option);

// A site "LAT,LON,H" (degrees north, degrees east, metres) within core/limits.h's ranges;
// throws rouen::Error naming `option` and the coordinate at fault.
Site ParseSiteOption(const std::string& text, const std::string& option);

}  // namespace rouen
