// One self-contained HTML page (`rouen report`): sections with text, tables, SVG plots
// (render/svg_plot.h) and images inlined as PNG data URIs; its style sheet is inline, it has no
// script and loads nothing from the network. Every text given is escaped.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "core/image.h"

namespace rouen {

// RFC 4648 base64 (with padding).
std::string Base64(std::string_view bytes);

class HtmlReport {
 public:
  // `title`: the page's title and first heading; `subtitle`: a line under it.
  HtmlReport(std::string title, std::string subtitle);

  // Starts a section (closing the one before): <section id="ID"><h2>TITLE</h2>. `id` is
  // lower-case letters, digits and '-', unique in the page (throws rouen::Error otherwise).
  void BeginSection(const std::string& id, const std::string& title);
  void Heading(const std::string& text);  // <h3>
  void Paragraph(const std::string& text);
  // A paragraph saying what is not shown and why (class "absent": set apart in the page).
  void Absent(const std::string& text);
  // A figure around an SVG plot (PlotXY, PlotBars, PlotPolarSky: trusted markup).
  void Svg(const std::string& svg, const std::string& caption = "");
  // Rows of cells under a header; every row as long as the header (throws rouen::Error).
  void Table(const std::vector<std::string>& header,
             const std::vector<std::vector<std::string>>& rows, const std::string& caption = "");
  // An 8-bit image (kDigital, 1 or 3 channels, 0..255) inlined as a PNG: shown `display_width`
  // CSS pixels wide (0: its own width), scaled without smoothing when `pixelated`.
  void Picture(const Image& image, const std::string& caption, int display_width = 0,
               bool pixelated = false);
  // Figures between these two sit side by side, wrapping.
  void BeginRow();
  void EndRow();

  // The page: head with the style sheet, a contents list of the sections, the sections.
  std::string Finish() const;

  int images() const { return images_; }
  int plots() const { return plots_; }

 private:
  struct Section {
    std::string id, title, body;
    int open_rows = 0;  // closed by Finish if a section ended inside a row
  };
  std::string& Body();
  std::string title_, subtitle_;
  std::vector<Section> sections_;
  // Picture's images, encoded by Finish all at once (in parallel) where their markers stand.
  std::vector<Image> pictures_;
  int images_ = 0, plots_ = 0;
};

}  // namespace rouen
