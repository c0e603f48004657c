// What a session holds and what its solve still lacks (`rouen status`): per slot and bracket
// the frames there are (exposures, LDR or HDR, ND filter, intrinsics and pose, times), then
// every problem that would stop `rouen solve`, each with what adds the missing piece. Reads
// session.json, the journal, the model and (when asked) the frame files' bytes for their
// sha256; never decodes a frame's pixels.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/session.h"
#include "core/time.h"

namespace rouen {

// One bracket (journal group "slot<k>/<target>/view<v>") as it is in the journal.
struct BracketStatus {
  std::string group;
  Target target = Target::kArchitecture;
  int frames = 0;
  int hdr_frames = 0;  // the others are LDR (8-bit digital numbers)
  // Exposure times in seconds, of the LDR frames when there are some (of HDR frames they are
  // provenance only), and how many distinct effective exposures (seconds x gain x ND
  // transmission) the LDR frames give: two or more recover a response curve.
  double min_exposure_s = 0, max_exposure_s = 0;
  int ldr_exposures = 0;
  double min_nd_density = 0, max_nd_density = 0;  // optical density of the ND filter in front
  int with_intrinsics = 0, with_pose = 0;
  UtcTime first_utc, last_utc;
};

struct SlotStatus {
  int slot = 0;
  // The slot's time as the solve takes it: the median time of its sky (and aureole) frames
  // (utc_from_sky), else of all its frames; unset for a slot without frames.
  std::optional<UtcTime> utc;
  bool utc_from_sky = false;
  std::vector<BracketStatus> brackets;  // by group name
};

enum class StatusProblemKind {
  kJournal,            // a journal line that does not parse, a duplicate id, a path outside
  kMissingFile,        // a journalled frame file is not there
  kChecksum,           // a frame file's sha256 is not the journalled one
  kFrameValue,         // exposure, ND density or gain out of range (CheckSessionFrames)
  kFrameImage,         // a frame's image unreadable, or not the size its intrinsics give
  kNoFrames,           // an empty journal
  kMixedBracket,       // LDR and HDR frames in one bracket
  kNoModel,            // session.json names no building model
  kModel,              // the model file is missing, outside the folder or malformed
  kSite,               // the site (GPS fixes' mean, or session.json's) is out of range
  kSlotLacksBracket,   // a slot without a sun, sky or landscape bracket
  kNoGeometry,         // a bracket's frames without intrinsics or pose
  kNoResponse,         // LDR brackets, but none of the building or landscape in 2+ exposures
  kCaptureUnfinished,  // the last capture run stopped before the end of its plan
  kJournalNote,        // a last journal line cut short by a crash (ignored, as the solve does)
  kSolveConfig,        // session.json's extra.solve_config, which the solve starts from
  kSkyMask,            // a sky mask file (extra.sky_masks) missing, outside or not the sky's size
  kNight,              // a slot whose time has the sun below the horizon at the site
};
// "journal", "missing_file", "checksum", ..., as the JSON report names the kinds.
const char* StatusProblemName(StatusProblemKind kind);

struct StatusProblem {
  StatusProblemKind kind = StatusProblemKind::kJournal;
  bool blocking = true;  // `rouen solve` stops on it
  std::string what;      // names the file and line, frame, bracket or slot
  std::string fix;       // the command or edit that adds what is missing
};

struct SessionStatus {
  std::filesystem::path dir;
  SessionInfo info;
  int frames = 0;                       // journal lines that parsed
  std::vector<SlotStatus> slots;        // 0 .. the last slot in the journal
  std::vector<StatusProblem> problems;  // blocking first, in the order found
  bool contents_verified = false;       // every present frame file's sha256 was compared
  // session.json's extra.capture_complete (SessionInfo::capture_complete); none for sessions
  // that do not record it (imports, captures before it was recorded).
  std::optional<bool> capture_complete;
  bool Solvable() const;  // no blocking problem
};

struct StatusOptions {
  bool verify_contents = true;  // compare every frame file's sha256 with the journal's
};

// The session in `dir` and what its solve lacks. Throws rouen::Error naming the folder or
// session.json only when `dir` is not a session (no such folder, no or a malformed
// session.json, no readable journal); every other problem is in the report.
SessionStatus ReadSessionStatus(const std::filesystem::path& dir,
                                const StatusOptions& options = {});

// The report as JSON: the same content `rouen status` prints.
nlohmann::json StatusToJson(const SessionStatus& status);

}  // namespace rouen
