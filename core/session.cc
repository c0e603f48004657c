#include "core/session.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <set>

#include "core/error.h"
#include "core/files.h"
#include "core/json_text.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rouen {
namespace {

constexpr int kFormatVersion = 1;
constexpr float kHalfMax = 65504.0f;

std::string Errno() { return std::strerror(errno); }

const json& Need(const json& j, const char* key, const char* what) {
  if (!j.is_object()) throw Error(std::string(what) + ": expected a JSON object");
  auto it = j.find(key);
  if (it == j.end()) throw Error(std::string(what) + ": missing key \"" + key + "\"");
  return *it;
}

double NeedNumber(const json& j, const char* key, const char* what) {
  const json& v = Need(j, key, what);
  if (!v.is_number()) throw Error(std::string(what) + ": key \"" + key + "\" is not a number");
  return v.get<double>();
}

// An integer within [lo, hi] (by default any int64; unsigned values above it are refused,
// not wrapped).
int64_t NeedInt(const json& j, const char* key, const char* what,
                int64_t lo = std::numeric_limits<int64_t>::min(),
                int64_t hi = std::numeric_limits<int64_t>::max()) {
  return JsonInteger(Need(j, key, what), lo, hi, std::string(what) + ": key \"" + key + "\"");
}

// An integer that fits an int (not truncated: slot 4294967296 is no slot 0).
int NeedInt32(const json& j, const char* key, const char* what) {
  return static_cast<int>(NeedInt(j, key, what, INT_MIN, INT_MAX));
}

std::string NeedString(const json& j, const char* key, const char* what) {
  const json& v = Need(j, key, what);
  if (!v.is_string()) throw Error(std::string(what) + ": key \"" + key + "\" is not a string");
  return v.get<std::string>();
}

bool NeedBool(const json& j, const char* key, const char* what) {
  const json& v = Need(j, key, what);
  if (!v.is_boolean()) throw Error(std::string(what) + ": key \"" + key + "\" is not a boolean");
  return v.get<bool>();
}

template <typename T, typename F>
T Optional(const json& j, const char* key, T fallback, F need) {
  auto it = j.find(key);
  if (it == j.end()) return fallback;
  return need(j, key);
}

UtcTime NeedTime(const json& j, const char* key, const char* what) {
  const std::string s = NeedString(j, key, what);
  try {
    return ParseIso8601(s);
  } catch (const Error& e) {
    throw Error(std::string(what) + ": key \"" + key + "\": " + e.what());
  }
}

void CheckFinite(double v, const char* name) {
  if (!std::isfinite(v)) throw Error(std::string("frame record: ") + name + " is not finite");
}

void CheckFrameFinite(const FrameRecord& f) {
  CheckFinite(f.exposure_s, "exposure_s");
  CheckFinite(f.gain, "gain");
  CheckFinite(f.aperture_f, "aperture_f");
  CheckFinite(f.nd_density, "nd_density");
  CheckFinite(f.sun_azimuth_deg, "sun azimuth_deg");
  CheckFinite(f.sun_elevation_deg, "sun elevation_deg");
  if (f.gps) {
    CheckFinite(f.gps->lat_deg, "gps lat_deg");
    CheckFinite(f.gps->lon_deg, "gps lon_deg");
    CheckFinite(f.gps->height_m, "gps height_m");
    CheckFinite(f.gps->hdop, "gps hdop");
  }
  if (f.pose && (!f.pose->rotation.allFinite() || !f.pose->position.allFinite())) {
    throw Error("frame record: pose is not finite");
  }
  if (f.intrinsics) f.intrinsics->Validate();
}

std::string JournalPath(const fs::path& dir) { return (dir / "frames.jsonl").string(); }

int OpenJournal(const fs::path& dir) {
  const std::string p = JournalPath(dir);
  const int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(p + ": cannot open for appending: " + Errno());
  return fd;
}

void FsyncDir(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw Error(dir.string() + ": cannot open: " + Errno());
  ::fsync(fd);
  ::close(fd);
}

constexpr const char* kLockName = "session.lock";

// One writer per session (flock on <dir>/session.lock, released when the fd closes, also on a
// crash). The holder writes its pid into the file so a second writer can name it.
int LockSession(const fs::path& dir) {
  const fs::path p = dir / kLockName;
  const int fd = ::open(p.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(IoErrorMessage(p, "cannot open the session lock", errno));
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char buf[32] = {};
    const ssize_t n = ::pread(fd, buf, sizeof buf - 1, 0);
    ::close(fd);
    if (err == EWOULDBLOCK) {
      std::string holder = n > 0 ? std::string(buf, static_cast<size_t>(n)) : "";
      while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' ')) holder.pop_back();
      throw Error(dir.string() + ": the session is in use by another rouen process" +
                  (holder.empty() ? "" : " (pid " + holder + ")") +
                  "; one capture or import writes a session at a time: wait for it to finish "
                  "or stop it, then run again");
    }
    throw Error(IoErrorMessage(p, "cannot lock the session", err));
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, pid.data(), pid.size(), 0) < 0) {
    // The pid is only for the message of a second writer; the lock itself holds.
  }
  return fd;
}

}  // namespace

bool SessionInUse(const fs::path& dir) {
  const fs::path p = dir / kLockName;
  const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool held = ::flock(fd, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  ::close(fd);  // releases the probe's lock, if it got one
  return held;
}

const char* TargetName(Target t) {
  switch (t) {
    case Target::kSun:
      return "sun";
    case Target::kAureole:
      return "aureole";
    case Target::kSky:
      return "sky";
    case Target::kLandscape:
      return "landscape";
    case Target::kArchitecture:
      return "architecture";
    case Target::kCalibration:
      return "calibration";
  }
  return "architecture";
}

Target ParseTarget(const std::string& s) {
  for (Target t : {Target::kSun, Target::kAureole, Target::kSky, Target::kLandscape,
                   Target::kArchitecture, Target::kCalibration}) {
    if (s == TargetName(t)) return t;
  }
  throw Error("unknown target \"" + s +
              "\" (sun, aureole, sky, landscape, architecture or calibration)");
}

std::string BracketName(int slot, Target target, int view) {
  return "slot" + std::to_string(slot) + "/" + TargetName(target) + "/view" + std::to_string(view);
}

BracketKey ParseBracketName(const std::string& name) {
  const auto bad = [&](const std::string& why) {
    return Error("bracket \"" + name + "\": " + why + " (expected slot<k>/<target>/view<v>)");
  };
  const size_t a = name.find('/'), b = name.rfind('/');
  if (a == std::string::npos || a == b) throw bad("not three parts");
  const auto number = [&](const std::string& text, const char* prefix) {
    const size_t n = std::char_traits<char>::length(prefix);
    if (text.rfind(prefix, 0) != 0 || text.size() == n || text.size() > n + 6 ||
        text.find_first_not_of("0123456789", n) != std::string::npos)
      throw bad(std::string("'") + text + "' is not " + prefix + "<number>");
    return std::stoi(text.substr(n));
  };
  BracketKey k;
  k.slot = number(name.substr(0, a), "slot");
  try {
    k.target = ParseTarget(name.substr(a + 1, b - a - 1));
  } catch (const Error& e) {
    throw bad(e.what());
  }
  k.view = number(name.substr(b + 1), "view");
  return k;
}

void to_json(json& j, const FrameRecord& f) {
  json gps = nullptr;
  if (f.gps) {
    gps = json{{"utc", f.gps->utc.Iso8601(9)}, {"lat_deg", f.gps->lat_deg},
               {"lon_deg", f.gps->lon_deg},    {"height_m", f.gps->height_m},
               {"mode", f.gps->mode},          {"satellites", f.gps->satellites},
               {"hdop", f.gps->hdop}};
    if (f.gps->received_utc) gps["received_utc"] = f.gps->received_utc->Iso8601(9);
  }
  j = json{{"id", f.id},
           {"device", f.device},
           {"target", TargetName(f.target)},
           {"group", f.group},
           {"slot", f.slot},
           {"utc", f.utc.Iso8601(9)},
           {"hdr", f.hdr},
           {"exposure_s", f.exposure_s},
           {"gain", f.gain},
           {"aperture_f", f.aperture_f},
           {"nd_density", f.nd_density},
           {"gps", gps},
           {"sun", {{"azimuth_deg", f.sun_azimuth_deg}, {"elevation_deg", f.sun_elevation_deg}}},
           {"intrinsics", f.intrinsics ? json(*f.intrinsics) : json(nullptr)},
           {"pose", f.pose ? json(*f.pose) : json(nullptr)},
           {"file", f.file},
           {"sha256", f.sha256}};
}

void from_json(const json& j, FrameRecord& f) {
  const char* what = "frame record";
  FrameRecord r;
  r.id = NeedInt(j, "id", what);
  r.device = NeedString(j, "device", what);
  r.target = ParseTarget(NeedString(j, "target", what));
  r.group = Optional<std::string>(
      j, "group", "", [&](const json& x, const char* k) { return NeedString(x, k, what); });
  r.slot = Optional<int>(j, "slot", 0,
                         [&](const json& x, const char* k) { return NeedInt32(x, k, what); });
  if (r.slot < 0 || r.slot > kMaxSlot) {
    throw Error(std::string(what) + ": key \"slot\" must be a slot number 0.." +
                std::to_string(kMaxSlot) + ", not " + std::to_string(r.slot));
  }
  // The bracket a frame is merged into is its group's: the group's slot and target must be the
  // frame's own, or the frame would land in another time's or target's bracket.
  if (!r.group.empty()) {
    BracketKey k;
    try {
      k = ParseBracketName(r.group);
    } catch (const Error& e) {
      throw Error(std::string(what) + ": key \"group\": " + e.what());
    }
    if (k.slot != r.slot)
      throw Error(std::string(what) + ": group \"" + r.group + "\" is slot " +
                  std::to_string(k.slot) + "'s but key \"slot\" is " + std::to_string(r.slot));
    if (k.target != r.target)
      throw Error(std::string(what) + ": group \"" + r.group + "\" is of target " +
                  TargetName(k.target) + " but key \"target\" is " + TargetName(r.target));
  }
  r.utc = NeedTime(j, "utc", what);
  r.hdr = Optional<bool>(j, "hdr", false,
                         [&](const json& x, const char* k) { return NeedBool(x, k, what); });
  r.exposure_s = NeedNumber(j, "exposure_s", what);
  r.gain = NeedNumber(j, "gain", what);
  r.aperture_f = NeedNumber(j, "aperture_f", what);
  r.nd_density = NeedNumber(j, "nd_density", what);
  const json& gps = Need(j, "gps", what);
  if (!gps.is_null()) {
    const char* gw = "frame record: gps";
    if (!gps.is_object()) throw Error("frame record: key \"gps\" is neither null nor an object");
    GpsFix g;
    g.utc = NeedTime(gps, "utc", gw);
    g.lat_deg = NeedNumber(gps, "lat_deg", gw);
    g.lon_deg = NeedNumber(gps, "lon_deg", gw);
    g.height_m = NeedNumber(gps, "height_m", gw);
    g.mode = NeedInt32(gps, "mode", gw);
    g.satellites = NeedInt32(gps, "satellites", gw);
    g.hdop = NeedNumber(gps, "hdop", gw);
    if (gps.contains("received_utc")) g.received_utc = NeedTime(gps, "received_utc", gw);
    r.gps = g;
  }
  const json& sun = Need(j, "sun", what);
  r.sun_azimuth_deg = NeedNumber(sun, "azimuth_deg", "frame record: sun");
  r.sun_elevation_deg = NeedNumber(sun, "elevation_deg", "frame record: sun");
  auto it = j.find("intrinsics");
  if (it != j.end() && !it->is_null()) {
    try {
      r.intrinsics = it->get<Intrinsics>();
    } catch (const Error& e) {
      throw Error(std::string("frame record: key \"intrinsics\": ") + e.what());
    }
  }
  it = j.find("pose");
  if (it != j.end() && !it->is_null()) {
    try {
      r.pose = it->get<Pose>();
    } catch (const Error& e) {
      throw Error(std::string("frame record: key \"pose\": ") + e.what());
    }
  }
  r.file = NeedString(j, "file", what);
  r.sha256 = NeedString(j, "sha256", what);
  f = std::move(r);
}

namespace {

constexpr double kNdMatch = 0.05;  // a frame's density within this of a filter's mean uses it

std::array<double, 3> NdDensities(const json& v, const std::string& where) {
  std::array<double, 3> d{};
  const json* src = &v;
  if (v.is_object()) {
    auto it = v.find("density_rgb");
    if (it == v.end())
      throw Error(where +
                  ": a calibration record needs \"density_rgb\" (as rouen calib nd writes)");
    src = &*it;
  }
  if (src->is_number()) {
    d.fill(src->get<double>());
  } else if (src->is_array() && src->size() == 3 && (*src)[0].is_number() &&
             (*src)[1].is_number() && (*src)[2].is_number()) {
    for (int c = 0; c < 3; ++c) d[c] = (*src)[c].get<double>();
  } else {
    throw Error(where + ": expected a density, [r, g, b] densities or {\"density_rgb\": [...]}");
  }
  for (double x : d)
    if (!std::isfinite(x) || x < 0 || x > 10) throw Error(where + ": density outside 0..10");
  return d;
}

// Moves the typed tables out of `extra` (what is left stays there).
void ParseExtraTables(json extra, SessionInfo* r) {
  const std::string where = "session info: extra.";
  auto object = [&](const char* key) -> const json* {
    auto it = extra.find(key);
    if (it == extra.end() || it->is_null()) return nullptr;
    if (!it->is_object()) throw Error(where + key + " must be an object");
    return &*it;
  };
  if (const json* t = object("nd_filters"))
    for (const auto& [name, v] : t->items()) {
      NdFilter f;
      f.density_rgb = NdDensities(v, where + "nd_filters." + name);
      if (v.is_object()) f.record = v;
      r->nd_filters[name] = f;
    }
  if (const json* t = object("vignetting"))
    for (const auto& [key, v] : t->items()) {
      try {
        r->vignetting[key] = v.get<VignettingModel>();
      } catch (const Error& e) {
        throw Error(where + "vignetting." + key + ": " + e.what());
      } catch (const json::exception& e) {
        throw Error(where + "vignetting." + key + ": " + e.what());
      }
    }
  if (const json* t = object("sky_masks"))
    for (const auto& [key, v] : t->items()) {
      if (!v.is_string() || v.get<std::string>().empty())
        throw Error(where + "sky_masks." + key + " must be an image file name or \"auto\"");
      SkyMaskSpec m;
      m.automatic = v == "auto";
      if (!m.automatic) m.file = v.get<std::string>();
      r->sky_masks[key] = m;
    }
  if (auto it = extra.find("heldout_slot"); it != extra.end() && !it->is_null()) {
    r->heldout_slot = static_cast<int>(JsonInteger(*it, 0, kMaxSlot, where + "heldout_slot"));
  }
  if (auto it = extra.find("capture_complete"); it != extra.end() && !it->is_null()) {
    if (!it->is_boolean()) throw Error(where + "capture_complete must be true or false");
    r->capture_complete = it->get<bool>();
  }
  if (const json* t = object("solve_config")) r->solve_config = *t;
  for (const char* key : {"nd_filters", "vignetting", "sky_masks", "heldout_slot",
                          "capture_complete", "solve_config"})
    extra.erase(key);
  r->extra = std::move(extra);
}

json ExtraTables(const SessionInfo& s) {
  json extra = s.extra.is_object() ? s.extra : json::object();
  if (!s.nd_filters.empty()) {
    json& t = extra["nd_filters"];
    for (const auto& [name, f] : s.nd_filters)
      t[name] = f.record.is_object() ? f.record : json(f.density_rgb);
  }
  if (!s.vignetting.empty()) {
    json& t = extra["vignetting"];
    for (const auto& [key, v] : s.vignetting) t[key] = v;
  }
  if (!s.sky_masks.empty()) {
    json& t = extra["sky_masks"];
    for (const auto& [key, m] : s.sky_masks) t[key] = m.automatic ? std::string("auto") : m.file;
  }
  if (s.heldout_slot) extra["heldout_slot"] = *s.heldout_slot;
  if (s.capture_complete) extra["capture_complete"] = *s.capture_complete;
  if (s.solve_config.is_object() && !s.solve_config.empty()) extra["solve_config"] = s.solve_config;
  return extra;
}

}  // namespace

const NdFilter* SessionInfo::FindNdFilter(double frame_density) const {
  const NdFilter* best = nullptr;
  double best_gap = kNdMatch;
  if (frame_density <= 0) return nullptr;
  for (const auto& [name, f] : nd_filters) {
    const double mean = (f.density_rgb[0] + f.density_rgb[1] + f.density_rgb[2]) / 3;
    if (std::abs(mean - frame_density) <= best_gap) {
      best_gap = std::abs(mean - frame_density);
      best = &f;
    }
  }
  return best;
}

std::array<double, 3> SessionInfo::NdTransmissionRgb(double frame_density) const {
  const double t = std::pow(10.0, -std::max(frame_density, 0.0));
  std::array<double, 3> out = {t, t, t};
  if (const NdFilter* f = FindNdFilter(frame_density))
    for (int c = 0; c < 3; ++c) out[c] = std::pow(10.0, -f->density_rgb[c]);
  return out;
}

const VignettingModel* SessionInfo::FindVignetting(const std::string& device, Target target) const {
  for (const std::string& key : {device + "/" + TargetName(target), device, std::string("*")}) {
    auto it = vignetting.find(key);
    if (it != vignetting.end()) return &it->second;
  }
  return nullptr;
}

const SkyMaskSpec* SessionInfo::FindSkyMask(const std::string& bracket) const {
  for (const std::string& key : {bracket, std::string("*")}) {
    auto it = sky_masks.find(key);
    if (it != sky_masks.end()) return &it->second;
  }
  return nullptr;
}

void to_json(json& j, const SessionInfo& s) {
  j = json{
      {"format_version", s.format_version},
      {"site",
       {{"lat_deg", s.site.lat_deg}, {"lon_deg", s.site.lon_deg}, {"height_m", s.site.height_m}}},
      {"site_source", s.site_source},
      {"rig", s.rig},
      {"created_utc", s.created_utc},
      {"clock_offset_s", s.clock_offset_s},
      {"model", s.model},
      {"surroundings", s.surroundings},
      {"notes", s.notes},
      {"extra", ExtraTables(s)}};
  if (!s.trees.empty()) j["trees"] = s.trees;
}

void from_json(const json& j, SessionInfo& s) {
  const char* what = "session info";
  SessionInfo r;
  r.format_version = NeedInt32(j, "format_version", what);
  if (r.format_version < 1 || r.format_version > kFormatVersion) {
    throw Error("session info: format_version " + std::to_string(r.format_version) +
                " is not supported (this build reads " + std::to_string(kFormatVersion) + ")");
  }
  const json& site = Need(j, "site", what);
  r.site.lat_deg = NeedNumber(site, "lat_deg", "session info: site");
  r.site.lon_deg = NeedNumber(site, "lon_deg", "session info: site");
  r.site.height_m = NeedNumber(site, "height_m", "session info: site");
  if (std::abs(r.site.lat_deg) > 90 || std::abs(r.site.lon_deg) > 360) {
    throw Error("session info: site latitude/longitude out of range");
  }
  auto str = [&](const json& x, const char* k) { return NeedString(x, k, what); };
  r.site_source = Optional<std::string>(j, "site_source", r.site_source, str);
  r.rig = Optional<std::string>(j, "rig", "", str);
  r.created_utc = Optional<std::string>(j, "created_utc", "", str);
  r.clock_offset_s = Optional<double>(j, "clock_offset_s", 0.0, [&](const json& x, const char* k) {
    return NeedNumber(x, k, what);
  });
  r.model = Optional<std::string>(j, "model", "", str);
  r.surroundings = Optional<std::string>(j, "surroundings", "", str);
  if (auto t = j.find("trees"); t != j.end() && !t->is_null()) {
    if (!t->is_array()) throw Error("session info: key \"trees\" is not an array of block names");
    for (const json& name : *t) {
      if (!name.is_string())
        throw Error("session info: key \"trees\" is not an array of block names");
      r.trees.push_back(name.get<std::string>());
    }
  }
  r.notes = Optional<std::string>(j, "notes", "", str);
  auto it = j.find("extra");
  if (it != j.end() && !it->is_null()) {
    if (!it->is_object()) throw Error("session info: key \"extra\" is not an object");
    ParseExtraTables(*it, &r);
  }
  s = std::move(r);
}

std::vector<JournalLine> SplitJournal(std::string_view text) {
  std::vector<JournalLine> lines;
  size_t pos = 0;
  int number = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    const bool terminated = end != std::string_view::npos;
    if (!terminated) end = text.size();
    const std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++number;
    if (line.find_first_not_of(" \t\r") != std::string_view::npos)
      lines.push_back({number, line, terminated});
  }
  return lines;
}

FrameRecord ParseJournalLine(std::string_view line) {
  const json j = ParseJsonText(line, "");
  try {
    return j.get<FrameRecord>();
  } catch (const json::exception& e) {
    throw Error(e.what());
  }
}

SessionInfo ParseSessionInfo(std::string_view text, const std::string& name) {
  const json j = ParseJsonText(text, name);
  try {
    return j.get<SessionInfo>();
  } catch (const Error& e) {
    throw Error(name + ": " + e.what());
  } catch (const json::exception& e) {
    throw Error(name + ": " + e.what());
  }
}

// ---------------------------------------------------------------------------------------
// Session

Session Session::Load(const fs::path& dir) {
  Session s;
  s.dir_ = dir;
  const fs::path info_path = dir / "session.json";
  if (!fs::is_directory(dir)) {
    throw Error(dir.string() + ": not a session folder (no such directory)");
  }
  s.info_ = ParseSessionInfo(ReadFileToString(info_path), info_path.string());
  const std::string journal = JournalPath(dir);
  const std::string text = ReadFileToString(journal);
  std::set<int64_t> ids;
  for (const auto& [number, line, terminated] : SplitJournal(text)) {
    const std::string where = journal + ":" + std::to_string(number) + ": ";
    try {
      FrameRecord f = ParseJournalLine(line);
      fs::path p;
      try {
        p = ResolveInside(dir, f.file);
      } catch (const Error& e) {
        throw Error(std::string("file: ") + e.what());
      }
      if (!fs::is_regular_file(p)) throw Error("frame file " + p.string() + " is missing");
      if (!ids.insert(f.id).second) throw Error("duplicate frame id " + std::to_string(f.id));
      if (!terminated) {
        s.warnings_.push_back(where + "last line has no newline (kept; it parsed completely)");
      }
      s.frames_.push_back(std::move(f));
    } catch (const Error& e) {
      if (!terminated) {
        s.warnings_.push_back(where + "ignored a last line cut short (" + e.what() + ")");
        continue;
      }
      throw Error(where + e.what());
    }
  }
  return s;
}

fs::path Session::PathOf(const FrameRecord& f) const {
  try {
    return ResolveInside(dir_, f.file);
  } catch (const Error& e) {
    throw Error(dir_.string() + ": frame " + std::to_string(f.id) + ": " + e.what());
  }
}

Image Session::LoadFrame(const FrameRecord& f) const {
  const fs::path p = PathOf(f);
  const std::string actual = Sha256File(p);
  if (actual != f.sha256) {
    throw Error(p.string() + ": frame " + std::to_string(f.id) + " (" + f.group +
                ") does not match its journal entry: sha256 " + actual + ", journalled " +
                f.sha256 + " (the file was changed or damaged after capture)");
  }
  return ReadImage(p.string());
}

// ---------------------------------------------------------------------------------------
// SessionWriter

void SessionWriterOptions::Validate() const {
  if (png_compression < 0 || png_compression > 9) {
    throw Error("session writer: png_compression " + std::to_string(png_compression) +
                " is not a zlib level (0: the default, 1 fastest .. 9 smallest)");
  }
}

SessionWriter SessionWriter::Create(const fs::path& dir, const SessionInfo& info,
                                    const SessionWriterOptions& options) {
  options.Validate();
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir)) {
    throw Error(dir.string() + ": exists and is not a directory");
  }
  fs::create_directories(dir, ec);
  if (ec) throw Error(dir.string() + ": cannot create the session folder: " + ec.message());
  SessionWriter w;
  w.options_ = options;
  w.lock_fd_ = LockSession(dir);
  {
    // A folder left by a crash before its session.json was written holds no data: only an
    // empty frames/ folder, an empty journal, the lock and temporary files. Anything else is
    // refused.
    for (const auto& entry : fs::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      const bool leftover =
          name.find(".tmp-") != std::string::npos || name == kLockName ||
          (name == "frames.jsonl" && fs::is_regular_file(entry.path()) &&
           fs::file_size(entry.path()) == 0) ||
          (name == "frames" && fs::is_directory(entry.path()) && fs::is_empty(entry.path()));
      if (!leftover)
        throw Error(dir.string() +
                    ": refusing to create a session in a non-empty folder "
                    "(use resume to continue it)");
    }
    for (const auto& entry : fs::directory_iterator(dir))
      if (entry.path().filename().string().find(".tmp-") != std::string::npos)
        fs::remove(entry.path(), ec);
  }
  fs::create_directories(dir / "frames", ec);
  if (ec) throw Error(dir.string() + ": cannot create the session folder: " + ec.message());
  w.dir_ = dir;
  w.info_ = info;
  if (w.info_.created_utc.empty()) w.info_.created_utc = NowUtc().Iso8601(3);
  // The empty journal first: once session.json exists, the session loads.
  w.journal_fd_ = OpenJournal(dir);
  if (CurrentFileIo().Fsync(w.journal_fd_) != 0) {
    throw Error(IoErrorMessage(JournalPath(dir), "fsync failed", errno));
  }
  WriteFileAtomic(dir / "session.json", json(w.info_).dump(2) + "\n");
  if (dir.has_parent_path()) FsyncDir(dir.parent_path());
  return w;
}

SessionWriter SessionWriter::Resume(const fs::path& dir, const SessionWriterOptions& options) {
  options.Validate();
  if (!fs::is_regular_file(dir / "session.json")) {
    throw Error(dir.string() + ": cannot resume: no session.json");
  }
  SessionWriter w;
  w.options_ = options;
  w.lock_fd_ = LockSession(dir);
  // A journal line cut short by a crash: keep it if it is complete but for the newline,
  // otherwise truncate it away.
  const std::string journal = JournalPath(dir);
  if (!fs::exists(journal)) {
    // Killed between session.json and the journal's creation: an empty journal.
    const int fd = OpenJournal(dir);
    ::close(fd);
  }
  {
    const std::string text = ReadFileToString(journal);
    if (!text.empty() && text.back() != '\n') {
      const size_t last_nl = text.rfind('\n');
      const size_t start = last_nl == std::string::npos ? 0 : last_nl + 1;
      bool complete = false;
      try {
        const FrameRecord f = ParseJournalLine(std::string_view(text).substr(start));
        complete = fs::is_regular_file(ResolveInside(dir, f.file));
      } catch (const Error&) {
        complete = false;
      }
      const int fd = ::open(journal.c_str(), O_WRONLY | O_CLOEXEC);
      if (fd < 0) throw Error(journal + ": cannot open: " + Errno());
      bool ok;
      if (complete) {
        ok = ::pwrite(fd, "\n", 1, static_cast<off_t>(text.size())) == 1;
      } else {
        ok = ::ftruncate(fd, static_cast<off_t>(start)) == 0;
      }
      ok = ok && ::fsync(fd) == 0;
      const std::string e = Errno();
      ::close(fd);
      if (!ok) throw Error(journal + ": cannot repair the last line: " + e);
    }
  }
  // Leftover temporary files from an interrupted write.
  for (const fs::path& folder : {dir, dir / "frames"}) {
    std::error_code ec;
    if (!fs::is_directory(folder, ec)) continue;
    for (const auto& entry : fs::directory_iterator(folder)) {
      if (entry.path().filename().string().find(".tmp-") != std::string::npos) {
        fs::remove(entry.path(), ec);
      }
    }
  }
  fs::create_directories(dir / "frames");
  Session s = Session::Load(dir);
  w.dir_ = dir;
  w.info_ = s.info();
  w.frames_ = s.frames();
  for (const auto& f : w.frames_) w.next_id_ = std::max(w.next_id_, f.id + 1);
  w.journal_fd_ = OpenJournal(dir);
  return w;
}

SessionWriter::~SessionWriter() { Close(); }

void SessionWriter::Close() {
  if (journal_fd_ >= 0) ::close(journal_fd_);
  if (lock_fd_ >= 0) ::close(lock_fd_);
  journal_fd_ = lock_fd_ = -1;
}

SessionWriter::SessionWriter(SessionWriter&& o) noexcept
    : dir_(std::move(o.dir_)),
      options_(o.options_),
      info_(std::move(o.info_)),
      frames_(std::move(o.frames_)),
      journal_fd_(o.journal_fd_),
      lock_fd_(o.lock_fd_),
      next_id_(o.next_id_) {
  o.journal_fd_ = o.lock_fd_ = -1;
}

SessionWriter& SessionWriter::operator=(SessionWriter&& o) noexcept {
  if (this != &o) {
    Close();
    dir_ = std::move(o.dir_);
    options_ = o.options_;
    info_ = std::move(o.info_);
    frames_ = std::move(o.frames_);
    journal_fd_ = o.journal_fd_;
    lock_fd_ = o.lock_fd_;
    next_id_ = o.next_id_;
    o.journal_fd_ = o.lock_fd_ = -1;
  }
  return *this;
}

FrameRecord SessionWriter::Append(FrameRecord meta, const Image& pixels) {
  if (journal_fd_ < 0) throw Error(dir_.string() + ": session writer is closed");
  CheckFrameFinite(meta);
  if (pixels.empty()) throw Error(dir_.string() + ": refusing to append an empty image");
  meta.id = next_id_;
  char name[64];
  std::snprintf(name, sizeof(name), "frames/%06lld.%s", static_cast<long long>(meta.id),
                meta.hdr ? "exr" : "png");
  meta.file = name;
  const fs::path path = dir_ / meta.file;
  StoredType type = StoredType::kUint8;
  if (meta.hdr) {
    type = StoredType::kHalf;
    for (float v : pixels.data) {
      // Beyond half range, or rounding to its maximum (a float above 65488 becomes 65504, the
      // value a half frame clips at, which the sun's measurement refuses): full precision.
      if (std::abs(v) > kHalfMax - 16) {
        type = StoredType::kFloat;
        break;
      }
    }
  }
  // The frame enters the journal only once its whole file is on disk: encoded and decoded
  // back in memory, every write checked, fsynced, its size checked, renamed into place.
  std::vector<ImageAttribute> encoding;
  if (!meta.hdr && options_.png_compression > 0)
    encoding.push_back({"png:compressionLevel", options_.png_compression});
  const std::string bytes = EncodeImage(path.string(), pixels, type, encoding);
  meta.sha256 = Sha256Hex(bytes);
  const std::string line = json(meta).dump() + "\n";
  const std::string journal = JournalPath(dir_);
  off_t before = -1;
  try {
    WriteFileAtomic(path, bytes);
    before = ::lseek(journal_fd_, 0, SEEK_END);
    if (before < 0) throw Error(IoErrorMessage(journal, "cannot seek", errno));
    WriteAll(journal_fd_, line, journal);
    if (CurrentFileIo().Fsync(journal_fd_) != 0) {
      throw Error(IoErrorMessage(journal, "fsync failed", errno));
    }
  } catch (const Error& e) {
    // The journal ends at the previous frame again (Load and Resume also tolerate a cut last
    // line), and the unjournalled file goes: the session stays consistent for --resume.
    if (before >= 0 && ::ftruncate(journal_fd_, before) == 0) ::fsync(journal_fd_);
    ::unlink(path.c_str());
    throw Error(std::string(e.what()) + " (frame " + std::to_string(meta.id) + ", " + meta.group +
                ", was not journalled; the session keeps its first " +
                std::to_string(frames_.size()) + " frames)");
  }
  ++next_id_;
  frames_.push_back(meta);
  return meta;
}

void SessionWriter::UpdateInfo(const SessionInfo& info) {
  WriteFileAtomic(dir_ / "session.json", json(info).dump(2) + "\n");
  info_ = info;
}

}  // namespace rouen
