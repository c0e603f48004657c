// rouen timelapse: a solved scene's building through one local day, sunrise to sunset, as EXR
// and PNG frames at one exposure and, when ffmpeg is installed, an MP4.
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "app/render_options.h"
#include "app/stop_signal.h"
#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/outputs.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"
#include "pipeline/timelapse.h"

namespace rouen {
namespace {

struct TimelapseArgs {
  std::string scene, out, date, from = "sunrise", to = "sunset", step = "10min", tz;
  CameraArgs camera;
  PredictionArgs prediction;
  double exposure = 0;
  double fps = 12;
  bool no_video = false;
};

void Run(const TimelapseArgs& a) {
  namespace fs = std::filesystem;
  // Every option and the output folder before the scene is read.
  TimelapseSchedule schedule;
  schedule.date = ParseLocalDate(a.date, "--date");
  schedule.from = a.from;
  schedule.to = a.to;
  if (a.from != "sunrise") ParseClockSeconds(a.from, "--from");
  if (a.to != "sunset") ParseClockSeconds(a.to, "--to");
  schedule.step_s = ParseDurationSeconds(a.step, 86400, "--step");
  Mp4Options mp4;
  mp4.fps = a.fps;
  mp4.Validate();
  RenderRequest request;
  ApplyPrediction(a.prediction, &request.relight);
  const bool own_camera = CameraFromArgs(a.camera, &request.intrinsics, &request.pose);
  CheckWritableFolder("--out", a.out);
  const fs::path video = fs::path(a.out) / "timelapse.mp4";

  auto say = [](const std::string& s) { std::fprintf(stderr, "timelapse: %s\n", s.c_str()); };
  const LoadedScene scene = LoadScene(a.scene, say);
  if (!own_camera) {
    const SceneView& view = FindView(scene, a.camera.view);
    request.intrinsics = view.intrinsics;
    request.pose = view.pose;
  }
  // The local day: --tz, else the site's longitude rounded to the hour (scenes record no zone).
  schedule.utc_offset_minutes = a.tz.empty() ? LongitudeUtcOffsetMinutes(scene.scene.site)
                                             : ParseUtcOffsetMinutes(a.tz, "--tz");
  const std::string zone = "UTC" + FormatUtcOffset(schedule.utc_offset_minutes);
  say("local time " + zone +
      (a.tz.empty() ? " (from the site's longitude " + FormatNumber(scene.scene.site.lon_deg) +
                          " deg rounded to the hour; give --tz for the civil zone, e.g. summer "
                          "time)"
                    : " (--tz)"));
  const TimelapseTimes times = TimelapseTimesOf(scene.scene.site, schedule);
  const Daylight& d = times.daylight;
  say("sun above " + FormatNumber(schedule.min_elevation_deg) + " deg from " +
      FormatLocalClock(d.sunrise, schedule.utc_offset_minutes) + " to " +
      FormatLocalClock(d.sunset, schedule.utc_offset_minutes) + " (highest " +
      FormatNumber(d.highest_elevation_deg) + " deg at " +
      FormatLocalClock(d.highest, schedule.utc_offset_minutes) + "); " +
      std::to_string(times.times.size()) + " frames " +
      FormatLocalClock(times.times.front(), schedule.utc_offset_minutes) + " to " +
      FormatLocalClock(times.times.back(), schedule.utc_offset_minutes));

  TimelapseOptions options;
  options.exposure = a.exposure;
  ProgressLine line(true);
  StopOnSignals stop;
  const TimelapseSummary summary =
      RenderTimelapse(scene, request, times.times, a.out, options, [&](const TimelapseProgress& p) {
        char text[160];
        std::snprintf(text, sizeof text, "timelapse: frame %d/%d %s %s, sun %.1f deg, %.2f s/frame",
                      p.done, p.total,
                      FormatLocalClock(p.time, schedule.utc_offset_minutes).c_str(), zone.c_str(),
                      p.sun_elevation_deg, p.seconds / p.done);
        line.Update(text);
        return !stop.flag()->load();
      });
  line.Done();
  const double per_frame = summary.seconds / static_cast<double>(summary.exrs.size());
  std::printf(
      "%s: %zu frames %dx%d (EXR radiance and PNG), %s to %s %s, PNG exposure factor "
      "%.4g, %.3f s per frame\n",
      a.out.c_str(), summary.exrs.size(), summary.width, summary.height,
      FormatLocalClock(summary.times.front(), schedule.utc_offset_minutes).c_str(),
      FormatLocalClock(summary.times.back(), schedule.utc_offset_minutes).c_str(), zone.c_str(),
      summary.exposure, per_frame);
  if (summary.stopped) {
    std::printf("stopped by a signal after %zu of %zu frames: those are kept, no video made\n",
                summary.exrs.size(), times.times.size());
    throw ExitStatus{128 + stop.signal()};
  }
  if (a.no_video) return;
  if (FindOnPath("ffmpeg").empty()) {
    std::printf(
        "no MP4: ffmpeg is not on PATH (Debian: apt-get install ffmpeg); the frames are "
        "kept\n");
    return;
  }
  const uintmax_t bytes = EncodeMp4(summary.pngs, video, mp4);
  std::printf("%s: H.264 MP4, %zu frames at %g fps, %ju bytes\n", video.string().c_str(),
              summary.pngs.size(), mp4.fps, bytes);
}

}  // namespace

void RegisterTimelapse(CLI::App& app) {
  auto a = std::make_shared<TimelapseArgs>();
  CLI::App* c = app.add_subcommand("timelapse", CommandSummary("timelapse"));
  c->footer(
      "Renders the building under lighting predicted for each time of one local day (as `rouen\n"
      "render --time`: sun from the site and time, sky interpolated, environment from its\n"
      "normals, paper §5), from the scene loaded once. Times are local clock times on --date at\n"
      "the offset --tz (default: the site's longitude / 15 deg rounded to the hour, which can\n"
      "differ from the civil zone by an hour or more; the zone used is printed).\n"
      "  --from sunrise|HH:MM  --to sunset|HH:MM  --step 10min\n"
      "Sunrise and sunset are when the sun's apparent elevation crosses 1 deg (rendering needs\n"
      "the sun above the horizon). From sunrise the frames fall on the step's grid from local\n"
      "midnight (06:10, 06:20, ...), the first at or after sunrise; from a clock time, on that\n"
      "time plus multiples of the step. A clock time when the sun is below 1 deg is refused.\n"
      "--out DIR gets one RGBA radiance EXR (header: time, sun, camera, as rouen render writes)\n"
      "and one PNG per frame, named by the UTC time (20260825T194000Z.exr), all PNGs at one\n"
      "exposure (--exposure, else automatic on the frame with the highest sun), so the day\n"
      "darkens and reddens towards sunset as the light does; then, when ffmpeg is on PATH,\n"
      "DIR/timelapse.mp4 (H.264, yuv420p, --fps frames a second). Without ffmpeg the frames are\n"
      "kept and the command says so. Ctrl-C stops after the frame in flight; frames written are\n"
      "kept whole.\n"
      "The camera is one of the scene's views (--view), a lens and a pose file, or a new camera\n"
      "(--look-at/--from-point with --fov and --size), as for rouen render.\n"
      "Example: rouen timelapse s.scene --date 2026-08-25 --tz -07:00 --from sunrise --to sunset\n"
      "           --step 10min --look-at 0,0,10 --from-point 40,-30,5 --out day/");
  c->add_option("scene", a->scene, "Scene folder (from rouen solve)")->required();
  c->add_option("--date", a->date, "Local date of the day, YYYY-MM-DD")->required();
  c->add_option("--from", a->from, "First time: sunrise or a local clock time HH:MM")
      ->capture_default_str();
  c->add_option("--to", a->to, "Last time: sunset or a local clock time HH:MM")
      ->capture_default_str();
  c->add_option("--step", a->step, "Time between frames (e.g. 10min, 1h, 30s)")
      ->capture_default_str();
  c->add_option("--tz", a->tz,
                "Local time's offset from UTC, +HH:MM or -HH:MM (default: from the site's "
                "longitude)");
  AddCameraOptions(c, &a->camera);
  AddPredictionOptions(c, &a->prediction, kSkyInterpOption | kPbsOption);
  c->add_option("--exposure", a->exposure,
                "PNG exposure factor for every frame (default: automatic at the highest sun)")
      ->check(Positive());
  c->add_option("--fps", a->fps, "Frames per second of the MP4")
      ->check(Within(0.1, 240))
      ->capture_default_str();
  c->add_flag("--no-video", a->no_video, "Write the frames only, even when ffmpeg is installed");
  c->add_option("--out", a->out, "Folder for the frames and timelapse.mp4")->required();
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
