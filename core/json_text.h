// JSON text for files people open: objects one member per line, indented, and every array of
// numbers (or of short arrays of numbers, such as RGB triples) on one line. A scene's maps and
// curves are then a few hundred lines instead of one line per number, and the text parses back
// to the same values (numbers as nlohmann::json writes them: shortest round trip).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

namespace rouen {

std::string JsonText(const nlohmann::json& j);

// A JSON file people write by hand, parsed: a key given twice in one object is refused (a
// contradiction, where the parser would keep the last), as is text that is not JSON. Throws
// rouen::Error "NAME: not valid JSON: ..." or "NAME: key "K" given twice in one object" (without
// "NAME: " when `name` is empty).
nlohmann::json ParseJsonText(std::string_view text, const std::string& name);

}  // namespace rouen
