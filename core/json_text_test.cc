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

// An integer read from a file is the integer written, or refused: never truncated (2.5 -> 2),
// wrapped (4294967297 -> 1, 2^64 - 1 -> -1) or converted out of range (1e36, undefined
// behaviour in get<int>(); found by the scene reader's fuzzer in an environment map's bands).
TEST(JsonTextTest, IntegersAreReadExactlyOrRefused) {
  using nlohmann::json;
  EXPECT_EQ(JsonGet<int>(json::parse("-7")), -7);
  EXPECT_EQ(JsonGet<size_t>(json::parse("9007199254740993")), 9007199254740993u);
  EXPECT_EQ(JsonInteger(json::parse("3"), 1, 5, "n"), 3);
  const auto error_of = [](const char* text, auto read) {
    try {
      read(json::parse(text));
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const auto as_int = [](const json& v) { return JsonGet<int>(v, "bands"); };
  EXPECT_EQ(error_of("1e36", as_int), "bands is 1e+36, not an integer");
  EXPECT_EQ(error_of("2.5", as_int), "bands is 2.5, not an integer");
  EXPECT_EQ(error_of("\"9\"", as_int), "bands is \"9\", not an integer");
  EXPECT_EQ(error_of("4294967297", as_int), "bands is 4294967297, outside -2147483648..2147483647");
  EXPECT_EQ(error_of("18446744073709551615", [](const json& v) { return JsonGet<int64_t>(v); }),
            "18446744073709551615 is outside -9223372036854775808..9223372036854775807");
  // An unsigned value below a positive lower bound (nlohmann keeps 0 as unsigned).
  EXPECT_EQ(error_of("0", [](const json& v) { return JsonInteger(v, 1, 5, "slot"); }),
            "slot is 0, outside 1..5");
  EXPECT_EQ(error_of("-1", [](const json& v) { return JsonGet<uint8_t>(v, "flag"); }),
            "flag is -1, outside 0..255");
  // A float past a float's range, and vectors element by element.
  EXPECT_EQ(error_of("1e39", [](const json& v) { return JsonGet<float>(v, "cell"); }),
            "cell is 1e+39, not a number a float holds");
  EXPECT_EQ(JsonGet<float>(json::parse("0.5")), 0.5f);
  EXPECT_EQ(JsonGet<std::vector<int>>(json::parse("[1, 2]")), (std::vector<int>{1, 2}));
  EXPECT_EQ(error_of("[1, 2.5]", [](const json& v) { return JsonGet<std::vector<int>>(v, "ids"); }),
            "ids is 2.5, not an integer");
  EXPECT_EQ(error_of("{}", [](const json& v) { return JsonGet<std::vector<int>>(v, "ids"); }),
            "ids is {}, not an array");
}

}  // namespace
}  // namespace rouen
