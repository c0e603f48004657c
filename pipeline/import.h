// A session folder from existing photographs (JPEG/PNG/TIFF/EXR/DNG/RAW), so offline
// reprocessing works on photographs from any camera.
//
// Decisions:
// - Exposure: the list's value, else EXIF ExposureTime; neither is an error naming the photo
//   (EXR/HDR inputs are already radiance and need none).
// - Time: the list's time column (ISO 8601 with offset), else EXIF DateTimeOriginal in the
//   photo's own offset (OffsetTimeOriginal or an XMP time with offset), else in `timezone`
//   (required then); `time` only for photos with no time at all; else an error naming it.
// - Pixels: 8-bit JPEG/PNG/TIFF are LDR frames (kDigital). 16-bit PNG/TIFF are treated as
//   LDR digital numbers too (camera output through an unknown response) and stored, like every
//   LDR session frame, as 8-bit PNG: their low 8 bits are rounded away (a note says so).
//   Float EXR/HDR are HDR frames as they are. DNG/camera RAW are read linear through libraw
//   and journalled as HDR frames already divided by exposure_s x gain (gain = ISO/100, 1 when
//   the ISO is unknown): the EXR holds relative radiance in the same units the pipeline's
//   merge produces (signal / (exposure x gain)); exposure_s and gain stay in the record as
//   provenance and must not be divided out again.
// - ND filters: a list column nd=D (optical density) or nd=R,G,B (per channel; recorded in
//   session.json's nd_filters, the frame's density being their mean).
// - Grouping: slot = cluster of capture times (a gap > 30 min starts a new slot); within a
//   slot, each list group=NAME (default: one unnamed group) and target is one bracket
//   "slot<k>/<target>/view<v>", views numbered in order of first capture.
// - Cameras: a cameras file maps photos to their intrinsics and pose, given inline or as the
//   files `rouen calib intrinsics` (a lens file) and `rouen calib pose` write.
// - Output: written into OUT.tmp-<pid> (a sibling) and renamed to OUT at the end; on any
//   error, Ctrl-C or SIGTERM the temporary folder is deleted, so no half-written session is
//   left behind.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/session.h"
#include "core/solar.h"
#include "core/time.h"
#include "core/trees.h"

namespace rouen {

struct ImportOptions {
  std::filesystem::path photos;  // folder of photos
  // List file: "image seconds [ISO-time] [group=NAME] [target=T] [nd=D | nd=R,G,B]" per line
  // (seconds may be a fraction 1/250 or '-' for EXIF; images relative to `photos`; target=T+T
  // imports the photo once per target, e.g. landscape+sky).
  std::filesystem::path list;
  // Cameras file (JSON): {"<image>" | "group=<NAME>" | "*": {"intrinsics": {...} | "lens":
  // "LENS.json", "pose": {...} | "POSE.json"}}: an image's own entry, else its list group's,
  // else "*". File names are relative to the cameras file.
  std::filesystem::path cameras;
  // A COLMAP sparse model (calib/colmap.h: cameras, images, points3D, binary or text): each
  // photo it registered (matched by its listed path, else by its file name) takes its
  // intrinsics and pose from it; the cameras file gives the others (e.g. panoramas). Its frame
  // is aligned to the site's east-north-up metres by a similarity fitted to the control points
  // of `colmap_control` (ReadControlPoints: 3 or more, not on a line) when given, else to the
  // registered photos' GPS positions (EXIF; 3 or more photos, not on a line; their altitudes
  // on the datum of the site's height, without altitude the camera is put at the site's
  // height). An alignment whose residual RMS exceeds `colmap_max_rms_m` is refused (default:
  // 0.5 m with control points, 5 m with GPS, a phone's or camera's GPS being good to a few
  // metres).
  std::filesystem::path colmap;
  std::filesystem::path colmap_control;
  std::optional<double> colmap_max_rms_m;
  Site site;
  std::optional<int> timezone_minutes;  // UTC offset of the camera clock
  std::optional<UtcTime> time;          // for photos that carry no time at all
  Target target = Target::kArchitecture;
  std::filesystem::path model;  // the building (OBJ), copied into the session
  // Coarse geometry around it (OBJ, e.g. footprints and heights from a city model), copied
  // into the session as its surroundings (SessionInfo::surroundings); needs `model`.
  std::filesystem::path surroundings;
  // Trees (a CSV, core/trees.h: position, height, crown per tree), each made a crown on a trunk
  // and added to the session's surroundings as its own block; needs `model`.
  std::filesystem::path trees;
  TreeMeshOptions tree_mesh;
  std::string sky_mask;  // "", "auto" or a mask image copied into the session
  std::function<void(const std::string&)> log;  // notes
};

struct ImportSummary {
  int photos = 0, hdr = 0, brackets = 0, slots = 0;
  int trees = 0;  // made from ImportOptions::trees
  // ImportOptions::colmap: the photos posed from it and its alignment to the site ("residual
  // RMS 0.012 m, largest 0.020 m over 4 control points (scale 5)", SimilarityFit::BriefReport).
  int colmap_photos = 0;
  std::string colmap_alignment;
  // The photos taken with the sun's whole disc below the horizon at the site, "NAME (UTC,
  // sun -12.3 deg)": a wrong camera clock, time zone or site, or calibration photos taken at
  // night; `rouen status` lists the slots the solve cannot use.
  std::vector<std::string> night;
};

// Imports the photos into the new session folder `out` (which must not exist, or be empty).
// Everything is checked before a pixel is written; throws rouen::Error naming the photo, the
// list line or the file.
ImportSummary ImportPhotos(const ImportOptions& options, const std::filesystem::path& out);

}  // namespace rouen
