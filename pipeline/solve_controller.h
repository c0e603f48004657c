// The solve of a calibrated session as a controller: one method per stage, in the paper's order
// (§3 the lighting of every slot, §4 the surface grid, the photos' observations and the
// pseudo-albedos), each with its own figures; progress told as events (PipelineOptions::progress)
// and a cancellation checked between the stages and inside the long ones.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/session.h"
#include "pipeline/session_solve.h"
#include "solve/environment.h"

namespace rouen {

class SolveController {
 public:
  // The stages in the order Run calls them (SolveEvent::stage), one per method below.
  static const std::vector<std::string>& Stages();

  // `session` and `calib` (CalibrateSession's) are read, not owned: they outlive the controller.
  SolveController(const Session& session, const CalibResult& calib, const PipelineOptions& options);

  // "model": the session's model and surroundings (ReadSessionModel), the modelled ground
  // (SolveConfig::ground) and the ray casters; the grid options with the surroundings' spacing.
  void ReadModel();
  // "lighting", per slot: §3.1 the sun's radiance from its ND frames (or a whole HDR disc),
  // §3.2 the seven-parameter sky from the sky photos, §3.3 the environment from the landscape
  // panoramas. Throws rouen::Error naming the session and the slot that lacks a bracket.
  void SolveLighting();
  // "ground reflection" (beyond §5.2): how roughly the ground reflects the sun, from the slots
  // the albedos use; the environments read again with it (EnvOptions::lit_ground).
  void FitGroundReflection();
  // "ground field" (beyond §3.3): the ground as a light field from those slots' panoramas
  // (SolveConfig::ground_field), lent to every slot's lighting; nothing when it is off.
  void BuildGroundField();
  // "surface grid": the grid on the model and its hemisphere visibility (§4.1), its memory
  // checked before it is made.
  void BuildGrid();
  // "observations": the architecture photos of the training slots (and the surroundings in the
  // landscape panoramas, SolveConfig::surroundings_from_panoramas) sampled at the grid (§4).
  void CollectObservations();
  // "pseudo-albedos": irradiance with interreflection and the albedos (§4.1-4.2, the specular
  // lobes, the rough diffuse), then, with a ground field read with the walls' light, the field
  // read again from the solved walls and the albedos solved again.
  void SolveAlbedos();

  // Every stage in order; the result (TakeResult).
  SolveResult Run();
  // What the stages run so far made.
  const SolveResult& result() const { return r_; }
  SolveResult TakeResult() { return std::move(r_); }
  // CollectObservations': the photos sampled and their observations of the grid points.
  const std::vector<ArchitecturePhoto>& photos() const { return photos_; }
  const std::vector<Observation>& observations() const { return observations_; }

 private:
  // Throws rouen::Error unless `stage` is the next one; tells its start.
  void Begin(int stage);
  // Records the stage's time, tells its end with its figures, checks the cancellation.
  void End(int stage, std::vector<std::pair<std::string, double>> figures = {});
  // Tells progress `fraction` through the current stage.
  void Tell(double fraction, const std::string& message);
  void Log(const std::string& line) const;
  // Records a step's time as scene.json keeps it ("stages") and logs "done: <step> (<s> s)".
  void Lap(const std::string& stage, double seconds);
  // The ground field from field_times_, lent to every slot's lighting.
  void MakeGroundField();
  void LogFitted() const;

  const Session& session_;
  const CalibResult& calib_;
  const PipelineOptions& options_;
  SolveResult r_;
  int next_ = 0;  // the next stage to run
  double stage_start_ = 0;
  std::unique_ptr<RayCaster> building_only_;  // the model without the modelled ground, or null
  // Per slot: its landscape panoramas (and sky photo) and sun, to read the environment again.
  std::vector<std::vector<EnvPanorama>> slot_panoramas_;
  std::vector<EnvSun> slot_env_sun_;
  std::vector<int> env_slot_ids_;  // the slots the albedos use (not held out)
  std::vector<GroundFieldTime> field_times_;
  std::vector<size_t> field_slots_;  // index into r_.slots of each of field_times_
  std::vector<ArchitecturePhoto> photos_;
  std::vector<Observation> observations_;
};

// Sun, sky and environment per slot; irradiance at the surface grid; pseudo-albedos from the
// architecture photos of the slots not excluded: SolveController's stages in order.
SolveResult SolveSession(const Session& session, const CalibResult& calib,
                         const PipelineOptions& options);

}  // namespace rouen
