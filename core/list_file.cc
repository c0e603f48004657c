#include "core/list_file.h"

#include <filesystem>
#include <system_error>

#include "core/error.h"
#include "core/files.h"
#include "core/text.h"

namespace rouen {
namespace {

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f' || c == '\n';
}

}  // namespace

std::vector<ListLine> ParseListText(std::string_view text, const std::string& name) {
  text = WithoutUtf8Bom(text);
  std::vector<ListLine> out;
  int line_no = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    line = line.substr(0, line.find('#'));
    ListLine entry;
    size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && IsSpace(line[i])) ++i;
      size_t j = i;
      while (j < line.size() && !IsSpace(line[j])) ++j;
      if (j > i) entry.words.emplace_back(line.substr(i, j - i));
      i = j;
    }
    if (entry.words.empty()) continue;
    entry.where = name + ":" + std::to_string(line_no);
    out.push_back(std::move(entry));
  }
  return out;
}

std::vector<ListLine> ReadListFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw Error(path + ": is a folder, not a list file");
  if (!std::filesystem::is_regular_file(path, ec))
    throw Error(path + ": cannot open the list file");
  std::vector<ListLine> lines = ParseListText(ReadFileToString(path), path);
  if (lines.empty()) throw Error(path + ": lists nothing");
  return lines;
}

}  // namespace rouen
