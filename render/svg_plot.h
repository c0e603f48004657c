// SVG plots drawn by rouen for its HTML report (render/html_report.h): line and scatter plots
// with axes, ticks, labels and a legend; horizontal bars; a polar sky chart (azimuth from north
// eastward, elevation from the horizon ring to the zenith at the centre). Plain SVG text, no
// scripts and no external fonts; every text is escaped. Each series is one <g class="series">
// (drawn even when it has no point, marked data-empty="1"), so a reader can count them.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace rouen {

// `text` with & < > " ' replaced by entities and the control characters XML forbids (all below
// 0x20 but tab, LF and CR) dropped: safe in HTML and SVG text and attribute values.
std::string EscapeXml(std::string_view text);

// An axis's range and its ticks at round values (1, 2 or 5 x 10^k apart; decades on a log axis).
struct AxisTicks {
  double lo = 0, hi = 1;       // the range drawn: covers the data, ends on ticks
  std::vector<double> values;  // tick positions, increasing, within [lo, hi]
  double step = 0.2;           // between ticks (linear axes)
  bool log = false;
};
// Ticks covering [lo, hi] (lo == hi: a range around the value). Throws rouen::Error when lo or
// hi is not finite or hi < lo.
AxisTicks NiceTicks(double lo, double hi, int target_ticks = 5);
// Decades covering [lo, hi] (with 2 and 5 between them when the range spans under 3 decades).
// Throws rouen::Error unless 0 < lo <= hi, both finite.
AxisTicks LogTicks(double lo, double hi);
// A tick label: as many decimals as the step needs; very large or small values in %g form.
std::string FormatTick(double value, double step);

enum class SeriesStyle { kLine, kPoints, kLinePoints };

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;  // same length
  SeriesStyle style = SeriesStyle::kLine;
  std::string colour;  // CSS colour; empty: the palette's colour for the series' index
  bool dashed = false;
};

struct PlotAxis {
  std::string label;
  bool log = false;
  std::optional<double> min, max;  // forced ends; points beyond them are skipped
  // Tick label text; empty: FormatTick.
  std::function<std::string(double)> format;
};

struct PlotOptions {
  std::string title;
  PlotAxis x, y;
  int width = 560, height = 300;  // pixels, 160..4000 x 120..4000
  bool legend = true;             // to the right of the plot area
};

struct SvgPlot {
  std::string svg;
  AxisTicks x, y;          // the axes drawn (PlotXY; PlotBars: x only)
  int series = 0;          // groups drawn, one per series given
  int points_drawn = 0;    // points that made it onto the plot
  int points_skipped = 0;  // not finite, not positive on a log axis, or beyond a forced end
};

// Line and scatter plots. A point that is skipped breaks a line there. With no point to draw
// at all the axes span [0, 1] and the plot says "no data". Throws rouen::Error for a series
// whose x and y differ in length, or a size out of range.
SvgPlot PlotXY(const std::vector<PlotSeries>& series, const PlotOptions& options);

struct BarOptions {
  std::string title;
  std::string value_label;  // the axis under the bars
  int width = 560;
  int bar_height = 18;
  std::string colour = "#1f77b4";
  std::function<std::string(double)> format;  // the value written after each bar
};
// Horizontal bars, one per label, in the order given (one series). Values that are not finite
// or negative are skipped (their label stays, with "n/a"). Throws rouen::Error when the labels
// and values differ in number.
SvgPlot PlotBars(const std::vector<std::string>& labels, const std::vector<double>& values,
                 const BarOptions& options);

struct PolarSeries {
  std::string label;
  std::vector<double> azimuth_deg, elevation_deg;  // same length; from north eastward
  SeriesStyle style = SeriesStyle::kLine;
  std::string colour;
  std::vector<std::string> point_labels;  // empty, or one text per point written beside it
};

struct PolarOptions {
  std::string title;
  int size = 380;  // the chart's square, pixels (the legend is beside it)
  bool legend = true;
};

// A sky chart as seen from above: north up, east right, the zenith at the centre and the
// horizon on the outer ring (radius proportional to the zenith angle), rings every 30 degrees.
// Points below the horizon or not finite are skipped. Throws rouen::Error for a series whose
// lengths differ (point_labels: empty or one per point).
SvgPlot PlotPolarSky(const std::vector<PolarSeries>& series, const PolarOptions& options);

}  // namespace rouen
