// rouen plan: the capture times of one day that show every face of a model both sunlit and in
// shadow (what §4.1 needs to separate the sun and sky+environment albedos).
#include <cstdio>
#include <memory>
#include <string>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/mesh.h"
#include "core/outputs.h"
#include "pipeline/plan.h"

namespace rouen {
namespace {

struct PlanArgs {
  std::string model, site, date, tz, views, step = "15min", from = "sunrise", to = "sunset", json;
  double spacing = 1.0;
  double min_elevation = 5;
  int max_times = 5;
};

void Run(const PlanArgs& a) {
  PlanOptions o;
  o.site = ParseSiteOption(a.site, "--site");
  o.schedule.date = ParseLocalDate(a.date, "--date");
  o.schedule.utc_offset_minutes =
      a.tz.empty() ? LongitudeUtcOffsetMinutes(o.site) : ParseUtcOffsetMinutes(a.tz, "--tz");
  o.schedule.step_s = ParseDurationSeconds(a.step, 86400, "--step");
  o.schedule.from = a.from;
  o.schedule.to = a.to;
  if (a.from != "sunrise") ParseClockSeconds(a.from, "--from");
  if (a.to != "sunset") ParseClockSeconds(a.to, "--to");
  o.schedule.min_elevation_deg = a.min_elevation;
  o.spacing_m = a.spacing;
  o.max_times = a.max_times;
  o.Validate();
  OutputSet outputs;
  const std::string json_temp =
      a.json.empty() ? std::string() : outputs.Add("--json", a.json, OutputKind::kFile);
  if (!a.views.empty()) o.views = ReadPlanViews(a.views);
  const Mesh mesh = ReadObj(a.model);
  const std::string zone = "UTC" + FormatUtcOffset(o.schedule.utc_offset_minutes);
  std::fprintf(stderr, "plan: local time %s%s\n", zone.c_str(),
               a.tz.empty() ? " (from the site's longitude rounded to the hour; give --tz for "
                              "the civil zone)"
                            : " (--tz)");
  const PlanResult plan = PlanCapture(
      mesh, o, [](const std::string& s) { std::fprintf(stderr, "plan: %s\n", s.c_str()); });
  const int tz = o.schedule.utc_offset_minutes;

  std::printf("%s on %s at %s: sun above %g deg from %s to %s %s; %zu candidate times every %s\n",
              a.model.c_str(), a.date.c_str(), a.site.c_str(), o.schedule.min_elevation_deg,
              FormatLocalClock(plan.daylight.sunrise, tz).c_str(),
              FormatLocalClock(plan.daylight.sunset, tz).c_str(), zone.c_str(),
              plan.candidates.size(), a.step.c_str());
  std::printf(
      "\nSchedule (%zu capture times%s; pairs: the (point, sunlit) and (point, shadowed) "
      "pairs each time adds, faces: the same in fractions of their faces):\n",
      plan.chosen.size(),
      o.views.empty() ? ", every point assumed seen"
                      : (", seen by " + std::to_string(o.views.size()) + " views").c_str());
  std::printf("  %-8s %-20s %7s %7s %7s %7s %6s %6s\n", "local", "UTC", "sun az", "sun el",
              "sunlit", "shadow", "pairs", "faces");
  for (const PlanTime& t : plan.chosen)
    std::printf("  %-8s %-20s %7.1f %7.1f %7d %7d %6d %6.2f\n",
                FormatLocalClock(t.time, tz).c_str(), t.time.Iso8601(0).c_str(), t.sun_azimuth_deg,
                t.sun_elevation_deg, t.sunlit, t.shadowed, t.gain, t.face_gain);
  std::printf(
      "\nCoverage (percent of each face's grid points both sunlit and in shadow at the "
      "chosen times; a face is a block's triangles in one plane):\n");
  std::printf("  %3s %-16s %-9s %8s %7s %8s  %s\n", "#", "block", "facing", "area m2", "points",
              "covered", "cannot be covered");
  for (size_t n = 0; n < plan.faces.size(); ++n) {
    const PlanFace& f = plan.faces[n];
    std::string lacks;
    auto add = [&](int count, const char* what) {
      if (count == 0) return;
      lacks += (lacks.empty() ? "" : ", ") + std::to_string(count) + " " + what;
    };
    add(f.never_sunlit, "never sunlit");
    add(f.never_shadowed, "never shadowed");
    add(f.unseen, "unseen");
    std::printf("  %3zu %-16s %-9s %8.1f %7d %7.1f%%  %s\n", n, f.block_name.c_str(),
                f.facing.c_str(), f.area_m2, f.points, f.CoveredPercent(), lacks.c_str());
  }
  std::printf("\n%d of %d grid points covered (%d coverable on this date%s), %.2f s\n",
              plan.covered, plan.points, plan.coverable,
              plan.covered < plan.coverable ? "; more --max-times would cover more" : "",
              plan.seconds);
  if (!a.json.empty()) {
    WriteFileAtomic(json_temp, PlanToJson(plan, o).dump(2) + "\n");
    outputs.Commit();
    std::printf("%s: the plan as JSON\n", a.json.c_str());
  }
}

}  // namespace

void RegisterPlan(CLI::App& app) {
  auto a = std::make_shared<PlanArgs>();
  CLI::App* c = app.add_subcommand("plan", CommandSummary("plan"));
  c->footer(
      "Separating the sun albedo from the sky+environment albedo (paper §4.1, eqs. 11-12) needs\n"
      "each point photographed once in the sun and once in shadow. plan samples the model's\n"
      "surface (a grid of --spacing metres), casts each point's ray to the sun at every\n"
      "--step of the day (sun at least --min-elevation up), and chooses capture times by\n"
      "greedy set cover: first the time adding the most (point, sunlit) and (point, shadowed)\n"
      "pairs, until every coverable point is both or --max-times are chosen.\n"
      "A point is sunlit when the sun is unoccluded and at least ~6 deg above its plane (cosine\n"
      "0.1), in shadow when occluded or behind its plane. A face (a block's triangles in one\n"
      "plane) reports the percent of its points covered, and those that can never be covered on\n"
      "that date: never sunlit (a north wall in winter), never shadowed (an open roof), unseen.\n"
      "With --views (a JSON list of {\"name\", \"intrinsics\", \"pose\"}, as lens and pose files\n"
      "hold them) a point counts only when some view sees it; otherwise every point is seen.\n"
      "Times are local on --date at --tz (default: the site's longitude rounded to the hour).\n"
      "Example: rouen plan --model session/model.obj --site 37.8722,-122.2578,60 "
      "--date 2026-08-25 \\\n           --tz -07:00 --json plan.json");
  c->add_option("--model", a->model, "Building model (OBJ; groups are blocks)")->required();
  c->add_option("--site", a->site, "Site LAT,LON,H (degrees north, degrees east, metres)")
      ->required();
  c->add_option("--date", a->date, "Local date of the capture, YYYY-MM-DD")->required();
  c->add_option("--tz", a->tz, "Local time's offset from UTC, +HH:MM or -HH:MM");
  c->add_option("--views", a->views, "Cameras JSON (default: every point is seen)");
  c->add_option("--step", a->step, "Time between candidate times (e.g. 15min)")
      ->capture_default_str();
  c->add_option("--from", a->from, "First candidate time: sunrise or HH:MM")->capture_default_str();
  c->add_option("--to", a->to, "Last candidate time: sunset or HH:MM")->capture_default_str();
  c->add_option("--min-elevation", a->min_elevation, "Lowest sun for a capture (deg)")
      ->check(Within(0.5, 60, "deg"))
      ->capture_default_str();
  c->add_option("--spacing", a->spacing, "Grid spacing of the surface points (m)")
      ->check(Within(0.01, 100, "m"))
      ->capture_default_str();
  c->add_option("--max-times", a->max_times, "At most this many capture times")
      ->check(Within(1, 100))
      ->capture_default_str();
  c->add_option("--json", a->json, "Also write the plan as JSON to this file");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
