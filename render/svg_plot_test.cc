#include "render/svg_plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <regex>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

int Count(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

TEST(SvgPlotTest, EscapesEveryMarkupCharacter) {
  EXPECT_EQ(EscapeXml("a<b>&\"c\"'d'"), "a&lt;b&gt;&amp;&quot;c&quot;&#39;d&#39;");
  EXPECT_EQ(EscapeXml("plain 12.5 °"), "plain 12.5 °");
  PlotSeries s;
  s.label = "<script>alert('x')</script>";
  s.x = {0, 1};
  s.y = {0, 1};
  PlotOptions o;
  o.title = "R&D <plot>";
  o.x.label = "x \"quoted\"";
  const SvgPlot p = PlotXY({s}, o);
  EXPECT_EQ(p.svg.find("<script"), std::string::npos);
  EXPECT_EQ(p.svg.find("<plot>"), std::string::npos);
  EXPECT_NE(p.svg.find("R&amp;D &lt;plot&gt;"), std::string::npos);
  EXPECT_NE(p.svg.find("&lt;script&gt;alert(&#39;x&#39;)"), std::string::npos);
  EXPECT_NE(p.svg.find("x &quot;quoted&quot;"), std::string::npos);
}

TEST(SvgPlotTest, TicksAreRoundAndCoverTheRange) {
  AxisTicks t = NiceTicks(0.3, 9.7);
  EXPECT_DOUBLE_EQ(t.lo, 0);
  EXPECT_DOUBLE_EQ(t.hi, 10);
  EXPECT_DOUBLE_EQ(t.step, 2);
  ASSERT_EQ(t.values.size(), 6u);
  EXPECT_DOUBLE_EQ(t.values.back(), 10);

  t = NiceTicks(-0.013, 0.047);
  EXPECT_LE(t.lo, -0.013);
  EXPECT_GE(t.hi, 0.047);
  EXPECT_NEAR(t.step, 0.02, 1e-12);  // 0.06 / 5 rounds up to 0.02
  for (double v : t.values) EXPECT_NEAR(v / t.step, std::round(v / t.step), 1e-9) << v;
  // A range exactly on ticks gains no extra step.
  t = NiceTicks(0, 200);
  EXPECT_DOUBLE_EQ(t.step, 50);
  EXPECT_DOUBLE_EQ(t.lo, 0);
  EXPECT_DOUBLE_EQ(t.hi, 200);
  // One value: a range around it.
  t = NiceTicks(5, 5);
  EXPECT_LT(t.lo, 5);
  EXPECT_GT(t.hi, 5);
  t = NiceTicks(0, 0);
  EXPECT_LT(t.lo, 0);
  EXPECT_GT(t.hi, 0);

  EXPECT_THROW(NiceTicks(kNan, 1), Error);
  EXPECT_THROW(NiceTicks(0, kInf), Error);
  EXPECT_THROW(NiceTicks(2, 1), Error);
}

TEST(SvgPlotTest, LogTicksAreDecades) {
  AxisTicks t = LogTicks(0.0009, 0.03);
  EXPECT_DOUBLE_EQ(t.lo, 1e-4);
  EXPECT_NEAR(t.hi, 0.1, 1e-15);
  EXPECT_TRUE(t.log);
  EXPECT_EQ(t.values.size(), 4u);  // 3 decades: decades only
  // Under 3 decades: 1, 2, 5 per decade.
  t = LogTicks(0.002, 0.03);
  EXPECT_EQ(t.values.size(), 7u);
  EXPECT_NEAR(t.values[1], 0.002, 1e-15);
  EXPECT_NEAR(t.values[2], 0.005, 1e-15);
  t = LogTicks(1e-4, 10);
  EXPECT_EQ(t.values.size(), 6u);  // decades only
  t = LogTicks(1, 1);              // one value: its decade
  EXPECT_DOUBLE_EQ(t.lo, 1);
  EXPECT_DOUBLE_EQ(t.hi, 10);
  EXPECT_THROW(LogTicks(0, 1), Error);
  EXPECT_THROW(LogTicks(-1, 1), Error);
  EXPECT_THROW(LogTicks(1, kNan), Error);
}

TEST(SvgPlotTest, TickLabelsHaveTheDigitsTheStepNeeds) {
  EXPECT_EQ(FormatTick(0.25, 0.05), "0.25");
  EXPECT_EQ(FormatTick(10, 2), "10");
  EXPECT_EQ(FormatTick(0.5, 0.1), "0.5");
  EXPECT_EQ(FormatTick(1e-5, 0), "1e-05");
  EXPECT_EQ(FormatTick(0, 0.01), "0.00");
}

TEST(SvgPlotTest, AxesCoverTheDataAndEverySeriesIsAGroup) {
  PlotSeries a, b;
  a.label = "a";
  a.x = {1, 2, 3};
  a.y = {10, 20, 35};
  b.label = "b";
  b.x = {0.5, 4};
  b.y = {-3, 12};
  b.style = SeriesStyle::kPoints;
  const SvgPlot p = PlotXY({a, b}, PlotOptions{});
  EXPECT_LE(p.x.lo, 0.5);
  EXPECT_GE(p.x.hi, 4);
  EXPECT_LE(p.y.lo, -3);
  EXPECT_GE(p.y.hi, 35);
  EXPECT_EQ(p.series, 2);
  EXPECT_EQ(p.points_drawn, 5);
  EXPECT_EQ(p.points_skipped, 0);
  EXPECT_EQ(Count(p.svg, "<g class=\"series\""), 2);
  EXPECT_EQ(Count(p.svg, "<circle"), 2 + 1);  // b's points and b's legend swatch
  EXPECT_EQ(p.svg.rfind("<svg", 0), 0u);
  EXPECT_EQ(p.svg.substr(p.svg.size() - 6), "</svg>");
}

TEST(SvgPlotTest, NonFinitePointsAreSkippedAndBreakTheLine) {
  PlotSeries s;
  s.label = "broken";
  s.x = {0, 1, 2, 3, 4};
  s.y = {1, kNan, 3, kInf, 5};
  const SvgPlot p = PlotXY({s}, PlotOptions{});
  EXPECT_EQ(p.points_drawn, 3);
  EXPECT_EQ(p.points_skipped, 2);
  // Three separate pieces: three "M" moves and no "L" joins across the gaps.
  const std::regex path("d=\"([^\"]*)\"");
  std::smatch found;
  ASSERT_TRUE(std::regex_search(p.svg, found, path));
  EXPECT_EQ(Count(found[1].str(), "M"), 3);
  EXPECT_EQ(Count(found[1].str(), "L"), 0);
  EXPECT_EQ(p.svg.find("nan"), std::string::npos);
  EXPECT_EQ(p.svg.find("inf"), std::string::npos);
}

TEST(SvgPlotTest, LogAxesSkipValuesThatAreNotPositive) {
  PlotSeries s;
  s.x = {1, 2, 3};
  s.y = {0.001, 0, -1};
  PlotOptions o;
  o.y.log = true;
  const SvgPlot p = PlotXY({s}, o);
  EXPECT_EQ(p.points_drawn, 1);
  EXPECT_EQ(p.points_skipped, 2);
  EXPECT_TRUE(p.y.log);
  EXPECT_LE(p.y.lo, 0.001);
}

TEST(SvgPlotTest, ForcedEndsAreKeptAndPointsBeyondThemSkipped) {
  PlotSeries s;
  s.x = {-10, 0, 100, 255, 300};
  s.y = {1, 2, 3, 4, 5};
  PlotOptions o;
  o.x.min = 0;
  o.x.max = 255;
  const SvgPlot p = PlotXY({s}, o);
  EXPECT_DOUBLE_EQ(p.x.lo, 0);
  EXPECT_DOUBLE_EQ(p.x.hi, 255);
  EXPECT_EQ(p.points_skipped, 2);
  for (double v : p.x.values) {
    EXPECT_GE(v, 0);
    EXPECT_LE(v, 255);
  }
  o.x.min = 10;
  o.x.max = 5;
  EXPECT_THROW(PlotXY({s}, o), Error);
}

TEST(SvgPlotTest, NoDataIsSaidNotDrawn) {
  const SvgPlot none = PlotXY({}, PlotOptions{});
  EXPECT_NE(none.svg.find("no data"), std::string::npos);
  EXPECT_EQ(none.series, 0);
  EXPECT_DOUBLE_EQ(none.x.lo, 0);
  EXPECT_DOUBLE_EQ(none.x.hi, 1);
  PlotSeries s;
  s.label = "all NaN";
  s.x = {kNan, 1};
  s.y = {1, kNan};
  const SvgPlot nan = PlotXY({s}, PlotOptions{});
  EXPECT_NE(nan.svg.find("no data"), std::string::npos);
  EXPECT_EQ(nan.points_drawn, 0);
  EXPECT_EQ(Count(nan.svg, "data-empty=\"1\""), 1);
  EXPECT_EQ(nan.svg.find("<path"), std::string::npos);
}

TEST(SvgPlotTest, BadInputIsRefused) {
  PlotSeries s;
  s.label = "uneven";
  s.x = {1, 2, 3};
  s.y = {1, 2};
  try {
    PlotXY({s}, PlotOptions{});
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("uneven"), std::string::npos) << e.what();
  }
  PlotOptions tiny;
  tiny.width = 10;
  EXPECT_THROW(PlotXY({}, tiny), Error);
  EXPECT_THROW(PlotBars({"a", "b"}, {1}, BarOptions{}), Error);
  PolarSeries ps;
  ps.azimuth_deg = {1, 2};
  ps.elevation_deg = {1};
  EXPECT_THROW(PlotPolarSky({ps}, PolarOptions{}), Error);
  ps.elevation_deg = {1, 2};
  ps.point_labels = {"only one"};
  EXPECT_THROW(PlotPolarSky({ps}, PolarOptions{}), Error);
}

TEST(SvgPlotTest, BarsSkipValuesTheyCannotDraw) {
  BarOptions o;
  o.title = "stages";
  const SvgPlot p = PlotBars({"a", "b & c", "d"}, {2.5, kNan, -1}, o);
  EXPECT_EQ(p.points_drawn, 1);
  EXPECT_EQ(p.points_skipped, 2);
  EXPECT_EQ(Count(p.svg, "<rect"), 1);
  EXPECT_EQ(Count(p.svg, "n/a"), 2);
  EXPECT_NE(p.svg.find("b &amp; c"), std::string::npos);
  EXPECT_GE(p.x.hi, 2.5);
  EXPECT_EQ(p.series, 1);
}

// The centre of the chart: the zenith; the horizon ring: elevation 0; north up, east right.
TEST(SvgPlotTest, SkyChartPutsTheZenithAtTheCentreAndNorthUp) {
  PolarOptions o;
  o.size = 400;
  o.legend = false;
  PolarSeries s;
  s.label = "points";
  s.style = SeriesStyle::kPoints;
  s.azimuth_deg = {0, 0, 90, 45, 10};
  s.elevation_deg = {90, 0, 0, -5, kNan};
  s.point_labels = {"zenith", "north", "east", "below", "nan"};
  const SvgPlot p = PlotPolarSky({s}, o);
  EXPECT_EQ(p.points_drawn, 3);
  EXPECT_EQ(p.points_skipped, 2);
  EXPECT_EQ(p.svg.find("below"), std::string::npos);
  std::vector<std::pair<double, double>> dots;
  const std::regex circle("<circle cx=\"([-0-9.]+)\" cy=\"([-0-9.]+)\" r=\"4\"/>");
  for (auto it = std::sregex_iterator(p.svg.begin(), p.svg.end(), circle);
       it != std::sregex_iterator(); ++it)
    dots.emplace_back(std::stod((*it)[1]), std::stod((*it)[2]));
  ASSERT_EQ(dots.size(), 3u);
  const double cx = 200, cy = 8 + 200, R = 200 - 24;
  EXPECT_NEAR(dots[0].first, cx, 0.06);
  EXPECT_NEAR(dots[0].second, cy, 0.06);
  EXPECT_NEAR(dots[1].first, cx, 0.06);  // north: straight up, on the horizon ring
  EXPECT_NEAR(dots[1].second, cy - R, 0.06);
  EXPECT_NEAR(dots[2].first, cx + R, 0.06);  // east: right
  EXPECT_NEAR(dots[2].second, cy, 0.06);
}

}  // namespace
}  // namespace rouen
