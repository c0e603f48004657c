#include "render/html_report.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/error.h"
#include "render/svg_plot.h"

namespace rouen {

namespace {

// Where Picture leaves an image's data URI to Finish: this, its index, then '\x1F' (no text the
// page escapes holds that control character).
constexpr const char* kPictureMarker = "\x1Fpicture:";

constexpr const char* kStyle = R"(
body { font-family: sans-serif; margin: 0 auto; max-width: 1240px; padding: 0 20px 40px;
  color: #222; background: #fff; line-height: 1.4; }
h1 { margin-bottom: 4px; } .subtitle { color: #555; margin-top: 0; }
nav ul { columns: 3; padding-left: 20px; }
section { border-top: 1px solid #ccc; margin-top: 24px; }
h2 { margin-bottom: 6px; } h3 { margin: 14px 0 6px; font-size: 1.05em; }
p.absent { background: #fff6e0; border-left: 4px solid #e0a000; padding: 6px 10px; }
table { border-collapse: collapse; margin: 6px 0 10px; font-size: 0.9em; }
th, td { border: 1px solid #ddd; padding: 2px 8px; text-align: left; }
th { background: #f2f2f2; } td.n { text-align: right; font-variant-numeric: tabular-nums; }
caption { caption-side: bottom; color: #555; font-size: 0.9em; text-align: left; padding-top: 3px; }
figure { margin: 6px 12px 10px 0; display: inline-block; vertical-align: top; }
figcaption { color: #555; font-size: 0.85em; max-width: 560px; }
.row { display: flex; flex-wrap: wrap; align-items: flex-start; }
img.pixelated { image-rendering: pixelated; }
svg.plot { background: #fff; }
)";

// A cell that is one number (right-aligned in its column).
bool IsNumber(const std::string& text) {
  if (text.empty()) return false;
  char* end = nullptr;
  std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size();
}

bool ValidId(const std::string& id) {
  if (id.empty()) return false;
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-';
  });
}

}  // namespace

std::string Base64(std::string_view bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) |
                       (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                       static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < bytes.size()) {
    unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

HtmlReport::HtmlReport(std::string title, std::string subtitle)
    : title_(std::move(title)), subtitle_(std::move(subtitle)) {}

std::string& HtmlReport::Body() {
  if (sections_.empty()) throw Error("HTML report: content before the first section");
  return sections_.back().body;
}

void HtmlReport::BeginSection(const std::string& id, const std::string& title) {
  if (!ValidId(id)) throw Error("HTML report: section id '" + id + "' is not [a-z0-9-]+");
  for (const Section& s : sections_)
    if (s.id == id) throw Error("HTML report: two sections have the id '" + id + "'");
  sections_.push_back({id, title, "", 0});
}

void HtmlReport::Heading(const std::string& text) {
  Body() += "<h3>" + EscapeXml(text) + "</h3>\n";
}

void HtmlReport::Paragraph(const std::string& text) {
  Body() += "<p>" + EscapeXml(text) + "</p>\n";
}

void HtmlReport::Absent(const std::string& text) {
  Body() += "<p class=\"absent\">" + EscapeXml(text) + "</p>\n";
}

void HtmlReport::Svg(const std::string& svg, const std::string& caption) {
  std::string& b = Body();
  b += "<figure>" + svg;
  if (!caption.empty()) b += "<figcaption>" + EscapeXml(caption) + "</figcaption>";
  b += "</figure>\n";
  ++plots_;
}

void HtmlReport::Table(const std::vector<std::string>& header,
                       const std::vector<std::vector<std::string>>& rows,
                       const std::string& caption) {
  std::string t = "<table>";
  if (!caption.empty()) t += "<caption>" + EscapeXml(caption) + "</caption>";
  // A header of empty cells is no header (a table of names and values).
  if (std::any_of(header.begin(), header.end(), [](const std::string& h) { return !h.empty(); })) {
    t += "<tr>";
    for (const std::string& h : header) t += "<th>" + EscapeXml(h) + "</th>";
    t += "</tr>";
  }
  for (const auto& row : rows) {
    if (row.size() != header.size())
      throw Error("HTML report: a table row has " + std::to_string(row.size()) +
                  " cells under a header of " + std::to_string(header.size()));
    t += "<tr>";
    for (const std::string& c : row)
      t += (IsNumber(c) ? "<td class=\"n\">" : "<td>") + EscapeXml(c) + "</td>";
    t += "</tr>";
  }
  Body() += t + "</table>\n";
}

void HtmlReport::Picture(const Image& image, const std::string& caption, int display_width,
                         bool pixelated) {
  if (image.channels != 1 && image.channels != 3)
    throw Error("HTML report: an image of " + std::to_string(image.channels) + " channels");
  const int w = display_width > 0 ? display_width : image.width;
  const int h = static_cast<int>(std::lround(static_cast<double>(image.height) * w / image.width));
  std::string& b = Body();
  // The PNG comes in Finish, in place of the marker.
  b += "<figure><img src=\"" + std::string(kPictureMarker) + std::to_string(pictures_.size()) +
       "\x1F\" width=\"" + std::to_string(w) + "\" height=\"" + std::to_string(h) + "\" alt=\"" +
       EscapeXml(caption) + "\"" + (pixelated ? " class=\"pixelated\"" : "") + ">";
  if (!caption.empty()) b += "<figcaption>" + EscapeXml(caption) + "</figcaption>";
  b += "</figure>\n";
  pictures_.push_back(image);
  ++images_;
}

void HtmlReport::BeginRow() {
  Body() += "<div class=\"row\">\n";
  ++sections_.back().open_rows;
}
void HtmlReport::EndRow() {
  if (sections_.empty() || sections_.back().open_rows == 0)
    throw Error("HTML report: EndRow without BeginRow");
  Body() += "</div>\n";
  --sections_.back().open_rows;
}

std::string HtmlReport::Finish() const {
  std::vector<std::string> data(pictures_.size());
  tbb::parallel_for(size_t{0}, pictures_.size(), [&](size_t k) {
    data[k] = "data:image/png;base64," +
              Base64(EncodeImage("image.png", pictures_[k], StoredType::kUint8));
  });
  // A section's body with each picture's marker replaced by its PNG.
  const auto with_pictures = [&](const std::string& body) {
    std::string out;
    size_t from = 0;
    for (size_t at; (at = body.find(kPictureMarker, from)) != std::string::npos;) {
      const size_t num = at + std::strlen(kPictureMarker), end = body.find('\x1F', num);
      out.append(body, from, at - from);
      out += data.at(std::stoul(body.substr(num, end - num)));
      from = end + 1;
    }
    return out.append(body, from, std::string::npos);
  };
  std::string h =
      "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
      "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>" +
      EscapeXml(title_) + "</title>\n<style>" + kStyle + "</style>\n</head>\n<body>\n<h1>" +
      EscapeXml(title_) + "</h1>\n<p class=\"subtitle\">" + EscapeXml(subtitle_) +
      "</p>\n<nav><ul>\n";
  for (const Section& s : sections_)
    h += "<li><a href=\"#" + s.id + "\">" + EscapeXml(s.title) + "</a></li>\n";
  h += "</ul></nav>\n";
  for (const Section& s : sections_) {
    h += "<section id=\"" + s.id + "\">\n<h2>" + EscapeXml(s.title) + "</h2>\n" +
         with_pictures(s.body);
    for (int i = 0; i < s.open_rows; ++i) h += "</div>\n";
    h += "</section>\n";
  }
  return h + "</body>\n</html>\n";
}

}  // namespace rouen
