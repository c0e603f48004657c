// JSON text for files people open: objects one member per line, indented, and every array of
// numbers (or of short arrays of numbers, such as RGB triples) on one line. A scene's maps and
// curves are then a few hundred lines instead of one line per number, and the text parses back
// to the same values (numbers as nlohmann::json writes them: shortest round trip).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace rouen {

std::string JsonText(const nlohmann::json& j);

}  // namespace rouen
