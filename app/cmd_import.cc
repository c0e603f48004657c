// rouen import: a session folder from existing photographs (pipeline/import.h does the work).
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "core/error.h"
#include "core/exif.h"
#include "core/limits.h"
#include "core/session.h"
#include "core/time.h"
#include "pipeline/import.h"

namespace rouen {
namespace {

struct ImportArgs {
  std::string photos, list, cameras, site, timezone, time,
      target = "architecture", out, model, surroundings, trees, sky_mask, colmap, colmap_control;
  double colmap_max_rms_m = 0;  // 0: ImportOptions' default for the alignment's source
};

void Run(const ImportArgs& a) {
  ImportOptions o;
  o.photos = a.photos;
  o.list = a.list;
  o.cameras = a.cameras;
  o.colmap = a.colmap;
  o.colmap_control = a.colmap_control;
  if (a.colmap_max_rms_m > 0) o.colmap_max_rms_m = a.colmap_max_rms_m;
  o.site = ParseSiteOption(a.site, "--site");
  try {
    o.target = ParseTarget(a.target);
  } catch (const Error& e) {
    throw Error(std::string("--target: ") + e.what());
  }
  if (!a.timezone.empty()) {
    try {
      o.timezone_minutes = ParseUtcOffsetMinutes(a.timezone);
    } catch (const Error& e) {
      throw Error(std::string("--timezone: ") + e.what());
    }
  }
  if (!a.time.empty()) {
    o.time = ParseTimeOption(a.time, "--time");
  }
  o.model = a.model;
  o.surroundings = a.surroundings;
  o.trees = a.trees;
  o.sky_mask = a.sky_mask;
  o.log = [](const std::string& s) { std::fprintf(stderr, "rouen import: %s\n", s.c_str()); };
  const ImportSummary s = ImportPhotos(o, a.out);
  std::printf("%s: imported %d photos (%d HDR) into %d bracket%s in %d slot%s\n", a.out.c_str(),
              s.photos, s.hdr, s.brackets, s.brackets == 1 ? "" : "s", s.slots,
              s.slots == 1 ? "" : "s");
  if (!s.night.empty()) {
    std::string some;
    for (size_t k = 0; k < s.night.size() && k < 3; ++k) some += "\n  " + s.night[k];
    std::fprintf(stderr,
                 "rouen import: warning: %zu of the photos were taken with the sun below the "
                 "horizon at --site:%s%s\n(a camera clock or --timezone off by hours, or the wrong "
                 "site; calibration photos may be taken at night, a slot the solve uses may not)\n",
                 s.night.size(), some.c_str(), s.night.size() > 3 ? "\n  ..." : "");
  }
  if (s.colmap_photos > 0)
    std::printf("  %d photos posed from the COLMAP model (alignment %s)\n", s.colmap_photos,
                s.colmap_alignment.c_str());
  std::printf("next: rouen status %s\n", a.out.c_str());
}

}  // namespace

void RegisterImport(CLI::App& app) {
  auto a = std::make_shared<ImportArgs>();
  CLI::App* c = app.add_subcommand("import", CommandSummary("import"));
  c->footer(
      "Exposure: --list value, else EXIF ExposureTime. Time: --list third column, else EXIF\n"
      "DateTimeOriginal in its own UTC offset, else in --timezone (required then); --time\n"
      "only for photos with no time at all. Each frame's sun position is computed from its\n"
      "UTC and --site. Southern/western sites: --site=-33.86,151.21,40 also works.\n"
      "LIST lines: 'image seconds [ISO-time] [group=NAME] [target=T] [nd=D]' ('#' comments;\n"
      "seconds may be a fraction 1/250 or '-' for EXIF; images relative to --photos, never\n"
      "outside; nd=4.5 is the optical density of the ND filter in front, nd=4.4,4.5,4.7 one per\n"
      "channel, as `rouen calib nd` measures it; target=landscape+sky imports one photo as\n"
      "both, e.g. a panorama from the ground that is the sky and the landscape photo).\n"
      "Photos of one group form one bracket; capture times more than 30 min apart start a\n"
      "new slot. 8-bit JPEG/PNG/TIFF are LDR frames (16-bit ones are stored as 8-bit);\n"
      "EXR/HDR are HDR frames as they are; DNG/RAW are read linear (libraw) and stored as\n"
      "HDR radiance divided by exposure x ISO/100.\n"
      "CAMERAS (--cameras, or --poses): a JSON object; a key is an image name, \"group=NAME\"\n"
      "(every photo of a list group) or \"*\" (every photo); a value gives \"intrinsics\" (an\n"
      "object, core/camera.h) or \"lens\" (a lens file from `rouen calib intrinsics`) and "
      "\"pose\"\n"
      "(an object, or a pose file from `rouen calib pose`), files relative to the JSON:\n"
      "  {\"*\": {\"lens\": \"mycam.json\"}, \"group=west\": {\"pose\": \"west-pose.json\"}}\n"
      "--colmap DIR: a COLMAP sparse model (cameras, images, points3D; .bin or .txt, e.g.\n"
      "sparse/0 of `colmap mapper`) gives each photo it registered (by its listed path, else\n"
      "its file name) its intrinsics and pose; CAMERAS gives the others. Its frame is aligned\n"
      "to the site by --colmap-control, a CSV of 3 or more points known in both, not on one\n"
      "line, whose header names x,y,z (the model's frame) and east_m,north_m,up_m (metres from\n"
      "--site); without it, by the GPS positions in the registered photos' EXIF (3 or more\n"
      "photos not on one line; their altitude taken on the datum of --site's height, a photo\n"
      "without one put at that height). The residual is printed and one beyond\n"
      "--colmap-max-rms-m refused (default 0.5 m with control points, 5 m with GPS).\n"
      "--model copies the building (OBJ; its groups are the blocks) into the session;\n"
      "--surroundings adds coarse geometry around it (OBJ: houses across the street, a city\n"
      "model's or OpenStreetMap's footprints extruded to their heights): it shades the\n"
      "building and hides its sky, and lights it as solved surfaces on a coarser grid\n"
      "([surroundings] spacing_m) whose albedos the landscape panoramas read too\n"
      "([surroundings] from_panoramas), never scored by validate;\n"
      "--trees adds trees to the surroundings from a CSV whose header names its columns:\n"
      "  name,x_m,y_m,height_m,crown_diameter_m[,crown_depth_m,trunk_diameter_m,base_z_m]\n"
      "(east and north of the model's origin, the crown's top above the ground, the crown's\n"
      "width and depth, default round; OpenStreetMap's natural=tree height and\n"
      "diameter_crown): each a crown (an ellipsoid) on a trunk, its own block; a tree the\n"
      "model lacks casts a shadow rouen cannot see coming and hides the wall behind it;\n"
      "--sky-mask auto segments the sky photos' sky, a mask image (nonzero = sky, the sky\n"
      "photos' size) keeps those pixels.\n"
      "The session is written to OUT.tmp-<pid> and renamed at the end; on error or Ctrl-C "
      "nothing is left.\n"
      "Example: rouen import --photos stlouis_arch --site 38.6247,-90.1848,147 --out s1\n"
      "         rouen import --photos memorial --list memorial/exposures.txt \\\n"
      "           --time 1997-03-01T12:00:00-08:00 --site 37.4275,-122.1697,30 --out s2");
  c->add_option("--photos", a->photos, "Folder of photos to import")->required();
  c->add_option("--list", a->list,
                "List file: 'image seconds [ISO-time] [group=NAME] [target=T] [nd=D]'");
  c->add_option("--cameras,--poses", a->cameras,
                "JSON: image, group=NAME or * -> {intrinsics or lens file, pose or pose file}");
  c->add_option("--colmap", a->colmap,
                "COLMAP sparse model folder: intrinsics and poses of the photos it registered");
  c->add_option("--colmap-control", a->colmap_control,
                "CSV of control points (x,y,z,east_m,north_m,up_m) aligning --colmap to the site");
  c->add_option("--colmap-max-rms-m", a->colmap_max_rms_m,
                "Largest alignment residual RMS accepted, metres (default 0.5 with control "
                "points, 5 with GPS)")
      ->check(Positive());
  c->add_option("--site", a->site, "Site LAT,LON,H (degrees, degrees east, metres)")->required();
  c->add_option("--timezone", a->timezone,
                "UTC offset of the camera clock (+HH:MM) for EXIF times without one");
  c->add_option("--time", a->time,
                "ISO 8601 time (with offset) for photos that carry no time at all");
  c->add_option("--target", a->target,
                "Target of the photos: architecture (default), landscape, sky, sun, aureole, "
                "calibration");
  c->add_option("--model", a->model, "The building's model (OBJ), copied into the session");
  c->add_option("--surroundings", a->surroundings,
                "Coarse geometry around the building (OBJ, its groups their own blocks), copied "
                "into the session");
  c->add_option("--trees", a->trees,
                "Trees (CSV: name,x_m,y_m,height_m,crown_diameter_m,...) added to the "
                "surroundings");
  c->add_option("--sky-mask", a->sky_mask,
                "Sky photos' sky pixels: 'auto' (segmented) or a mask image (nonzero = sky)");
  c->add_option("--out", a->out, "Session folder to create")->required();
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
