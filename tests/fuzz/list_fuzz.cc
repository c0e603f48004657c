// List files (core/list_file.h ParseListText: exposure, import, image and envmap lists) and
// the column parsers the commands apply to their words: ISO 8601 times, targets, UTC
// offsets. Words hold no whitespace or '#'; a time that parses prints and re-parses to the
// same instant.
#include <string>

#include "core/exif.h"
#include "core/list_file.h"
#include "core/session.h"
#include "core/time.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  const std::vector<ListLine> lines = ParseListText(fuzz::Text(data, size), "list.txt");
  int last = 0;
  for (const ListLine& l : lines) {
    FUZZ_CHECK(!l.words.empty(), "a listed line without words");
    FUZZ_CHECK(l.where.rfind("list.txt:", 0) == 0, l.where);
    const int line_no = std::stoi(l.where.substr(9));
    FUZZ_CHECK(line_no > last, "line numbers must increase: " + l.where);
    last = line_no;
    for (const std::string& w : l.words) {
      FUZZ_CHECK(!w.empty() && w.find_first_of(" \t\r\n\v\f#") == std::string::npos, w);
      UtcTime t;
      if (fuzz::Accepts([&] { t = ParseIso8601(w); })) {
        const std::string printed = t.Iso8601(9);
        UtcTime again;
        FUZZ_CHECK(fuzz::Accepts([&] { again = ParseIso8601(printed); }),
                   w + " printed as " + printed + " does not parse");
        FUZZ_CHECK(again == t, w + " printed as " + printed + " is another instant");
      }
      if (w.rfind("target=", 0) == 0) fuzz::Accepts([&] { ParseTarget(w.substr(7)); });
      int minutes = 0;
      if (fuzz::Accepts([&] { minutes = ParseUtcOffsetMinutes(w); }))
        FUZZ_CHECK(minutes >= -14 * 60 - 59 && minutes <= 14 * 60 + 59, w);
    }
  }
  return 0;
}
