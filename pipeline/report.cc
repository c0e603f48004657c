#include "pipeline/report.h"

#include <tbb/task_group.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/json_text.h"
#include "core/mesh.h"
#include "core/response_curve.h"
#include "core/session.h"
#include "core/solar.h"
#include "core/stats.h"
#include "core/text.h"
#include "core/time.h"
#include "pipeline/session_solve.h"
#include "render/html_report.h"
#include "render/metrics.h"
#include "render/svg_plot.h"
#include "render/tonemap.h"
#include "solve/albedo.h"
#include "solve/atlas.h"
#include "solve/env_stereo.h"
#include "solve/environment.h"
#include "solve/relight.h"
#include "solve/scene.h"
#include "solve/sky_fit.h"
#include "solve/sky_model.h"

namespace rouen {

namespace {

namespace fs = std::filesystem;
using Log = std::function<void(const std::string&)>;

// A number with `digits` significant digits.
std::string G(double v, int digits = 4) {
  if (!std::isfinite(v)) return "n/a";
  const std::string buf = Formatted("%.*g", digits, v);
  return buf;
}
// A number with `decimals` decimals.
std::string F(double v, int decimals = 2) {
  if (!std::isfinite(v)) return "n/a";
  const std::string buf = Formatted("%.*f", decimals, v);
  return buf;
}
// A block's lobe for the albedo table: "none", or its parameters, with its fit's costs.
std::string LobeText(const std::vector<SpecularLobe>& lobes, const std::vector<double>& cost0,
                     const std::vector<double>& cost1, int b) {
  const SpecularLobe l = BlockLobe(lobes, b);
  std::string cost;
  if (b < static_cast<int>(cost0.size()) && b < static_cast<int>(cost1.size()) && cost0[b] > 0) {
    const std::string text = Formatted(" (cost %.0f -> %.0f)", cost0[b], cost1[b]);
    cost = text;
  }
  if (l.IsZero()) return "none" + cost;
  return l.Text() + cost;
}

std::string Rgb(const Eigen::Vector3d& v, int digits = 4) {
  return G(v[0], digits) + " / " + G(v[1], digits) + " / " + G(v[2], digits);
}
// HH:MM of an instant (UTC).
std::string Hhmm(UtcTime t) {
  const CivilTime c = ToCivil(t);
  const std::string buf = Formatted("%02d:%02d", c.hour, c.minute);
  return buf;
}
// Hours since `day0` as "HH:MM" of the day (wrapping at 24 h).
std::string HourOfDay(double hours) {
  double h = std::fmod(hours, 24.0);
  if (h < 0) h += 24;
  int minutes = static_cast<int>(std::lround(h * 60)) % (24 * 60);
  const std::string buf = Formatted("%02d:%02d", minutes / 60, minutes % 60);
  return buf;
}

const char* kChannelNames[] = {"R", "G", "B"};
const char* kChannelColours[] = {"#d62728", "#2ca02c", "#1f77b4"};

// One slot of the scene as scene.json records it.
struct SlotRecord {
  UtcTime utc;
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d sun_radiance = Eigen::Vector3d::Zero();
  double sun_solid_angle_sr = 0;
  SkyModel sky;
  EnvironmentMap env;
};

Eigen::Vector3d JsonVec(const nlohmann::json& j) {
  if (!j.is_array() || j.size() != 3) throw Error("not 3 numbers");
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

// The page and what it records of each section.
class Page {
 public:
  Page(HtmlReport* html, ReportSummary* summary) : html_(html), summary_(summary) {}
  void Section(const std::string& id, const std::string& title) {
    html_->BeginSection(id, title);
    summary_->sections.push_back({id, title, {}});
  }
  void Absent(const std::string& text) {
    html_->Absent(text);
    summary_->sections.back().absent.push_back(text);
  }
  HtmlReport& html() { return *html_; }

 private:
  HtmlReport* html_;
  ReportSummary* summary_;
};

// Everything the sections read, loaded once; each part may be missing, with the reason.
struct Inputs {
  fs::path scene_dir;
  nlohmann::json scene;  // scene.json
  std::vector<SlotRecord> slots;
  std::string slots_error;
  std::set<int> holdout;
  Site site;
  bool have_site = false;
  std::map<std::string, SceneView> views;
  std::optional<Session> session;
  std::string session_error;
  // The model, its grid and the albedos (solve/scene.h ReadScene).
  std::optional<SceneModel> model;
  Mesh mesh;
  SurfaceGrid grid;
  std::string model_error;
  std::optional<ResponseCurve> response;
};

void Say(const Log& log, const std::string& s) {
  if (log) log(s);
}

Inputs LoadInputs(const ReportRequest& r) {
  Inputs in;
  in.scene_dir = r.scene;
  const fs::path json_path = r.scene / "scene.json";
  std::error_code ec;
  if (!fs::is_directory(r.scene, ec))
    throw Error(r.scene.string() + ": no such scene folder (rouen solve writes one)");
  if (!fs::is_regular_file(json_path, ec))
    throw Error(json_path.string() + ": no such file: " + r.scene.string() +
                " is not a scene folder (rouen solve writes one)");
  try {
    in.scene = nlohmann::json::parse(ReadFileToString(json_path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(json_path.string() + ": not valid JSON: " + e.what());
  }
  if (!in.scene.is_object()) throw Error(json_path.string() + ": not a JSON object");
  const nlohmann::json& j = in.scene;
  try {
    const auto& s = j.at("site");
    in.site.lat_deg = s.at("lat_deg").get<double>();
    in.site.lon_deg = s.at("lon_deg").get<double>();
    in.site.height_m = s.at("height_m").get<double>();
    in.have_site = true;
  } catch (const std::exception&) {
  }
  try {
    for (const auto& s : j.at("slots")) {
      SlotRecord m;
      m.utc = ParseIso8601(s.at("utc").get<std::string>());
      m.sun_dir = JsonVec(s.at("sun_dir"));
      m.sun_radiance = JsonVec(s.at("sun_radiance"));
      m.sun_solid_angle_sr = s.value("sun_solid_angle_sr", 0.0);
      m.sky = s.at("sky").get<SkyModel>();
      m.env = s.at("env").get<EnvironmentMap>();
      in.slots.push_back(std::move(m));
    }
  } catch (const std::exception& e) {
    in.slots.clear();
    in.slots_error = json_path.string() + ": its slots cannot be read: " + e.what();
  }
  if (j.contains("holdout_slots") && j["holdout_slots"].is_array())
    for (const auto& h : j["holdout_slots"]) {
      try {
        in.holdout.insert(static_cast<int>(JsonInteger(h, 0, std::numeric_limits<int>::max())));
      } catch (const Error&) {
        // A slot that is not one is left out, as the views that cannot be read are.
      }
    }
  if (j.contains("views") && j["views"].is_object()) {
    for (const auto& [name, v] : j["views"].items()) {
      try {
        SceneView view;
        view.slot = JsonGet<int>(v.at("slot"), "slot");
        view.target = v.at("target").get<std::string>();
        view.utc = ParseIso8601(v.at("utc").get<std::string>());
        view.intrinsics = v.at("intrinsics").get<Intrinsics>();
        view.pose = v.at("pose").get<Pose>();
        in.views.emplace(name, view);
      } catch (const std::exception&) {
        // A view that cannot be read is left out; the sections that need it say so.
      }
    }
  }
  if (j.contains("response") && !j["response"].is_null()) {
    try {
      in.response = j["response"].get<ResponseCurve>();
    } catch (const std::exception&) {
      in.response.reset();
    }
  }
  Say(r.log, "reading the model, grid and albedos of " + r.scene.string());
  try {
    in.model = ReadScene(r.scene, &in.mesh, &in.grid);
  } catch (const std::exception& e) {
    in.model_error = e.what();
  }
  if (!r.session.empty()) {
    try {
      in.session = Session::Load(r.session);
    } catch (const std::exception& e) {
      in.session_error = e.what();
    }
  }
  return in;
}

// ---------------------------------------------------------------------------------------------
// Images

// Radiance (or albedo) as 8-bit sRGB at `exposure`; 1-channel and other units taken as they are.
Image Srgb(const Image& img, double exposure) {
  Image rgb = img;
  rgb.units = PixelUnits::kRadiance;
  if (rgb.channels != 3) {
    Image c(img.width, img.height, 3, PixelUnits::kRadiance);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x)
        for (int k = 0; k < 3; ++k) c.at(x, y, k) = img.at(x, y, std::min(k, img.channels - 1));
    rgb = std::move(c);
  }
  for (float& v : rgb.data)
    if (!std::isfinite(v) || v < 0) v = 0;
  return ToSrgbDigital(rgb, exposure);
}

// A radiance image through the scene's response when it has one (as photographs look), else
// through sRGB; exposed so the 99th percentile of `reference` is near white.
Image Preview(const Image& radiance, const Image& reference,
              const std::optional<ResponseCurve>& r) {
  Image ref = reference;
  for (float& v : ref.data)
    if (!std::isfinite(v) || v < 0) v = 0;
  Image rad = radiance;
  ref.units = rad.units = PixelUnits::kRadiance;
  for (float& v : rad.data)
    if (!std::isfinite(v) || v < 0) v = 0;
  if (r && r->valid()) return ToDigital(rad, *r, AutoExposure(ref, *r));
  return ToSrgbDigital(rad, AutoExposureSrgb(ref));
}

// `img` shrunk by the smallest whole factor that brings its longer side to `max_side` or less,
// each pixel the mean of its block (the last row and column of blocks may be partial).
Image Shrink(const Image& img, int max_side) {
  const int f = (std::max(img.width, img.height) + max_side - 1) / max_side;
  if (f <= 1) return img;
  Image out((img.width + f - 1) / f, (img.height + f - 1) / f, img.channels, img.units);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x)
      for (int c = 0; c < img.channels; ++c) {
        double sum = 0;
        int n = 0;
        for (int yy = y * f; yy < std::min(img.height, (y + 1) * f); ++yy)
          for (int xx = x * f; xx < std::min(img.width, (x + 1) * f); ++xx, ++n)
            sum += img.at(xx, yy, c);
        out.at(x, y, c) = static_cast<float>(sum / n);
      }
  return out;
}

// A signed value as a colour: blue (-limit) through white (0) to red (+limit); `valid` false:
// grey.
void Diverging(double v, double limit, bool valid, float* rgb) {
  if (!valid || !std::isfinite(v)) {
    rgb[0] = rgb[1] = rgb[2] = 70;
    return;
  }
  const double t = std::clamp(v / limit, -1.0, 1.0);
  const double a = 255 * (1 - std::abs(t));
  if (t >= 0) {
    rgb[0] = 255;
    rgb[1] = rgb[2] = static_cast<float>(a);
  } else {
    rgb[2] = 255;
    rgb[0] = rgb[1] = static_cast<float>(a);
  }
}

// ---------------------------------------------------------------------------------------------
// Sections

void Overview(Page& p, const ReportRequest& r, const Inputs& in) {
  p.Section("overview", "Scene");
  const nlohmann::json& j = in.scene;
  std::vector<std::vector<std::string>> rows;
  rows.push_back({"scene folder", r.scene.string()});
  if (in.have_site)
    rows.push_back({"site", F(in.site.lat_deg, 5) + "°, " + F(in.site.lon_deg, 5) + "°, " +
                                F(in.site.height_m, 1) + " m"});
  rows.push_back({"times of day (slots)", std::to_string(in.slots.size())});
  std::string held;
  for (int h : in.holdout) held += (held.empty() ? "" : ", ") + std::to_string(h);
  rows.push_back({"held out of the albedos", held.empty() ? "none" : "slot " + held});
  if (j.contains("points")) rows.push_back({"surface grid points", j["points"].dump()});
  if (in.model)
    rows.push_back({"model blocks", std::to_string(in.mesh.block_names.size()) + " (" +
                                        std::to_string(in.mesh.triangles.size()) + " triangles)"});
  rows.push_back({"views (photographed brackets)", std::to_string(in.views.size())});
  if (j.contains("provenance") && j["provenance"].is_object()) {
    const auto& pv = j["provenance"];
    if (pv.contains("rouen_version"))
      rows.push_back({"solved by rouen", pv.value("rouen_version", "")});
    if (pv.contains("inputs_sha256"))
      rows.push_back({"inputs sha256", pv.value("inputs_sha256", "")});
  }
  rows.push_back(
      {"session folder", r.session.empty() ? "not given (--session)" : r.session.string()});
  rows.push_back({"work folder", r.work.empty() ? "not given (--work)" : r.work.string()});
  p.html().Table({"", ""}, rows);
  if (!in.model_error.empty())
    p.Absent("The model, grid and albedos could not be read: " + in.model_error);
  if (!in.slots_error.empty()) p.Absent(in.slots_error);
  if (!in.session_error.empty()) p.Absent("The session could not be read: " + in.session_error);
}

void Timeline(Page& p, const ReportRequest& r, const Inputs& in) {
  p.Section("timeline", "Capture timeline");
  if (!in.session) {
    p.Absent(r.session.empty()
                 ? "No session given (--session): the frames, their times and exposures are in "
                   "the session's frames.jsonl."
                 : "The session could not be read: " + in.session_error);
    if (!in.views.empty()) {
      std::map<int, std::map<std::string, int>> per;
      std::set<std::string> targets;
      for (const auto& [name, v] : in.views) {
        per[v.slot][v.target]++;
        targets.insert(v.target);
      }
      std::vector<std::string> header = {"slot"};
      header.insert(header.end(), targets.begin(), targets.end());
      std::vector<std::vector<std::string>> rows;
      for (const auto& [slot, m] : per) {
        std::vector<std::string> row = {std::to_string(slot)};
        for (const std::string& t : targets)
          row.push_back(m.count(t) ? std::to_string(m.at(t)) : "0");
        rows.push_back(row);
      }
      p.html().Table(header, rows, "Photographed brackets (views) per slot, from scene.json");
    }
    return;
  }
  const Session& s = *in.session;
  if (s.frames().empty()) {
    p.Absent("The session's journal holds no frame.");
    return;
  }
  UtcTime first = s.frames().front().utc, last = first;
  for (const FrameRecord& f : s.frames()) {
    first = std::min(first, f.utc);
    last = std::max(last, f.utc);
  }
  CivilTime c0 = ToCivil(first);
  c0.hour = c0.minute = 0;
  c0.second = 0;
  const UtcTime day0 = FromCivil(c0);
  const Target order[] = {Target::kSun,       Target::kAureole,      Target::kSky,
                          Target::kLandscape, Target::kArchitecture, Target::kCalibration};
  std::vector<PlotSeries> series;
  int hdr_frames = 0;
  std::map<int, std::map<Target, int>> per_slot;
  std::map<int, std::pair<double, double>> exposure_range;
  std::map<int, UtcTime> slot_start;
  const double h0 = (first.ns - day0.ns) * 1e-9 / 3600, h1 = (last.ns - day0.ns) * 1e-9 / 3600;
  for (Target t : order) {
    const double offset = (static_cast<int>(t) - 2) * std::max(h1 - h0, 1.0) / 60;
    PlotSeries ser;
    ser.label = TargetName(t);
    ser.style = SeriesStyle::kPoints;
    for (const FrameRecord& f : s.frames()) {
      if (f.target != t) continue;
      per_slot[f.slot][t]++;
      if (!slot_start.count(f.slot) || f.utc < slot_start[f.slot]) slot_start[f.slot] = f.utc;
      if (f.hdr) {
        ++hdr_frames;
        continue;
      }
      // Targets side by side (a few minutes apart) so that equal exposures stay visible.
      ser.x.push_back((f.utc.ns - day0.ns) * 1e-9 / 3600 + offset);
      ser.y.push_back(f.exposure_s);
      auto& range = exposure_range.try_emplace(f.slot, f.exposure_s, f.exposure_s).first->second;
      range.first = std::min(range.first, f.exposure_s);
      range.second = std::max(range.second, f.exposure_s);
    }
    bool any = false;
    for (const FrameRecord& f : s.frames()) any |= f.target == t;
    if (any) series.push_back(std::move(ser));
  }
  PlotOptions po;
  po.title = "Exposure of every frame";
  po.width = 900;
  po.height = 340;
  po.x.label = "time of day (UTC, " + first.Iso8601(0).substr(0, 10) + ")";
  po.x.format = HourOfDay;
  po.x.min = std::floor(h0 - 0.5);
  po.x.max = std::ceil(h1 + 0.5);
  po.y.label = "exposure (s)";
  po.y.log = true;
  const SvgPlot plot = PlotXY(series, po);
  p.html().Svg(plot.svg,
               "Each dot is one frame of the journal (frames.jsonl) at its UTC time, by target "
               "(the targets drawn a few minutes apart so that equal exposures stay visible); "
               "the sun's frames are taken through an ND filter.");
  if (hdr_frames > 0)
    p.html().Paragraph(std::to_string(hdr_frames) +
                       " HDR frame(s) have no exposure time and are counted in the table only.");
  std::vector<std::string> header = {"slot", "first frame (UTC)"};
  std::vector<Target> present;
  for (Target t : order) {
    bool any = false;
    for (const auto& [slot, m] : per_slot) any |= m.count(t) > 0;
    if (any) {
      present.push_back(t);
      header.push_back(TargetName(t));
    }
  }
  header.push_back("exposures (s)");
  std::vector<std::vector<std::string>> rows;
  for (const auto& [slot, m] : per_slot) {
    std::vector<std::string> row = {
        std::to_string(slot) + (in.holdout.count(slot) ? " (held out)" : ""),
        slot_start[slot].Iso8601(0)};
    for (Target t : present) row.push_back(m.count(t) ? std::to_string(m.at(t)) : "0");
    const auto it = exposure_range.find(slot);
    row.push_back(it == exposure_range.end()
                      ? "HDR"
                      : G(it->second.first, 3) + " – " + G(it->second.second, 3));
    rows.push_back(row);
  }
  p.html().Table(header, rows,
                 "Frames per slot and target (" + std::to_string(s.frames().size()) +
                     " frames in " + r.session.string() + ")");
}

void SunPath(Page& p, const Inputs& in) {
  p.Section("sunpath", "Sun path and capture times");
  if (!in.have_site) {
    p.Absent("scene.json records no site: the sun's path cannot be computed.");
    return;
  }
  if (in.slots.empty()) {
    p.Absent("scene.json holds no readable slot: no capture time to show. " + in.slots_error);
    return;
  }
  // The daylight around the first capture: back and forward in 10-minute steps from it until
  // the sun sets (at most a day each way).
  const UtcTime t0 = in.slots.front().utc;
  const UtcTime tl = in.slots.back().utc;
  auto el_at = [&](UtcTime t) { return ComputeSunPosition(t, in.site).elevation_deg; };
  UtcTime start = t0, end = tl;
  for (int i = 0; i < 144 && el_at(start.PlusSeconds(-600)) > 0; ++i)
    start = start.PlusSeconds(-600);
  for (int i = 0; i < 144 && el_at(end.PlusSeconds(600)) > 0; ++i) end = end.PlusSeconds(600);
  PolarSeries path;
  path.label = "sun path, " + t0.Iso8601(0).substr(0, 10) + " (UTC)";
  path.colour = "#ff9900";
  for (UtcTime t = start.PlusSeconds(-600); t <= end.PlusSeconds(600); t = t.PlusSeconds(300)) {
    const SunPosition sp = ComputeSunPosition(t, in.site);
    path.azimuth_deg.push_back(sp.azimuth_deg);
    path.elevation_deg.push_back(sp.elevation_deg);
  }
  PolarSeries captured, held;
  captured.label = "captured slots";
  captured.style = SeriesStyle::kPoints;
  captured.colour = "#1f77b4";
  held.label = "held-out slots";
  held.style = SeriesStyle::kPoints;
  held.colour = "#d62728";
  std::vector<std::vector<std::string>> rows;
  for (size_t k = 0; k < in.slots.size(); ++k) {
    const SlotRecord& s = in.slots[k];
    double az, el;
    AzElFromEnu(s.sun_dir, &az, &el);
    PolarSeries& ser = in.holdout.count(static_cast<int>(k)) ? held : captured;
    ser.azimuth_deg.push_back(az);
    ser.elevation_deg.push_back(el);
    ser.point_labels.push_back(std::to_string(k) + " " + Hhmm(s.utc));
    const SunPosition sp = ComputeSunPosition(s.utc, in.site);
    rows.push_back(
        {std::to_string(k) + (in.holdout.count(static_cast<int>(k)) ? " (held out)" : ""),
         s.utc.Iso8601(0), F(az, 2), F(el, 2), F(sp.elevation_deg, 2), Rgb(s.sun_radiance),
         G(s.sun_solid_angle_sr, 4)});
  }
  std::vector<PolarSeries> series = {path, captured};
  if (!held.azimuth_deg.empty()) series.push_back(held);
  PolarOptions po;
  po.title = "Sun over the site";
  const SvgPlot plot = PlotPolarSky(series, po);
  p.html().Svg(
      plot.svg,
      "Seen from above (north up, east right), horizon on the outer ring, zenith at the "
      "centre. The path is computed from the site and date (ERFA, refracted); the dots are "
      "the sun directions the scene's slots were solved with, labelled slot and UTC time.");
  p.html().Table({"slot", "UTC", "azimuth (°)", "elevation (°)", "elevation from the almanac (°)",
                  "sun radiance R/G/B", "sun solid angle (sr)"},
                 rows, "The sun of each slot as recorded in scene.json");
}

void Response(Page& p, const Inputs& in) {
  p.Section("response", "Camera response");
  const nlohmann::json& j = in.scene;
  if (!j.contains("response") || j["response"].is_null()) {
    p.Absent(
        "scene.json records no response curve: the photographs came in as HDR radiance "
        "(or the scene predates it), so there is no curve to show.");
    return;
  }
  if (!in.response) {
    p.Absent(
        "scene.json's response curve cannot be read (not 3 channels of 256 non-decreasing "
        "values).");
    return;
  }
  std::vector<PlotSeries> series;
  for (int c = 0; c < 3; ++c) {
    PlotSeries s;
    s.label = kChannelNames[c];
    s.colour = kChannelColours[c];
    for (int z = 0; z < 256; ++z) {
      s.x.push_back(z);
      s.y.push_back(in.response->g[c][z]);
    }
    series.push_back(std::move(s));
  }
  PlotOptions po;
  po.title = "Response curve g(z) = ln exposure, per channel";
  po.x.label = "digital value z";
  po.x.min = 0;
  po.x.max = 255;
  po.y.label = "ln exposure";
  const SvgPlot plot = PlotXY(series, po);
  p.html().Svg(
      plot.svg,
      "Debevec–Malik: the log exposure (radiance × seconds × gain × ND transmission, up to "
      "one scale) that gives each digital value.");
  // Anything recorded beside the curve (a fit residual, the method) is shown as it is.
  std::vector<std::vector<std::string>> rows;
  for (const auto& [k, v] : j["response"].items())
    if (k != "g") rows.push_back({k, v.is_string() ? v.get<std::string>() : v.dump()});
  if (j.contains("response_summary") && j["response_summary"].is_object())
    for (const auto& [k, v] : j["response_summary"].items()) rows.push_back({k, v.dump()});
  if (rows.empty())
    p.Absent(
        "The response fit's residual is not recorded: scene.json (like calib/response.json) "
        "holds the curve g only.");
  else
    p.html().Table({"fit", "value"}, rows, "Recorded with the curve");
}

// The sky photos of a slot merged by the calibration (work/calib/hdr), as HdrGroups.
std::vector<HdrGroup> SkyPhotos(const ReportRequest& r, const Inputs& in, int slot,
                                std::string* problem) {
  std::vector<HdrGroup> out;
  for (int v = 0;; ++v) {
    const std::string name = BracketName(slot, Target::kSky, v);
    const auto it = in.views.find(name);
    if (it == in.views.end()) break;
    std::string safe = name;
    std::replace(safe.begin(), safe.end(), '/', '_');
    const fs::path base = r.work / "calib" / "hdr" / safe;
    try {
      HdrGroup g;
      g.name = name;
      g.slot = slot;
      g.target = Target::kSky;
      g.intrinsics = it->second.intrinsics;
      g.pose = it->second.pose;
      g.utc = it->second.utc;
      g.radiance = ReadImage((base.string() + ".exr"));
      if (g.radiance.width != g.intrinsics.width || g.radiance.height != g.intrinsics.height ||
          g.radiance.channels < 3)
        throw Error(base.string() + ".exr is not the size of the view " + name);
      std::error_code ec;
      if (fs::exists(base.string() + ".valid.png", ec))
        g.valid = ReadMask(base.string() + ".valid.png", g.radiance.width, g.radiance.height, name);
      else
        g.valid.assign(static_cast<size_t>(g.radiance.width) * g.radiance.height, 1);
      out.push_back(std::move(g));
    } catch (const std::exception& e) {
      *problem = e.what();
      return {};
    }
  }
  if (out.empty() && problem->empty())
    *problem = "the scene has no sky view of slot " + std::to_string(slot);
  return out;
}

void Sky(Page& p, const ReportRequest& r, const Inputs& in) {
  p.Section("sky", "Sky fits");
  if (in.slots.empty()) {
    p.Absent("No slot could be read from scene.json: no sky model to show. " + in.slots_error);
    return;
  }
  p.html().Paragraph(
      "The seven-parameter model of §3.2 (eq. 9) per channel: Ls = Lz [1 + a exp(b / cos ξ)] "
      "[1 + c exp(d γ^h) + e cos² γ], ξ the zenith angle, γ the angle from the sun.");
  std::vector<std::vector<std::string>> rows;
  for (size_t k = 0; k < in.slots.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      const SkyParams& q = in.slots[k].sky.channel[c];
      rows.push_back({c == 0 ? std::to_string(k) + " " + Hhmm(in.slots[k].utc) : "",
                      kChannelNames[c], G(q.Lz), G(q.a), G(q.b), G(q.c), G(q.d), G(q.e), G(q.h)});
    }
  p.html().Table({"slot", "channel", "Lz", "a", "b", "c", "d", "e", "h"}, rows,
                 "Fitted parameters per slot and channel (scene.json slots[].sky)");
  // The two factors of the model, green channel, per slot.
  std::vector<PlotSeries> grad, scat;
  for (size_t k = 0; k < in.slots.size(); ++k) {
    const SkyParams& q = in.slots[k].sky.channel[1];
    PlotSeries g, s;
    g.label = s.label = "slot " + std::to_string(k) + " " + Hhmm(in.slots[k].utc);
    g.dashed = s.dashed = in.holdout.count(static_cast<int>(k)) > 0;
    for (int deg = 0; deg <= 87; ++deg) {
      g.x.push_back(deg);
      g.y.push_back(SkyBackground(q, deg * kDeg));
    }
    for (int deg = 1; deg <= 180; ++deg) {
      s.x.push_back(deg);
      s.y.push_back(SkyScattering(q, deg * kDeg));
    }
    grad.push_back(std::move(g));
    scat.push_back(std::move(s));
  }
  PlotOptions po;
  po.width = 600;
  po.title = "Gradation Bg(ξ), green";
  po.x.label = "zenith angle ξ (°)";
  po.x.min = 0;
  po.x.max = 90;
  po.y.label = "Bg";
  p.html().BeginRow();
  p.html().Svg(PlotXY(grad, po).svg, "1 + a exp(b / cos ξ): brightening towards the horizon.");
  po.title = "Scattering Sa(γ), green";
  po.x.min = 0;
  po.x.max = 180;
  po.x.label = "angle from the sun γ (°)";
  po.y.label = "Sa";
  po.y.log = true;
  p.html().Svg(PlotXY(scat, po).svg,
               "1 + c exp(d γ^h) + e cos² γ: the aureole and the anti-solar rise (log scale).");
  p.html().EndRow();

  // Errors against the merged sky photos.
  p.html().Heading("Fit error against the sky photographs");
  if (r.work.empty()) {
    p.Absent(
        "The error by elevation and by angle from the sun needs the merged HDR sky photos of "
        "the solve's work folder (calib/hdr): give --work (rouen solve --work, or the "
        "demo's DIR/work).");
    return;
  }
  if (!in.session)
    p.html().Paragraph(
        "No session given: the sky masks of session.json are not applied; every "
        "well-exposed pixel of the sky photos is compared.");
  // The sky's pixels as the solve took them (its recorded options; older scenes: defaults).
  const SolveConfig config =
      in.model ? SceneSolveConfig(*in.model, (in.scene_dir / "scene.json").string())
               : DefaultSolveConfig(false);
  constexpr double kBin = 5;
  std::vector<PlotSeries> by_el, by_gamma;
  std::vector<std::vector<std::string>> stats_rows;
  std::vector<std::pair<Image, Image>> maps;  // photo, residual map per slot
  std::vector<std::string> map_captions;
  std::string problems;
  for (size_t k = 0; k < in.slots.size(); ++k) {
    const SlotRecord& slot = in.slots[k];
    std::string problem;
    const std::vector<HdrGroup> photos = SkyPhotos(r, in, static_cast<int>(k), &problem);
    if (photos.empty()) {
      problems += " slot " + std::to_string(k) + ": " + problem + ".";
      continue;
    }
    SkyModel model = slot.sky;
    model.sun_dir = slot.sun_dir;
    std::vector<SkySample> samples;
    std::vector<std::vector<uint8_t>> masks;
    try {
      for (const HdrGroup& g : photos) {
        std::vector<uint8_t> mask =
            in.session ? SkyMaskFor(*in.session, g, slot.sun_dir, config.sky_segment) : g.valid;
        const std::vector<SkySample> part = ExtractSkySamples(
            g.radiance, &mask, g.intrinsics, g.pose, slot.sun_dir, config.sky_samples);
        samples.insert(samples.end(), part.begin(), part.end());
        masks.push_back(std::move(mask));
      }
    } catch (const std::exception& e) {
      problems += " slot " + std::to_string(k) + ": " + e.what() + ".";
      continue;
    }
    if (samples.empty()) {
      problems += " slot " + std::to_string(k) + ": no sky pixel in its photos.";
      continue;
    }
    const std::vector<Eigen::Vector3d> res = SkyRelativeResiduals(model, samples);
    const SkyResidualStats st = SummarizeSkyResiduals(res);
    std::vector<std::vector<double>> el_bins(18), gamma_bins(36);
    std::vector<double> all;
    for (size_t i = 0; i < samples.size(); ++i) {
      const Eigen::Vector3d& d = samples[i].dir;
      const double e = res[i].cwiseAbs().mean();
      all.push_back(e);
      const double el = std::asin(std::clamp(d.z(), -1.0, 1.0)) / kDeg;
      const double gamma = std::acos(std::clamp(d.dot(slot.sun_dir), -1.0, 1.0)) / kDeg;
      el_bins[std::clamp(static_cast<int>(el / kBin), 0, 17)].push_back(e);
      gamma_bins[std::clamp(static_cast<int>(gamma / kBin), 0, 35)].push_back(e);
    }
    PlotSeries se, sg;
    se.label = sg.label = "slot " + std::to_string(k) + " " + Hhmm(slot.utc);
    se.style = sg.style = SeriesStyle::kLinePoints;
    se.dashed = sg.dashed = in.holdout.count(static_cast<int>(k)) > 0;
    for (size_t b = 0; b < el_bins.size(); ++b) {
      se.x.push_back((b + 0.5) * kBin);
      se.y.push_back(el_bins[b].size() >= 5 ? 100 * Quantile(el_bins[b], 0.5) : std::nan(""));
    }
    for (size_t b = 0; b < gamma_bins.size(); ++b) {
      sg.x.push_back((b + 0.5) * kBin);
      sg.y.push_back(gamma_bins[b].size() >= 5 ? 100 * Quantile(gamma_bins[b], 0.5) : std::nan(""));
    }
    by_el.push_back(std::move(se));
    by_gamma.push_back(std::move(sg));
    stats_rows.push_back(
        {std::to_string(k) + (in.holdout.count(static_cast<int>(k)) ? " (held out)" : ""),
         std::to_string(samples.size()), F(100 * Quantile(all, 0.5), 2),
         F(100 * Quantile(all, 0.9), 2), F(100 * std::max({st.max[0], st.max[1], st.max[2]}), 1)});
    // The residual map of the first photo: (model - photo) / photo, mean over channels.
    const HdrGroup& g = photos.front();
    Image map(g.radiance.width, g.radiance.height, 3, PixelUnits::kDigital);
    for (int y = 0; y < g.radiance.height; ++y)
      for (int x = 0; x < g.radiance.width; ++x) {
        const size_t i = static_cast<size_t>(y) * g.radiance.width + x;
        double v = std::nan("");
        bool ok = masks.front()[i] != 0;
        if (ok) {
          const Eigen::Vector3d d =
              (g.pose.rotation * Unproject(g.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5)))
                  .normalized();
          // The pixels the fit leaves out (SkySampleOptions): near the horizon, near the sun.
          const SkySampleOptions so;
          ok = d.allFinite() && d.z() > std::sin(so.min_elevation_deg * kDeg) &&
               d.dot(slot.sun_dir) < std::cos(so.min_sun_distance_deg * kDeg);
          if (ok) {
            const Eigen::Vector3d m = model.Radiance(d);
            double sum = 0;
            for (int c = 0; c < 3; ++c) {
              const double ph = g.radiance.at(x, y, c);
              if (!(ph > 0)) ok = false;
              sum += (m[c] - ph) / ph;
            }
            v = sum / 3;
          }
        }
        Diverging(v, 0.1, ok, &map.at(x, y, 0));
      }
    maps.emplace_back(Shrink(Preview(g.radiance, g.radiance, std::nullopt), 200), Shrink(map, 200));
    map_captions.push_back("slot " + std::to_string(k) + " " + Hhmm(slot.utc) + ", " + g.name);
  }
  if (!problems.empty())
    p.Absent("Sky photos missing or unreadable in " + r.work.string() + ":" + problems);
  if (by_el.empty()) return;
  PlotOptions pe;
  pe.width = 600;
  pe.title = "Sky fit error by elevation";
  pe.x.label = "elevation (°)";
  pe.x.min = 0;
  pe.x.max = 90;
  pe.y.label = "median |model − photo| / photo (%)";
  pe.y.min = 0;
  PlotOptions pg = pe;
  pg.title = "Sky fit error by angle from the sun";
  pg.x.label = "angle from the sun γ (°)";
  pg.x.max = 180;
  p.html().BeginRow();
  p.html().Svg(PlotXY(by_el, pe).svg,
               "Median relative error (mean over R, G, B) per 5° band of "
               "the sky pixels the fit uses (§3.2's sample selection).");
  p.html().Svg(PlotXY(by_gamma, pg).svg, "The same by angle from the sun.");
  p.html().EndRow();
  p.html().Table({"slot", "samples", "median |error| (%)", "p90 (%)", "max (%)"}, stats_rows,
                 "Relative error of the fitted model at the fit's sky samples");
  p.html().Paragraph(
      "Residual maps: (model − photo) / photo over the sky pixels the fit uses, blue −10% to red "
      "+10%; grey: not sky, not well exposed, or left out of the fit (the last 3° above the "
      "horizon, 3° around the sun).");
  p.html().BeginRow();
  for (size_t k = 0; k < maps.size(); ++k) {
    p.html().Picture(maps[k].first, map_captions[k] + " (photo)", 200);
    p.html().Picture(maps[k].second, map_captions[k] + " (residual)", 200);
  }
  p.html().EndRow();
}

// An environment map layer as a lat-long image: north (azimuth 0) at the left, eastwards; the
// zenith band at the top. `value` gives a region's RGB (0..255).
template <typename F>
Image LatLong(const EnvironmentMap& env, int layer, F value) {
  Image img(env.sectors, env.num_bands(), 3, PixelUnits::kDigital);
  for (int band = 0; band < env.num_bands(); ++band)
    for (int s = 0; s < env.sectors; ++s) {
      const int region = band * env.sectors + s;
      const Eigen::Vector3d v = value(layer * env.num_regions() + region);
      for (int c = 0; c < 3; ++c)
        img.at(s, env.num_bands() - 1 - band, c) = static_cast<float>(std::clamp(v[c], 0.0, 255.0));
    }
  return img;
}

// The environment's photometric stereo from the slots the albedos used (held-out slots left
// out), as rouen render fits it to predict a novel time; nothing when every slot is held out.
std::optional<EnvStereoResult> FitStereo(const Inputs& in) {
  std::vector<Lighting> measured;
  std::vector<int> measured_slots;
  for (size_t k = 0; k < in.slots.size(); ++k) {
    if (in.holdout.count(static_cast<int>(k))) continue;
    measured_slots.push_back(static_cast<int>(k));
    Lighting l;
    l.utc = in.slots[k].utc;
    l.sun_dir = in.slots[k].sun_dir;
    l.sun_radiance = in.slots[k].sun_radiance;
    l.sun_solid_angle_sr = in.slots[k].sun_solid_angle_sr;
    l.sky = in.slots[k].sky;
    l.sky.sun_dir = l.sun_dir;
    l.env = in.slots[k].env;
    measured.push_back(std::move(l));
  }
  if (measured.empty()) return std::nullopt;
  // The options the solve fitted with (its recorded ones; older scenes: the defaults).
  EnvStereoOptions eo =
      (in.model ? SceneSolveConfig(*in.model, (in.scene_dir / "scene.json").string())
                : DefaultSolveConfig(false))
          .env_stereo;
  if (in.scene.contains("environment") && in.scene["environment"].is_object()) {
    const nlohmann::json& env = in.scene["environment"];
    eo.ground_retro = env.value("ground_retro", 0.0);
    // The solve's own fit, when it was made from these slots with these options.
    if (env.contains("stereo")) {
      const std::optional<EnvStereoResult> stored = env["stereo"].at("fit").get<EnvStereoResult>();
      if (const EnvStereoResult* fit = FitFor(
              stored, JsonGet<std::vector<int>>(env["stereo"].at("slots")), measured_slots, eo))
        return *fit;
    }
  }
  return SolveEnvStereo(EnvObservationsOf(measured), eo);
}

// FitStereo run beside the report's first sections: its result or its error once Wait returns.
class StereoFit {
 public:
  explicit StereoFit(const Inputs& in) {
    group_.run([this, &in] {
      try {
        result_ = FitStereo(in);
      } catch (const std::exception& e) {
        error_ = e.what();
      }
    });
  }
  ~StereoFit() { group_.wait(); }
  void Wait() { group_.wait(); }
  const std::optional<EnvStereoResult>& result() const { return result_; }
  const std::string& error() const { return error_; }

 private:
  tbb::task_group group_;
  std::optional<EnvStereoResult> result_;
  std::string error_;
};

void Environment(Page& p, const Inputs& in, StereoFit* stereo_fit) {
  p.Section("environment", "Environment");
  if (in.slots.empty()) {
    p.Absent("No slot could be read from scene.json: no environment map to show. " +
             in.slots_error);
    return;
  }
  // One exposure for every map, so their brightness compares.
  std::vector<double> greens;
  for (const SlotRecord& s : in.slots)
    for (const Eigen::Vector3d& v : s.env.radiance) greens.push_back(std::max({v[0], v[1], v[2]}));
  const double p99 = greens.empty() ? 1 : Quantile(greens, 0.99);
  const double exposure = p99 > 0 ? 0.9 / p99 : 1;
  auto srgb = [](double v) {
    v = std::clamp(v, 0.0, 1.0);
    return 255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055);
  };
  p.html().Paragraph(
      "The coarse environment of §3.3 per slot: the mean radiance of each latitude-longitude "
      "region of the landscape panoramas (regions never seen: the sky model above the horizon, "
      "the nearest region below). North at the left edge, azimuth eastwards; zenith at the top, "
      "nadir at the bottom; one exposure for all.");
  p.html().BeginRow();
  for (size_t k = 0; k < in.slots.size(); ++k) {
    const EnvironmentMap& env = in.slots[k].env;
    for (int layer = 0; layer < env.num_layers(); ++layer) {
      const Image img = LatLong(env, layer, [&](int i) {
        const Eigen::Vector3d& v = env.radiance[i];
        return Eigen::Vector3d(srgb(v[0] * exposure), srgb(v[1] * exposure), srgb(v[2] * exposure));
      });
      p.html().Picture(
          img,
          "slot " + std::to_string(k) + " " + Hhmm(in.slots[k].utc) +
              (env.num_layers() > 1 ? ", layer at " + F(env.layer_z[layer], 1) + " m" : "") + ", " +
              F(100 * env.ObservedFraction(), 0) + "% observed",
          env.sectors * 10, true);
    }
  }
  p.html().EndRow();

  p.html().Heading("Photometric-stereo normals of the environment (§5.2)");
  stereo_fit->Wait();
  if (!stereo_fit->error().empty()) {
    p.Absent("The environment's photometric stereo failed: " + stereo_fit->error());
    return;
  }
  if (!stereo_fit->result()) {
    p.Absent("Every slot is held out: no environment normals to fit.");
    return;
  }
  const EnvStereoResult& stereo = *stereo_fit->result();
  p.html().Paragraph(
      "From the environment maps of the slots the albedos used (held-out slots left out), "
      "as rouen render predicts a novel time with it: the solve's fit, kept in scene.json "
      "(fitted here for a scene without one). " +
      stereo.summary.BriefReport());
  EnvironmentMap grid;
  grid.bands_below = stereo.bands_below;
  grid.bands_above = stereo.bands_above;
  grid.sectors = stereo.sectors;
  p.html().BeginRow();
  for (int layer = 0; layer < static_cast<int>(stereo.layer_z.size()); ++layer) {
    const std::string where =
        stereo.layer_z.size() > 1 ? ", layer at " + F(stereo.layer_z[layer], 1) + " m" : "";
    p.html().Picture(LatLong(grid, layer,
                             [&](int i) {
                               const EnvRegionFit& f = stereo.regions[i];
                               if (f.kind == EnvRegionKind::kSky)
                                 return Eigen::Vector3d(235, 235, 235);
                               if (f.kind == EnvRegionKind::kUnobserved)
                                 return Eigen::Vector3d(0, 0, 0);
                               return Eigen::Vector3d(127.5 * (f.normal + Eigen::Vector3d::Ones()));
                             }),
                     "normals (R east, G north, B up; light grey: sky)" + where, grid.sectors * 10,
                     true);
    p.html().Picture(LatLong(grid, layer,
                             [&](int i) {
                               switch (stereo.regions[i].kind) {
                                 case EnvRegionKind::kSky:
                                   return Eigen::Vector3d(150, 200, 255);
                                 case EnvRegionKind::kLandscape:
                                   return Eigen::Vector3d(90, 160, 60);
                                 case EnvRegionKind::kSkyOnly:
                                   return Eigen::Vector3d(230, 170, 40);
                                 default:
                                   return Eigen::Vector3d(0, 0, 0);
                               }
                             }),
                     "region kinds: blue sky, green landscape (sun + sky), orange sky-only "
                     "fallback, black unobserved" +
                         where,
                     grid.sectors * 10, true);
  }
  p.html().EndRow();
}

// An atlas EXR of the scene folder, or nothing with the reason.
std::optional<Image> ReadAtlas(const fs::path& dir, const std::string& relative,
                               std::string* problem) {
  try {
    const fs::path path = ResolveInside(dir, relative);
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) {
      *problem = path.string() + " is missing";
      return std::nullopt;
    }
    return ReadImage(path.string());
  } catch (const std::exception& e) {
    *problem = e.what();
    return std::nullopt;
  }
}

void Albedo(Page& p, const Inputs& in) {
  p.Section("albedo", "Albedos");
  const nlohmann::json& j = in.scene;
  if (j.contains("albedo") && j["albedo"].is_object() && j["albedo"].contains("summary") &&
      j["albedo"]["summary"].is_object()) {
    std::vector<std::vector<std::string>> rows;
    for (const auto& [k, v] : j["albedo"]["summary"].items()) {
      std::string text;
      if (v.is_number_float())
        text = G(v.get<double>());
      else if (v.is_array()) {
        for (const auto& x : v)
          text += (text.empty() ? "" : ", ") + (x.is_number() ? G(x.get<double>(), 3) : x.dump());
      } else {
        text = v.dump();
      }
      rows.push_back({k, text});
    }
    p.html().Table({"albedo solve", "value"}, rows, "scene.json albedo.summary");
  } else {
    p.Absent("scene.json records no albedo summary.");
  }
  if (!in.model) {
    p.Absent("The albedos cannot be shown: " + in.model_error);
    return;
  }
  const AlbedoResult& a = in.model->albedo;
  const int nb = static_cast<int>(in.mesh.block_names.size());
  const uint8_t unobserved_bits = kAlbedoNoObservations | kAlbedoSunUnobserved;
  // Per block: points, flagged points, mean albedos.
  std::vector<int> points(nb, 0), unobserved(nb, 0), never_shadowed(nb, 0);
  std::vector<Eigen::Vector3d> sum_sun(nb, Eigen::Vector3d::Zero()),
      sum_se(nb, Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> flag_values(in.grid.size());
  for (int i = 0; i < in.grid.size(); ++i) {
    const int b = in.grid.points[i].block;
    if (b < 0 || b >= nb) continue;
    ++points[b];
    const bool u = a.flags[i] & unobserved_bits, ns = a.flags[i] & kAlbedoNeverShadowed;
    unobserved[b] += u;
    never_shadowed[b] += ns;
    sum_sun[b] += a.rho_sun[i];
    sum_se[b] += a.rho_se[i];
    flag_values[i] = Eigen::Vector3d(u ? 1 : 0, ns ? 1 : 0, 0);
  }
  std::vector<std::vector<std::string>> rows;
  for (int b = 0; b < nb; ++b) {
    const double n = std::max(1, points[b]);
    rows.push_back(
        {in.mesh.block_names[b], std::to_string(points[b]), std::to_string(unobserved[b]),
         std::to_string(never_shadowed[b]), Rgb(sum_sun[b] / n, 3), Rgb(sum_se[b] / n, 3),
         G(b < static_cast<int>(a.retro.size()) ? a.retro[b] : 0, 3),
         LobeText(a.sun_lobes, a.summary.lobe_cost_zero, a.summary.lobe_cost_fitted, b),
         LobeText(a.sky_lobes, a.summary.sky_lobe_cost_zero, a.summary.sky_lobe_cost_fitted, b)});
  }
  p.html().Table(
      {"block", "grid points", "unobserved", "never shadowed", "mean albedo, sun set (R/G/B)",
       "mean albedo, sky+env set", "sun-term retro", "sun lobe (eq. 13, 15)",
       "sky/env lobe (eq. 13, 14)"},
      rows,
      "Per block. Unobserved: never seen while lit, or never sunlit when seen (the sun "
      "albedo is then inferred); never shadowed: eq. 11 is missing and a prior fills "
      "the sky+env albedo. Retro: the rough diffuse reflection of the sun (0 = Lambert). "
      "Lobes: rho_s (R/G/B, 1/sr), kappa = -Cxy and n of the block's specular lobe for the "
      "sun (§4.2.2) and for the sky and environment (§4.2.1, fitted where the sun has one), "
      "with the fit's cost without and with it; none where the photos show no highlight.");
  // The lobes as curves: f_s (green) for a sun 45 degrees from the normal, against the angle
  // of the view from the normal in the plane of incidence (the mirror direction at +45).
  std::vector<PlotSeries> lobe_curves;
  for (int b = 0; b < nb; ++b) {
    const SpecularLobe l = BlockLobe(a.sun_lobes, b);
    if (l.IsZero()) continue;
    PlotSeries ps;
    ps.label = in.mesh.block_names[b];
    const Eigen::Vector3d nrm = Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d u(-std::sqrt(0.5), 0, std::sqrt(0.5));
    for (int k = -88; k <= 88; k += 2) {
      const double t = k * M_PI / 180;
      ps.x.push_back(k);
      ps.y.push_back(l.Eval(nrm, u, Eigen::Vector3d(std::sin(t), 0, std::cos(t)))[1]);
    }
    lobe_curves.push_back(ps);
  }
  if (!lobe_curves.empty()) {
    PlotOptions po;
    po.title = "Sun specular lobes (green)";
    po.x.label = "view angle from the normal (deg; mirror direction at +45)";
    po.y.label = "f_s (1/sr)";
    p.html().Svg(PlotXY(lobe_curves, po).svg,
                 "Eq. 13's lobe of each glossy block for a sun 45 degrees from the normal, "
                 "in the plane of incidence.");
  }
  // The atlases of scene.json (or baked from the grid when they are missing), with the flags.
  const nlohmann::json atlas =
      j.contains("atlas") && j["atlas"].is_object() ? j["atlas"] : nlohmann::json();
  AtlasOptions ao;
  if (!atlas.is_null()) ao.texels_per_cell = atlas.value("texels_per_cell", ao.texels_per_cell);
  AtlasLayout layout;
  try {
    layout = LayoutAtlases(in.mesh, in.grid, ao);
  } catch (const std::exception& e) {
    p.Absent(std::string("The atlases cannot be laid out: ") + e.what());
    return;
  }
  if (atlas.is_null() || !atlas.contains("blocks"))
    p.Absent(
        "scene.json lists no albedo atlases (atlas/): they are baked here from the albedo "
        "grids instead.");
  p.html().Paragraph(
      "Each block's atlas: the albedo for sunlight (eq. 12) and for sky and environment light "
      "(eq. 11), shown as sRGB with albedo 1 white; then the sun albedo in grey with the flagged "
      "points in colour: red unobserved, blue never shadowed, magenta both.");
  std::string missing;
  for (int b = 0; b < nb; ++b) {
    if (layout.width[b] == 0) continue;
    const std::string& name = in.mesh.block_names[b];
    Image sets[2];
    bool from_file = false;
    if (!atlas.is_null() && atlas.contains("blocks") && atlas["blocks"].contains(name)) {
      const auto& e = atlas["blocks"][name];
      std::string problem;
      std::optional<Image> sun = ReadAtlas(in.scene_dir, e.value("sun", ""), &problem);
      std::optional<Image> se = ReadAtlas(in.scene_dir, e.value("se", ""), &problem);
      if (sun && se && sun->width == layout.width[b] && sun->height == layout.height[b] &&
          se->width == sun->width && se->height == sun->height) {
        sets[0] = std::move(*sun);
        sets[1] = std::move(*se);
        from_file = true;
      } else {
        missing +=
            " " + name + (problem.empty() ? ": not the size of its layout" : ": " + problem) + ";";
      }
    }
    if (!from_file) {
      sets[0] = BakeAtlas(layout, in.grid, a.rho_sun, b);
      sets[1] = BakeAtlas(layout, in.grid, a.rho_se, b);
    }
    const Image flags = BakeAtlas(layout, in.grid, flag_values, b);
    Image marked = Srgb(sets[0], 1.0);
    for (int y = 0; y < marked.height; ++y)
      for (int x = 0; x < marked.width; ++x) {
        const float grey =
            (marked.at(x, y, 0) + marked.at(x, y, 1) + marked.at(x, y, 2)) / 3 * 0.6f;
        const bool u = flags.at(x, y, 0) >= 0.5f, ns = flags.at(x, y, 1) >= 0.5f;
        marked.at(x, y, 0) = u ? 230 : ns ? 30 : grey;
        marked.at(x, y, 1) = u || ns ? 30 : grey;
        marked.at(x, y, 2) = ns ? 230 : u ? 30 : grey;
      }
    const int w = std::clamp(layout.width[b] * 2, 120, 300);
    p.html().Heading(name + (from_file ? "" : " (baked from the albedo grids)"));
    p.html().BeginRow();
    p.html().Picture(Srgb(sets[0], 1.0), name + ": sun albedo", w, true);
    p.html().Picture(Srgb(sets[1], 1.0), name + ": sky+environment albedo", w, true);
    p.html().Picture(marked, name + ": flagged points", w, true);
    p.html().EndRow();
  }
  if (!missing.empty())
    p.Absent("Atlas files missing or unreadable, baked from the albedo grids instead:" + missing);
}

void Validations(Page& p, const ReportRequest& r, const Inputs& in) {
  p.Section("validation", "Validation");
  bool any = false;
  if (r.validation) {
    any = true;
    const Validation& v = *r.validation;
    p.html().Paragraph(
        "Slot " + std::to_string(v.slot) +
        (v.held_out ? ", held out of the albedos: a prediction."
                    : ", NOT held out of the albedos: a fit, not a prediction.") +
        " Each architecture photo (merged to radiance) beside the scene rendered at its camera "
        "and time, under the lighting measured at that slot and under lighting predicted from "
        "the other slots only (§5); error maps (render − photo) / photo over the scored pixels, "
        "blue −25% to red +25%, grey not scored.");
    auto row = [](const std::string& what, const RenderMetrics& m) {
      return std::vector<std::string>{what,
                                      F(m.rel_rmse, 4),
                                      F(m.psnr_db, 2),
                                      F(m.median_rel_error, 4),
                                      F(m.mean_ratio, 4),
                                      std::to_string(m.pixels)};
    };
    std::vector<std::vector<std::string>> rows;
    for (const PhotoValidation& ph : v.photos) {
      rows.push_back(row(ph.view + ", measured lighting", ph.measured));
      if (ph.predicted) rows.push_back(row(ph.view + ", predicted lighting", *ph.predicted));
    }
    rows.push_back(row("all photos, measured lighting", v.measured));
    if (v.predicted) rows.push_back(row("all photos, predicted lighting", *v.predicted));
    p.html().Table({"photo", "rel. RMSE", "PSNR (dB)", "median rel. error", "ratio", "pixels"},
                   rows, "Figures as rouen validate computes them (render/metrics.h)");
    MetricsOptions mo;
    if (in.response && in.response->valid()) mo.response = &*in.response;
    auto error_map = [&](const Image& rendered, const PhotoValidation& ph) {
      const Image d = RelativeDifference(rendered, ph.photo, ph.mask, mo);
      Image out(d.width, d.height, 3, PixelUnits::kDigital);
      for (int y = 0; y < d.height; ++y)
        for (int x = 0; x < d.width; ++x) {
          const size_t i = static_cast<size_t>(y) * d.width + x;
          const bool ok = ph.mask.empty() || ph.mask[i];
          Diverging((d.at(x, y, 0) + d.at(x, y, 1) + d.at(x, y, 2)) / 3, 0.25, ok,
                    &out.at(x, y, 0));
        }
      return out;
    };
    for (const PhotoValidation& ph : v.photos) {
      p.html().Heading(ph.view);
      p.html().BeginRow();
      p.html().Picture(Shrink(Preview(ph.photo, ph.photo, in.response), 240), "photo");
      p.html().Picture(Shrink(Preview(ph.rendered_measured, ph.photo, in.response), 240),
                       "render, measured lighting (rel. RMSE " + F(ph.measured.rel_rmse, 3) + ")");
      if (ph.predicted && !ph.rendered_predicted.empty())
        p.html().Picture(
            Shrink(Preview(ph.rendered_predicted, ph.photo, in.response), 240),
            "render, predicted lighting (rel. RMSE " + F(ph.predicted->rel_rmse, 3) + ")");
      p.html().EndRow();
      p.html().BeginRow();
      p.html().Picture(Shrink(error_map(ph.rendered_measured, ph), 240),
                       "error, measured lighting");
      if (ph.predicted && !ph.rendered_predicted.empty())
        p.html().Picture(Shrink(error_map(ph.rendered_predicted, ph), 240),
                         "error, predicted lighting");
      p.html().EndRow();
    }
  }
  for (const fs::path& file : r.metrics) {
    nlohmann::json m;
    try {
      m = nlohmann::json::parse(ReadFileToString(file));
    } catch (const std::exception& e) {
      p.Absent(file.string() + " cannot be read: " + e.what());
      continue;
    }
    any = true;
    // Every number, nested keys joined with '.', in the file's order.
    std::vector<std::vector<std::string>> rows;
    std::function<void(const nlohmann::json&, const std::string&)> walk =
        [&](const nlohmann::json& x, const std::string& key) {
          if (x.is_object()) {
            for (const auto& [k, v] : x.items()) walk(v, key.empty() ? k : key + "." + k);
          } else if (x.is_array()) {
            for (size_t i = 0; i < x.size(); ++i) {
              const std::string name =
                  x[i].is_object() && x[i].contains("view") && x[i]["view"].is_string()
                      ? x[i]["view"].get<std::string>()
                      : std::to_string(i);
              walk(x[i], key + "[" + name + "]");
            }
          } else if (x.is_number_float()) {
            rows.push_back({key, G(x.get<double>(), 5)});
          } else if (!x.is_string() || key.find("view") == std::string::npos) {
            rows.push_back({key, x.is_string() ? x.get<std::string>() : x.dump()});
          }
        };
    walk(m, "");
    p.html().Heading(file.filename().string());
    p.html().Table({"figure", "value"}, rows, file.string());
  }
  if (!any)
    p.Absent(
        "No validation results given: rouen report --validate SLOT --session S renders and "
        "compares a slot's photos; --metrics FILE shows the figures of rouen validate --json "
        "or of rouen demo (metrics.json).");
}

void Timings(Page& p, const Inputs& in) {
  p.Section("timings", "Timings");
  const nlohmann::json& j = in.scene;
  if (!j.contains("timings") || !j["timings"].is_array() || j["timings"].empty()) {
    p.Absent(
        "scene.json records no timings of the solve's stages (a scene written before they "
        "were recorded).");
    return;
  }
  std::vector<std::string> labels;
  std::vector<double> seconds;
  std::vector<std::vector<std::string>> rows;
  double total = 0;
  for (const auto& t : j["timings"]) {
    if (!t.is_object()) continue;
    const std::string stage = t.value("stage", std::string("?"));
    const double s = t.contains("seconds") && t["seconds"].is_number() ? t["seconds"].get<double>()
                                                                       : std::nan("");
    labels.push_back(stage);
    seconds.push_back(s);
    if (std::isfinite(s)) total += s;
    rows.push_back({stage, F(s, 2)});
  }
  rows.push_back({"total", F(total, 2)});
  BarOptions bo;
  bo.title = "Solve stages";
  bo.value_label = "seconds";
  bo.width = 760;
  bo.format = [](double v) { return F(v, 2) + " s"; };
  p.html().Svg(PlotBars(labels, seconds, bo).svg,
               "Wall-clock seconds of each stage of the solve that wrote the scene.");
  p.html().Table({"stage", "seconds"}, rows);
}

}  // namespace

std::string BuildReport(const ReportRequest& request, ReportSummary* summary) {
  const auto t0 = std::chrono::steady_clock::now();
  ReportSummary local;
  ReportSummary& sum = summary ? *summary : local;
  sum = ReportSummary{};
  const Inputs in = LoadInputs(request);
  std::string subtitle = "rouen report of " + request.scene.string();
  if (!in.slots.empty())
    subtitle +=
        ", captured " + in.slots.front().utc.Iso8601(0) + " to " + in.slots.back().utc.Iso8601(0);
  // The environment's photometric stereo, the report's longest computation, fitted while the
  // sections before it are written.
  StereoFit stereo_fit(in);
  HtmlReport html("rouen scene report", subtitle);
  Page page(&html, &sum);
  // Each section on its own: one that fails says so and the others still come.
  auto section = [&](const char* id, const char* title, const std::function<void()>& body) {
    Say(request.log, title);
    const size_t before = sum.sections.size();
    try {
      body();
    } catch (const std::exception& e) {
      if (sum.sections.size() == before) page.Section(id, title);
      page.Absent(std::string("This section could not be completed: ") + e.what());
    }
  };
  section("overview", "Scene", [&] { Overview(page, request, in); });
  section("timeline", "Capture timeline", [&] { Timeline(page, request, in); });
  section("sunpath", "Sun path and capture times", [&] { SunPath(page, in); });
  section("response", "Camera response", [&] { Response(page, in); });
  section("sky", "Sky fits", [&] { Sky(page, request, in); });
  section("environment", "Environment", [&] { Environment(page, in, &stereo_fit); });
  section("albedo", "Albedos", [&] { Albedo(page, in); });
  section("validation", "Validation", [&] { Validations(page, request, in); });
  section("timings", "Timings", [&] { Timings(page, in); });
  std::string text = html.Finish();
  sum.plots = html.plots();
  sum.images = html.images();
  sum.bytes = text.size();
  sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return text;
}

ReportSummary WriteReport(const ReportRequest& request, const fs::path& out) {
  ReportSummary summary;
  const std::string text = BuildReport(request, &summary);
  WriteFileAtomic(out, text);
  return summary;
}

}  // namespace rouen
