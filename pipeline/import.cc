#include "pipeline/import.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <tuple>

#include "calib/colmap.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/exif.h"
#include "core/files.h"
#include "core/geodesy.h"
#include "core/image.h"
#include "core/json_text.h"
#include "core/lens.h"
#include "core/limits.h"
#include "core/list_file.h"
#include "core/mesh.h"
#include "core/outputs.h"
#include "core/temporaries.h"
#include "core/text.h"

namespace rouen {
namespace fs = std::filesystem;
using nlohmann::json;
namespace {

void Log(const ImportOptions& o, const std::string& s) {
  if (o.log) o.log(s);
}

constexpr double kSlotGapSeconds = 30 * 60;
constexpr double kBaseIso = 100;

// One line of the list: "image seconds [ISO-time] [group=NAME] [target=T[+T...]] [nd=D|nd=R,G,B]".
struct ListEntry {
  std::string name;  // relative to --photos
  std::optional<double> seconds;
  std::optional<UtcTime> utc;
  std::string group;
  // What the photo shows; several (target=landscape+sky: one panorama from the ground is both
  // the landscape and the sky photo) import it once per target. Empty: ImportOptions::target.
  std::vector<Target> targets;
  double nd_density = 0;                        // the filter's optical density (mean)
  std::optional<std::array<double, 3>> nd_rgb;  // per channel, when given so
  std::string where;                            // "<list>:<line>", for messages
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
  double nd_density = 0;
  std::optional<std::array<double, 3>> nd_rgb;
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
  const size_t slash = s.find('/');
  double v = 0, d = 1;
  if (!ParseDecimal(std::string_view(s).substr(0, slash), &v) ||
      (slash != std::string::npos &&
       (!ParseDecimal(std::string_view(s).substr(slash + 1), &d) || !(d > 0))) ||
      !std::isfinite(v / d))
    throw Error(where + ": " + what + " '" + s + "' is not a number");
  return v / d;
}

// "nd=D" or "nd=R,G,B": optical densities within core/limits.h's range.
void ParseNd(const std::string& value, const std::string& where, ListEntry* e) {
  std::vector<std::string> parts;
  std::stringstream ss(value);
  std::string item;
  while (std::getline(ss, item, ',')) parts.push_back(item);
  if ((parts.size() != 1 && parts.size() != 3) || value.empty() || value.back() == ',')
    throw Error(where + ": nd=" + value +
                ": expected an optical density (nd=4.5) or one per channel (nd=4.4,4.5,4.7)");
  std::array<double, 3> d{};
  for (size_t k = 0; k < parts.size(); ++k) {
    d[k] = ParseNumber(parts[k], where, "ND density");
    Require(NdDensityProblem(d[k]), where);
  }
  if (parts.size() == 1) {
    e->nd_density = d[0];
  } else {
    e->nd_rgb = d;
    e->nd_density = (d[0] + d[1] + d[2]) / 3;
  }
}

std::vector<ListEntry> ReadImportList(const std::string& list) {
  std::vector<ListEntry> out;
  for (const ListLine& line : ReadListFile(list)) {
    const std::vector<std::string>& words = line.words;
    const std::string& where = line.where;
    if (words.size() < 2)
      throw Error(where + ": expected 'image seconds [ISO-time] [group=NAME] [target=T] [nd=D]'");
    ListEntry e;
    e.where = where;
    e.name = words[0];
    if (words[1] != "-") {
      const double s = ParseNumber(words[1], where, "exposure");
      Require(ExposureProblem(s), where);
      e.seconds = s;
    }
    std::set<std::string> keys;  // group=, nd=, target=: each at most once
    for (size_t i = 2; i < words.size(); ++i) {
      const std::string& w = words[i];
      const size_t eq = w.find('=');
      if (eq != std::string::npos && !keys.insert(w.substr(0, eq + 1)).second)
        throw Error(where + ": " + w.substr(0, eq + 1) + " given twice");
      if (w.rfind("group=", 0) == 0) {
        e.group = w.substr(6);
        if (e.group.empty() || e.group.find('/') != std::string::npos)
          throw Error(where + ": group name must be non-empty and contain no '/'");
      } else if (w.rfind("nd=", 0) == 0) {
        ParseNd(w.substr(3), where, &e);
      } else if (w.rfind("target=", 0) == 0) {
        std::stringstream ts(w.substr(7));
        std::string t;
        while (std::getline(ts, t, '+')) {
          try {
            e.targets.push_back(ParseTarget(t));
          } catch (const Error& err) {
            throw Error(where + ": " + err.what());
          }
          if (std::count(e.targets.begin(), e.targets.end(), e.targets.back()) > 1)
            throw Error(where + ": " + w + ": target '" + t + "' named twice");
        }
        if (e.targets.empty() || w.back() == '+')
          throw Error(where + ": " + w + ": expected target=T or target=T+T (e.g. landscape+sky)");
      } else if (!e.utc && i == 2) {
        try {
          e.utc = ParseIso8601(w);
        } catch (const Error& err) {
          throw Error(where + ": time: " + err.what());
        }
      } else {
        throw Error(where + ": unexpected column '" + w +
                    "' (expected an ISO time, group=NAME, target=T or nd=D)");
      }
    }
    out.push_back(std::move(e));
  }
  return out;
}

// Every photo with its exposure, time, kind, group; all checks that need no pixels.
std::vector<Photo> PlanImport(const ImportOptions& o, std::vector<std::string>* notes) {
  const fs::path& dir = o.photos;
  if (!fs::exists(dir)) throw Error(dir.string() + ": no such photos folder");
  if (!fs::is_directory(dir)) throw Error(dir.string() + ": is not a folder");
  const std::optional<int>& tz = o.timezone_minutes;
  const std::optional<UtcTime>& fallback_time = o.time;

  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name[0] == '.') continue;
    if (!entry.is_regular_file()) continue;
    if (IsImageName(name)) names.push_back(name);
  }
  std::sort(names.begin(), names.end());

  std::map<std::string, ListEntry> listed;  // by lexically normal relative path
  if (!o.list.empty()) {
    for (ListEntry& e : ReadImportList(o.list.string())) {
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
    throw Error(dir.string() + ": no photos found (JPEG, PNG, TIFF, EXR, HDR, DNG or camera RAW)");

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
      throw Error(name + ": no exposure time in EXIF and not in the list");
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
    if (le) {
      p.nd_density = le->nd_density;
      p.nd_rgb = le->nd_rgb;
    }
    const std::vector<Target> targets =
        le && !le->targets.empty() ? le->targets : std::vector<Target>{o.target};
    for (size_t t = 0; t < targets.size(); ++t) {
      p.target = targets[t];
      if (t + 1 < targets.size()) {
        photos.push_back(p);
      } else {
        photos.push_back(std::move(p));
      }
    }
  }

  // Slots: clusters of capture times separated by more than 30 minutes.
  std::sort(photos.begin(), photos.end(), [](const Photo& x, const Photo& y) {
    return std::tie(x.utc, x.name, x.target) < std::tie(y.utc, y.name, y.target);
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
    const std::string g = BracketName(p.slot, p.target, p.view);
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

// A camera's intrinsics or pose given inline (an object) or as a file name (a string,
// relative to the cameras file), as `rouen calib intrinsics` / `rouen calib pose` write them.
Intrinsics CameraIntrinsics(const json& v, const fs::path& base) {
  if (v.is_string())
    return ReadLensFile(ResolveInside(base, v.get<std::string>()).string()).intrinsics;
  Intrinsics in = v.get<Intrinsics>();
  in.Validate();
  return in;
}

Pose CameraPose(const json& v, const fs::path& base) {
  Pose pose = v.is_string() ? ReadPoseFile(ResolveInside(base, v.get<std::string>()).string())
                            : v.get<Pose>();
  if (!pose.rotation.allFinite() || !pose.position.allFinite()) throw Error("pose is not finite");
  return pose;
}

void AttachCameras(const fs::path& cameras_file, std::vector<Photo>& photos) {
  const std::string file = cameras_file.string();
  const json j = ParseJsonText(ReadFileToString(cameras_file), file);
  if (!j.is_object())
    throw Error(file +
                ": expected an object mapping image names (or \"group=NAME\", or \"*\") to "
                "{\"intrinsics\" or \"lens\", \"pose\"}");
  const fs::path base =
      cameras_file.parent_path().empty() ? fs::path(".") : cameras_file.parent_path();
  struct Camera {
    std::optional<Intrinsics> intrinsics;
    std::optional<Pose> pose;
  };
  std::map<std::string, Camera> by_key;
  std::set<std::string> groups;
  for (const Photo& p : photos)
    if (!p.group.empty()) groups.insert(p.group);
  for (const auto& [name, entry] : j.items()) {
    std::string key = name;
    if (name.rfind("group=", 0) == 0) {
      if (!groups.count(name.substr(6)))
        throw Error(file + ": \"" + name + "\": no listed photo has that group");
    } else if (name != "*") {
      key = fs::path(name).lexically_normal().string();
      if (std::none_of(photos.begin(), photos.end(), [&](const Photo& p) { return p.name == key; }))
        throw Error(file + ": \"" + name + "\" is not one of the imported photos");
    }
    if (!entry.is_object()) throw Error(file + ": \"" + name + "\": expected an object");
    Camera cam;
    try {
      for (const auto& [field, value] : entry.items()) {
        if (value.is_null()) continue;
        if (field == "intrinsics" || field == "lens") {
          if (cam.intrinsics) throw Error("give \"intrinsics\" or \"lens\", not both");
          cam.intrinsics = CameraIntrinsics(value, base);
        } else if (field == "pose") {
          cam.pose = CameraPose(value, base);
        } else {
          throw Error("unknown key \"" + field + "\" (expected intrinsics, lens, pose)");
        }
      }
    } catch (const Error& e) {
      throw Error(file + ": \"" + name + "\": " + e.what());
    } catch (const json::exception& e) {
      throw Error(file + ": \"" + name + "\": " + e.what());
    }
    by_key[key] = cam;
  }
  for (Photo& p : photos) {
    // The photo's own entry, else its group's, else "*", field by field.
    for (const std::string& key : {p.name, "group=" + p.group, std::string("*")}) {
      const auto it = by_key.find(key);
      if (it == by_key.end()) continue;
      if (!p.intrinsics && it->second.intrinsics) p.intrinsics = it->second.intrinsics;
      if (!p.pose && it->second.pose) p.pose = it->second.pose;
    }
    if (p.intrinsics &&
        (p.intrinsics->width != p.meta.width || p.intrinsics->height != p.meta.height))
      throw Error(file + ": \"" + p.name + "\": intrinsics are for " +
                  std::to_string(p.intrinsics->width) + "x" + std::to_string(p.intrinsics->height) +
                  " but the image is " + std::to_string(p.meta.width) + "x" +
                  std::to_string(p.meta.height));
  }
}

// The similarity taking the COLMAP model's frame to the site's: from the control points, else
// from the registered photos' GPS positions (ImportOptions::colmap).
SimilarityFit AlignColmap(const ImportOptions& o, const ColmapModel& model,
                          const std::vector<Photo>& photos, std::string* source) {
  std::vector<Eigen::Vector3d> from, to;
  if (!o.colmap_control.empty()) {
    for (const ControlPoint& c : ReadControlPoints(o.colmap_control)) {
      from.push_back(c.model);
      to.push_back(c.enu);
    }
    *source = o.colmap_control.string();
  } else {
    // One pair per registered image: its centre in the model, its GPS position on the site.
    const LocalFrame site(o.site);
    std::vector<std::string> unusable;
    std::set<std::string> used;
    for (const Photo& p : photos) {
      const ColmapImage* im = model.Find(p.name);
      if (!im || used.count(im->name)) continue;  // a photo imported for two targets: once
      if (!p.meta.gps) {
        unusable.push_back(p.name + (p.meta.gps_problem.empty() ? ": no GPS position"
                                                                : ": " + p.meta.gps_problem));
        continue;
      }
      used.insert(im->name);
      from.push_back(im->pose.position);
      to.push_back(site.ToEnu({p.meta.gps->lat_deg, p.meta.gps->lon_deg,
                               p.meta.gps->altitude_m.value_or(o.site.height_m)}));
    }
    if (from.size() < 3) {
      std::string why = unusable.empty() ? "" : " (" + unusable.front() + ")";
      throw Error(o.colmap.string() + ": " + std::to_string(from.size()) +
                  " of the photos it registered carry a GPS position in EXIF" + why +
                  "; aligning its frame to the site needs 3 or more, or --colmap-control with 3 "
                  "or more points known in both the model and the site");
    }
    *source = "the GPS positions in " + std::to_string(from.size()) + " photos' EXIF";
  }
  try {
    return FitSimilarity(from, to);
  } catch (const Error& e) {
    throw Error(*source + ": " + e.what());
  }
}

// The photos a COLMAP model registered take its intrinsics and pose, its frame aligned to the
// site (AlignColmap).
void AttachColmap(const ImportOptions& o, std::vector<Photo>& photos, ImportSummary* summary) {
  const double max_rms_m = o.colmap_max_rms_m.value_or(o.colmap_control.empty() ? 5.0 : 0.5);
  if (!(max_rms_m > 0) || !std::isfinite(max_rms_m))
    throw Error("--colmap-max-rms-m must be a positive number of metres");
  const ColmapModel model = ReadColmapModel(o.colmap);
  std::string source;
  const SimilarityFit fit = AlignColmap(o, model, photos, &source);
  const std::string residual =
      fit.BriefReport(o.colmap_control.empty() ? "GPS positions" : "control points");
  if (fit.rms_m > max_rms_m)
    throw Error(source + ": the alignment of " + o.colmap.string() + " leaves a " + residual +
                ", beyond --colmap-max-rms-m " + std::to_string(max_rms_m) +
                (o.colmap_control.empty()
                     ? " m: a GPS position of another photo, or a reconstruction that is wrong?"
                     : " m: a point given in the wrong frame, order or units?"));
  Log(o, "COLMAP model " + o.colmap.string() + " (" + std::to_string(model.images.size()) +
             " images) aligned to the site: " + residual);
  summary->colmap_alignment = residual;
  for (Photo& p : photos) {
    const ColmapImage* im = model.Find(p.name);
    if (!im) continue;
    if (im->intrinsics.width != p.meta.width || im->intrinsics.height != p.meta.height)
      throw Error(o.colmap.string() + ": image " + im->name + " is " +
                  std::to_string(im->intrinsics.width) + "x" +
                  std::to_string(im->intrinsics.height) + " but " + p.name + " is " +
                  std::to_string(p.meta.width) + "x" + std::to_string(p.meta.height));
    p.intrinsics = im->intrinsics;
    p.pose = fit.transform.Apply(im->pose);
    ++summary->colmap_photos;
  }
}

void RequireModelFile(const fs::path& model) {
  std::error_code ec;
  if (!fs::is_regular_file(model, ec)) throw Error(model.string() + ": no such model file");
}

// The building model, its surroundings and the trees' OBJ text (any may be empty), checked
// before they are written: each must parse and have faces (ReadObj), and no block may be in two.
void CheckModels(const ImportOptions& o, const std::string& trees_obj) {
  if (!o.surroundings.empty() && o.model.empty())
    throw Error(o.surroundings.string() + ": surroundings need the building's model (--model)");
  if (!o.trees.empty() && o.model.empty())
    throw Error(o.trees.string() + ": trees need the building's model (--model)");
  if (o.model.empty()) return;
  RequireModelFile(o.model);
  Mesh mesh = ReadObj(o.model.string());
  if (!o.surroundings.empty()) {
    RequireModelFile(o.surroundings);
    AppendObj(o.surroundings.string(), &mesh);
  }
  if (trees_obj.empty()) return;
  try {
    mesh.Append(ParseObj(trees_obj, o.trees.string()));
  } catch (const Error& e) {
    throw Error(o.trees.string() + ": " + e.what());
  }
}

// The session's surroundings: the given OBJ's text (if any) followed by the trees' (if any).
std::string SurroundingsText(const ImportOptions& o, const std::string& trees_obj) {
  std::string text = o.surroundings.empty() ? "" : ReadFileToString(o.surroundings);
  if (!text.empty() && !trees_obj.empty() && text.back() != '\n') text += '\n';
  return text + trees_obj;
}

// A sky mask file must be the size of every sky photo (the mask applies to each).
void CheckSkyMask(const std::string& mask, const std::vector<Photo>& photos) {
  if (mask.empty() || mask == "auto") return;
  std::error_code ec;
  if (!fs::is_regular_file(mask, ec)) throw Error(mask + ": no such sky mask file");
  for (const Photo& p : photos)
    if (p.target == Target::kSky || p.target == Target::kAureole)
      ReadMask(mask, p.meta.width, p.meta.height, "the sky photo " + p.name);
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

}  // namespace

ImportSummary ImportPhotos(const ImportOptions& o, const fs::path& out) {
  const Site& site = o.site;
  CheckSite(site, "the site");
  const std::string out_name = out.string();
  if (out.filename().empty() || out.filename() == "." || out.filename() == "..")
    throw Error(out_name + ": give the session folder's name, not a trailing '/'");
  if (fs::exists(out) && !(fs::is_directory(out) && fs::is_empty(out)))
    throw Error(out_name + ": already exists; choose a new session folder");
  CheckNewFolderPlace(out_name, out);
  ImportSummary summary;
  const std::vector<Tree> trees =
      o.trees.empty() ? std::vector<Tree>{} : ReadTrees(o.trees.string(), o.tree_mesh);
  summary.trees = static_cast<int>(trees.size());
  const std::string trees_obj = trees.empty() ? ""
                                              : "# trees from " + o.trees.filename().string() +
                                                    "\n" + TreesObjText(trees, o.tree_mesh);
  CheckModels(o, trees_obj);
  const std::string surroundings = SurroundingsText(o, trees_obj);

  std::vector<std::string> notes;
  std::vector<Photo> photos = PlanImport(o, &notes);
  if (!o.colmap.empty()) AttachColmap(o, photos, &summary);
  if (!o.cameras.empty()) AttachCameras(o.cameras, photos);
  CheckSkyMask(o.sky_mask, photos);
  // Journal order: by bracket, then capture time.
  std::stable_sort(photos.begin(), photos.end(), [](const Photo& x, const Photo& y) {
    return std::tie(x.slot, x.target, x.view) < std::tie(y.slot, y.target, y.view);
  });

  SessionInfo info;
  info.site = site;
  info.site_source = "user";
  info.rig = "";
  info.notes =
      "imported by rouen import from " + fs::absolute(o.photos).lexically_normal().string();
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
      Log(o, "removing " + e.path().string() + ", left by an import that was interrupted");
      fs::remove_all(e.path(), ec);
    }
  }
  fs::remove_all(tmp, ec);
  WatchForTemporaries(tmp.parent_path().empty() ? fs::path(".") : tmp.parent_path());
  int& slots = summary.slots;
  int& groups = summary.brackets;
  int& hdr = summary.hdr;
  try {
    // The session names its model and sky mask; their files are copied into it.
    std::string mask_file;
    if (!o.model.empty()) info.model = "model.obj";
    if (!surroundings.empty()) info.surroundings = "surroundings.obj";
    for (const Tree& t : trees) info.trees.push_back(t.name);
    if (!o.sky_mask.empty()) {
      SkyMaskSpec spec;
      spec.automatic = o.sky_mask == "auto";
      if (!spec.automatic) {
        mask_file = "sky_mask" + Lower(fs::path(o.sky_mask).extension().string());
        spec.file = mask_file;
      }
      info.sky_masks["*"] = spec;
    }
    // Per-channel ND filters: one named entry per distinct set of densities.
    std::map<std::array<double, 3>, std::string> nd_names;
    for (const Photo& p : photos) {
      if (!p.nd_rgb || nd_names.count(*p.nd_rgb)) continue;
      const std::string name = "import-" + std::to_string(nd_names.size() + 1);
      nd_names[*p.nd_rgb] = name;
      info.nd_filters[name].density_rgb = *p.nd_rgb;
    }
    SessionWriter writer = SessionWriter::Create(tmp, info);
    if (!o.model.empty()) WriteFileAtomic(tmp / info.model, ReadFileToString(o.model));
    if (!surroundings.empty()) WriteFileAtomic(tmp / info.surroundings, surroundings);
    if (!mask_file.empty()) WriteFileAtomic(tmp / mask_file, ReadFileToString(o.sky_mask));
    json sources = json::array();
    std::set<std::string> group_names;
    for (const Photo& p : photos) {
      FrameRecord r;
      r.device = DeviceName(p.meta);
      r.target = p.target;
      r.slot = p.slot;
      r.group = BracketName(p.slot, p.target, p.view);
      r.utc = p.utc;
      r.hdr = p.kind != Kind::kLdr;
      r.exposure_s = p.exposure_s;
      r.gain = p.gain;
      r.aperture_f = p.meta.f_number.value_or(0.0);
      r.nd_density = p.nd_density;
      const SunPosition sun = ComputeSunPosition(r.utc, site);
      r.sun_azimuth_deg = sun.azimuth_deg;
      r.sun_elevation_deg = sun.elevation_deg;
      if (sun.BelowHorizon()) {
        summary.night.push_back(p.name + " (" + r.utc.Iso8601(0) +
                                Formatted(", sun %.1f deg)", sun.elevation_deg));
      }
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
    done_info.extra["import"] = {{"photos", fs::absolute(o.photos).lexically_normal().string()},
                                 {"frames", sources}};
    if (!o.trees.empty()) {
      done_info.extra["import"]["trees"] = {
          {"file", fs::absolute(o.trees).lexically_normal().string()},
          {"sha256", Sha256File(o.trees)},
          {"count", summary.trees}};
    }
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
    throw Error(out_name + ": cannot finish the session: " + e.what());
  }
  for (const std::string& n : notes) Log(o, "note: " + n);
  if (summary.trees > 0)
    Log(o, std::to_string(summary.trees) + (summary.trees == 1 ? " tree" : " trees") + " from " +
               o.trees.string() + " added to the surroundings (a crown on a trunk each)");
  summary.photos = static_cast<int>(photos.size());
  return summary;
}

}  // namespace rouen
