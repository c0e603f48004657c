#include "app/options.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "core/error.h"
#include "core/limits.h"
#include "core/text.h"

namespace rouen {
namespace {

// The number in `text` if it is a decimal as people write one (ParseDecimal; not CLI11's
// reading, which takes 0x10, nan and inf).
std::optional<double> Number(const std::string& text) {
  double v = 0;
  if (!ParseDecimal(text, &v)) return std::nullopt;
  return v;
}

}  // namespace

CLI::Validator Within(double lo, double hi, const std::string& unit) {
  const std::string range =
      (std::isinf(hi) ? ">= " + FormatNumber(lo) : FormatNumber(lo) + ".." + FormatNumber(hi)) +
      (unit.empty() ? "" : " ") + unit;
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        const std::optional<double> v = Number(text);
        if (v && *v >= lo && *v <= hi) return {};  // false for NaN
        return "'" + text + "' is not a number within " + range;
      },
      "NUMBER in " + range);
}

CLI::Validator Positive() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        const std::optional<double> v = Number(text);
        if (v && *v > 0 && std::isfinite(*v)) return {};
        return "'" + text + "' is not a positive number";
      },
      "POSITIVE");
}

CLI::Validator Obeys(std::string (*problem)(double)) {
  return CLI::Validator(
      [problem](std::string& text) -> std::string {
        const std::optional<double> v = Number(text);
        return v ? problem(*v) : "'" + text + "' is not a number";
      },
      "");
}

std::vector<double> ParseNumberList(const std::string& text, size_t n, const std::string& option) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    double x = 0;
    if (!ParseDecimal(item, &x))
      throw Error(option + " '" + text + "': '" + item + "' is not a number");
    v.push_back(x);
  }
  if (v.size() != n || (!text.empty() && text.back() == ','))
    throw Error(option + " '" + text + "': expected " + std::to_string(n) +
                " comma-separated numbers");
  return v;
}

UtcTime ParseTimeOption(const std::string& text, const std::string& option) {
  try {
    return ParseIso8601(text);
  } catch (const Error& e) {
    throw Error(option + ": " + e.what());
  }
}

double ParseDurationSeconds(const std::string& text, double max_s, const std::string& option) {
  const std::string where = option + " '" + text + "'";
  // The number, then its unit: the letters at the end (the exponent's 'e' is the number's).
  size_t used = text.size();
  while (used > 0 && std::isalpha(static_cast<unsigned char>(text[used - 1])) &&
         !(text[used - 1] == 'e' && used >= 2 &&
           std::isdigit(static_cast<unsigned char>(text[used - 2]))))
    --used;
  const std::string unit = text.substr(used);
  double value = 0;
  if (!ParseDecimal(std::string_view(text).substr(0, used), &value))
    throw Error(where + ": not a duration (e.g. 15min, 1h, 30s)");
  double scale = 0;
  if (unit.empty() || unit == "s") scale = 1;
  if (unit == "min") scale = 60;
  if (unit == "h") scale = 3600;
  if (scale == 0) throw Error(where + ": unknown unit '" + unit + "' (s, min or h)");
  const double seconds = value * scale;
  if (!std::isfinite(seconds) || seconds <= 0 || seconds > max_s)
    throw Error(where + ": must be above 0 and at most " + FormatNumber(max_s) + " s");
  return seconds;
}

Site ParseSiteOption(const std::string& text, const std::string& option) {
  const std::string where = option + " '" + text + "'";
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) parts.push_back(item);
  if (parts.size() != 3 || text.back() == ',')
    throw Error(where +
                ": expected LAT,LON,H (degrees north, degrees east, metres), e.g. "
                "38.6247,-90.1848,147");
  double v[3];
  const char* names[3] = {"latitude", "longitude", "height"};
  for (int k = 0; k < 3; ++k) {
    if (!ParseDecimal(parts[k], &v[k]))
      throw Error(where + ": " + names[k] + " '" + parts[k] + "' is not a number");
  }
  const Site site{v[0], v[1], v[2]};
  CheckSite(site, where);
  return site;
}

}  // namespace rouen
