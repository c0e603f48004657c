#include "render/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {

namespace {

constexpr const char* kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                    "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};

std::string SeriesColour(const std::string& given, size_t index) {
  return given.empty() ? kPalette[index % (sizeof kPalette / sizeof kPalette[0])] : given;
}

// A coordinate with one decimal: enough for screen pixels, short in the file.
std::string N(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}

std::string Text(double x, double y, const std::string& text, const char* anchor,
                 const std::string& extra = "") {
  return "<text x=\"" + N(x) + "\" y=\"" + N(y) + "\" text-anchor=\"" + anchor + "\"" +
         (extra.empty() ? "" : " " + extra) + ">" + EscapeXml(text) + "</text>";
}

std::string Open(int width, int height, const std::string& title) {
  std::string s = "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"plot\" role=\"img\" width=\"" +
                  std::to_string(width) + "\" height=\"" + std::to_string(height) +
                  "\" viewBox=\"0 0 " + std::to_string(width) + " " + std::to_string(height) +
                  "\" font-family=\"sans-serif\" font-size=\"11\">";
  if (!title.empty()) {
    s += "<title>" + EscapeXml(title) + "</title>";
    s += Text(width / 2.0, 16, title, "middle", "font-size=\"13\" font-weight=\"bold\"");
  }
  return s;
}

std::string SeriesGroup(const std::string& label, const std::string& colour, bool empty) {
  return "<g class=\"series\" data-label=\"" + EscapeXml(label) + "\" stroke=\"" + colour +
         "\" fill=\"" + colour + "\"" + (empty ? " data-empty=\"1\"" : "") + ">";
}

// The legend's entries from (x, y) downwards: a swatch (line or dot) and the label.
std::string Legend(double x, double y, const std::vector<std::string>& labels,
                   const std::vector<std::string>& colours, const std::vector<SeriesStyle>& styles,
                   const std::vector<bool>& dashed) {
  std::string s = "<g class=\"legend\">";
  for (size_t i = 0; i < labels.size(); ++i) {
    const double yy = y + 16.0 * i;
    if (styles[i] == SeriesStyle::kPoints) {
      s += "<circle cx=\"" + N(x + 9) + "\" cy=\"" + N(yy - 4) + "\" r=\"3\" fill=\"" + colours[i] +
           "\"/>";
    } else {
      s += "<line x1=\"" + N(x) + "\" y1=\"" + N(yy - 4) + "\" x2=\"" + N(x + 18) + "\" y2=\"" +
           N(yy - 4) + "\" stroke=\"" + colours[i] + "\" stroke-width=\"2\"" +
           (dashed[i] ? " stroke-dasharray=\"4 3\"" : "") + "/>";
    }
    s += Text(x + 24, yy, labels[i], "start");
  }
  return s + "</g>";
}

bool Drawable(double v, bool log) { return std::isfinite(v) && (!log || v > 0); }

void CheckSize(int width, int height, const char* what) {
  if (width < 160 || width > 4000 || height < 120 || height > 4000)
    throw Error(std::string(what) + ": size " + std::to_string(width) + "x" +
                std::to_string(height) + " is outside 160..4000 x 120..4000 pixels");
}

// A value's position along an axis, 0 at lo and 1 at hi.
double Fraction(const AxisTicks& t, double v) {
  if (t.log) return (std::log10(v) - std::log10(t.lo)) / (std::log10(t.hi) - std::log10(t.lo));
  return (v - t.lo) / (t.hi - t.lo);
}

}  // namespace

std::string EscapeXml(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        // Control characters other than tab and line ends are not allowed in XML: dropped.
        if (static_cast<unsigned char>(c) < 0x20 && c != '\t' && c != '\n' && c != '\r') break;
        out += c;
    }
  }
  return out;
}

AxisTicks NiceTicks(double lo, double hi, int target_ticks) {
  if (!std::isfinite(lo) || !std::isfinite(hi) || hi < lo)
    throw Error("axis range [" + std::to_string(lo) + ", " + std::to_string(hi) +
                "] is not a finite, increasing range");
  target_ticks = std::clamp(target_ticks, 2, 20);
  if (hi == lo) {
    const double pad = lo == 0 ? 1 : std::abs(lo) * 0.1;
    lo -= pad;
    hi += pad;
  }
  const double raw = (hi - lo) / target_ticks;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    step = m * mag;
    if (step >= raw) break;
  }
  AxisTicks t;
  t.step = step;
  // Ends on ticks; a value within a hair of a tick counts as on it (no empty extra step).
  const double eps = step * 1e-9;
  t.lo = std::floor((lo + eps) / step) * step;
  t.hi = std::ceil((hi - eps) / step) * step;
  if (t.hi <= t.lo) t.hi = t.lo + step;
  const int n = static_cast<int>(std::llround((t.hi - t.lo) / step));
  for (int i = 0; i <= n; ++i) {
    double v = t.lo + i * step;
    if (std::abs(v) < step * 1e-9) v = 0;  // no "-0"
    t.values.push_back(v);
  }
  return t;
}

AxisTicks LogTicks(double lo, double hi) {
  if (!(lo > 0) || !std::isfinite(lo) || !std::isfinite(hi) || hi < lo)
    throw Error("log axis range [" + std::to_string(lo) + ", " + std::to_string(hi) +
                "] must be positive, finite and increasing");
  AxisTicks t;
  t.log = true;
  const int d0 = static_cast<int>(std::floor(std::log10(lo) + 1e-9));
  int d1 = static_cast<int>(std::ceil(std::log10(hi) - 1e-9));
  if (d1 <= d0) d1 = d0 + 1;
  t.lo = std::pow(10.0, d0);
  t.hi = std::pow(10.0, d1);
  t.step = 0;
  const bool fine = d1 - d0 < 3;
  for (int d = d0; d <= d1; ++d) {
    const double decade = std::pow(10.0, d);
    t.values.push_back(decade);
    if (fine && d < d1) {
      t.values.push_back(2 * decade);
      t.values.push_back(5 * decade);
    }
  }
  return t;
}

std::string FormatTick(double value, double step) {
  char buf[48];
  const double a = std::abs(value);
  if (value != 0 && (a >= 1e6 || a < 1e-3 || step <= 0)) {
    std::snprintf(buf, sizeof buf, "%g", value);
    return buf;
  }
  int decimals = 0;
  if (step > 0 && step < 1)
    decimals = std::min(9, static_cast<int>(std::ceil(-std::log10(step) - 1e-9)));
  std::snprintf(buf, sizeof buf, "%.*f", decimals, value);
  return buf;
}

SvgPlot PlotXY(const std::vector<PlotSeries>& series, const PlotOptions& o) {
  CheckSize(o.width, o.height, "plot");
  for (const PlotSeries& s : series)
    if (s.x.size() != s.y.size())
      throw Error("plot series '" + s.label + "': " + std::to_string(s.x.size()) +
                  " x values but " + std::to_string(s.y.size()) + " y values");
  auto inside = [](const PlotAxis& a, double v) {
    return Drawable(v, a.log) && (!a.min || v >= *a.min) && (!a.max || v <= *a.max);
  };
  // The data's extent over the points that can be drawn.
  double xlo = std::numeric_limits<double>::infinity(), xhi = -xlo, ylo = xlo, yhi = -xlo;
  SvgPlot out;
  for (const PlotSeries& s : series)
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!inside(o.x, s.x[i]) || !inside(o.y, s.y[i])) {
        ++out.points_skipped;
        continue;
      }
      ++out.points_drawn;
      xlo = std::min(xlo, s.x[i]);
      xhi = std::max(xhi, s.x[i]);
      ylo = std::min(ylo, s.y[i]);
      yhi = std::max(yhi, s.y[i]);
    }
  const bool empty = out.points_drawn == 0;
  auto axis = [&](const PlotAxis& a, double lo, double hi) {
    if (empty) {
      lo = a.log ? 1 : 0;
      hi = a.log ? 10 : 1;
    }
    if (a.min) lo = *a.min;
    if (a.max) hi = *a.max;
    if (hi < lo) throw Error("plot axis '" + a.label + "': its forced ends are reversed");
    AxisTicks t = a.log ? LogTicks(lo, hi) : NiceTicks(lo, hi);
    // Forced ends are kept exactly; the ticks beyond them are dropped.
    if (a.min || a.max) {
      if (a.min) t.lo = *a.min;
      if (a.max) t.hi = *a.max;
      if (t.hi <= t.lo) t.hi = t.lo + (a.log ? t.lo : 1);
      std::vector<double> kept;
      for (double v : t.values)
        if (v >= t.lo - 1e-12 * std::abs(t.lo) && v <= t.hi + 1e-12 * std::abs(t.hi))
          kept.push_back(v);
      t.values = kept;
    }
    return t;
  };
  out.x = axis(o.x, xlo, xhi);
  out.y = axis(o.y, ylo, yhi);

  const bool legend = o.legend && !series.empty();
  const double left = 64, right = legend ? 170 : 16, top = o.title.empty() ? 12 : 28,
               bottom = o.x.label.empty() ? 28 : 44;
  const double pw = o.width - left - right, ph = o.height - top - bottom;
  if (pw < 40 || ph < 40)
    throw Error("plot: " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                " leaves no room for the data");
  auto px = [&](double v) { return left + Fraction(out.x, v) * pw; };
  auto py = [&](double v) { return top + (1 - Fraction(out.y, v)) * ph; };

  std::string& s = out.svg;
  s = Open(o.width, o.height, o.title);
  s += "<g class=\"axes\" stroke=\"#888\" fill=\"none\"><rect x=\"" + N(left) + "\" y=\"" + N(top) +
       "\" width=\"" + N(pw) + "\" height=\"" + N(ph) + "\"/>";
  std::string labels = "<g class=\"ticks\" fill=\"#333\">";
  for (double v : out.x.values) {
    s += "<line x1=\"" + N(px(v)) + "\" y1=\"" + N(top) + "\" x2=\"" + N(px(v)) + "\" y2=\"" +
         N(top + ph) + "\" stroke=\"#e4e4e4\"/>";
    labels += Text(px(v), top + ph + 14, o.x.format ? o.x.format(v) : FormatTick(v, out.x.step),
                   "middle");
  }
  for (double v : out.y.values) {
    s += "<line x1=\"" + N(left) + "\" y1=\"" + N(py(v)) + "\" x2=\"" + N(left + pw) + "\" y2=\"" +
         N(py(v)) + "\" stroke=\"#e4e4e4\"/>";
    labels +=
        Text(left - 5, py(v) + 4, o.y.format ? o.y.format(v) : FormatTick(v, out.y.step), "end");
  }
  s += "</g>" + labels + "</g>";
  if (!o.x.label.empty()) s += Text(left + pw / 2, o.height - 8, o.x.label, "middle");
  if (!o.y.label.empty()) {
    const double cy = top + ph / 2;
    s += Text(14, cy, o.y.label, "middle", "transform=\"rotate(-90 14 " + N(cy) + ")\"");
  }
  if (empty) s += Text(left + pw / 2, top + ph / 2, "no data", "middle", "fill=\"#999\"");

  std::vector<std::string> names, colours;
  std::vector<SeriesStyle> styles;
  std::vector<bool> dashes;
  for (size_t k = 0; k < series.size(); ++k) {
    const PlotSeries& ser = series[k];
    const std::string colour = SeriesColour(ser.colour, k);
    std::string path, dots;
    bool pen_down = false, any = false;
    for (size_t i = 0; i < ser.x.size(); ++i) {
      if (!inside(o.x, ser.x[i]) || !inside(o.y, ser.y[i])) {
        pen_down = false;
        continue;
      }
      any = true;
      const double X = px(ser.x[i]), Y = py(ser.y[i]);
      if (ser.style != SeriesStyle::kPoints) {
        path += (pen_down ? " L" : " M") + N(X) + " " + N(Y);
        pen_down = true;
      }
      if (ser.style != SeriesStyle::kLine)
        dots += "<circle cx=\"" + N(X) + "\" cy=\"" + N(Y) + "\" r=\"2.5\"/>";
    }
    s += SeriesGroup(ser.label, colour, !any);
    if (!path.empty())
      s += "<path fill=\"none\" stroke-width=\"1.8\"" +
           std::string(ser.dashed ? " stroke-dasharray=\"5 3\"" : "") + " d=\"" + path.substr(1) +
           "\"/>";
    s += dots + "</g>";
    names.push_back(ser.label);
    colours.push_back(colour);
    styles.push_back(ser.style);
    dashes.push_back(ser.dashed);
    ++out.series;
  }
  if (legend) s += Legend(left + pw + 12, top + 12, names, colours, styles, dashes);
  s += "</svg>";
  return out;
}

SvgPlot PlotBars(const std::vector<std::string>& labels, const std::vector<double>& values,
                 const BarOptions& o) {
  if (labels.size() != values.size())
    throw Error("bar chart: " + std::to_string(labels.size()) + " labels but " +
                std::to_string(values.size()) + " values");
  if (o.bar_height < 8 || o.bar_height > 100) throw Error("bar chart: bar height out of 8..100");
  const double left = 230, right = 80, top = o.title.empty() ? 12 : 28, bottom = 40;
  const double ph = std::max<double>(1, labels.size()) * (o.bar_height + 6);
  const int height = static_cast<int>(top + ph + bottom);
  CheckSize(o.width, std::max(height, 120), "bar chart");
  SvgPlot out;
  double hi = 0;
  for (double v : values) {
    if (std::isfinite(v) && v >= 0) {
      hi = std::max(hi, v);
      ++out.points_drawn;
    } else {
      ++out.points_skipped;
    }
  }
  out.x = NiceTicks(0, hi > 0 ? hi : 1);
  const double pw = o.width - left - right;
  auto px = [&](double v) { return left + (v - out.x.lo) / (out.x.hi - out.x.lo) * pw; };
  std::string& s = out.svg;
  s = Open(o.width, std::max(height, 120), o.title);
  s += "<g class=\"axes\" stroke=\"#888\" fill=\"none\">";
  std::string ticks = "<g class=\"ticks\" fill=\"#333\">";
  for (double v : out.x.values) {
    s += "<line x1=\"" + N(px(v)) + "\" y1=\"" + N(top) + "\" x2=\"" + N(px(v)) + "\" y2=\"" +
         N(top + ph) + "\" stroke=\"#e4e4e4\"/>";
    ticks += Text(px(v), top + ph + 14, FormatTick(v, out.x.step), "middle");
  }
  s += "<line x1=\"" + N(left) + "\" y1=\"" + N(top) + "\" x2=\"" + N(left) + "\" y2=\"" +
       N(top + ph) + "\"/></g>" + ticks + "</g>";
  if (!o.value_label.empty()) s += Text(left + pw / 2, top + ph + 32, o.value_label, "middle");
  s += SeriesGroup(o.title, o.colour, out.points_drawn == 0);
  for (size_t i = 0; i < labels.size(); ++i) {
    const double y = top + i * (o.bar_height + 6) + 3;
    const double v = values[i];
    const bool ok = std::isfinite(v) && v >= 0;
    if (ok)
      s += "<rect x=\"" + N(left) + "\" y=\"" + N(y) + "\" width=\"" + N(px(v) - left) +
           "\" height=\"" + std::to_string(o.bar_height) + "\"/>";
    const std::string value = !ok ? "n/a" : o.format ? o.format(v) : FormatTick(v, out.x.step / 10);
    s += Text(ok ? px(v) + 4 : left + 4, y + o.bar_height * 0.75, value, "start",
              "stroke=\"none\" fill=\"#333\"");
  }
  s += "</g><g class=\"labels\" fill=\"#333\">";
  for (size_t i = 0; i < labels.size(); ++i)
    s += Text(left - 6, top + i * (o.bar_height + 6) + 3 + o.bar_height * 0.75, labels[i], "end");
  s += "</g></svg>";
  out.series = 1;
  return out;
}

SvgPlot PlotPolarSky(const std::vector<PolarSeries>& series, const PolarOptions& o) {
  for (const PolarSeries& s : series) {
    if (s.azimuth_deg.size() != s.elevation_deg.size())
      throw Error("sky chart series '" + s.label + "': " + std::to_string(s.azimuth_deg.size()) +
                  " azimuths but " + std::to_string(s.elevation_deg.size()) + " elevations");
    if (!s.point_labels.empty() && s.point_labels.size() != s.azimuth_deg.size())
      throw Error("sky chart series '" + s.label + "': " + std::to_string(s.point_labels.size()) +
                  " point labels for " + std::to_string(s.azimuth_deg.size()) + " points");
  }
  const bool legend = o.legend && !series.empty();
  const int width = o.size + (legend ? 200 : 0);
  const double top = o.title.empty() ? 8 : 24;
  const int height = static_cast<int>(o.size + top);
  CheckSize(width, height, "sky chart");
  const double cx = o.size / 2.0, cy = top + o.size / 2.0, R = o.size / 2.0 - 24;
  auto pos = [&](double az, double el, double* x, double* y) {
    const double r = R * (90 - el) / 90, a = az * kDeg;
    *x = cx + r * std::sin(a);
    *y = cy - r * std::cos(a);
  };
  SvgPlot out;
  out.x.lo = 0;
  out.x.hi = 360;
  out.y = NiceTicks(0, 90, 3);
  std::string& s = out.svg;
  s = Open(width, height, o.title);
  s += "<g class=\"axes\" stroke=\"#bbb\" fill=\"none\">";
  std::string labels = "<g class=\"ticks\" fill=\"#555\">";
  for (int el : {0, 30, 60}) {
    s += "<circle cx=\"" + N(cx) + "\" cy=\"" + N(cy) + "\" r=\"" + N(R * (90 - el) / 90) + "\"" +
         (el == 0 ? " stroke=\"#888\"" : "") + "/>";
    labels += Text(cx + 3, cy - R * (90 - el) / 90 + 12, std::to_string(el) + "°", "start");
  }
  const char* names[] = {"N", "NE", "E", "SE", "S", "SW", "W", "NW"};
  for (int k = 0; k < 8; ++k) {
    double x0, y0, x1, y1;
    pos(45 * k, 90, &x0, &y0);
    pos(45 * k, 0, &x1, &y1);
    s += "<line x1=\"" + N(x0) + "\" y1=\"" + N(y0) + "\" x2=\"" + N(x1) + "\" y2=\"" + N(y1) +
         "\"/>";
    const double a = 45 * k * kDeg;
    labels += Text(cx + (R + 12) * std::sin(a), cy - (R + 12) * std::cos(a) + 4, names[k], "middle",
                   k % 2 ? "" : "font-weight=\"bold\"");
  }
  s += "</g>" + labels + "</g>";
  std::vector<std::string> legend_names, colours;
  std::vector<SeriesStyle> styles;
  std::vector<bool> dashes;
  for (size_t k = 0; k < series.size(); ++k) {
    const PolarSeries& ser = series[k];
    const std::string colour = SeriesColour(ser.colour, k);
    std::string path, dots, texts;
    bool pen_down = false, any = false;
    for (size_t i = 0; i < ser.azimuth_deg.size(); ++i) {
      const double az = ser.azimuth_deg[i], el = ser.elevation_deg[i];
      if (!std::isfinite(az) || !std::isfinite(el) || el < 0 || el > 90) {
        ++out.points_skipped;
        pen_down = false;
        continue;
      }
      ++out.points_drawn;
      any = true;
      double X, Y;
      pos(az, el, &X, &Y);
      if (ser.style != SeriesStyle::kPoints) {
        path += (pen_down ? " L" : " M") + N(X) + " " + N(Y);
        pen_down = true;
      }
      if (ser.style != SeriesStyle::kLine)
        dots += "<circle cx=\"" + N(X) + "\" cy=\"" + N(Y) + "\" r=\"4\"/>";
      if (!ser.point_labels.empty() && !ser.point_labels[i].empty())
        texts += Text(X + 6, Y - 5, ser.point_labels[i], "start", "stroke=\"none\"");
    }
    s += SeriesGroup(ser.label, colour, !any);
    if (!path.empty())
      s += "<path fill=\"none\" stroke-width=\"1.8\" d=\"" + path.substr(1) + "\"/>";
    s += dots + texts + "</g>";
    legend_names.push_back(ser.label);
    colours.push_back(colour);
    styles.push_back(ser.style);
    dashes.push_back(false);
    ++out.series;
  }
  if (legend) s += Legend(o.size + 8, top + 20, legend_names, colours, styles, dashes);
  s += "</svg>";
  return out;
}

}  // namespace rouen
