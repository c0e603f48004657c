// Offline processing of a session: calibrate (response curve, HDR radiance per bracket),
// then solve (sun, sky, environment per slot; irradiance; pseudo-albedos). Each stage writes
// its files into the work folder so it can be inspected or rerun alone.
#pragma once

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "calib/response.h"
#include "core/cancel.h"
#include "core/mesh.h"
#include "core/session.h"
#include "pipeline/solve_config.h"
#include "solve/albedo.h"
#include "solve/env_stereo.h"
#include "solve/environment.h"
#include "solve/grid.h"
#include "solve/irradiance.h"
#include "solve/raycast.h"
#include "solve/sky_fit.h"
#include "solve/sky_segment.h"
#include "solve/sun.h"

namespace rouen {

// One step of a solve's progress, for a progress bar or a log (SolveController's stages): the
// stage, its number (1-based) of how many, how far through it (0 as it starts, 1 when done), a
// line a person reads, and when the stage is done its figures (its "seconds", the counts it made).
struct SolveEvent {
  std::string stage;
  int index = 0, count = 0;
  double fraction = 0;
  std::string message;
  std::vector<std::pair<std::string, double>> figures;
};

struct PipelineOptions {
  std::filesystem::path work_dir;         // calib/ is written here
  std::vector<int> exclude_albedo_slots;  // held-out slots: their architecture photos unused
  // Every choice of the calibration and the solve (recorded in the scene).
  SolveConfig config = DefaultSolveConfig(false);
  // A response curve known from an earlier calibration: used instead of recovering one.
  std::optional<ResponseCurve> response;
  std::function<void(const std::string&)> log;      // what each stage found, as lines
  std::function<void(const SolveEvent&)> progress;  // each stage's start, progress and end
  // Polled between stages and inside the long ones (not owned; null: the solve runs to its
  // end); a requested cancellation stops the work with Cancelled.
  const Cancellation* cancel = nullptr;
};

// The bracket a frame is merged into: its own, except that a slot's aureole frames join its
// sky view 0 (the sky camera's view; CalibrateSession merges them together).
std::string MergedBracketName(const FrameRecord& f);

// One bracket merged to radiance.
struct HdrGroup {
  std::string name;
  int slot = 0;
  Target target = Target::kArchitecture;
  Image radiance;              // kRadiance
  std::vector<uint8_t> valid;  // 1 where some frame was well exposed
  Intrinsics intrinsics;
  Pose pose;
  UtcTime utc;  // median frame time
  double nd_density = 0;
};

// How long one stage of a solve took (rouen solve prints them; scene.json keeps them).
struct StageTime {
  std::string stage;
  double seconds = 0;
};

struct CalibResult {
  std::vector<StageTime> stages;
  ResponseCurve response;
  ResponseSummary response_summary;
  std::map<std::string, HdrGroup> groups;
};

// Response curve from the session's LDR brackets, then every bracket merged to radiance
// (sky and aureole brackets of a slot merge together). Writes calib/response.json,
// calib/hdr/<group>.exr (RGB radiance), <group>.valid.png (nonzero where some frame was well
// exposed) and, last,
// calib/manifest.json with the hash of its inputs (the session's files, the response options):
// when the manifest in the work folder has the same hash, the calibration is read back
// instead of made again. First checks every frame record (CheckSessionFrames); a frame whose
// image is not the size of its intrinsics is an error naming it.
CalibResult CalibrateSession(const Session& session, const PipelineOptions& options);

// One bracket of the session (e.g. "slot2/architecture/view0") merged to radiance as
// CalibrateSession merges it: LDR frames through `response`, HDR frames averaged, with the
// merge options of `config` (a scene's: those its solve used). Throws rouen::Error naming the
// session and the bracket when there is no such bracket.
HdrGroup MergeSessionBracket(const Session& session, const std::string& name,
                             const ResponseCurve& response, const SolveConfig& config);

// Checks the journal's values the pipeline computes with: the exposure of LDR frames and the
// ND density (core/limits.h), the gain. Throws rouen::Error naming frames.jsonl, the frame's
// id, file and bracket.
void CheckSessionFrames(const Session& session);
// What CheckSessionFrames finds wrong with one frame's values ("" when nothing).
std::string FrameValuesProblem(const FrameRecord& f);

// The session's building model (session.json "model", inside the session folder) with its
// surroundings appended ("surroundings", when given; their block names in `surroundings`,
// which may be null). Throws rouen::Error naming session.json when there is no model, or the
// file that is malformed, has no faces, or shares a block name with the other.
Mesh ReadSessionModel(const Session& session, std::vector<std::string>* surroundings = nullptr);
// The same for a session folder `dir` whose session.json is `info`.
Mesh ReadSessionModel(const std::filesystem::path& dir, const SessionInfo& info,
                      std::vector<std::string>* surroundings = nullptr);

struct SlotSolve {
  int slot = 0;
  UtcTime utc;
  SunPosition sun;  // from GPS site + UTC (ERFA)
  SunMeasurement sun_measured;
  SkyFitSummary sky_summary;
  Lighting lighting;
};

struct SolveResult {
  std::vector<StageTime> stages;
  Mesh mesh;
  std::vector<std::string> surrounding_blocks;  // the session's surroundings, in `mesh`
  GridOptions grid_options;  // the config's, with the surroundings' spacing (SolveConfig)
  SurfaceGrid grid;
  std::unique_ptr<RayCaster> caster;
  HemisphereCache hemisphere;
  std::vector<SlotSolve> slots;
  std::vector<SlotIrradiance> irradiance;  // per slot, with interreflection
  AlbedoResult albedo;
  AlbedoOptions albedo_options;  // what the albedos were solved with (irradiance, bounces)
  double env_ground_retro = 0;   // the ground's sun reflection for predictions (FitGroundRetro)
  // The environment's photometric stereo fitted with it, from these slots (SceneModel).
  std::optional<EnvStereoResult> env_stereo;
  std::vector<int> env_stereo_slots;
  // The ground as a light field (SolveConfig::ground_field), shared by every slot's lighting.
  std::shared_ptr<const GroundField> ground_field;
};

// The sky pixels of a sky photo for the §3.2 fit (the paper masks buildings and trees out),
// as session.json's extra.sky_masks says for the group's name (or for "*"): an image file
// inside the session folder (nonzero = sky), or "auto" for automatic segmentation
// (solve/sky_segment.h, the sun excluded). Without an entry every pixel counts: the sky
// camera looks up at open sky, and segmentation of such a photo also drops steep parts of the
// real sky (the low aureole, the horizon band), which raised the demo's sky p90 from 3.6% to
// 5.5%. Always within the photo's valid pixels. `source` gets "all", "automatic" or the mask's
// path. Throws rouen::Error naming session.json, the mask file or the group.
std::vector<uint8_t> SkyMaskFor(const Session& session, const HdrGroup& group,
                                const Eigen::Vector3d& sun_dir, const SkySegmentOptions& segment,
                                std::string* source = nullptr);

// The sky samples of a slot for the §3.2 fit: the pixels SkyMaskFor keeps in each of the
// slot's sky photos (slot<N>/sky/view0, view1, ...; the aureole brackets merge into view0),
// spread over solid angle per photo and fitted together. `sources` gets "group: mask source"
// per photo. Throws rouen::Error when no photo gives a sample.
std::vector<SkySample> SlotSkySamples(const Session& session, const CalibResult& calib, int slot,
                                      const Eigen::Vector3d& sun_dir,
                                      const SkySegmentOptions& segment,
                                      const SkySampleOptions& sampling,
                                      std::string* sources = nullptr);

// The session folder's files, one line each: relative path, size and modification time (the
// journal holds each frame's sha256, and a file changed behind it changes its time). What a
// stage's inputs hash covers of the session.
std::string SessionFilesStamp(const Session& session);

// Site of a session: the GPS fixes' mean when there are any, else session.json's site.
// Throws rouen::Error naming frames.jsonl or session.json when it is outside core/limits.h's
// ranges.
Site SessionSite(const Session& session);
// The same for a session folder `dir` whose session.json is `info` and journal `frames`.
Site SessionSite(const std::filesystem::path& dir, const SessionInfo& info,
                 const std::vector<FrameRecord>& frames);

// The time the solve gives each slot 0..the last in `frames`: the median time of its sky
// frames (the aureole's merged in), else of all its frames; unset for a slot without frames.
// `from_sky` (when given) gets whether each slot's time came from its sky frames.
std::vector<std::optional<UtcTime>> SlotTimes(const std::vector<FrameRecord>& frames,
                                              std::vector<bool>* from_sky = nullptr);

// Empty while any of the sun's disc is above the horizon at `utc` at `site`; else why slot
// `slot` cannot be solved (§3.1 measures the sun in every slot): its time, how far below the
// horizon the sun is, and that the photos' clock, time zone or the site is the usual cause.
std::string NightSlotProblem(int slot, const UtcTime& utc, const Site& site);

}  // namespace rouen
