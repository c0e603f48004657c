#include "pipeline/capture_session.h"

#include <algorithm>
#include <memory>
#include <optional>
#include <set>

#include "core/error.h"
#include "core/files.h"
#include "core/lens.h"
#include "core/mesh.h"
#include "core/outputs.h"
#include "core/session.h"
#include "pipeline/solve_config.h"

namespace rouen {
namespace {

struct PlannedGroup {
  std::string name;  // BracketName(slot, target, view)
  int slot = 0;
};

// The brackets the plan captures, in the controller's order: slot, target, view.
std::vector<PlannedGroup> PlannedGroups(const CapturePlan& plan, const Camera* camera) {
  std::vector<PlannedGroup> out;
  for (int k = 0; k < static_cast<int>(plan.slots.size()); ++k) {
    const int s = plan.first_slot + k;
    for (Target t : plan.targets) {
      const int views = camera ? std::max(1, camera->ViewCount(t)) : 1;
      for (int v = 0; v < views; ++v) out.push_back({BracketName(s, t, v), s});
    }
  }
  return out;
}

// What a --resume would capture (CaptureController::Run): the planned brackets not in the
// journal and, unless the last run finished, the one journalled last (it may be partial).
void CountLeft(const std::vector<PlannedGroup>& planned, const std::vector<FrameRecord>& frames,
               bool finished, CaptureSessionSummary* summary) {
  std::set<std::string> done;
  for (const FrameRecord& f : frames) done.insert(f.group);
  if (!finished && !frames.empty()) done.erase(frames.back().group);
  std::set<int> slots;
  summary->brackets_planned = static_cast<int>(planned.size());
  summary->brackets_left.clear();
  for (const PlannedGroup& g : planned) {
    if (done.count(g.name)) continue;
    summary->brackets_left.push_back(g.name);
    slots.insert(g.slot);
  }
  summary->slots_left = static_cast<int>(slots.size());
  summary->frames_total = static_cast<int>(frames.size());
}

bool MarkedComplete(const SessionInfo& info) { return info.capture_complete.value_or(false); }

}  // namespace

CaptureSessionSummary CaptureToSession(const RigConfig& rig, RigDevices& dev,
                                       const std::filesystem::path& out,
                                       const CaptureSessionOptions& opts) {
  namespace fs = std::filesystem;
  const bool field = !rig.simulated() && rig.kind != "replay";
  std::error_code ec;
  if (opts.resume && !fs::exists(out, ec))
    throw Error(out.string() +
                ": no session to resume (no such folder); drop --resume to start a new session "
                "there");
  if (opts.new_slot && !field)
    throw Error(
        "--new-slot adds a time of day to a field session; simulated and replay rigs "
        "capture all their slots in one run");
  if (!opts.resume && !opts.new_slot) CheckNewFolderPlace(out.string(), out);
  if (opts.new_slot && !fs::exists(out / "session.json"))
    throw Error(out.string() + ": --new-slot needs an existing session (run without it first)");
  // The rig's [solve] options are checked now, not after the capture.
  ApplySolveConfig(rig.solve_config, DefaultSolveConfig(false), rig.path + ": [solve]");
  auto event = [&opts](const std::string& text) {
    if (!opts.progress) return;
    CaptureProgress p;
    p.event = text;
    opts.progress(p);
  };
  // The recorded session of a replay, read once for its site, notes and model.
  std::optional<Session> src;
  if (!opts.from_session.empty()) src.emplace(Session::Load(opts.from_session));
  // A simulated or replayed plan's times are known: one at night is refused before the session
  // is made (a field rig's one slot, now, is checked by the controller with its GPS fix).
  if (!field) CheckPlanDaylight(dev.plan, dev.plan.slots, src ? src->info().site : rig.site);
  std::optional<SessionWriter> writer;
  if ((opts.resume || opts.new_slot) && fs::exists(out / "session.json")) {
    writer.emplace(SessionWriter::Resume(out, opts.writer));
    if (field) {
      // A field run is one slot: --resume continues the session's last slot, --new-slot
      // starts the next one now.
      int last = -1;
      for (const FrameRecord& f : writer->frames()) last = std::max(last, f.slot);
      dev.plan.first_slot = opts.new_slot ? last + 1 : std::max(last, 0);
      if (opts.new_slot) {
        SessionInfo info = writer->info();
        if (info.extra.contains("plan") && info.extra["plan"].contains("slots"))
          info.extra["plan"]["slots"].push_back(dev.plan.slots.front().Iso8601(9));
        writer->UpdateInfo(info);
      }
    }
    // --resume of a finished plan: nothing to capture, nothing written.
    CaptureSessionSummary summary;
    CountLeft(PlannedGroups(dev.plan, dev.camera.get()), writer->frames(),
              MarkedComplete(writer->info()), &summary);
    if (opts.resume && MarkedComplete(writer->info()) && summary.brackets_left.empty()) {
      summary.already_complete = true;
      return summary;
    }
  } else {
    SessionInfo info;
    info.site = rig.site;
    info.site_source = "rig";
    info.rig = fs::path(rig.path).filename().string();
    info.created_utc = NowUtc().Iso8601(3);
    info.extra["plan"] = PlanToJson(dev.plan);
    info.nd_filters["sun"].density_rgb = rig.sun_nd_density_rgb;
    info.capture_complete = false;
    if (rig.heldout_slot >= 0) info.heldout_slot = rig.heldout_slot;
    info.solve_config = rig.solve_config;
    if (src) {
      info.site = src->info().site;
      info.site_source = src->info().site_source;
      info.clock_offset_s = src->info().clock_offset_s;
      info.notes = "replayed from " + opts.from_session.string();
      if (src->info().heldout_slot) info.heldout_slot = src->info().heldout_slot;
      if (!src->info().nd_filters.empty()) info.nd_filters = src->info().nd_filters;
      info.vignetting = src->info().vignetting;
      if (!src->info().solve_config.empty()) info.solve_config = src->info().solve_config;
    }
    writer.emplace(SessionWriter::Create(out, info, opts.writer));
  }
  // A lens file's vignetting model travels with the session too, keyed by the frames' device
  // and target (pipeline/session_solve.cc divides it out); one already there (e.g. from
  // `rouen calib vignetting --session`) is kept.
  if (rig.kind != "replay" && dev.camera) {
    SessionInfo info = writer->info();
    bool changed = false;
    for (Target t : dev.plan.targets) {
      const std::string path = rig.LensPath(t);
      if (path.empty()) continue;
      const std::optional<VignettingModel> v = ReadLensFile(path).vignetting;
      const std::string key = dev.camera->Id() + "/" + TargetName(t);
      if (!v || info.vignetting.count(key)) continue;
      info.vignetting[key] = *v;
      changed = true;
    }
    if (changed) writer->UpdateInfo(info);
  }
  // The building model travels with the session (also after a crash before it was written).
  if (writer->info().model.empty() && (dev.model || (src && !src->info().model.empty()))) {
    if (dev.model) {
      WriteObj((out / "model.obj").string(), *dev.model);
    } else {
      WriteFileAtomic(out / "model.obj",
                      ReadFileToString(ResolveInside(src->dir(), src->info().model)));
    }
    SessionInfo info = writer->info();
    info.model = "model.obj";
    writer->UpdateInfo(info);
  }
  // Unfinished from here until the plan is done (a finished run is left alone by --resume).
  {
    SessionInfo info = writer->info();
    if (info.capture_complete != false) {
      info.capture_complete = false;
      writer->UpdateInfo(info);
    }
  }
  DeviceLossOptions loss;
  loss.policy = rig.on_device_lost;
  loss.reconnect_timeout_s = rig.reconnect_timeout_s;
  CaptureController controller(dev.Devices(), dev.plan, writer->info().site, loss);
  // Field rigs: report USB cameras and receivers pulled out or plugged back in as it happens.
  std::shared_ptr<void> usb_watch;
  if (field) usb_watch = WatchUsb(event);
  CaptureSessionSummary summary;
  CaptureSummary& s = summary.capture;
  try {
    s = controller.Run(*writer, opts.progress, opts.stop);
  } catch (const Error& e) {
    // A full disk, a read-only disk: everything journalled so far is whole and stays.
    throw Error(std::string(e.what()) + "\n" + out.string() + ": the " +
                std::to_string(writer->frames().size()) +
                " frames journalled so far are kept; once the problem is fixed, continue with "
                "`rouen capture --rig ... --out " +
                out.string() + " --resume`");
  }
  usb_watch.reset();
  // The site actually used: the GPS fix if one came, else the rig's fallback (stated).
  SessionInfo info = writer->info();
  for (const FrameRecord& f : writer->frames()) {
    if (f.gps && f.gps->valid()) {
      info.site = {f.gps->lat_deg, f.gps->lon_deg, f.gps->height_m};
      info.site_source = "gps";
    }
  }
  if (info.site_source != "gps")
    s.warnings.push_back("no GPS fix: sun positions use the rig's fallback site (" +
                         std::to_string(info.site.lat_deg) + ", " +
                         std::to_string(info.site.lon_deg) + ")");
  if (!s.stopped) info.capture_complete = true;
  writer->UpdateInfo(info);
  CountLeft(PlannedGroups(dev.plan, dev.camera.get()), writer->frames(), !s.stopped, &summary);
  return summary;
}

}  // namespace rouen
