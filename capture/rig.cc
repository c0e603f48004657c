#include "capture/rig.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"

namespace rouen {
namespace {

// Bounds of the plan's lists: a rig asking for more is a typo or a runaway generator, and
// would capture for hours before anyone noticed.
constexpr size_t kMaxAureoleExposures = 32;  // as a bracket's max_frames
constexpr size_t kMaxSlots = 48;             // one every half hour of a day
constexpr size_t kMaxTargets = 6;            // every target once

class RigReader {
 public:
  RigReader(const toml::table& t, std::string name) : root_(t), name_(std::move(name)) {}

  [[noreturn]] void Fail(const toml::node* node, const std::string& msg) const {
    std::ostringstream os;
    os << name_;
    if (node && node->source().begin.line > 0) os << ":" << node->source().begin.line;
    os << ": " << msg;
    throw Error(os.str());
  }
  const toml::table* Table(const char* key, bool required) const {
    const toml::node* n = root_.get(key);
    if (!n) {
      if (required) Fail(nullptr, std::string("missing table [") + key + "]");
      return nullptr;
    }
    if (!n->is_table()) Fail(n, std::string("'") + key + "' must be a table");
    return n->as_table();
  }
  double Number(const toml::table* t, const char* section, const char* key, double def,
                bool required = false) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) {
      if (required) Fail(t, std::string("[") + section + "] needs '" + key + "'");
      return def;
    }
    std::optional<double> v = n->value<double>();
    if (!v || !std::isfinite(*v))
      Fail(n, std::string("[") + section + "] '" + key + "' must be a number");
    return *v;
  }
  bool Bool(const toml::table* t, const char* section, const char* key, bool def) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) return def;
    if (!n->is_boolean())
      Fail(n, std::string("[") + section + "] '" + key + "' must be true or false");
    return *n->value<bool>();
  }
  int64_t Int64(const toml::table* t, const char* section, const char* key, int64_t def, int64_t lo,
                int64_t hi) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) return def;
    std::optional<int64_t> v = n->is_integer() ? n->value<int64_t>() : std::nullopt;
    if (!v || *v < lo || *v > hi)
      Fail(n, std::string("[") + section + "] '" + key + "' must be an integer within " +
                  std::to_string(lo) + ".." + std::to_string(hi));
    return *v;
  }
  int Int(const toml::table* t, const char* section, const char* key, int def, int lo,
          int hi) const {
    return static_cast<int>(Int64(t, section, key, def, lo, hi));
  }
  std::string String(const toml::table* t, const char* section, const char* key,
                     const std::string& def, bool required = false) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) {
      if (required) Fail(t, std::string("[") + section + "] needs '" + key + "'");
      return def;
    }
    if (!n->is_string()) Fail(n, std::string("[") + section + "] '" + key + "' must be a string");
    return *n->value<std::string>();
  }
  // A number whose range is one of core/limits.h's rules: `problem` says what is wrong.
  double Checked(const toml::table* t, const char* section, const char* key, double def,
                 std::string (*problem)(double)) const {
    const double v = Number(t, section, key, def);
    const std::string p = problem(v);
    if (!p.empty())
      Fail(t ? t->get(key) : nullptr, std::string("[") + section + "] '" + key + "': " + p);
    return v;
  }
  // An array of at most `max_count` entries.
  const toml::array* Array(const toml::table* t, const char* section, const char* key,
                           size_t max_count) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) return nullptr;
    if (!n->is_array()) Fail(n, std::string("[") + section + "] '" + key + "' must be an array");
    const toml::array* a = n->as_array();
    if (a->size() > max_count)
      Fail(n, std::string("[") + section + "] '" + key + "' has " + std::to_string(a->size()) +
                  " entries; at most " + std::to_string(max_count));
    return a;
  }
  std::vector<double> Numbers(const toml::table* t, const char* section, const char* key,
                              std::vector<double> def, size_t max_count,
                              std::string (*problem)(double) = nullptr) const {
    const toml::array* a = Array(t, section, key, max_count);
    if (!a) return def;
    std::vector<double> out;
    for (const toml::node& e : *a) {
      std::optional<double> v = e.value<double>();
      if (!v || !std::isfinite(*v) || *v <= 0)
        Fail(&e, std::string("[") + section + "] '" + key + "' must hold positive numbers");
      const std::string p = problem ? problem(*v) : std::string();
      if (!p.empty()) Fail(&e, std::string("[") + section + "] '" + key + "': " + p);
      out.push_back(*v);
    }
    return out;
  }
  std::vector<std::string> Strings(const toml::table* t, const char* section, const char* key,
                                   size_t max_count) const {
    const toml::array* a = Array(t, section, key, max_count);
    if (!a) return {};
    std::vector<std::string> out;
    for (const toml::node& e : *a) {
      if (!e.is_string())
        Fail(&e, std::string("[") + section + "] '" + key + "' must hold strings");
      out.push_back(*e.value<std::string>());
    }
    return out;
  }

 private:
  const toml::table& root_;
  std::string name_;
};

}  // namespace

const std::vector<std::string>& RigKinds() {
  static const std::vector<std::string> kinds = {
      "sim", "replay", "uvc-webcam", "rpi-libcamera", "gige-aravis", "aravis-fake", "gphoto2"};
  return kinds;
}

std::string RigConfig::LensPath(Target target) const {
  auto it = camera.target_lens.find(target);
  return Resolve(it != camera.target_lens.end() ? it->second : camera.lens);
}

std::string RigConfig::Resolve(const std::string& file) const {
  if (file.empty()) return {};
  std::filesystem::path p(file);
  if (p.is_relative()) p = std::filesystem::path(path).parent_path() / p;
  return p.string();
}

namespace {

// Throws rouen::Error "<name>:<line>: <problem>".
toml::table ParseToml(const std::string& text, const std::string& name) {
  try {
    return toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    std::ostringstream os;
    os << name << ":" << e.source().begin.line << ": " << e.description();
    throw Error(os.str());
  }
}

// Through toml++'s own JSON writer, then the strict JSON reader.
nlohmann::json TableAsJson(const toml::table& table, const std::string& name) {
  std::ostringstream json_text;
  json_text << toml::json_formatter{table};
  try {
    return nlohmann::json::parse(json_text.str());
  } catch (const nlohmann::json::exception&) {
    throw Error(name + ": every value must be a finite number, a string, a boolean or a table");
  }
}

// [camera] keys of the streaming drivers (V4L2, libcamera, Aravis), and of gphoto2 rigs.
const std::vector<std::string>& StreamingKeys() {
  static const std::vector<std::string> keys = {"device",       "width",   "height",
                                                "pixel_format", "buffers", "control_latency_frames",
                                                "timeout_s"};
  return keys;
}
const std::vector<std::string>& Gphoto2Keys() {
  static const std::vector<std::string> keys = {"model",
                                                "port",
                                                "serial",
                                                "download_dir",
                                                "aperture_f",
                                                "max_attempts",
                                                "backoff_initial_s",
                                                "backoff_max_s",
                                                "capture_timeout_s",
                                                "exif_tolerance_stops",
                                                "base_iso",
                                                "delete_on_camera"};
  return keys;
}

// Every [camera] key of every kind (ParseGphoto2Camera says which kind a key belongs to).
std::vector<std::string> CameraKeys() {
  std::vector<std::string> keys = {"id", "lens"};
  for (const auto* list : {&StreamingKeys(), &Gphoto2Keys()})
    keys.insert(keys.end(), list->begin(), list->end());
  return keys;
}

// A gphoto2 rig's [camera] (bounds as Gphoto2Options::Validate's); refuses keys of other kinds,
// and gphoto2 keys in rigs of other kinds.
void ParseGphoto2Camera(const RigReader& r, const toml::table* t, const std::string& kind,
                        Gphoto2CameraConfig* g) {
  if (!t) return;
  const bool gphoto2 = kind == "gphoto2";
  for (const std::string& key : gphoto2 ? StreamingKeys() : Gphoto2Keys()) {
    const toml::node* n = t->get(key);
    if (!n) continue;
    if (gphoto2)
      r.Fail(n, "[camera] '" + key +
                    "' is not used by gphoto2 rigs (the camera's own settings decide its image "
                    "size and format; name the camera with 'model', 'port' or 'serial'; the "
                    "capture waits 'capture_timeout_s' for each file)");
    r.Fail(n,
           "[camera] '" + key + "' is for gphoto2 rigs only (this rig's kind is '" + kind + "')");
  }
  if (!gphoto2) return;
  auto within = [&](const char* key, double v, double lo, double hi, bool lo_open,
                    const char* what) {
    if ((lo_open ? v > lo : v >= lo) && v <= hi) return;
    r.Fail(t->get(key), std::string("[camera] '") + key + "' must be " + what);
  };
  g->model = r.String(t, "camera", "model", g->model);
  g->port = r.String(t, "camera", "port", g->port);
  g->serial = r.String(t, "camera", "serial", g->serial);
  g->download_dir = r.String(t, "camera", "download_dir", g->download_dir);
  g->aperture_f = r.Number(t, "camera", "aperture_f", g->aperture_f);
  if (g->aperture_f != 0)
    within("aperture_f", g->aperture_f, 0.5, 128, false,
           "0 (as the camera is set) or an f-number within 0.5..128");
  g->max_attempts = r.Int(t, "camera", "max_attempts", g->max_attempts, 1, 100);
  g->backoff_initial_s = r.Number(t, "camera", "backoff_initial_s", g->backoff_initial_s);
  within("backoff_initial_s", g->backoff_initial_s, 0, 60, true, "within (0, 60] s");
  g->backoff_max_s = r.Number(t, "camera", "backoff_max_s", g->backoff_max_s);
  within("backoff_max_s", g->backoff_max_s, g->backoff_initial_s, 600, false,
         "at least backoff_initial_s and at most 600 s");
  g->capture_timeout_s = r.Number(t, "camera", "capture_timeout_s", g->capture_timeout_s);
  within("capture_timeout_s", g->capture_timeout_s, 0, 3600, true, "within (0, 3600] s");
  g->exif_tolerance_stops = r.Number(t, "camera", "exif_tolerance_stops", g->exif_tolerance_stops);
  within("exif_tolerance_stops", g->exif_tolerance_stops, 0, 10, true, "within (0, 10] stops");
  g->base_iso = r.Number(t, "camera", "base_iso", g->base_iso);
  within("base_iso", g->base_iso, 0, 1e6, true, "a positive ISO");
  g->delete_on_camera = r.Bool(t, "camera", "delete_on_camera", g->delete_on_camera);
}

}  // namespace

nlohmann::json ParseTomlAsJson(const std::string& text, const std::string& name) {
  return TableAsJson(ParseToml(text, name), name);
}

RigConfig ParseRig(const std::string& text, const std::string& name) {
  const toml::table root = ParseToml(text, name);
  RigReader r(root, name);
  // A misspelt table or key would silently fall back to a default in the field: refuse it.
  static const std::map<std::string, std::vector<std::string>> kSchema = {
      {"rig", {"name", "kind", "seed", "quick"}},
      {"site", {"lat_deg", "lon_deg", "height_m"}},
      {"camera", CameraKeys()},
      {"lens", {}},  // target = lens file
      {"gps", {"source", "device", "baud", "host", "port", "timeout_s"}},
      {"nd", {"sun_density"}},
      {"bracket",
       {"step_stops", "min_exposure_s", "max_exposure_s", "max_frames", "saturation_dn",
        "noise_floor_dn"}},
      {"plan",
       {"date", "timezone", "times", "heldout", "targets", "views", "start_exposure_s",
        "sun_start_exposure_s", "aureole_exposures_s"}},
      {"capture", {"on_device_lost", "reconnect_timeout_s"}},
      {"solve", {}},  // any key of the solve's options, checked by the pipeline
  };
  for (const auto& [key, node] : root) {
    auto it = kSchema.find(std::string(key.str()));
    if (it == kSchema.end()) {
      r.Fail(&node, "unknown table [" + std::string(key.str()) + "]");
    }
    if (it->first == "lens" || it->first == "solve" || !node.is_table()) continue;
    for (const auto& [k2, n2] : *node.as_table()) {
      const std::vector<std::string>& known = it->second;
      if (std::find(known.begin(), known.end(), std::string(k2.str())) == known.end()) {
        std::string list;
        for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
        r.Fail(&n2, "unknown key '" + std::string(k2.str()) + "' in [" + it->first +
                        "] (known: " + list + ")");
      }
    }
  }
  RigConfig rig;
  rig.path = name;
  const toml::table* t_rig = r.Table("rig", true);
  rig.name = r.String(t_rig, "rig", "name", "", true);
  rig.kind = r.String(t_rig, "rig", "kind", "", true);
  const std::vector<std::string>& kinds = RigKinds();
  if (std::find(kinds.begin(), kinds.end(), rig.kind) == kinds.end()) {
    std::string known;
    for (const std::string& k : kinds) known += (known.empty() ? "" : ", ") + k;
    r.Fail(t_rig->get("kind"), "unknown rig kind '" + rig.kind + "' (known: " + known + ")");
  }
  const bool field = !rig.simulated() && rig.kind != "replay";
  rig.quick = r.Bool(t_rig, "rig", "quick", false);
  rig.seed = static_cast<uint64_t>(
      r.Int64(t_rig, "rig", "seed", 1, 0, std::numeric_limits<int64_t>::max()));

  const toml::table* t_site = r.Table("site", rig.simulated() || field);
  rig.site.lat_deg = r.Checked(t_site, "site", "lat_deg", rig.site.lat_deg, LatitudeProblem);
  rig.site.lon_deg = r.Checked(t_site, "site", "lon_deg", rig.site.lon_deg, LongitudeProblem);
  rig.site.height_m = r.Checked(t_site, "site", "height_m", rig.site.height_m, HeightProblem);

  const toml::table* t_cam = r.Table("camera", field);
  CameraConfig& cam = rig.camera;
  cam.id = r.String(t_cam, "camera", "id", cam.id);
  if (cam.id.empty()) r.Fail(t_cam, "[camera] 'id' must not be empty");
  cam.device = r.String(t_cam, "camera", "device", cam.device);
  cam.width = r.Int(t_cam, "camera", "width", 0, 0, 20000);
  cam.height = r.Int(t_cam, "camera", "height", 0, 0, 20000);
  cam.pixel_format = r.String(t_cam, "camera", "pixel_format", "");
  cam.buffers = r.Int(t_cam, "camera", "buffers", cam.buffers, 2, 64);
  cam.control_latency_frames = r.Int(t_cam, "camera", "control_latency_frames", 0, 0, 30);
  cam.timeout_s = r.Number(t_cam, "camera", "timeout_s", cam.timeout_s);
  if (!(cam.timeout_s > 0 && cam.timeout_s <= 600))
    r.Fail(t_cam ? t_cam->get("timeout_s") : nullptr, "[camera] timeout_s must be in (0, 600]");
  cam.lens = r.String(t_cam, "camera", "lens", "");
  ParseGphoto2Camera(r, t_cam, rig.kind, &cam.gphoto2);
  if (const toml::table* t_lens = r.Table("lens", false)) {
    for (const auto& [key, node] : *t_lens) {
      Target target;
      try {
        target = ParseTarget(std::string(key.str()));
      } catch (const Error& e) {
        r.Fail(&node, std::string("[lens] ") + e.what());
      }
      if (!node.is_string()) r.Fail(&node, "[lens] values must be lens file names");
      cam.target_lens[target] = *node.value<std::string>();
    }
  }

  const toml::table* t_gps = r.Table("gps", false);
  GpsConfig& gps = rig.gps;
  gps.source = r.String(t_gps, "gps", "source",
                        rig.simulated()        ? "sim"
                        : rig.kind == "replay" ? "replay"
                                               : "none");
  static const char* kSources[] = {"sim", "replay", "nmea", "gpsd", "none"};
  if (std::find(std::begin(kSources), std::end(kSources), gps.source) == std::end(kSources))
    r.Fail(t_gps->get("source"),
           "unknown GPS source '" + gps.source + "' (known: sim, replay, nmea, gpsd, none)");
  if ((gps.source == "sim") != rig.simulated() && gps.source != "none")
    r.Fail(t_gps->get("source"), "GPS source 'sim' goes with simulated rigs only");
  if ((gps.source == "replay") != (rig.kind == "replay") && gps.source != "none")
    r.Fail(t_gps->get("source"), "GPS source 'replay' goes with replay rigs only");
  gps.device = r.String(t_gps, "gps", "device", "");
  if (gps.source == "nmea" && gps.device.empty())
    r.Fail(t_gps, "[gps] source 'nmea' needs 'device' (a serial port or a log file)");
  gps.baud = r.Int(t_gps, "gps", "baud", gps.baud, 0, 921600);
  gps.host = r.String(t_gps, "gps", "host", gps.host);
  gps.port = r.String(t_gps, "gps", "port", gps.port);
  gps.timeout_s = r.Number(t_gps, "gps", "timeout_s", gps.timeout_s);
  if (!(gps.timeout_s > 0 && gps.timeout_s <= 60))
    r.Fail(t_gps, "[gps] timeout_s must be in (0, 60]");

  const toml::table* t_nd = r.Table("nd", false);
  if (const toml::node* n = t_nd ? t_nd->get("sun_density") : nullptr) {
    if (n->is_array()) {
      std::vector<double> d = r.Numbers(t_nd, "nd", "sun_density", {}, 3);
      if (d.size() != 3) r.Fail(n, "[nd] sun_density: one number, or three (R, G, B)");
      std::copy(d.begin(), d.end(), rig.sun_nd_density_rgb.begin());
    } else {
      rig.sun_nd_density_rgb.fill(r.Number(t_nd, "nd", "sun_density", 0));
    }
    for (double d : rig.sun_nd_density_rgb)
      if (!(d >= 0 && d < 10)) r.Fail(n, "[nd] sun_density must be within 0..10 (optical density)");
  }
  rig.plan.sun_nd_density =
      (rig.sun_nd_density_rgb[0] + rig.sun_nd_density_rgb[1] + rig.sun_nd_density_rgb[2]) / 3;

  const toml::table* t_b = r.Table("bracket", false);
  BracketOptions& b = rig.plan.bracket;
  b.step_stops = r.Number(t_b, "bracket", "step_stops", b.step_stops);
  b.min_exposure_s = r.Checked(t_b, "bracket", "min_exposure_s", b.min_exposure_s, ExposureProblem);
  b.max_exposure_s = r.Checked(t_b, "bracket", "max_exposure_s", b.max_exposure_s, ExposureProblem);
  b.max_frames = r.Int(t_b, "bracket", "max_frames", b.max_frames, 1, 32);
  b.saturation_dn = r.Number(t_b, "bracket", "saturation_dn", b.saturation_dn);
  b.noise_floor_dn = r.Number(t_b, "bracket", "noise_floor_dn", b.noise_floor_dn);

  const toml::table* t_plan = r.Table("plan", rig.kind == "sim");
  rig.plan.start_exposure_s =
      r.Checked(t_plan, "plan", "start_exposure_s", rig.plan.start_exposure_s, ExposureProblem);
  rig.plan.sun_start_exposure_s = r.Checked(t_plan, "plan", "sun_start_exposure_s",
                                            rig.plan.sun_start_exposure_s, ExposureProblem);
  rig.plan.aureole_exposures_s =
      r.Numbers(t_plan, "plan", "aureole_exposures_s", rig.plan.aureole_exposures_s,
                kMaxAureoleExposures, ExposureProblem);
  std::vector<std::string> targets = r.Strings(t_plan, "plan", "targets", kMaxTargets);
  if (!targets.empty()) {
    rig.plan.targets.clear();
    for (const std::string& s : targets) {
      Target target;
      try {
        target = ParseTarget(s);
      } catch (const Error& e) {
        r.Fail(t_plan->get("targets"), e.what());
      }
      if (std::find(rig.plan.targets.begin(), rig.plan.targets.end(), target) !=
          rig.plan.targets.end())
        r.Fail(t_plan->get("targets"), "[plan] targets: '" + s + "' is listed twice");
      rig.plan.targets.push_back(target);
    }
  }
  if (const toml::node* n = t_plan ? t_plan->get("views") : nullptr) {
    if (!n->is_table()) r.Fail(n, "[plan] views must be a table, e.g. { architecture = 4 }");
    for (const auto& [key, node] : *n->as_table()) {
      Target target;
      try {
        target = ParseTarget(std::string(key.str()));
      } catch (const Error& e) {
        r.Fail(&node, std::string("[plan] views: ") + e.what());
      }
      std::optional<int64_t> v = node.value<int64_t>();
      if (!v || *v < 1 || *v > 64) r.Fail(&node, "[plan] views: counts must be within 1..64");
      rig.views[target] = static_cast<int>(*v);
    }
  }
  if (t_plan) {
    rig.slot_labels = r.Strings(t_plan, "plan", "times", kMaxSlots);
    std::string date = r.String(t_plan, "plan", "date", "", !rig.slot_labels.empty());
    std::string zone = r.String(t_plan, "plan", "timezone", "Z");
    for (const std::string& hhmm : rig.slot_labels) {
      try {
        rig.plan.slots.push_back(ParseIso8601(date + "T" + hhmm + ":00" + zone));
      } catch (const Error& e) {
        r.Fail(t_plan->get("times"), std::string("bad slot time: ") + e.what());
      }
    }
    std::string heldout = r.String(t_plan, "plan", "heldout", "");
    if (!heldout.empty()) {
      auto it = std::find(rig.slot_labels.begin(), rig.slot_labels.end(), heldout);
      if (it == rig.slot_labels.end())
        r.Fail(t_plan->get("heldout"), "heldout time '" + heldout + "' is not one of the times");
      rig.heldout_slot = static_cast<int>(it - rig.slot_labels.begin());
    }
  }
  if (rig.simulated() && rig.plan.slots.empty()) r.Fail(t_plan, "[plan] needs 'times'");
  if (field && !rig.plan.slots.empty())
    r.Fail(t_plan->get("times"),
           "[plan] times are for simulated rigs; a field rig captures one slot per run (now)");

  const toml::table* t_capture = r.Table("capture", false);
  std::string lost = r.String(t_capture, "capture", "on_device_lost", "stop");
  if (lost == "stop") {
    rig.on_device_lost = DeviceLostPolicy::kStop;
  } else if (lost == "reconnect") {
    rig.on_device_lost = DeviceLostPolicy::kReconnect;
  } else {
    r.Fail(t_capture->get("on_device_lost"),
           "[capture] on_device_lost must be \"stop\" or \"reconnect\"");
  }
  rig.reconnect_timeout_s = r.Number(t_capture, "capture", "reconnect_timeout_s", 60);
  if (!(rig.reconnect_timeout_s > 0 && rig.reconnect_timeout_s <= 3600))
    r.Fail(t_capture, "[capture] reconnect_timeout_s must be in (0, 3600]");
  try {
    rig.plan.bracket.Validate();
  } catch (const Error& e) {
    r.Fail(t_b, e.what());
  }
  if (const toml::table* t_solve = r.Table("solve", false))
    rig.solve_config = TableAsJson(*t_solve, name + ": [solve]");
  return rig;
}

RigConfig LoadRig(const std::filesystem::path& path) {
  std::string text;
  try {
    text = ReadFileToString(path);
  } catch (const Error& e) {
    throw Error("rig " + path.string() + ": cannot read: " + e.what());
  }
  return ParseRig(text, path.string());
}

}  // namespace rouen
