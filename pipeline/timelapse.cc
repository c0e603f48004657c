#include "pipeline/timelapse.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/limits.h"
#include "core/outputs.h"
#include "core/process.h"
#include "core/text.h"
#include "pipeline/export.h"
#include "render/tonemap.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

constexpr double kDay = 86400;

// Digits only, all of them: "07" -> 7; -1 for anything else.
int Digits(const std::string& s) {
  if (s.empty() || s.size() > 4) return -1;
  int v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return -1;
    v = v * 10 + (c - '0');
  }
  return v;
}

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> parts;
  std::string item;
  std::stringstream ss(s);
  while (std::getline(ss, item, sep)) parts.push_back(item);
  if (!s.empty() && s.back() == sep) parts.push_back("");
  return parts;
}

double Elevation(const Site& site, UtcTime t) { return ComputeSunPosition(t, site).elevation_deg; }

// The instant (to 1 s) between `below` and `above` where the elevation reaches `threshold`: the
// returned time is at or above it.
UtcTime Crossing(const Site& site, UtcTime below, UtcTime above, double threshold) {
  while (std::abs(above.UnixSeconds() - below.UnixSeconds()) > 1) {
    const UtcTime mid =
        below.PlusSeconds(std::round((above.UnixSeconds() - below.UnixSeconds()) / 2));
    (Elevation(site, mid) >= threshold ? above : below) = mid;
  }
  return above;
}

std::string LocalClockMessage(UtcTime t, int offset) {
  return FormatLocalClock(t, offset) + " (UTC" + FormatUtcOffset(offset) + ")";
}

}  // namespace

std::string SequenceFrameName(UtcTime t) {
  const CivilTime c = ToCivil(t);
  const std::string name = Formatted("%04d%02d%02dT%02d%02d%02dZ", c.year, c.month, c.day, c.hour,
                                     c.minute, static_cast<int>(c.second));
  return name;
}

LocalDate ParseLocalDate(const std::string& text, const std::string& option) {
  const std::vector<std::string> p = Split(text, '-');
  const std::string where = option + " '" + text + "'";
  if (p.size() != 3 || p[0].size() != 4 || p[1].size() != 2 || p[2].size() != 2)
    throw Error(where + ": expected a date YYYY-MM-DD, e.g. 2026-08-25");
  LocalDate d{Digits(p[0]), Digits(p[1]), Digits(p[2])};
  if (d.year < 1900 || d.year > 2200 || d.month < 1 || d.month > 12 || d.day < 1)
    throw Error(where + ": not a date between 1900 and 2200 (YYYY-MM-DD)");
  // A real day of that month: the civil date round-trips.
  const CivilTime back = ToCivil(FromCivil({d.year, d.month, d.day, 12, 0, 0}));
  if (back.month != d.month || back.day != d.day)
    throw Error(where + ": there is no such day in that month");
  return d;
}

double ParseClockSeconds(const std::string& text, const std::string& option) {
  const std::vector<std::string> p = Split(text, ':');
  const std::string where = option + " '" + text + "'";
  if (p.size() < 2 || p.size() > 3)
    throw Error(where + ": expected a local clock time HH:MM (or HH:MM:SS), e.g. 07:30");
  int v[3] = {0, 0, 0};
  for (size_t k = 0; k < p.size(); ++k) {
    v[k] = p[k].size() == 2 ? Digits(p[k]) : -1;
    if (v[k] < 0) throw Error(where + ": expected two digits in each of HH:MM (e.g. 07:30)");
  }
  if (v[0] > 23 || v[1] > 59 || v[2] > 59)
    throw Error(where + ": not a time of day (00:00 .. 23:59:59)");
  return v[0] * 3600.0 + v[1] * 60.0 + v[2];
}

int ParseUtcOffsetMinutes(const std::string& text, const std::string& option) {
  const std::string where = option + " '" + text + "'";
  if (text == "Z" || text == "z") return 0;
  const std::vector<std::string> p = Split(text.size() > 1 ? text.substr(1) : "", ':');
  const int h = p.size() == 2 && p[0].size() == 2 ? Digits(p[0]) : -1;
  const int m = p.size() == 2 && p[1].size() == 2 ? Digits(p[1]) : -1;
  if ((text[0] != '+' && text[0] != '-') || h < 0 || m < 0 || m > 59)
    throw Error(where + ": expected an offset from UTC +HH:MM or -HH:MM (e.g. -07:00) or Z");
  const int minutes = (text[0] == '-' ? -1 : 1) * (h * 60 + m);
  if (minutes < -12 * 60 || minutes > 14 * 60)
    throw Error(where + ": offsets from UTC run from -12:00 to +14:00");
  return minutes;
}

std::string FormatUtcOffset(int minutes) {
  const int a = std::abs(minutes);
  return Formatted("%c%02d:%02d", minutes < 0 ? '-' : '+', a / 60, a % 60);
}

int LongitudeUtcOffsetMinutes(const Site& site) {
  return 60 * static_cast<int>(std::lround(site.lon_deg / 15.0));
}

std::string FormatLocalClock(UtcTime t, int offset_minutes) {
  const CivilTime c = ToCivil(t.PlusSeconds(offset_minutes * 60.0));
  const std::string s = Formatted("%02d:%02d:%02d", c.hour, c.minute, static_cast<int>(c.second));
  return s;
}

Daylight DaylightOf(const Site& site, const LocalDate& date, int utc_offset_minutes,
                    double threshold_deg) {
  Daylight d;
  d.midnight =
      FromCivil({date.year, date.month, date.day, 0, 0, 0}).PlusSeconds(-60.0 * utc_offset_minutes);
  // The elevation every 5 minutes of the day; the daylight is the run around the highest sample,
  // its ends refined by bisection to the second.
  constexpr double kSample = 300;
  constexpr int kSamples = static_cast<int>(kDay / kSample);
  std::vector<double> el(kSamples + 1);
  int top = 0;
  for (int m = 0; m <= kSamples; ++m) {
    el[m] = Elevation(site, d.midnight.PlusSeconds(kSample * m));
    if (el[m] > el[top]) top = m;
  }
  d.highest = d.midnight.PlusSeconds(kSample * top);
  d.highest_elevation_deg = el[top];
  if (!(el[top] >= threshold_deg)) {
    const std::string date_text = Formatted("%04d-%02d-%02d", date.year, date.month, date.day);
    throw Error(std::string("the sun stays below ") + FormatNumber(threshold_deg) +
                " deg elevation all day on " + date_text + " at latitude " +
                FormatNumber(site.lat_deg) + " (highest " + FormatNumber(el[top]) +
                " deg): no daylight to render");
  }
  int rise = top, set = top;
  while (rise > 0 && el[rise - 1] >= threshold_deg) --rise;
  while (set < kSamples && el[set + 1] >= threshold_deg) ++set;
  d.up_at_midnight = rise == 0 || set == kSamples;
  const UtcTime rise_t = d.midnight.PlusSeconds(kSample * rise);
  const UtcTime set_t = d.midnight.PlusSeconds(kSample * set);
  d.sunrise =
      rise == 0 ? rise_t : Crossing(site, rise_t.PlusSeconds(-kSample), rise_t, threshold_deg);
  d.sunset =
      set == kSamples ? set_t : Crossing(site, set_t.PlusSeconds(kSample), set_t, threshold_deg);
  return d;
}

void CheckFrameCount(double frames, int max_frames) {
  if (frames > max_frames)
    throw Error("--from/--to/--step make " + FormatCount(frames) + " frames, more than " +
                std::to_string(max_frames) + "; take a longer --step");
}

TimelapseTimes TimelapseTimesOf(const Site& site, const TimelapseSchedule& s) {
  if (!(s.step_s > 0) || !std::isfinite(s.step_s) || s.step_s > kDay)
    throw Error("--step: must be above 0 and at most a day");
  if (!(s.min_elevation_deg > 0 && s.min_elevation_deg < 60))
    throw Error("the minimum sun elevation must be in 0..60 deg (exclusive of 0)");
  TimelapseTimes r;
  r.daylight = DaylightOf(site, s.date, s.utc_offset_minutes, s.min_elevation_deg);
  const Daylight& d = r.daylight;
  const int tz = s.utc_offset_minutes;
  const double sunrise = d.sunrise.UnixSeconds() - d.midnight.UnixSeconds();
  const double sunset = d.sunset.UnixSeconds() - d.midnight.UnixSeconds();
  const std::string daylight_text = "the sun is above " + FormatNumber(s.min_elevation_deg) +
                                    " deg from " + LocalClockMessage(d.sunrise, tz) + " to " +
                                    LocalClockMessage(d.sunset, tz);
  // Seconds after local midnight of the first and last allowed instants, and the grid's origin.
  const bool from_sunrise = s.from == "sunrise";
  const bool to_sunset = s.to == "sunset";
  const double from = from_sunrise ? sunrise : ParseClockSeconds(s.from, "--from");
  const double to = to_sunset ? sunset : ParseClockSeconds(s.to, "--to");
  if (!from_sunrise && from < sunrise)
    throw Error("--from " + s.from + " is before sunrise: " + daylight_text +
                "; rouen renders daylight only (use --from sunrise)");
  if (!to_sunset && to > sunset)
    throw Error("--to " + s.to + " is after sunset: " + daylight_text +
                "; rouen renders daylight only (use --to sunset)");
  if (!from_sunrise && from > sunset)
    throw Error("--from " + s.from + " is after sunset: " + daylight_text);
  if (!to_sunset && to < sunrise)
    throw Error("--to " + s.to + " is before sunrise: " + daylight_text);
  if (!(to > from))
    throw Error("--to " + s.to + " (" + LocalClockMessage(d.midnight.PlusSeconds(to), tz) +
                ") is not after --from " + s.from + " (" +
                LocalClockMessage(d.midnight.PlusSeconds(from), tz) + ")");
  const double origin = from_sunrise ? 0 : from;
  const double first_k = std::ceil((from - origin) / s.step_s - 1e-9);
  const double last_k = std::floor((to - origin) / s.step_s + 1e-9);
  if (last_k < first_k)
    throw Error("--step " + FormatNumber(s.step_s) + " s: no frame falls between --from and --to");
  CheckFrameCount(last_k - first_k + 1, s.max_frames);
  for (double k = first_k; k <= last_k; k += 1) {
    // Whole seconds: frame names and headers hold seconds.
    const double at = std::round(origin + k * s.step_s);
    if (at < sunrise || at > sunset) continue;  // the grid rounded outside the daylight
    r.times.push_back(d.midnight.PlusSeconds(at));
  }
  if (r.times.empty()) throw Error("--step: no frame falls between --from and --to");
  return r;
}

TimelapseSummary RenderTimelapse(const LoadedScene& scene, const RenderRequest& base,
                                 const std::vector<UtcTime>& times, const fs::path& out,
                                 const TimelapseOptions& options,
                                 const std::function<bool(const TimelapseProgress&)>& progress) {
  if (times.empty()) throw Error("a time-lapse needs at least one time");
  if (options.exposure < 0 || !std::isfinite(options.exposure))
    throw Error("--exposure must be above 0");
  if (!std::is_sorted(times.begin(), times.end()))
    throw Error("the time-lapse's times must be in order");
  std::vector<RenderRequest> requests;
  for (UtcTime t : times) {
    RenderRequest r = base;
    r.slot.reset();
    r.time = t;
    try {
      CheckRenderRequest(scene, r);
    } catch (const Error& e) {
      throw Error("at " + t.Iso8601(0) + ": " + e.what());
    }
    requests.push_back(r);
  }
  // The predictor is fitted once (§5: sun extinction, sky interpolation, environment normals);
  // each frame asks it for its time.
  const LightingPredictor predictor = PredictorFor(scene, base);
  {
    OutputSet folder;
    folder.Protect("the scene", scene.dir.string());
    folder.CreateFolder("--out", out.string());
  }

  // The highest sun first: its automatic exposure is the sequence's.
  std::vector<double> elevation(times.size());
  size_t top = 0;
  for (size_t i = 0; i < times.size(); ++i) {
    elevation[i] = ComputeSunPosition(times[i], scene.scene.site).elevation_deg;
    if (elevation[i] > elevation[top]) top = i;
  }
  std::vector<size_t> order{top};
  for (size_t i = 0; i < times.size(); ++i)
    if (i != top) order.push_back(i);

  const ResponseCurve& response = scene.scene.response;
  TimelapseSummary summary;
  summary.exposure = options.exposure;
  std::vector<bool> written(times.size(), false);
  const auto start = std::chrono::steady_clock::now();
  int done = 0;
  for (size_t i : order) {
    const std::string name = SequenceFrameName(times[i]);
    OutputSet outputs;
    const std::string exr =
        outputs.Add("--out", (out / (name + ".exr")).string(), OutputKind::kRadiance);
    const std::string png =
        options.png ? outputs.Add("--out", (out / (name + ".png")).string(), OutputKind::kImage)
                    : std::string();
    RenderedView view =
        RenderSceneViewUnder(scene, requests[i], predictor.At(times[i], scene.scene.site));
    WriteImage(exr, view.rgba, StoredType::kFloat, view.attributes);
    if (options.png) {
      if (summary.exposure <= 0)
        summary.exposure =
            response.valid() ? AutoExposure(view.rgb, response) : AutoExposureSrgb(view.rgb);
      WriteImage(png,
                 response.valid() ? ToDigital(view.rgb, response, summary.exposure)
                                  : ToSrgbDigital(view.rgb, summary.exposure),
                 StoredType::kUint8);
    }
    outputs.Commit();
    summary.width = view.rgb.width;
    summary.height = view.rgb.height;
    written[i] = true;
    ++done;
    TimelapseProgress p;
    p.done = done;
    p.total = static_cast<int>(times.size());
    p.time = times[i];
    p.sun_elevation_deg = elevation[i];
    p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (progress && !progress(p) && done < p.total) {
      summary.stopped = true;
      break;
    }
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  for (size_t i = 0; i < times.size(); ++i) {
    if (!written[i]) continue;
    const std::string name = SequenceFrameName(times[i]);
    summary.times.push_back(times[i]);
    summary.exrs.push_back((out / (name + ".exr")).string());
    if (options.png) summary.pngs.push_back((out / (name + ".png")).string());
  }
  return summary;
}

void Mp4Options::Validate() const {
  if (!(fps >= 0.1 && fps <= 240)) throw Error("--fps " + FormatNumber(fps) + ": must be 0.1..240");
}

uintmax_t EncodeMp4(const std::vector<std::string>& pngs, const fs::path& out,
                    const Mp4Options& options) {
  options.Validate();
  if (pngs.empty()) throw Error(out.string() + ": no frames to encode");
  const std::string ffmpeg = FindOnPath(options.ffmpeg);
  if (ffmpeg.empty())
    throw Error(out.string() + ": " + options.ffmpeg +
                " is not on PATH (Debian: apt-get install ffmpeg); the frames are kept");
  OutputSet outputs;
  const std::string temp = outputs.Add("--out", out.string(), OutputKind::kFile);
  // ffmpeg reads numbered frames: links 000000.png, ... to the frames in a temporary folder
  // (named as a temporary, so a crash's leftover is recognisable) that is removed afterwards.
  const fs::path links = TempPathFor(out, ".frames");
  struct RemoveLinks {
    fs::path dir;
    ~RemoveLinks() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } remove_links{links};
  fs::create_directories(links);
  for (size_t i = 0; i < pngs.size(); ++i) {
    const std::string name = Formatted("%06zu.png", i);
    fs::create_symlink(fs::absolute(pngs[i]), links / name);
  }
  // '%' is ffmpeg's pattern character: a literal one in the folder's path is written "%%".
  std::string pattern;
  for (char c : links.string()) {
    pattern.push_back(c);
    if (c == '%') pattern.push_back('%');
  }
  pattern += "/%06d.png";
  const fs::path log = links / "ffmpeg.log";
  const std::string fps = Formatted("%.6g", options.fps);
  std::vector<std::string> args = {ffmpeg,       "-nostdin",   "-hide_banner",
                                   "-loglevel",  "error",      "-y",
                                   "-framerate", fps,          "-i",
                                   pattern,      "-vf",        "pad=ceil(iw/2)*2:ceil(ih/2)*2",
                                   "-c:v",       "libx264",    "-pix_fmt",
                                   "yuv420p",    "-r",         fps,
                                   "-movflags",  "+faststart", "-f",
                                   "mp4",        temp};
  int code = 0;
  try {
    code = RunProcess(args, log);
  } catch (const Error& e) {
    throw Error(out.string() + ": " + e.what());
  }
  if (code != 0) {
    std::string messages;
    std::ifstream in(log);
    std::string line;
    std::vector<std::string> lines;
    while (std::getline(in, line)) lines.push_back(line);
    for (size_t k = lines.size() > 8 ? lines.size() - 8 : 0; k < lines.size(); ++k)
      messages += "\n  " + lines[k];
    throw Error(out.string() + ": ffmpeg " +
                (code < 128 ? "failed (exit " + std::to_string(code) + ")"
                            : "was killed (signal " + std::to_string(code - 128) + ")") +
                " encoding " + std::to_string(pngs.size()) + " frames; the frames are kept" +
                (messages.empty() ? std::string() : ":" + messages));
  }
  std::error_code ec;
  const uintmax_t bytes = fs::file_size(temp, ec);
  if (ec || bytes == 0) throw Error(out.string() + ": ffmpeg wrote no video");
  outputs.Commit();
  return bytes;
}

}  // namespace rouen
