// JSON text for files people open: objects one member per line, indented, and every array of
// numbers (or of short arrays of numbers, such as RGB triples) on one line. A scene's maps and
// curves are then a few hundred lines instead of one line per number, and the text parses back
// to the same values (numbers as nlohmann::json writes them: shortest round trip).
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/error.h"

namespace rouen {

std::string JsonText(const nlohmann::json& j);

// A JSON file people write by hand, parsed: a key given twice in one object is refused (a
// contradiction, where the parser would keep the last), as is text that is not JSON. Throws
// rouen::Error "NAME: not valid JSON: ..." or "NAME: key "K" given twice in one object" (without
// "NAME: " when `name` is empty).
nlohmann::json ParseJsonText(std::string_view text, const std::string& name);

// A JSON integer within [lo, hi]; a number with a fraction (2.5), a float (1e36) or an integer
// outside the range is refused, where nlohmann's get<int>() would truncate, wrap or overflow.
// Throws rouen::Error "WHAT is VALUE, not an integer" or "WHAT is VALUE, outside LO..HI" ("VALUE
// is ..." when `what` is empty).
int64_t JsonInteger(const nlohmann::json& v, int64_t lo, int64_t hi, const std::string& what = "");

namespace internal {
template <typename T>
struct IsVector : std::false_type {};
template <typename T, typename A>
struct IsVector<std::vector<T, A>> : std::true_type {};
}  // namespace internal

// A value of a JSON file as T, refused by rouen::Error where get<T>() would not be exact: an
// integer type takes JsonInteger in its range (at most int64's), a float a number within the
// float's range, a std::vector<T> each element so; other types as get<T>().
template <typename T>
T JsonGet(const nlohmann::json& v, const std::string& what = "") {
  if constexpr (std::is_same_v<T, bool>) {
    return v.get<bool>();
  } else if constexpr (std::is_integral_v<T>) {
    constexpr int64_t lo = static_cast<int64_t>(std::numeric_limits<T>::min());
    constexpr int64_t hi = std::numeric_limits<T>::max() > static_cast<uint64_t>(INT64_MAX)
                               ? INT64_MAX
                               : static_cast<int64_t>(std::numeric_limits<T>::max());
    return static_cast<T>(JsonInteger(v, lo, hi, what));
  } else if constexpr (std::is_same_v<T, float>) {
    const double d = v.get<double>();
    if (!(std::abs(d) <= std::numeric_limits<float>::max()))
      throw Error((what.empty() ? "" : what + " is ") + v.dump() + ", not a number a float holds");
    return static_cast<float>(d);
  } else if constexpr (internal::IsVector<T>::value) {
    if (!v.is_array())
      throw Error((what.empty() ? "" : what + " is ") + v.dump() + ", not an array");
    T out;
    for (const nlohmann::json& e : v) out.push_back(JsonGet<typename T::value_type>(e, what));
    return out;
  } else {
    return v.get<T>();
  }
}

}  // namespace rouen
