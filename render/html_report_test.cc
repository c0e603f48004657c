#include "render/html_report.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <regex>
#include <string>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "render/svg_plot.h"

namespace rouen {
namespace {

std::string DecodeBase64(const std::string& in) {
  const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  int bits = 0, value = 0;
  for (char c : in) {
    const size_t d = alphabet.find(c);
    if (d == std::string::npos) continue;
    value = (value << 6) | static_cast<int>(d);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<char>((value >> bits) & 0xff));
    }
  }
  return out;
}

TEST(HtmlReportTest, Base64MatchesRfc4648) {
  EXPECT_EQ(Base64(""), "");
  EXPECT_EQ(Base64("f"), "Zg==");
  EXPECT_EQ(Base64("fo"), "Zm8=");
  EXPECT_EQ(Base64("foo"), "Zm9v");
  EXPECT_EQ(Base64("foob"), "Zm9vYg==");
  EXPECT_EQ(Base64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(Base64("foobar"), "Zm9vYmFy");
  const std::string bytes("\x00\xff\x80\x7f", 4);
  EXPECT_EQ(DecodeBase64(Base64(bytes)), bytes);
}

TEST(HtmlReportTest, TextIsEscapedAndSectionsAreListed) {
  HtmlReport r("Title <1>", "sub & title");
  r.BeginSection("first", "First & <best>");
  r.Paragraph("<b>bold</b> & \"quoted\"");
  r.Absent("no <data>");
  r.Table({"key", "value"}, {{"<k>", "v&"}}, "caption <c>");
  r.BeginSection("second-2", "Second");
  r.Heading("h<3>");
  const std::string html = r.Finish();
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  for (const char* raw : {"<1>", "<best>", "<b>bold", "<data>", "<k>", "<c>", "<3>"})
    EXPECT_EQ(html.find(raw), std::string::npos) << raw;
  for (const char* escaped : {"Title &lt;1&gt;", "sub &amp; title", "First &amp; &lt;best&gt;",
                              "&lt;b&gt;bold&lt;/b&gt; &amp; &quot;quoted&quot;",
                              "<p class=\"absent\">no &lt;data&gt;</p>", "<td>&lt;k&gt;</td>",
                              "<td>v&amp;</td>", "h&lt;3&gt;"})
    EXPECT_NE(html.find(escaped), std::string::npos) << escaped;
  EXPECT_NE(html.find("<a href=\"#first\">"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"#second-2\">"), std::string::npos);
  EXPECT_NE(html.find("<section id=\"first\">"), std::string::npos);
  EXPECT_LT(html.find("<section id=\"first\">"), html.find("<section id=\"second-2\">"));
  // Nothing to fetch: no script, no style sheet or image from elsewhere.
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(html.find("<link"), std::string::npos);
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
}

TEST(HtmlReportTest, NumbersAreRightAlignedAndAnEmptyHeaderIsLeftOut) {
  HtmlReport r("t", "s");
  r.BeginSection("t", "Table");
  r.Table({"", ""}, {{"pi", "3.14"}, {"range", "1 - 2"}, {"big", "1e+07"}});
  const std::string html = r.Finish();
  EXPECT_EQ(html.find("<th>"), std::string::npos);
  EXPECT_NE(html.find("<td class=\"n\">3.14</td>"), std::string::npos);
  EXPECT_NE(html.find("<td class=\"n\">1e+07</td>"), std::string::npos);
  EXPECT_NE(html.find("<td>1 - 2</td>"), std::string::npos);
  EXPECT_NE(html.find("<td>pi</td>"), std::string::npos);
}

// Rows left open by a section that stopped half-way are closed with it.
TEST(HtmlReportTest, OpenRowsAreClosedWithTheirSection) {
  HtmlReport r("t", "s");
  r.BeginSection("a", "A");
  r.BeginRow();
  r.Paragraph("half-way");
  r.BeginSection("b", "B");
  EXPECT_THROW(r.EndRow(), Error);
  const std::string html = r.Finish();
  const size_t a = html.find("<section id=\"a\">"), b = html.find("<section id=\"b\">");
  const std::string first = html.substr(a, b - a);
  EXPECT_NE(first.find("<div class=\"row\">"), std::string::npos);
  EXPECT_NE(first.find("</div>\n</section>"), std::string::npos);
}

TEST(HtmlReportTest, RefusesWhatWouldMakeABrokenPage) {
  HtmlReport r("t", "s");
  EXPECT_THROW(r.Paragraph("before any section"), Error);
  EXPECT_THROW(r.BeginSection("Has Space", "x"), Error);
  EXPECT_THROW(r.BeginSection("", "x"), Error);
  r.BeginSection("a", "A");
  EXPECT_THROW(r.BeginSection("a", "again"), Error);
  EXPECT_THROW(r.Table({"one", "two"}, {{"only one"}}), Error);
  EXPECT_THROW(r.Picture(Image(2, 2, 4, PixelUnits::kDigital), "four channels"), Error);
}

TEST(HtmlReportTest, PicturesAreInlinedPngsOfTheirSize) {
  HtmlReport r("t", "s");
  r.BeginSection("pics", "Pictures");
  Image img(7, 5, 3, PixelUnits::kDigital, 0.f);
  img.at(3, 2, 0) = 255;
  r.Picture(img, "a <red> dot", 70, true);
  r.Svg(PlotXY({}, PlotOptions{}).svg, "an empty plot");
  EXPECT_EQ(r.images(), 1);
  EXPECT_EQ(r.plots(), 1);
  const std::string html = r.Finish();
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      html, m,
      std::regex("<img src=\"data:image/png;base64,([A-Za-z0-9+/=]+)\" width=\"70\" "
                 "height=\"50\" alt=\"a &lt;red&gt; dot\" class=\"pixelated\">")));
  const std::string png = DecodeBase64(m[1].str());
  ASSERT_GE(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  const auto file = std::filesystem::temp_directory_path() /
                    ("rouen_html_report_test_" + std::to_string(::getpid()) + ".png");
  WriteFileAtomic(file, png);
  const Image back = ReadImage(file.string());
  std::filesystem::remove(file);
  EXPECT_EQ(back.width, 7);
  EXPECT_EQ(back.height, 5);
  EXPECT_FLOAT_EQ(back.at(3, 2, 0), 255.f);
  EXPECT_FLOAT_EQ(back.at(3, 2, 1), 0.f);
  EXPECT_NE(html.find("<figcaption>an empty plot</figcaption>"), std::string::npos);
}

// Pictures are encoded when the page is finished, each where it was placed; text cannot pose
// as one (the control character that marks them is dropped from text).
TEST(HtmlReportTest, ManyPicturesEachInItsPlace) {
  HtmlReport r("t", "s");
  r.BeginSection("one", "One");
  r.Picture(Image(3, 2, 3, PixelUnits::kDigital, 10.f), "first");
  r.Paragraph("not a \x1Fpicture:0\x1F picture");
  r.Picture(Image(5, 4, 1, PixelUnits::kDigital, 20.f), "second");
  r.BeginSection("two", "Two");
  r.Picture(Image(9, 6, 3, PixelUnits::kDigital, 30.f), "third");
  const std::string html = r.Finish();
  EXPECT_NE(html.find("<p>not a picture:0 picture</p>"), std::string::npos);
  const std::regex img("<img src=\"data:image/png;base64,([A-Za-z0-9+/=]+)\" width=\"(\\d+)\"");
  std::vector<std::pair<int, int>> sizes;
  for (auto it = std::sregex_iterator(html.begin(), html.end(), img); it != std::sregex_iterator();
       ++it) {
    const auto file = std::filesystem::temp_directory_path() /
                      ("rouen_html_report_many_" + std::to_string(::getpid()) + ".png");
    WriteFileAtomic(file, DecodeBase64((*it)[1].str()));
    const Image back = ReadImage(file.string());
    std::filesystem::remove(file);
    EXPECT_EQ(std::to_string(back.width), (*it)[2].str());
    sizes.push_back({back.width, back.height});
  }
  EXPECT_EQ(sizes, (std::vector<std::pair<int, int>>{{3, 2}, {5, 4}, {9, 6}}));
}

}  // namespace
}  // namespace rouen
