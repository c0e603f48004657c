#include "core/json_text.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

// The text parses back to the same values, numbers to the bit; arrays of numbers and of RGB
// triples take one line each, objects and other arrays one line per member.
TEST(JsonText, ParsesBackAndKeepsNumberArraysOnOneLine) {
  std::vector<nlohmann::json> rgb;
  for (int k = 0; k < 500; ++k) rgb.push_back({0.1 * k, 1e-300 * k, -3.25e7 / (k + 1)});
  const nlohmann::json j = {
      {"name", "scene \"one\""},
      {"curve", {1, 2.5, -0.0, 1.0 / 3, 123456789012345LL}},
      {"radiance", rgb},
      {"regions", {{{"kind", 1}, {"normal", {0.0, 0.6, 0.8}}}, {{"kind", 0}}}},
      {"empty", nlohmann::json::array()},
      {"nothing", nlohmann::json::object()},
      {"flags", {true, false}},
  };
  const std::string text = JsonText(j);
  const nlohmann::json back = nlohmann::json::parse(text);
  EXPECT_EQ(back, j);
  EXPECT_EQ(back["radiance"][7][2].get<double>(), rgb[7][2].get<double>());
  // 7 members + braces; the regions list 2 objects of 2 and 1 member; the flags 2 lines.
  const auto lines = std::count(text.begin(), text.end(), '\n');
  EXPECT_LT(lines, 30) << text.substr(0, 400);
  EXPECT_NE(text.find("\"curve\": [1,2.5,-0.0,"), std::string::npos) << text.substr(0, 400);
  EXPECT_NE(text.find("\"normal\": [0.0,0.6,0.8]"), std::string::npos);
}

// A key given twice in one object is a contradiction: refused, naming the file and the key. The
// same key in different objects is not.
TEST(JsonTextTest, AKeyGivenTwiceInOneObjectIsRefused) {
  auto error_of = [](const std::string& text, const std::string& name) -> std::string {
    try {
      ParseJsonText(text, name);
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(error_of(R"({"model": "a.obj", "model": "b.obj"})", "s/session.json"),
            "s/session.json: key \"model\" given twice in one object");
  EXPECT_EQ(error_of(R"({"extra": {"slot": 1, "x": [{"slot": 2, "slot": 3}]}})", ""),
            "key \"slot\" given twice in one object");
  EXPECT_EQ(error_of(R"({"a": {"k": 1}, "b": {"k": 2}, "k": [{"k": 3}, {"k": 4}]})", "f"), "");
  EXPECT_EQ(ParseJsonText(R"({"a": {"k": 1}})", "f")["a"]["k"], 1);
  EXPECT_EQ(error_of("{\"a\": ", "f.json").rfind("f.json: not valid JSON: ", 0), 0u);
}

}  // namespace
}  // namespace rouen
