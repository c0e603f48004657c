// List files (exposure lists, import lists, image lists, environment-map lists): one entry
// per line, whitespace-separated words, '#' starts a comment, blank lines are skipped. What
// the words mean is up to each reader.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace rouen {

struct ListLine {
  std::vector<std::string> words;  // at least one
  std::string where;               // "<name>:<line>" (1-based) for messages
};

// Splits the text of a list file; `name` (the file) goes into each line's `where`. Words are
// separated by spaces, tabs, carriage returns, vertical tabs and form feeds; a leading UTF-8
// byte-order mark is not part of the first word.
std::vector<ListLine> ParseListText(std::string_view text, const std::string& name);

// The lines of the list file `path`. Throws rouen::Error naming it when it is a folder, cannot
// be read, or lists nothing.
std::vector<ListLine> ReadListFile(const std::string& path);

}  // namespace rouen
