#include "capture/rig.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <toml++/toml.h>

#include "capture/replay/replay_devices.h"
#include "capture/sim/sim_devices.h"
#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

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
  std::vector<double> Numbers(const toml::table* t, const char* section, const char* key,
                              std::vector<double> def) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) return def;
    if (!n->is_array()) Fail(n, std::string("[") + section + "] '" + key + "' must be an array");
    std::vector<double> out;
    for (const toml::node& e : *n->as_array()) {
      std::optional<double> v = e.value<double>();
      if (!v || !std::isfinite(*v) || *v <= 0)
        Fail(&e, std::string("[") + section + "] '" + key + "' must hold positive numbers");
      out.push_back(*v);
    }
    return out;
  }
  std::vector<std::string> Strings(const toml::table* t, const char* section, const char* key) const {
    const toml::node* n = t ? t->get(key) : nullptr;
    if (!n) return {};
    if (!n->is_array()) Fail(n, std::string("[") + section + "] '" + key + "' must be an array");
    std::vector<std::string> out;
    for (const toml::node& e : *n->as_array()) {
      if (!e.is_string()) Fail(&e, std::string("[") + section + "] '" + key + "' must hold strings");
      out.push_back(*e.value<std::string>());
    }
    return out;
  }

 private:
  const toml::table& root_;
  std::string name_;
};

}  // namespace

RigConfig ParseRig(const std::string& text, const std::string& name) {
  toml::table root;
  try {
    root = toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    std::ostringstream os;
    os << name << ":" << e.source().begin.line << ": " << e.description();
    throw Error(os.str());
  }
  RigReader r(root, name);
  RigConfig rig;
  rig.path = name;
  const toml::table* t_rig = r.Table("rig", true);
  rig.name = r.String(t_rig, "rig", "name", "", true);
  rig.kind = r.String(t_rig, "rig", "kind", "", true);
  if (rig.kind != "sim" && rig.kind != "replay")
    r.Fail(t_rig->get("kind"), "unknown rig kind '" + rig.kind +
                                   "' (this build knows: sim, replay)");
  rig.quick = t_rig->get("quick") && t_rig->get("quick")->value<bool>().value_or(false);
  rig.seed = static_cast<uint64_t>(r.Number(t_rig, "rig", "seed", 1));

  const toml::table* t_site = r.Table("site", rig.kind == "sim");
  rig.site.lat_deg = r.Number(t_site, "site", "lat_deg", rig.site.lat_deg);
  rig.site.lon_deg = r.Number(t_site, "site", "lon_deg", rig.site.lon_deg);
  rig.site.height_m = r.Number(t_site, "site", "height_m", rig.site.height_m);
  if (std::abs(rig.site.lat_deg) > 90 || std::abs(rig.site.lon_deg) > 180)
    r.Fail(t_site, "site latitude/longitude out of range");

  const toml::table* t_cam = r.Table("camera", false);
  rig.camera_id = r.String(t_cam, "camera", "id", rig.camera_id);
  rig.control_latency_frames =
      static_cast<int>(r.Number(t_cam, "camera", "control_latency_frames", 0));
  if (rig.control_latency_frames < 0 || rig.control_latency_frames > 30)
    r.Fail(t_cam, "control_latency_frames must be within 0..30");

  const toml::table* t_gps = r.Table("gps", false);
  rig.gps_source = r.String(t_gps, "gps", "source", rig.kind);

  const toml::table* t_nd = r.Table("nd", false);
  rig.plan.sun_nd_density = r.Number(t_nd, "nd", "sun_density", rig.plan.sun_nd_density);

  const toml::table* t_b = r.Table("bracket", false);
  BracketOptions& b = rig.plan.bracket;
  b.step_stops = r.Number(t_b, "bracket", "step_stops", b.step_stops);
  b.min_exposure_s = r.Number(t_b, "bracket", "min_exposure_s", b.min_exposure_s);
  b.max_exposure_s = r.Number(t_b, "bracket", "max_exposure_s", b.max_exposure_s);
  b.max_frames = static_cast<int>(r.Number(t_b, "bracket", "max_frames", b.max_frames));
  b.saturation_dn = r.Number(t_b, "bracket", "saturation_dn", b.saturation_dn);
  b.noise_floor_dn = r.Number(t_b, "bracket", "noise_floor_dn", b.noise_floor_dn);

  const toml::table* t_plan = r.Table("plan", rig.kind == "sim");
  rig.plan.start_exposure_s =
      r.Number(t_plan, "plan", "start_exposure_s", rig.plan.start_exposure_s);
  rig.plan.sun_start_exposure_s =
      r.Number(t_plan, "plan", "sun_start_exposure_s", rig.plan.sun_start_exposure_s);
  rig.plan.aureole_exposures_s =
      r.Numbers(t_plan, "plan", "aureole_exposures_s", rig.plan.aureole_exposures_s);
  std::vector<std::string> targets = r.Strings(t_plan, "plan", "targets");
  if (!targets.empty()) {
    rig.plan.targets.clear();
    for (const std::string& s : targets) {
      try {
        rig.plan.targets.push_back(ParseTarget(s));
      } catch (const Error& e) {
        r.Fail(t_plan->get("targets"), e.what());
      }
    }
  }
  if (t_plan) {
    std::string date = r.String(t_plan, "plan", "date", "", rig.kind == "sim");
    std::string zone = r.String(t_plan, "plan", "timezone", "Z");
    rig.slot_labels = r.Strings(t_plan, "plan", "times");
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
  if (rig.kind == "sim" && rig.plan.slots.empty()) r.Fail(t_plan, "[plan] needs 'times'");
  try {
    rig.plan.bracket.Validate();
  } catch (const Error& e) {
    r.Fail(t_b, e.what());
  }
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

RigDevices OpenRig(const RigConfig& rig, const std::filesystem::path& from_session) {
  RigDevices d;
  d.plan = rig.plan;
  if (rig.kind == "replay") {
    if (from_session.empty()) throw Error(rig.path + ": a replay rig needs --from SESSION");
    auto src = std::make_shared<ReplaySource>(from_session);
    const nlohmann::json& extra = src->session().info().extra;
    if (extra.contains("plan")) d.plan = PlanFromJson(extra["plan"]);  // the recorded plan
    d.plan.slots = src->slot_times();
    d.camera = std::make_unique<ReplayCamera>(src);
    d.gps = std::make_unique<ReplayGps>(src);
    d.clock = std::make_unique<ReplayClock>(src);
    d.keep_alive = src;
    return d;
  }
  SimWorldOptions wo;
  wo.site = rig.site;
  wo.quick = rig.quick;
  wo.seed = rig.seed;
  auto world = std::make_shared<SimWorld>(wo);
  auto clock = std::make_unique<SimClock>();
  d.camera = std::make_unique<SimCamera>(world, clock.get(), rig.quick, rig.seed);
  if (rig.gps_source == "sim") d.gps = std::make_unique<SimGps>(world, clock.get(), rig.seed + 7);
  d.clock = std::move(clock);
  d.model = world->Model();
  d.keep_alive = world;
  return d;
}

}  // namespace rouen
