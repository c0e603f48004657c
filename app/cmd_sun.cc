// rouen sun: solar position for a place and time, or for a CSV batch.
#include <cstdio>
#include <nlohmann/json.hpp>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/solar.h"
#include "core/text.h"

namespace rouen {
namespace {

struct SunArgs {
  double lat = 0, lon = 0, height = 0;
  std::string time, batch;
  bool json = false;
  double pressure = 1010, temperature = 10;
  bool have_lat = false, have_lon = false;
};

void RunBatch(const SunArgs& a) {
  const std::vector<std::string> lines = ReadTextLines(a.batch, "the CSV file");
  int lineno = 0;
  std::printf("utc,lat,lon,elev_m,azimuth_deg,elevation_deg,elevation_true_deg\n");
  for (const std::string& line : lines) {
    ++lineno;
    const std::string t = Trimmed(line);
    if (t.empty() || t[0] == '#') continue;
    if (lineno == 1 && t.rfind("utc", 0) == 0) continue;  // header
    const std::vector<std::string> cols = CsvFields(t);
    if (cols.size() != 4)
      throw Error(a.batch + ":" + std::to_string(lineno) +
                  ": expected 4 columns utc,lat,lon,elev_m, got " + std::to_string(cols.size()));
    Site site;
    if (!ParseDecimal(cols[1], &site.lat_deg) || !ParseDecimal(cols[2], &site.lon_deg) ||
        !ParseDecimal(cols[3], &site.height_m))
      throw Error(a.batch + ":" + std::to_string(lineno) + ": lat, lon and elev_m must be numbers");
    CheckSite(site, a.batch + ":" + std::to_string(lineno));
    UtcTime t0;
    try {
      t0 = ParseIso8601(cols[0]);
    } catch (const Error& e) {
      throw Error(a.batch + ":" + std::to_string(lineno) + ": " + e.what());
    }
    SunPosition p = ComputeSunPosition(t0, site, {a.pressure, a.temperature});
    std::printf("%s,%.6f,%.6f,%.3f,%.6f,%.6f,%.6f\n", cols[0].c_str(), site.lat_deg, site.lon_deg,
                site.height_m, p.azimuth_deg, p.elevation_deg, p.elevation_true_deg);
  }
}

void Run(const SunArgs& a) {
  if (!a.batch.empty()) return RunBatch(a);
  if (a.time.empty() || !a.have_lat || !a.have_lon)
    throw Error("sun: give --lat, --lon and --time (or --batch FILE.csv)");
  UtcTime t = ParseIso8601(a.time);
  Site site{a.lat, a.lon, a.height};
  SunPosition p = ComputeSunPosition(t, site, {a.pressure, a.temperature});
  if (a.json) {
    nlohmann::json j = {{"utc", t.Iso8601(3)},
                        {"lat_deg", a.lat},
                        {"lon_deg", a.lon},
                        {"height_m", a.height},
                        {"azimuth_deg", p.azimuth_deg},
                        {"elevation_deg", p.elevation_deg},
                        {"elevation_true_deg", p.elevation_true_deg},
                        {"zenith_deg", 90 - p.elevation_deg},
                        {"distance_au", p.distance_au},
                        {"angular_radius_deg", p.angular_radius_deg},
                        {"solid_angle_sr", p.SolidAngleSr()}};
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("utc                 %s\n", t.Iso8601(3).c_str());
  std::printf("azimuth             %.6f deg (from north, eastward)\n", p.azimuth_deg);
  std::printf("elevation           %.6f deg (refracted, %.0f mbar, %.1f C)\n", p.elevation_deg,
              a.pressure, a.temperature);
  std::printf("elevation (airless) %.6f deg\n", p.elevation_true_deg);
  std::printf("earth-sun distance  %.6f AU\n", p.distance_au);
  std::printf("angular radius      %.5f deg (solid angle %.4e sr)\n", p.angular_radius_deg,
              p.SolidAngleSr());
}

}  // namespace

void RegisterSun(CLI::App& app) {
  auto a = std::make_shared<SunArgs>();
  CLI::App* c = app.add_subcommand("sun", CommandSummary("sun"));
  c->footer(
      "Examples:\n"
      "  rouen sun --lat 37.8722 --lon -122.2578 --height 60 --time 2026-08-25T13:30:00-07:00\n"
      "  rouen sun --batch fixes.csv      (columns utc,lat,lon,elev_m; prints CSV with\n"
      "                                    azimuth_deg,elevation_deg,elevation_true_deg)");
  CLI::Option* lat =
      c->add_option("--lat", a->lat, "Latitude, degrees north")->check(Obeys(LatitudeProblem));
  CLI::Option* lon = c->add_option("--lon", a->lon, "Longitude, degrees east (west is negative)")
                         ->check(Obeys(LongitudeProblem));
  CLI::Option* height =
      c->add_option("--height", a->height, "Height above the WGS84 ellipsoid, metres (-500..9000)")
          ->check(Obeys(HeightProblem));
  CLI::Option* time =
      c->add_option("--time", a->time, "ISO 8601 time with a zone, e.g. 2026-08-25T13:30:00Z");
  CLI::Option* json = c->add_flag("--json", a->json, "Print JSON");
  // The file gives each line's time and site, and the output is CSV: one or the other.
  c->add_option("--batch", a->batch, "CSV file with columns utc,lat,lon,elev_m")
      ->excludes(lat)
      ->excludes(lon)
      ->excludes(height)
      ->excludes(time)
      ->excludes(json);
  // From no air (0: no refraction) past the highest sea-level pressure (1084 mbar); from
  // below the coldest to above the hottest air measured (-89 C, 57 C).
  c->add_option("--pressure", a->pressure, "Air pressure for refraction, mbar")
      ->check(Within(0, 1100, "mbar"))
      ->capture_default_str();
  c->add_option("--temperature", a->temperature, "Air temperature for refraction, Celsius")
      ->check(Within(-100, 70, "C"))
      ->capture_default_str();
  c->callback([a, lat, lon] {
    a->have_lat = lat->count() > 0;
    a->have_lon = lon->count() > 0;
    Run(*a);
  });
}

}  // namespace rouen
