#include "pipeline/status.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string_view>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/mesh.h"
#include "pipeline/capture_session.h"
#include "pipeline/session_solve.h"
#include "pipeline/solve_config.h"

namespace rouen {
namespace fs = std::filesystem;
namespace {

double EffectiveExposure(const FrameRecord& f) {
  return f.exposure_s * f.gain * std::pow(10.0, -f.nd_density);
}

// "<dir>/frames.jsonl: frame <id> (<file>, bracket <group>)", as the solve names a frame.
std::string FrameWhere(const fs::path& dir, const FrameRecord& f) {
  return (dir / "frames.jsonl").string() + ": frame " + std::to_string(f.id) + " (" + f.file +
         ", bracket " + f.group + ")";
}

// The commands that add what is missing, worded for how the session was made: `rouen capture`
// records its plan in session.json, `rouen import` its list.
class Fixes {
 public:
  Fixes(const fs::path& dir, const SessionInfo& info)
      : dir_(dir.string()),
        captured_(info.extra.contains("plan")),
        rig_(info.rig.empty() ? "the rig file it was captured with"
                              : "the rig file it was captured with, " + info.rig) {}

  // `rouen capture ... --resume`, with `extra` options.
  std::string Capture(const std::string& extra = "") const {
    return "rouen capture --rig RIG --out " + dir_ + " --resume" + extra + " (RIG: " + rig_ + ")";
  }
  std::string SlotBracket(const char* target) const {
    const std::string t = target;
    if (captured_)
      return Capture(" --target " + t) +
             " (a simulated or replay rig captures the brackets a slot lacks; a field rig "
             "continues only the session's last slot, --new-slot adds another)";
    return "import the slot's " + t + " photos with the others: rouen import --photos DIR --list " +
           "LIST with 'target=" + t + "' on their lines (import builds the whole session)";
  }
  std::string Model() const {
    return "import the photos again with rouen import ... --model BUILDING.obj (a Wavefront OBJ, "
           "its groups the blocks), or put the model in the session folder and name it in " +
           dir_ + "/session.json: \"model\": \"model.obj\"";
  }
  std::string Geometry() const {
    return "rouen calib intrinsics (the lens), rouen calib pose (each view), then import the "
           "photos again with rouen import --cameras CAMERAS.json naming those files";
  }
  std::string Response() const {
    return captured_ ? "capture bracketed views of the building or landscape: " +
                           Capture(" --target architecture")
                     : "add a bracket of the building or landscape in two or more exposures: "
                       "rouen import --list LIST with 'image seconds group=NAME' lines of "
                       "different seconds";
  }
  std::string Restore() const {
    return "restore the frame files from a copy of the session (rouen writes a frame once and "
           "never changes it); else remove the bracket's lines from frames.jsonl and capture "
           "or import it again";
  }
  std::string FrameValue() const {
    return captured_ ? "correct the frame's line in " + dir_ + "/frames.jsonl"
                     : "correct the exposure list and import again (rouen import --list LIST), or "
                       "the frame's line in " +
                           dir_ + "/frames.jsonl";
  }
  std::string Journal() const {
    return "repair or remove the line in " + dir_ +
           "/frames.jsonl (every other line is kept as it is)";
  }
  std::string Site() const {
    return "correct \"site\" in " + dir_ + "/session.json (or the GPS fixes in frames.jsonl)";
  }
  std::string Night() const {
    return captured_ ? "capture the slot again in daylight (rouen plan lists the day's times)"
                     : "import again with the camera clock's offset (rouen import --timezone "
                       "+HH:MM, or --time), or correct the site";
  }
  std::string Frames() const {
    return captured_ ? Capture() : "rouen capture --rig RIG --out DIR, or rouen import";
  }
  std::string Mixed() const {
    return "give the LDR and the HDR frames different groups (rouen import --list LIST "
           "'group=NAME')";
  }

 private:
  std::string dir_;
  bool captured_;
  std::string rig_;
};

void Add(SessionStatus* s, StatusProblemKind kind, bool blocking, const std::string& what,
         const std::string& fix) {
  s->problems.push_back({kind, blocking, what, fix});
}

// The journal read line by line as Session::Load reads it, every problem noted instead of the
// first thrown.
std::vector<FrameRecord> ReadJournal(const fs::path& dir, const Fixes& fixes, bool verify,
                                     SessionStatus* s) {
  std::vector<FrameRecord> frames;
  const fs::path journal = dir / "frames.jsonl";
  std::error_code ec;
  if (!fs::is_regular_file(journal, ec)) {
    Add(s, StatusProblemKind::kJournal, true, journal.string() + ": missing", fixes.Frames());
    return frames;
  }
  const std::string text = ReadFileToString(journal);
  std::set<int64_t> ids;
  for (const auto& [number, line, terminated] : SplitJournal(text)) {
    const std::string where = journal.string() + ":" + std::to_string(number);
    FrameRecord f;
    try {
      f = ParseJournalLine(line);
    } catch (const Error& e) {
      if (!terminated) {
        Add(s, StatusProblemKind::kJournalNote, false,
            where + ": a last line cut short (" + e.what() + "); the solve ignores it",
            "nothing to do; rouen capture --resume removes it");
        continue;
      }
      Add(s, StatusProblemKind::kJournal, true, where + ": " + e.what(), fixes.Journal());
      continue;
    }
    fs::path path;
    try {
      path = ResolveInside(dir, f.file);
    } catch (const Error& e) {
      Add(s, StatusProblemKind::kJournal, true, where + ": file: " + e.what(), fixes.Journal());
      continue;
    }
    if (!ids.insert(f.id).second) {
      Add(s, StatusProblemKind::kJournal, true,
          where + ": duplicate frame id " + std::to_string(f.id), fixes.Journal());
      continue;
    }
    if (!fs::is_regular_file(path, ec)) {
      Add(s, StatusProblemKind::kMissingFile, true,
          FrameWhere(dir, f) + ": the file " + path.string() + " is missing", fixes.Restore());
    } else if (verify) {
      const std::string actual = Sha256File(path);
      if (actual != f.sha256) {
        Add(s, StatusProblemKind::kChecksum, true,
            FrameWhere(dir, f) + ": sha256 " + actual + ", journalled " + f.sha256 +
                " (the file was changed or damaged after capture)",
            fixes.Restore());
      } else {
        // The image as the solve reads it: its header, and the size its intrinsics give.
        try {
          const ImageSize size = ReadImageSize(path.string());
          if (f.intrinsics &&
              (size.width != f.intrinsics->width || size.height != f.intrinsics->height))
            Add(s, StatusProblemKind::kFrameImage, true,
                FrameWhere(dir, f) + ": the image is " + std::to_string(size.width) + "x" +
                    std::to_string(size.height) + " but its intrinsics are " +
                    std::to_string(f.intrinsics->width) + "x" +
                    std::to_string(f.intrinsics->height),
                fixes.Geometry());
        } catch (const Error& e) {
          Add(s, StatusProblemKind::kFrameImage, true, FrameWhere(dir, f) + ": " + e.what(),
              fixes.Restore());
        }
      }
    }
    const std::string value = FrameValuesProblem(f);
    if (!value.empty())
      Add(s, StatusProblemKind::kFrameValue, true, FrameWhere(dir, f) + ": " + value,
          fixes.FrameValue());
    frames.push_back(std::move(f));
  }
  return frames;
}

BracketStatus Describe(const std::string& group, const std::vector<const FrameRecord*>& frames) {
  BracketStatus b;
  b.group = group;
  b.target = frames.front()->target;
  b.frames = static_cast<int>(frames.size());
  std::set<double> effective;
  for (const FrameRecord* f : frames) {
    const bool first = f == frames.front();
    if (f->hdr) ++b.hdr_frames;
    if (f->intrinsics) ++b.with_intrinsics;
    if (f->pose) ++b.with_pose;
    if (first || f->nd_density < b.min_nd_density) b.min_nd_density = f->nd_density;
    if (first || f->nd_density > b.max_nd_density) b.max_nd_density = f->nd_density;
    if (first || f->utc < b.first_utc) b.first_utc = f->utc;
    if (first || b.last_utc < f->utc) b.last_utc = f->utc;
  }
  const bool any_ldr = b.hdr_frames < b.frames;
  bool first_exposure = true;
  for (const FrameRecord* f : frames) {
    if (any_ldr && f->hdr) continue;
    if (first_exposure || f->exposure_s < b.min_exposure_s) b.min_exposure_s = f->exposure_s;
    if (first_exposure || f->exposure_s > b.max_exposure_s) b.max_exposure_s = f->exposure_s;
    first_exposure = false;
    if (!f->hdr) effective.insert(EffectiveExposure(*f));
  }
  b.ldr_exposures = static_cast<int>(effective.size());
  return b;
}

}  // namespace

const char* StatusProblemName(StatusProblemKind kind) {
  switch (kind) {
    case StatusProblemKind::kJournal:
      return "journal";
    case StatusProblemKind::kMissingFile:
      return "missing_file";
    case StatusProblemKind::kChecksum:
      return "checksum";
    case StatusProblemKind::kFrameValue:
      return "frame_value";
    case StatusProblemKind::kFrameImage:
      return "frame_image";
    case StatusProblemKind::kSolveConfig:
      return "solve_config";
    case StatusProblemKind::kSkyMask:
      return "sky_mask";
    case StatusProblemKind::kNoFrames:
      return "no_frames";
    case StatusProblemKind::kMixedBracket:
      return "mixed_bracket";
    case StatusProblemKind::kNoModel:
      return "no_model";
    case StatusProblemKind::kModel:
      return "model";
    case StatusProblemKind::kSite:
      return "site";
    case StatusProblemKind::kSlotLacksBracket:
      return "slot_lacks_bracket";
    case StatusProblemKind::kNoGeometry:
      return "no_geometry";
    case StatusProblemKind::kNoResponse:
      return "no_response";
    case StatusProblemKind::kCaptureUnfinished:
      return "capture_unfinished";
    case StatusProblemKind::kJournalNote:
      return "journal_note";
    case StatusProblemKind::kNight:
      return "night";
  }
  return "?";
}

bool SessionStatus::Solvable() const {
  return std::none_of(problems.begin(), problems.end(),
                      [](const StatusProblem& p) { return p.blocking; });
}

SessionStatus ReadSessionStatus(const fs::path& dir, const StatusOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(dir.string() + ": not a session folder (no such directory)");
  SessionStatus s;
  s.dir = dir;
  const fs::path info_path = dir / "session.json";
  s.info = ParseSessionInfo(ReadFileToString(info_path), info_path.string());
  const Fixes fixes(dir, s.info);
  s.capture_complete = s.info.capture_complete;

  const std::vector<FrameRecord> frames = ReadJournal(dir, fixes, options.verify_contents, &s);
  s.frames = static_cast<int>(frames.size());
  s.contents_verified = options.verify_contents;

  // What each slot holds, bracket by bracket.
  std::map<std::string, std::vector<const FrameRecord*>> groups, merged;
  int nslots = 0;
  for (const FrameRecord& f : frames) {
    groups[f.group].push_back(&f);
    merged[MergedBracketName(f)].push_back(&f);
    nslots = std::max(nslots, f.slot + 1);
  }
  s.slots.resize(nslots);
  for (int k = 0; k < nslots; ++k) s.slots[k].slot = k;
  for (const auto& [name, fr] : groups)
    s.slots[fr.front()->slot].brackets.push_back(Describe(name, fr));
  std::vector<bool> from_sky;
  const std::vector<std::optional<UtcTime>> times = SlotTimes(frames, &from_sky);
  for (SlotStatus& slot : s.slots) {
    slot.utc = times[slot.slot];
    slot.utc_from_sky = from_sky[slot.slot];
  }

  if (frames.empty() && std::none_of(s.problems.begin(), s.problems.end(), [](const auto& p) {
        return p.kind == StatusProblemKind::kJournal;
      }))
    Add(&s, StatusProblemKind::kNoFrames, true, (dir / "frames.jsonl").string() + ": no frames",
        fixes.Frames());

  // The brackets as the solve merges them: all LDR or all HDR, and the first frame's camera
  // (intrinsics and pose) is the merged image's.
  bool any_ldr = false, response_bracket = false;
  for (const auto& [name, fr] : merged) {
    const bool hdr = fr.front()->hdr;
    any_ldr = any_ldr || !hdr;
    for (const FrameRecord* f : fr) {
      if (f->hdr == hdr) continue;
      Add(&s, StatusProblemKind::kMixedBracket, true,
          dir.string() + ": bracket " + name + " mixes LDR and HDR frames (frames " +
              std::to_string(fr.front()->id) + " and " + std::to_string(f->id) + ")",
          fixes.Mixed());
      break;
    }
    int without = 0;
    for (const FrameRecord* f : fr) without += !f->intrinsics || !f->pose;
    const FrameRecord& first = *fr.front();
    if (!first.intrinsics || !first.pose) {
      Add(&s, StatusProblemKind::kNoGeometry, true,
          dir.string() + ": bracket " + name + ": " + std::to_string(without) + " of " +
              std::to_string(fr.size()) + " frames have no " +
              (!first.intrinsics && !first.pose ? "intrinsics or pose"
               : !first.intrinsics              ? "intrinsics"
                                                : "pose") +
              " (the first, frame " + std::to_string(first.id) + ", gives the bracket's camera)",
          fixes.Geometry());
    }
    if (!hdr && (first.target == Target::kArchitecture || first.target == Target::kLandscape)) {
      std::set<double> exposures;
      for (const FrameRecord* f : fr) exposures.insert(EffectiveExposure(*f));
      response_bracket = response_bracket || exposures.size() >= 2;
    }
  }
  // §2 (Debevec-Malik): the response curve needs a bracket of two or more exposures.
  if (any_ldr && !response_bracket)
    Add(&s, StatusProblemKind::kNoResponse, true,
        dir.string() +
            ": no LDR bracket of the building or landscape with two or more exposures to "
            "recover the response curve from (and not every frame is HDR)",
        fixes.Response());

  // §3: every slot needs its sun (§3.1), sky (§3.2) and landscape (§3.3) brackets.
  for (const SlotStatus& slot : s.slots) {
    const std::string prefix = "slot" + std::to_string(slot.slot) + "/";
    std::vector<const char*> lacks;
    const bool has_sky = merged.count(prefix + "sky/view0") > 0;
    // An HDR sky or landscape photo of the slot may hold the whole sun disc; an LDR one cannot.
    bool hdr_panorama = false;
    for (const auto& [name, fr] : merged) {
      const bool panorama =
          name.rfind(prefix + "sky/", 0) == 0 || name.rfind(prefix + "landscape/", 0) == 0;
      hdr_panorama = hdr_panorama || (panorama && fr.front()->hdr);
    }
    if (!merged.count(prefix + "sun/view0")) {
      // §3.1 from an HDR sky or landscape photo instead, if its disc is not clipped.
      if (has_sky && hdr_panorama)
        Add(&s, StatusProblemKind::kSlotLacksBracket, false,
            dir.string() + ": slot " + std::to_string(slot.slot) + " has no sun bracket (" +
                prefix + "sun/view0): the solve measures the sun in its sky or landscape " +
                "photos, which needs an HDR disc that is not clipped",
            fixes.SlotBracket("sun"));
      else
        lacks.push_back("sun");
    }
    if (!has_sky) lacks.push_back("sky");
    if (!merged.count(prefix + "landscape/view0")) lacks.push_back("landscape");
    for (const char* t : lacks)
      Add(&s, StatusProblemKind::kSlotLacksBracket, true,
          dir.string() + ": slot " + std::to_string(slot.slot) + " lacks a " + t + " bracket (" +
              prefix + t + "/view0)",
          fixes.SlotBracket(t));
  }

  // The building model and the site, read as the solve reads them.
  if (s.info.model.empty()) {
    Add(&s, StatusProblemKind::kNoModel, true,
        info_path.string() + ": no building model (\"model\") given", fixes.Model());
  } else {
    try {
      ReadSessionModel(dir, s.info);
    } catch (const Error& e) {
      Add(&s, StatusProblemKind::kModel, true, e.what(),
          "fix or replace the model (a Wavefront OBJ with faces, inside the session folder)");
    }
  }
  try {
    const Site site = SessionSite(dir, s.info, frames);
    for (const SlotStatus& slot : s.slots) {
      if (!slot.utc) continue;
      const std::string night = NightSlotProblem(slot.slot, *slot.utc, site);
      if (!night.empty())
        Add(&s, StatusProblemKind::kNight, true, dir.string() + ": " + night, fixes.Night());
    }
  } catch (const Error& e) {
    Add(&s, StatusProblemKind::kSite, true, e.what(), fixes.Site());
  }
  // The options the solve starts from, read as it reads them.
  try {
    SessionSolveConfig(s.info, info_path.string(), false);
  } catch (const Error& e) {
    Add(&s, StatusProblemKind::kSolveConfig, true, e.what(),
        "correct or remove extra.solve_config in " + info_path.string() +
            " (rouen solve --print-config shows every key and its range)");
  }
  // Each sky photo's mask file, read as the solve reads it (at the bracket's size).
  for (const auto& [name, fr] : merged) {
    const FrameRecord& first = *fr.front();
    if (first.target != Target::kSky || !first.intrinsics) continue;
    const SkyMaskSpec* spec = s.info.FindSkyMask(name);
    if (!spec || spec->automatic) continue;
    try {
      ReadMask(ResolveInside(dir, spec->file).string(), first.intrinsics->width,
               first.intrinsics->height, "the merged " + name);
    } catch (const Error& e) {
      Add(&s, StatusProblemKind::kSkyMask, true,
          info_path.string() + ": extra.sky_masks: " + e.what(),
          "give a mask image inside the session folder, the sky photo's size (rouen import "
          "--sky-mask FILE), or \"auto\"");
    }
  }

  // What the reading above could miss, Session::Load (which the solve starts with) finds.
  if (s.Solvable()) {
    try {
      Session::Load(dir);
    } catch (const Error& e) {
      Add(&s, StatusProblemKind::kJournal, true, e.what(), fixes.Journal());
    }
  }

  if (s.capture_complete == false)
    Add(&s, StatusProblemKind::kCaptureUnfinished, false,
        dir.string() + ": the last capture stopped before the end of its plan", fixes.Capture());
  std::stable_partition(s.problems.begin(), s.problems.end(),
                        [](const StatusProblem& p) { return p.blocking; });
  return s;
}

nlohmann::json StatusToJson(const SessionStatus& s) {
  using nlohmann::json;
  json j;
  j["session"] = s.dir.string();
  j["solvable"] = s.Solvable();
  j["frames"] = s.frames;
  j["contents_verified"] = s.contents_verified;
  j["rig"] = s.info.rig;
  j["model"] = s.info.model;
  j["surroundings"] = s.info.surroundings;
  j["site"] = {{"lat_deg", s.info.site.lat_deg},
               {"lon_deg", s.info.site.lon_deg},
               {"height_m", s.info.site.height_m},
               {"source", s.info.site_source}};
  j["capture_complete"] = s.capture_complete ? json(*s.capture_complete) : json(nullptr);
  j["slots"] = json::array();
  for (const SlotStatus& slot : s.slots) {
    json js;
    js["slot"] = slot.slot;
    js["utc"] = slot.utc ? json(slot.utc->Iso8601(3)) : json(nullptr);
    js["utc_from_sky"] = slot.utc_from_sky;
    js["brackets"] = json::array();
    for (const BracketStatus& b : slot.brackets)
      js["brackets"].push_back({{"group", b.group},
                                {"target", TargetName(b.target)},
                                {"frames", b.frames},
                                {"ldr_frames", b.frames - b.hdr_frames},
                                {"hdr_frames", b.hdr_frames},
                                {"exposure_s", {b.min_exposure_s, b.max_exposure_s}},
                                {"ldr_exposures", b.ldr_exposures},
                                {"nd_density", {b.min_nd_density, b.max_nd_density}},
                                {"with_intrinsics", b.with_intrinsics},
                                {"with_pose", b.with_pose},
                                {"utc", {b.first_utc.Iso8601(3), b.last_utc.Iso8601(3)}}});
    j["slots"].push_back(std::move(js));
  }
  j["problems"] = json::array();
  for (const StatusProblem& p : s.problems)
    j["problems"].push_back({{"kind", StatusProblemName(p.kind)},
                             {"blocking", p.blocking},
                             {"what", p.what},
                             {"fix", p.fix}});
  return j;
}

}  // namespace rouen
