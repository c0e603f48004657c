// A time-lapse of a solved scene: the times of one local day from sunrise to sunset (or between
// two clock times), the frames rendered from the scene loaded once (pipeline/scene.h), one
// exposure for the whole day, and an MP4 through ffmpeg when it is installed.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/solar.h"
#include "core/time.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"

namespace rouen {

// A frame of a sequence is named by its time (UTC): 20260825T194000Z (rouen render --from and
// rouen timelapse).
std::string SequenceFrameName(UtcTime t);

// A civil date at the site (the local day a time-lapse covers).
struct LocalDate {
  int year = 0, month = 0, day = 0;
};
// "YYYY-MM-DD" (a real calendar day, years 1900..2200); throws rouen::Error naming `option`.
LocalDate ParseLocalDate(const std::string& text, const std::string& option);
// "HH:MM" or "HH:MM:SS" (00:00 .. 23:59:59) as seconds after local midnight; throws rouen::Error
// naming `option`.
double ParseClockSeconds(const std::string& text, const std::string& option);
// "+HH:MM", "-HH:MM" or "Z" (offsets -12:00 .. +14:00) as minutes east of UTC; throws
// rouen::Error naming `option`.
int ParseUtcOffsetMinutes(const std::string& text, const std::string& option);
// "+02:00", "-07:00", "+05:30".
std::string FormatUtcOffset(int minutes);
// The site's mean solar zone: its longitude / 15 degrees, rounded to the hour, in minutes (the
// default when neither the user nor the scene says the zone; civil zones and summer time may
// differ by an hour or more).
int LongitudeUtcOffsetMinutes(const Site& site);
// "HH:MM:SS" of `t` at `offset_minutes` east of UTC.
std::string FormatLocalClock(UtcTime t, int offset_minutes);

// The sun must stand at least this high (apparent elevation, degrees) for a frame: rendering
// needs the sun above the horizon, and a degree keeps the refraction-dominated, air-mass-40 sun
// at the horizon out of a sequence.
constexpr double kTimelapseMinElevationDeg = 1.0;

// The part of a local day (midnight to midnight at the offset) when the sun is at or above a
// threshold: the interval around the sun's highest point.
struct Daylight {
  UtcTime midnight;         // local midnight starting the day
  UtcTime sunrise, sunset;  // first and last instants (to 1 s) at or above the threshold
  UtcTime highest;          // the sun's highest point (to 5 minutes)
  double highest_elevation_deg = 0;
  bool up_at_midnight = false;  // polar day: sunrise is the day's start (or sunset its end)
};
// Throws rouen::Error when the sun stays below `threshold_deg` all day (polar night).
Daylight DaylightOf(const Site& site, const LocalDate& date, int utc_offset_minutes,
                    double threshold_deg = kTimelapseMinElevationDeg);

// Which times of the day: --from "sunrise" or a clock time, --to "sunset" or a clock time, every
// `step_s` seconds. Frames are on a grid: from a clock time, that time plus multiples of the
// step; from sunrise, local midnight plus multiples of the step (10min: 06:10, 06:20, ...), the
// first at or after sunrise; the last at or before --to (or sunset).
struct TimelapseSchedule {
  LocalDate date;
  int utc_offset_minutes = 0;
  std::string from = "sunrise", to = "sunset";
  double step_s = 600;
  double min_elevation_deg = kTimelapseMinElevationDeg;
  int max_frames = 5000;
};
struct TimelapseTimes {
  std::vector<UtcTime> times;
  Daylight daylight;
};
// Throws rouen::Error naming --from, --to or --step: a malformed clock time, --to not after
// --from, a clock time when the sun is below the threshold (before sunrise or after sunset, with
// both said in local time), no frame in the span, more than max_frames.
TimelapseTimes TimelapseTimesOf(const Site& site, const TimelapseSchedule& schedule);

// Refuses a sequence of `frames` frames (counted in floating point, so a step of 1e-300 s is
// counted, not overflowed) when it is more than `max_frames`: rouen::Error naming
// --from/--to/--step with both counts.
void CheckFrameCount(double frames, int max_frames);

struct TimelapseOptions {
  bool png = true;      // also 8-bit PNGs through the response (sRGB when the photos were HDR)
  double exposure = 0;  // PNG exposure factor; 0: automatic on the frame with the highest sun
};
struct TimelapseProgress {
  int done = 0, total = 0;  // frames written so far, of
  UtcTime time;             // the frame just written
  double sun_elevation_deg = 0;
  double seconds = 0;  // since the start
};
struct TimelapseSummary {
  std::vector<UtcTime> times;     // of the frames written, in time order
  std::vector<std::string> exrs;  // DIR/<name>.exr, in time order
  std::vector<std::string> pngs;  // DIR/<name>.png (with options.png)
  double exposure = 0;
  int width = 0, height = 0;
  double seconds = 0;  // rendering and writing
  bool stopped = false;
};
// Renders `base` (camera and relighting options; its slot and time are ignored) at each time
// into `out` (created): RGBA radiance EXRs with RenderSceneView's header, and PNGs all at one
// exposure, so the sequence darkens towards sunset as the light does. Every time is checked
// (CheckRenderRequest) and the folder's writability before any work. The frame with the highest
// sun is rendered first (it sets the automatic exposure), then the others in time order; each
// frame's files are written whole (OutputSet). `progress` after each frame: returning false
// stops after it, keeping the frames written (summary.stopped).
TimelapseSummary RenderTimelapse(
    const LoadedScene& scene, const RenderRequest& base, const std::vector<UtcTime>& times,
    const std::filesystem::path& out, const TimelapseOptions& options,
    const std::function<bool(const TimelapseProgress&)>& progress = {});

struct Mp4Options {
  double fps = 12;
  std::string ffmpeg = "ffmpeg";  // a name looked up on PATH, or a path
  void Validate() const;          // fps in 0.1..240
};
// Encodes the PNG frames, in order, as H.264 (yuv420p, odd sizes padded to even) in an MP4 at
// `out`, written to a temporary and renamed when ffmpeg succeeded. Throws rouen::Error when
// ffmpeg is not found or fails (with the end of its messages), leaving no file at `out`.
// Returns the file's size in bytes.
uintmax_t EncodeMp4(const std::vector<std::string>& pngs, const std::filesystem::path& out,
                    const Mp4Options& options);

}  // namespace rouen
