#include "core/text.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"

namespace rouen {
namespace {

TEST(TextTest, ByteOrderMarkAndCrlfAreNotPartOfTheLines) {
  EXPECT_EQ(WithoutUtf8Bom("\xEF\xBB\xBFutc,lat"), "utc,lat");
  EXPECT_EQ(WithoutUtf8Bom("utc,lat"), "utc,lat");
  EXPECT_EQ(WithoutUtf8Bom("\xEF\xBB"), "\xEF\xBB");
  const std::filesystem::path p = std::filesystem::temp_directory_path() /
                                  ("rouen_text_" + std::to_string(::getpid()) + ".csv");
  std::ofstream(p, std::ios::binary) << "\xEF\xBB\xBFutc,lat\r\n\r\nlast";
  EXPECT_EQ(ReadTextLines(p.string(), "CSV file"),
            (std::vector<std::string>{"utc,lat", "", "last"}));
  std::filesystem::remove(p);
  try {
    ReadTextLines(p.string(), "CSV file");
    FAIL() << "read a missing file";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), p.string() + ": cannot open CSV file");
  }
  const std::string dir = std::filesystem::temp_directory_path().string();
  try {
    ReadTextLines(dir, "a list file");
    FAIL() << "read a folder";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), dir + ": is a folder, not a list file");
  }
  // A device never ends (sun --batch /dev/zero died of std::bad_alloc).
  try {
    ReadTextLines("/dev/zero", "the CSV file");
    FAIL() << "read a device";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), "/dev/zero: is a device, not the CSV file");
  }
}

TEST(TextTest, FormattedIsPrintfIntoAStringOfAnyLength) {
  EXPECT_EQ(Formatted("%05.1f|%s|%d|%c", 3.14159, "ab", 42, 'x'), "003.1|ab|42|x");
  EXPECT_EQ(Formatted("%s", ""), "");
  const std::string long_text(1000, 'q');
  EXPECT_EQ(Formatted("<%s>", long_text.c_str()), "<" + long_text + ">");
}

// What people write as a number reads as it; what std::stod would also take but nobody means
// is refused (found by the second hostile probe: --step 0x10 rendered a frame every 16 s).
TEST(TextTest, ParseDecimalReadsDecimalsOnly) {
  double v = -1;
  for (const auto& [text, want] : std::vector<std::pair<std::string, double>>{
           {"15", 15}, {"-2.5", -2.5}, {"+.5", 0.5}, {"5.", 5}, {"1e-3", 1e-3}, {"2E+2", 200}}) {
    EXPECT_TRUE(ParseDecimal(text, &v)) << text;
    EXPECT_EQ(v, want) << text;
  }
  for (const char* text : {"", "-", ".", "e5", "1e", "1e+", "0x10", "0x1p-3", "inf", "nan", " 1",
                           "1 ", "1,5", "1.2.3", "1e400", "--1", "1/250"}) {
    v = 7;
    EXPECT_FALSE(ParseDecimal(text, &v)) << text;
    EXPECT_EQ(v, 7) << text;  // untouched when refused
  }
}

}  // namespace
}  // namespace rouen
