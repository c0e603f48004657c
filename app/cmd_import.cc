// rouen import: a session folder from existing photographs (JPEG/PNG/TIFF/EXR/DNG/RAW), so
// offline reprocessing works on photographs from any camera.
//
// Decisions (also in --help):
// - Exposure: --list value, else EXIF ExposureTime; neither is an error naming the photo
//   (EXR/HDR inputs are already radiance and need none).
// - Time: --list's third column (ISO 8601 with offset), else EXIF DateTimeOriginal in the
//   photo's own offset (OffsetTimeOriginal or an XMP time with offset), else in --timezone
//   (required then); --time only for photos with no time at all; else an error naming it.
// - Pixels: 8-bit JPEG/PNG/TIFF are LDR frames (kDigital). 16-bit PNG/TIFF are treated as
//   LDR digital numbers too (camera output through an unknown response) and stored, like every
//   LDR session frame, as 8-bit PNG: their low 8 bits are rounded away (a note says so).
//   Float EXR/HDR are HDR frames as they are. DNG/camera RAW are read linear through libraw
//   and journalled as HDR frames already divided by exposure_s x gain (gain = ISO/100, 1 when
//   the ISO is unknown): the EXR holds relative radiance in the same units the pipeline's
//   merge produces (signal / (exposure x gain)); exposure_s and gain stay in the record as
//   provenance and must not be divided out again.
// - Grouping: slot = cluster of capture times (a gap > 30 min starts a new slot); within a
//   slot, each --list group=NAME (default: one unnamed group) and target is one bracket
//   "slot<k>/<target>/view<v>", views numbered in order of first capture.
// - Output: written into OUT.tmp-<pid> (a sibling) and renamed to OUT at the end; on any
//   error, Ctrl-C or SIGTERM the temporary folder is deleted, so no half-written session is
//   left behind.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "app/commands.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/exif.h"
#include "core/files.h"
#include "core/image.h"
#include "core/limits.h"
#include "core/session.h"
#include "core/solar.h"
#include "core/temporaries.h"
#include "core/time.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rouen {
namespace {

constexpr double kSlotGapSeconds = 30 * 60;
constexpr double kBaseIso = 100;

struct ImportArgs {
  std::string photos, list, poses, site, timezone, time, target = "architecture", out;
};

// One line of --list: "image seconds [ISO-time] [group=NAME] [target=T]".
struct ListEntry {
  std::string name;  // relative to --photos
  std::optional<double> seconds;
  std::optional<UtcTime> utc;
  std::string group;
  std::optional<Target> target;
  std::string where;  // "<list>:<line>", for messages
};

enum class Kind { kLdr, kHdr, kRaw };

struct Photo {
  std::string name;  // relative to --photos, as listed
  fs::path path;
  PhotoMetadata meta;
  Kind kind = Kind::kLdr;
  double exposure_s = 0;
  double gain = 1;
  UtcTime utc;
  std::string time_source;
  std::string group;
  Target target = Target::kArchitecture;
  int slot = 0, view = 0;
  std::optional<Intrinsics> intrinsics;
  std::optional<Pose> pose;
};

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

bool IsImageName(const std::string& name) {
  static const std::set<std::string> kExt = {".jpg",  ".jpeg", ".png", ".tif",
                                             ".tiff", ".exr",  ".hdr"};
  return kExt.count(Lower(fs::path(name).extension().string())) > 0 || IsRawFileName(name);
}

double ParseNumber(const std::string& s, const std::string& where, const std::string& what) {
  // Accepts decimals and fractions such as 1/250.
  try {
    size_t used = 0;
    double v = std::stod(s, &used);
    if (used < s.size() && s[used] == '/') {
      size_t used2 = 0;
      const std::string den = s.substr(used + 1);
      const double d = std::stod(den, &used2);
      if (used2 != den.size() || !(d > 0)) throw std::invalid_argument("");
      v /= d;
      used = s.size();
    }
    if (used != s.size() || !std::isfinite(v)) throw std::invalid_argument("");
    return v;
  } catch (const std::exception&) {
    throw Error(where + ": " + what + " '" + s + "' is not a number");
  }
}

Site ParseSite(const std::string& text) {
  const std::string where = "--site \"" + text + "\"";
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) parts.push_back(item);
  if (parts.size() != 3 || text.back() == ',')
    throw Error(where +
                ": expected LAT,LON,H (degrees, degrees east, metres), e.g. "
                "38.6247,-90.1848,147");
  Site s;
  s.lat_deg = ParseNumber(parts[0], where, "latitude");
  s.lon_deg = ParseNumber(parts[1], where, "longitude");
  s.height_m = ParseNumber(parts[2], where, "height");
  CheckSite(s, where);
  return s;
}

std::vector<ListEntry> ReadImportList(const std::string& list) {
  std::vector<ListEntry> out;
  ForEachListLine(list, [&](const std::vector<std::string>& words, const std::string& where) {
    if (words.size() < 2)
      throw Error(where + ": expected 'image seconds [ISO-time] [group=NAME] [target=T]'");
    ListEntry e;
    e.where = where;
    e.name = words[0];
    if (words[1] != "-") {
      const double s = ParseNumber(words[1], where, "exposure");
      Require(ExposureProblem(s), where);
      e.seconds = s;
    }
    for (size_t i = 2; i < words.size(); ++i) {
      const std::string& w = words[i];
      if (w.rfind("group=", 0) == 0) {
        e.group = w.substr(6);
        if (e.group.empty() || e.group.find('/') != std::string::npos)
          throw Error(where + ": group name must be non-empty and contain no '/'");
      } else if (w.rfind("target=", 0) == 0) {
        try {
          e.target = ParseTarget(w.substr(7));
        } catch (const Error& err) {
          throw Error(where + ": " + err.what());
        }
      } else if (!e.utc && i == 2) {
        try {
          e.utc = ParseIso8601(w);
        } catch (const Error& err) {
          throw Error(where + ": time: " + err.what());
        }
      } else {
        throw Error(where + ": unexpected column '" + w +
                    "' (expected an ISO time, group=NAME or target=T)");
      }
    }
    out.push_back(std::move(e));
  });
  return out;
}

// Every photo with its exposure, time, kind, group; all checks that need no pixels.
std::vector<Photo> PlanImport(const ImportArgs& a, const Target default_target,
                              std::vector<std::string>* notes) {
  const fs::path dir(a.photos);
  if (!fs::exists(dir)) throw Error(a.photos + ": no such photos folder");
  if (!fs::is_directory(dir)) throw Error(a.photos + ": is not a folder");

  std::optional<int> tz;
  if (!a.timezone.empty()) {
    try {
      tz = ParseUtcOffsetMinutes(a.timezone);
    } catch (const Error& e) {
      throw Error(std::string("--timezone: ") + e.what());
    }
  }
  std::optional<UtcTime> fallback_time;
  if (!a.time.empty()) {
    try {
      fallback_time = ParseIso8601(a.time);
    } catch (const Error& e) {
      throw Error(std::string("--time: ") + e.what());
    }
  }

  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name[0] == '.') continue;
    if (!entry.is_regular_file()) continue;
    if (IsImageName(name)) names.push_back(name);
  }
  std::sort(names.begin(), names.end());

  std::map<std::string, ListEntry> listed;  // by lexically normal relative path
  if (!a.list.empty()) {
    for (ListEntry& e : ReadImportList(a.list)) {
      const std::string& where = e.where;
      fs::path p;
      try {
        p = ResolveInside(dir, e.name);
      } catch (const Error& err) {
        throw Error(where + ": " + e.name + ": refused, it leaves the photos folder (" +
                    err.what() + ")");
      }
      if (!fs::is_regular_file(p)) throw Error(where + ": " + p.string() + ": no such photo");
      const std::string key = fs::path(e.name).lexically_normal().string();
      if (std::find(names.begin(), names.end(), key) == names.end()) {
        if (!IsImageName(key))
          throw Error(where + ": " + key + ": not an image type rouen imports");
        names.push_back(key);  // a photo in a subfolder of --photos
      }
      if (listed.count(key)) throw Error(where + ": " + key + " is listed twice");
      listed.emplace(key, std::move(e));
    }
  }
  if (names.empty())
    throw Error(a.photos + ": no photos found (JPEG, PNG, TIFF, EXR, HDR, DNG or camera RAW)");

  std::vector<Photo> photos;
  bool warned16 = false;
  for (const std::string& name : names) {
    Photo p;
    p.name = name;
    p.path = ResolveInside(dir, name);
    p.meta = ReadPhotoMetadata(p.path.string());
    const ListEntry* le = nullptr;
    if (auto it = listed.find(name); it != listed.end()) le = &it->second;
    if (IsRawFileName(name) || p.meta.is_raw) {
      p.kind = Kind::kRaw;
    } else if (p.meta.is_float) {
      p.kind = Kind::kHdr;
    } else {
      p.kind = Kind::kLdr;
      if (p.meta.bits > 8 && !warned16) {
        notes->push_back(name + ": " + std::to_string(p.meta.bits) +
                         "-bit image stored as 8-bit LDR digital numbers (the session's LDR "
                         "format); convert linear 16-bit images to EXR to keep them as HDR");
        warned16 = true;
      }
    }
    if (p.meta.channels != 1 && p.meta.channels != 3 && p.meta.channels != 4)
      throw Error(name + ": " + std::to_string(p.meta.channels) +
                  " channels; expected grey, RGB or RGBA");
    // Exposure.
    if (le && le->seconds) {
      p.exposure_s = *le->seconds;
    } else if (p.meta.exposure_s) {
      p.exposure_s = *p.meta.exposure_s;
      Require(ExposureProblem(p.exposure_s), name + ": EXIF ExposureTime");
    } else if (p.kind != Kind::kHdr) {
      throw Error(name + ": no exposure time in EXIF and not in --list");
    }
    if (p.meta.iso) p.gain = *p.meta.iso / kBaseIso;
    // Time.
    std::optional<UtcTime> exif_utc;
    try {
      exif_utc = CaptureUtc(p.meta, tz);
    } catch (const Error& e) {
      throw Error(name + ": EXIF " + p.meta.datetime_source + " \"" + *p.meta.datetime +
                  "\": " + e.what());
    }
    if (le && le->utc) {
      p.utc = *le->utc;
      p.time_source = "list";
    } else if (exif_utc) {
      p.utc = *exif_utc;
      p.time_source = HasOwnOffset(p.meta) ? "exif" : "exif+timezone";
    } else if (p.meta.datetime) {
      throw Error(name + ": EXIF time \"" + *p.meta.datetime +
                  "\" has no UTC offset; give --timezone +HH:MM (the camera clock's zone)");
    } else if (fallback_time) {
      p.utc = *fallback_time;
      p.time_source = "--time";
    } else {
      throw Error(name +
                  ": no capture time in EXIF and not in --list (add an ISO time as the "
                  "list's third column, or give --time)");
    }
    p.group = le ? le->group : "";
    p.target = le && le->target ? *le->target : default_target;
    photos.push_back(std::move(p));
  }

  // Slots: clusters of capture times separated by more than 30 minutes.
  std::sort(photos.begin(), photos.end(), [](const Photo& x, const Photo& y) {
    return std::tie(x.utc, x.name) < std::tie(y.utc, y.name);
  });
  int slot = 0;
  for (size_t i = 0; i < photos.size(); ++i) {
    if (i > 0 && (photos[i].utc.UnixSeconds() - photos[i - 1].utc.UnixSeconds()) > kSlotGapSeconds)
      ++slot;
    photos[i].slot = slot;
  }
  // Views: each (slot, target, group name) in order of first capture.
  std::map<std::tuple<int, Target, std::string>, int> views;
  std::map<std::pair<int, Target>, int> next_view;
  for (Photo& p : photos) {
    auto key = std::make_tuple(p.slot, p.target, p.group);
    auto it = views.find(key);
    if (it == views.end()) it = views.emplace(key, next_view[{p.slot, p.target}]++).first;
    p.view = it->second;
  }
  // One size per bracket, and no LDR/HDR mixture within a bracket.
  std::map<std::string, const Photo*> first_of;
  for (const Photo& p : photos) {
    const std::string g = "slot" + std::to_string(p.slot) + "/" + TargetName(p.target) + "/view" +
                          std::to_string(p.view);
    auto [it, fresh] = first_of.emplace(g, &p);
    if (fresh) continue;
    const Photo& f = *it->second;
    if (p.meta.width != f.meta.width || p.meta.height != f.meta.height)
      throw Error(p.name + ": size " + std::to_string(p.meta.width) + "x" +
                  std::to_string(p.meta.height) + " differs from " + f.name + " (" +
                  std::to_string(f.meta.width) + "x" + std::to_string(f.meta.height) +
                  ") in the same bracket " + g);
    const int pc = p.meta.channels == 4 ? 3 : p.meta.channels;
    const int fc = f.meta.channels == 4 ? 3 : f.meta.channels;
    if (pc != fc)
      throw Error(p.name + ": " + std::to_string(pc) + " colour channels differ from " + f.name +
                  " (" + std::to_string(fc) + ") in the same bracket " + g);
    if ((p.kind == Kind::kLdr) != (f.kind == Kind::kLdr))
      throw Error(p.name + ": mixes LDR and HDR/RAW photos in the same bracket " + g + " (with " +
                  f.name + "); put them in different groups");
    if (p.meta.f_number && f.meta.f_number &&
        std::abs(*p.meta.f_number - *f.meta.f_number) > 0.05 * *f.meta.f_number)
      notes->push_back(p.name + ": f/" + std::to_string(*p.meta.f_number) + " differs from " +
                       f.name + " in bracket " + g +
                       "; the pipeline uses exposure time and gain only");
  }
  return photos;
}

void AttachPoses(const std::string& poses_file, std::vector<Photo>& photos) {
  const std::string text = ReadFileToString(poses_file);
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    throw Error(poses_file + ": not valid JSON: " + e.what());
  }
  if (!j.is_object())
    throw Error(poses_file +
                ": expected an object mapping image names to "
                "{\"intrinsics\": {...}, \"pose\": {...}}");
  for (const auto& [name, entry] : j.items()) {
    const std::string key = fs::path(name).lexically_normal().string();
    auto it =
        std::find_if(photos.begin(), photos.end(), [&](const Photo& p) { return p.name == key; });
    if (it == photos.end())
      throw Error(poses_file + ": \"" + name + "\" is not one of the imported photos");
    if (!entry.is_object()) throw Error(poses_file + ": \"" + name + "\": expected an object");
    try {
      if (auto k = entry.find("intrinsics"); k != entry.end() && !k->is_null()) {
        Intrinsics in = k->get<Intrinsics>();
        in.Validate();
        if (in.width != it->meta.width || in.height != it->meta.height)
          throw Error("intrinsics are for " + std::to_string(in.width) + "x" +
                      std::to_string(in.height) + " but the image is " +
                      std::to_string(it->meta.width) + "x" + std::to_string(it->meta.height));
        it->intrinsics = in;
      }
      if (auto p = entry.find("pose"); p != entry.end() && !p->is_null()) {
        Pose pose = p->get<Pose>();
        if (!pose.rotation.allFinite() || !pose.position.allFinite())
          throw Error("pose is not finite");
        it->pose = pose;
      }
    } catch (const Error& e) {
      throw Error(poses_file + ": \"" + name + "\": " + e.what());
    } catch (const json::exception& e) {
      throw Error(poses_file + ": \"" + name + "\": " + e.what());
    }
  }
}

Image LoadPixels(const Photo& p) {
  if (p.kind == Kind::kRaw) {
    Image im = ReadRawLinear(p.path.string());
    // Relative radiance: linear signal per second of exposure at ISO 100.
    const float scale = static_cast<float>(1.0 / (p.exposure_s * p.gain));
    for (float& v : im.data) v *= scale;
    return im;
  }
  Image im = ReadImage(p.path.string());
  const bool want_float = p.kind == Kind::kHdr;
  if ((im.units == PixelUnits::kRadiance) != want_float)
    throw Error(p.path.string() + ": pixel type changed between the header and the data");
  if (im.width != p.meta.width || im.height != p.meta.height)
    throw Error(p.path.string() + ": pixel size differs from the header");
  return im;
}

std::string DeviceName(const PhotoMetadata& m) {
  std::string d = "import";
  if (m.make || m.model) {
    d += ":";
    if (m.make) d += *m.make;
    if (m.model) {
      // Many cameras repeat the make in the model ("Canon" + "Canon PowerShot S3 IS").
      if (m.make && m.model->rfind(*m.make, 0) == 0) {
        d = "import:" + *m.model;
      } else {
        d += (m.make ? " " : "") + *m.model;
      }
    }
  }
  return d;
}

void RunImport(const ImportArgs& a) {
  const Site site = ParseSite(a.site);
  Target target;
  try {
    target = ParseTarget(a.target);
  } catch (const Error& e) {
    throw Error(std::string("--target: ") + e.what());
  }
  const fs::path out(a.out);
  if (out.filename().empty() || out.filename() == "." || out.filename() == "..")
    throw Error(a.out + ": give the session folder's name, not a trailing '/'");
  if (fs::exists(out) && !(fs::is_directory(out) && fs::is_empty(out)))
    throw Error(a.out + ": already exists; choose a new session folder");

  std::vector<std::string> notes;
  std::vector<Photo> photos = PlanImport(a, target, &notes);
  if (!a.poses.empty()) AttachPoses(a.poses, photos);
  // Journal order: by bracket, then capture time.
  std::stable_sort(photos.begin(), photos.end(), [](const Photo& x, const Photo& y) {
    return std::tie(x.slot, x.target, x.view) < std::tie(y.slot, y.target, y.view);
  });

  SessionInfo info;
  info.site = site;
  info.site_source = "user";
  info.rig = "";
  info.notes =
      "imported by rouen import from " + fs::absolute(a.photos).lexically_normal().string();
  const fs::path tmp =
      out.parent_path() / (out.filename().string() + ".tmp-" + std::to_string(::getpid()));
  std::error_code ec;
  // An import of the same folder killed earlier left its temporary session: no process holds
  // it any more, so it goes (one still being written is another import's, and stays).
  const std::string prefix = out.filename().string() + ".tmp-";
  for (const auto& e :
       fs::directory_iterator(out.parent_path().empty() ? fs::path(".") : out.parent_path(), ec)) {
    if (e.is_directory(ec) && e.path().filename().string().rfind(prefix, 0) == 0 &&
        !SessionInUse(e.path())) {
      std::fprintf(stderr, "rouen import: removing %s, left by an import that was interrupted\n",
                   e.path().c_str());
      fs::remove_all(e.path(), ec);
    }
  }
  fs::remove_all(tmp, ec);
  WatchForTemporaries(tmp.parent_path().empty() ? fs::path(".") : tmp.parent_path());
  int slots = 0, groups = 0, hdr = 0;
  try {
    SessionWriter writer = SessionWriter::Create(tmp, info);
    json sources = json::array();
    std::set<std::string> group_names;
    for (const Photo& p : photos) {
      FrameRecord r;
      r.device = DeviceName(p.meta);
      r.target = p.target;
      r.slot = p.slot;
      r.group = "slot" + std::to_string(p.slot) + "/" + TargetName(p.target) + "/view" +
                std::to_string(p.view);
      r.utc = p.utc;
      r.hdr = p.kind != Kind::kLdr;
      r.exposure_s = p.exposure_s;
      r.gain = p.gain;
      r.aperture_f = p.meta.f_number.value_or(0.0);
      r.nd_density = 0;
      const SunPosition sun = ComputeSunPosition(r.utc, site);
      r.sun_azimuth_deg = sun.azimuth_deg;
      r.sun_elevation_deg = sun.elevation_deg;
      r.intrinsics = p.intrinsics;
      r.pose = p.pose;
      const FrameRecord done = writer.Append(r, LoadPixels(p));
      json s = {{"id", done.id},
                {"source", p.name},
                {"source_sha256", Sha256File(p.path)},
                {"kind", p.kind == Kind::kRaw   ? "raw"
                         : p.kind == Kind::kHdr ? "hdr"
                                                : "ldr"},
                {"time_source", p.time_source}};
      if (!p.group.empty()) s["group_name"] = p.group;
      sources.push_back(std::move(s));
      group_names.insert(r.group);
      slots = std::max(slots, p.slot + 1);
      hdr += r.hdr ? 1 : 0;
    }
    groups = static_cast<int>(group_names.size());
    SessionInfo done_info = writer.info();
    done_info.extra["import"] = {{"photos", fs::absolute(a.photos).lexically_normal().string()},
                                 {"frames", sources}};
    writer.UpdateInfo(done_info);
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  // The writer is closed; check what was written, then move it into place.
  try {
    const Session check = Session::Load(tmp);
    if (check.frames().size() != photos.size())
      throw Error(tmp.string() + ": journal has " + std::to_string(check.frames().size()) +
                  " frames, expected " + std::to_string(photos.size()));
    if (fs::exists(out)) fs::remove(out);  // an empty folder, checked above
    fs::rename(tmp, out);
  } catch (const std::exception& e) {
    fs::remove_all(tmp, ec);
    throw Error(a.out + ": cannot finish the session: " + e.what());
  }
  for (const std::string& n : notes) std::fprintf(stderr, "rouen import: note: %s\n", n.c_str());
  std::printf("%s: imported %zu photos (%d HDR) into %d bracket%s in %d slot%s\n", a.out.c_str(),
              photos.size(), hdr, groups, groups == 1 ? "" : "s", slots, slots == 1 ? "" : "s");
}

}  // namespace

void RegisterImport(CLI::App& app) {
  auto a = std::make_shared<ImportArgs>();
  CLI::App* c = app.add_subcommand(
      "import", "Build a session folder from existing photos (JPEG/PNG/TIFF/EXR/DNG/RAW)");
  c->footer(
      "Exposure: --list value, else EXIF ExposureTime. Time: --list third column, else EXIF\n"
      "DateTimeOriginal in its own UTC offset, else in --timezone (required then); --time\n"
      "only for photos with no time at all. Each frame's sun position is computed from its\n"
      "UTC and --site. Southern/western sites: --site=-33.86,151.21,40 also works.\n"
      "LIST lines: 'image seconds [ISO-time] [group=NAME] [target=T]' ('#' comments; seconds\n"
      "may be a fraction 1/250 or '-' for EXIF; images relative to --photos, never outside).\n"
      "Photos of one group form one bracket; capture times more than 30 min apart start a\n"
      "new slot. 8-bit JPEG/PNG/TIFF are LDR frames (16-bit ones are stored as 8-bit);\n"
      "EXR/HDR are HDR frames as they are; DNG/RAW are read linear (libraw) and stored as\n"
      "HDR radiance divided by exposure x ISO/100.\n"
      "POSES: {\"IMG_1.jpg\": {\"intrinsics\": {...}, \"pose\": {...}}, ...} (core/camera.h).\n"
      "The session is written to OUT.tmp-<pid> and renamed at the end; on error or Ctrl-C "
      "nothing is left.\n"
      "Example: rouen import --photos stlouis_arch --site 38.6247,-90.1848,147 --out s1\n"
      "         rouen import --photos memorial --list memorial/exposures.txt \\\n"
      "           --time 1997-03-01T12:00:00-08:00 --site 37.4275,-122.1697,30 --out s2");
  c->add_option("--photos", a->photos, "Folder of photos to import")->required();
  c->add_option("--list", a->list, "List file: 'image seconds [ISO-time] [group=NAME]'");
  c->add_option("--poses", a->poses, "JSON: image name -> {intrinsics, pose}");
  c->add_option("--site", a->site, "Site LAT,LON,H (degrees, degrees east, metres)")->required();
  c->add_option("--timezone", a->timezone,
                "UTC offset of the camera clock (+HH:MM) for EXIF times without one");
  c->add_option("--time", a->time,
                "ISO 8601 time (with offset) for photos that carry no time at all");
  c->add_option("--target", a->target,
                "Target of the photos: architecture (default), landscape, sky, sun, aureole, "
                "calibration");
  c->add_option("--out", a->out, "Session folder to create")->required();
  c->callback([a] { RunImport(*a); });
}

}  // namespace rouen
