#include "app/options.h"

#include <cmath>
#include <optional>

#include "core/limits.h"

namespace rouen {
namespace {

// The number in `text` as CLI11 converts it (NaN and infinities included), if it is one.
std::optional<double> Number(const std::string& text) {
  double v = 0;
  if (!CLI::detail::lexical_cast(text, v)) return std::nullopt;
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

}  // namespace rouen
