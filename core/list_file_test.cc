#include "core/list_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

TEST(ListFileTest, WordsCommentsBlankLinesAndLineNumbers) {
  const std::string text =
      "# exposures\n"
      "a.jpg 0.01\n"
      "\n"
      "  b.jpg\t0.02   # brighter\r\n"
      "\t \r\n"
      "#c.jpg 1\n"
      "c d.jpg 2020-06-21T10:00:00Z group=x";  // no final newline
  const std::vector<ListLine> lines = ParseListText(text, "list.txt");
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0].words, (std::vector<std::string>{"a.jpg", "0.01"}));
  EXPECT_EQ(lines[0].where, "list.txt:2");
  EXPECT_EQ(lines[1].words, (std::vector<std::string>{"b.jpg", "0.02"}));
  EXPECT_EQ(lines[1].where, "list.txt:4");
  EXPECT_EQ(lines[2].words.size(), 4u);
  EXPECT_EQ(lines[2].where, "list.txt:7");
}

TEST(ListFileTest, EmptyAndCommentOnlyTextsListNothing) {
  EXPECT_TRUE(ParseListText("", "l").empty());
  EXPECT_TRUE(ParseListText("\n\n# nothing\n   \n", "l").empty());
  // A NUL byte is part of a word, as it was for the stream-based reader.
  const std::vector<ListLine> lines = ParseListText(std::string_view("a\0b c", 5), "l");
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].words[0], std::string("a\0b", 3));
}

TEST(ListFileTest, ReadListFileNamesTheFileItCannotUse) {
  namespace fs = std::filesystem;
  const fs::path d = fs::temp_directory_path() / ("rouen_list_" + std::to_string(::getpid()));
  fs::create_directories(d);
  WriteFileAtomic(d / "a.txt", "# photos\nimg.jpg 1/250\n");
  const std::vector<ListLine> lines = ReadListFile((d / "a.txt").string());
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].where, (d / "a.txt").string() + ":2");
  WriteFileAtomic(d / "empty.txt", "# nothing\n");
  for (const fs::path& bad : {d / "empty.txt", d / "missing.txt", d}) {
    try {
      ReadListFile(bad.string());
      ADD_FAILURE() << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(bad.string()), std::string::npos) << e.what();
    }
  }
  fs::remove_all(d);
}

}  // namespace
}  // namespace rouen
