// Text files as users save them: a UTF-8 byte-order mark (Windows editors write one) is not
// part of the first line, and CRLF line ends are not part of the lines.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace rouen {

// `text` without a leading UTF-8 byte-order mark (EF BB BF).
std::string_view WithoutUtf8Bom(std::string_view text);

// The lines of `text`, without a byte-order mark and without '\n' or "\r\n" ends.
std::vector<std::string> TextLines(std::string_view text);

// The lines of a text file (TextLines).
// Throws rouen::Error "<path>: cannot open <what>" when the file cannot be read (or "is a
// folder, not <what>").
std::vector<std::string> ReadTextLines(const std::string& path, const std::string& what);

// `text` without the white space around it (spaces, tabs, carriage returns, line ends).
std::string Trimmed(std::string_view text);

// The comma-separated fields of one CSV line, each Trimmed (no quoting: rouen's CSV files hold
// numbers and names). An empty line is one empty field.
std::vector<std::string> CsvFields(std::string_view line);

// A decimal number as people write one, the whole of `text`: [+-] digits [. digits]
// [e|E [+-] digits] (".5" and "5." too), finite. False for anything else -- blanks around it,
// hexadecimal ("0x10", which std::stod reads as 16), "inf", "nan", "1,5", "1e400".
bool ParseDecimal(std::string_view text, double* value);

// printf-style formatting into a string (numbers in messages, names and tables).
std::string Formatted(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace rouen
