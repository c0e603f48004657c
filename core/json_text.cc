#include "core/json_text.h"

#include <set>
#include <vector>

#include "core/error.h"

namespace rouen {
namespace {

bool Numbers(const nlohmann::json& a, size_t max_size) {
  if (!a.is_array() || a.size() > max_size) return false;
  for (const nlohmann::json& v : a)
    if (!v.is_number()) return false;
  return true;
}

// An array kept on one line: numbers, or arrays of at most four numbers each.
bool OneLine(const nlohmann::json& a) {
  if (!a.is_array() || a.empty()) return false;
  for (const nlohmann::json& v : a)
    if (!v.is_number() && !Numbers(v, 4)) return false;
  return true;
}

void Write(const nlohmann::json& j, int depth, std::string* out) {
  const std::string pad(depth + 1, ' '), close(depth, ' ');
  if (j.is_object() && !j.empty()) {
    *out += "{\n";
    size_t k = 0;
    for (const auto& [key, value] : j.items()) {
      *out += pad + nlohmann::json(key).dump() + ": ";
      Write(value, depth + 1, out);
      *out += ++k < j.size() ? ",\n" : "\n";
    }
    *out += close + "}";
  } else if (j.is_array() && !j.empty() && !OneLine(j)) {
    *out += "[\n";
    for (size_t k = 0; k < j.size(); ++k) {
      *out += pad;
      Write(j[k], depth + 1, out);
      *out += k + 1 < j.size() ? ",\n" : "\n";
    }
    *out += close + "]";
  } else {
    *out += j.dump();
  }
}

}  // namespace

std::string JsonText(const nlohmann::json& j) {
  std::string out;
  Write(j, 0, &out);
  return out + "\n";
}

nlohmann::json ParseJsonText(std::string_view text, const std::string& name) {
  const std::string prefix = name.empty() ? "" : name + ": ";
  std::vector<std::set<std::string>> keys;  // per open object
  const nlohmann::json::parser_callback_t check = [&](int, nlohmann::json::parse_event_t event,
                                                      nlohmann::json& parsed) {
    using E = nlohmann::json::parse_event_t;
    if (event == E::object_start) keys.emplace_back();
    if (event == E::object_end && !keys.empty()) keys.pop_back();
    if (event == E::key && !keys.empty() && !keys.back().insert(parsed.get<std::string>()).second)
      throw Error(prefix + "key " + parsed.dump() + " given twice in one object");
    return true;
  };
  try {
    return nlohmann::json::parse(text, check);
  } catch (const nlohmann::json::exception& e) {
    throw Error(prefix + "not valid JSON: " + e.what());
  }
}

int64_t JsonInteger(const nlohmann::json& v, int64_t lo, int64_t hi, const std::string& what) {
  const std::string is = (what.empty() ? "" : what + " is ") + v.dump();
  if (!v.is_number_integer()) throw Error(is + (what.empty() ? " is" : ",") + " not an integer");
  const bool in_range = v.is_number_unsigned()
                            ? hi >= 0 && v.get<uint64_t>() <= static_cast<uint64_t>(hi) &&
                                  (lo <= 0 || v.get<uint64_t>() >= static_cast<uint64_t>(lo))
                            : v.get<int64_t>() >= lo && v.get<int64_t>() <= hi;
  if (!in_range)
    throw Error(is + (what.empty() ? " is" : ",") + " outside " + std::to_string(lo) + ".." +
                std::to_string(hi));
  return v.is_number_unsigned() ? static_cast<int64_t>(v.get<uint64_t>()) : v.get<int64_t>();
}

}  // namespace rouen
