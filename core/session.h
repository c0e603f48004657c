// The session folder (DESIGN.md): session.json + append-only frames.jsonl + frames/.
// A frame is written under a temporary name, fsynced, renamed and only then journalled.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/solar.h"
#include "core/time.h"

namespace rouen {

enum class Target { kSun, kAureole, kSky, kLandscape, kArchitecture, kCalibration };
const char* TargetName(Target t);
Target ParseTarget(const std::string& s);  // throws rouen::Error

// A bracket's name, "slot<k>/<target>/view<v>" (e.g. "slot2/architecture/view1"): the one
// printer and parser of the key frames, merged images and scene views are filed under.
struct BracketKey {
  int slot = 0;
  Target target = Target::kArchitecture;
  int view = 0;
};
std::string BracketName(int slot, Target target, int view);
inline std::string BracketName(const BracketKey& k) {
  return BracketName(k.slot, k.target, k.view);
}
// Throws rouen::Error saying what is wrong with `name`.
BracketKey ParseBracketName(const std::string& name);

struct GpsFix {
  UtcTime utc;
  double lat_deg = 0, lon_deg = 0, height_m = 0;
  int mode = 0;  // 0 none, 2 = 2D, 3 = 3D
  int satellites = 0;
  double hdop = 99;
  // The laptop's clock when the fix was read from the receiver (real drivers set it):
  // utc - received_utc estimates the laptop clock's offset from GPS time (to within the
  // receiver's reporting lag, typically < 0.5 s).
  std::optional<UtcTime> received_utc;
  bool valid() const { return mode >= 2; }
};

// The highest time-of-day slot index a session holds (slots are 0..kMaxSlot).
constexpr int kMaxSlot = 1000;

struct FrameRecord {
  int64_t id = 0;
  std::string device;
  Target target = Target::kArchitecture;
  std::string group;  // bracket this frame belongs to, e.g. "slot2/architecture/view1"
  int slot = 0;       // index of the time-of-day slot in the capture plan
  UtcTime utc;
  bool hdr = false;       // true: linear radiance EXR; false: 8-bit LDR digital numbers
  double exposure_s = 0;  // LDR only
  double gain = 1;        // linear gain (ISO / base ISO)
  double aperture_f = 0;  // 0 = unknown / fixed
  double nd_density = 0;  // optical density of the ND filter in front (0 = none)
  std::optional<GpsFix> gps;
  double sun_azimuth_deg = 0, sun_elevation_deg = 0;  // at `utc` for the session site
  std::optional<Intrinsics> intrinsics;
  std::optional<Pose> pose;
  std::string file;  // relative to the session folder
  std::string sha256;
};

// An ND filter's optical density per channel (session.json extra.nd_filters.NAME: a density,
// [r, g, b] densities, or the record `rouen calib nd` writes, which holds "density_rgb" and is
// kept whole).
struct NdFilter {
  std::array<double, 3> density_rgb = {0, 0, 0};
  nlohmann::json record;  // the calibration record it came from; null for plain densities
};

// Where a sky bracket's sky pixels come from (extra.sky_masks.KEY: "auto" or a mask image
// relative to the session folder, nonzero = sky).
struct SkyMaskSpec {
  bool automatic = false;  // segment the sky (solve/sky_segment)
  std::string file;        // when not automatic
};

struct SessionInfo {
  int format_version = 1;
  Site site;
  std::string site_source = "rig";  // "gps" or "rig" (fallback, stated)
  std::string rig;                  // rig file name
  std::string created_utc;
  double clock_offset_s = 0;  // GPS time minus laptop clock, applied to frame times
  std::string model;          // optional relative path to the building model (OBJ)
  // Optional relative path to the surroundings (OBJ): coarse geometry around the building (a
  // city model's or OpenStreetMap's footprints and heights), solved with it but not scored.
  std::string surroundings;
  // The surroundings' blocks that are trees (`rouen import --trees`, core/trees.h): a tree no
  // photo saw takes the albedo of the trees they saw (AlbedoOptions::block_kind).
  std::vector<std::string> trees;
  std::string notes;
  // The typed tables of session.json's "extra" (one parser and one printer: from_json and
  // to_json below), with their keys:
  std::map<std::string, NdFilter> nd_filters;  // filter name -> densities ("sun" for a rig's)
  // "<device>/<target>", "<device>" or "*" -> the lens's vignetting (calib/vignetting.h)
  std::map<std::string, VignettingModel> vignetting;
  std::map<std::string, SkyMaskSpec> sky_masks;  // bracket name or "*" -> its sky pixels
  std::optional<int> heldout_slot;               // the rig's held-out time of day
  std::optional<bool> capture_complete;  // false while a capture runs; true once it finished
  // Options `rouen solve` starts from for this session, keyed as `rouen solve --print-config`
  // shows them (an object; checked by the pipeline, pipeline/solve_config.h).
  nlohmann::json solve_config = nlohmann::json::object();
  nlohmann::json extra = nlohmann::json::object();  // every other key (the plan, import, ...)

  // The filter of a frame with optical density `frame_density`: the one whose mean density is
  // within 0.05 of it (the closest), else none.
  const NdFilter* FindNdFilter(double frame_density) const;
  // Per-channel transmission of a frame with optical density `frame_density`: its filter's
  // (FindNdFilter), else 10^-frame_density in every channel; 1 without a filter.
  std::array<double, 3> NdTransmissionRgb(double frame_density) const;
  // The vignetting of a frame's device and target ("<device>/<target>", then "<device>", "*").
  const VignettingModel* FindVignetting(const std::string& device, Target target) const;
  // The sky mask of a bracket (its name, then "*").
  const SkyMaskSpec* FindSkyMask(const std::string& bracket) const;
};

void to_json(nlohmann::json& j, const FrameRecord& f);
// Throws rouen::Error naming the missing or mistyped key.
void from_json(const nlohmann::json& j, FrameRecord& f);
void to_json(nlohmann::json& j, const SessionInfo& s);
void from_json(const nlohmann::json& j, SessionInfo& s);

// The non-blank lines of a journal's text: the number of each (from 1), its text without
// '\n', and whether a newline ended it (a crash can cut the last line short).
struct JournalLine {
  int number = 0;
  std::string_view text;
  bool terminated = true;
};
std::vector<JournalLine> SplitJournal(std::string_view text);

// One line of frames.jsonl (without its newline) as a record; throws rouen::Error saying what
// is wrong (the caller adds file and line).
FrameRecord ParseJournalLine(std::string_view line);
// The text of a session.json; throws rouen::Error naming `name` (the file) and the problem.
SessionInfo ParseSessionInfo(std::string_view text, const std::string& name);

// Reads a session. Validates session.json, every journal line (JSON, keys, relative paths
// that stay inside the folder, files that exist). A last line cut short by a crash is
// ignored (reported in `warnings`); any other malformed line is an error naming the line.
class Session {
 public:
  static Session Load(const std::filesystem::path& dir);

  const std::filesystem::path& dir() const { return dir_; }
  const SessionInfo& info() const { return info_; }
  const std::vector<FrameRecord>& frames() const { return frames_; }
  const std::vector<std::string>& warnings() const { return warnings_; }
  std::filesystem::path PathOf(const FrameRecord& f) const;  // checked to stay inside
  // Reads a frame's pixels after checking the file's sha256 against the journal; a mismatch
  // is a rouen::Error naming the file, the frame and its bracket.
  Image LoadFrame(const FrameRecord& f) const;

 private:
  std::filesystem::path dir_;
  SessionInfo info_;
  std::vector<FrameRecord> frames_;
  std::vector<std::string> warnings_;
};

// True while some process holds `dir`'s writer lock (a writer that crashed holds none).
bool SessionInUse(const std::filesystem::path& dir);

// How a SessionWriter stores frames.
struct SessionWriterOptions {
  // zlib level of the 8-bit PNG frames: 1 (fastest) .. 9 (smallest); 0 keeps the PNG
  // writer's default (6). The pixels are the same at every level. A noisy 512x256 frame
  // encodes about 5x faster at 1 than at 6, for a file about 7% larger.
  int png_compression = 1;
  void Validate() const;  // throws rouen::Error naming the bad option
};

// Appends frames to a session folder. Create() makes a new folder (refusing a non-empty
// one); Resume() reopens an existing one and continues its ids. One writer per session: the
// writer holds an advisory lock (flock on <dir>/session.lock) from Create/Resume until it is
// closed or destroyed; a second writer, in this process or another, gets a rouen::Error
// naming the folder and the holder's pid.
class SessionWriter {
 public:
  static SessionWriter Create(const std::filesystem::path& dir, const SessionInfo& info,
                              const SessionWriterOptions& options = {});
  static SessionWriter Resume(const std::filesystem::path& dir,
                              const SessionWriterOptions& options = {});
  ~SessionWriter();
  SessionWriter(SessionWriter&&) noexcept;
  SessionWriter& operator=(SessionWriter&&) noexcept;

  const std::filesystem::path& dir() const { return dir_; }
  const std::vector<FrameRecord>& frames() const { return frames_; }
  // Writes the pixels (LDR -> 8-bit PNG, HDR -> half EXR) durably, then journals `meta`
  // with id, file and sha256 filled in. Returns the journalled record. On any failure (a full
  // disk, say) nothing of the frame stays: the journal and folder end at the previous frame.
  FrameRecord Append(FrameRecord meta, const Image& pixels);
  // Rewrites session.json atomically (e.g. after the GPS fix arrived).
  void UpdateInfo(const SessionInfo& info);
  const SessionInfo& info() const { return info_; }
  // Releases the journal and the session lock (the destructor does too).
  void Close();

 private:
  SessionWriter() = default;
  std::filesystem::path dir_;
  SessionWriterOptions options_;
  SessionInfo info_;
  std::vector<FrameRecord> frames_;
  int journal_fd_ = -1;
  int lock_fd_ = -1;
  int64_t next_id_ = 1;
};

}  // namespace rouen
