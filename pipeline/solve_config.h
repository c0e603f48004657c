// Every choice a solve makes, typed, with its default: `rouen solve --config solve.toml`
// overrides any of them (strict keys: a misspelt key is an error, not a silent default), and
// the scene records them all, so render and validate use what the solve used.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "calib/hdr.h"
#include "calib/response.h"
#include "core/session.h"
#include "solve/albedo.h"
#include "solve/env_stereo.h"
#include "solve/environment.h"
#include "solve/grid.h"
#include "solve/ground_apron.h"
#include "solve/irradiance.h"
#include "solve/scene.h"
#include "solve/sky_fit.h"
#include "solve/sky_segment.h"
#include "solve/sun.h"

namespace rouen {

struct SolveConfig {
  // The surface grid the albedos are solved on; 0.6 m, 1.5 m on a block named "plaza".
  GridOptions grid;
  // Beyond the paper: the ground around the building modelled as a surface (block "ground",
  // gridded at ground.spacing_m unless grid.block_spacing_m names it), its albedo solved from
  // the photos. Off by default (radius_m 0).
  GroundApronOptions ground;
  // The grid spacing on the session's surroundings (SessionInfo::surroundings: coarse
  // geometry seen mostly from afar, solved only to light the building) unless
  // grid.block_spacing_m names their block, metres.
  double surroundings_spacing_m = 2.0;
  // Whether the surroundings' albedos are read from the landscape panoramas of the training
  // slots as well as from the architecture photos: the panoramas are what sees the houses
  // around a square; without them a house no architecture view shows takes the fill (on the
  // Rouen world the houses across the square, the brightest light on the shaded west front in
  // the morning, read 0.64 / 0.58 / 0.50 against 0.46 / 0.36 / 0.27). The building's own
  // albedos never take a panorama's pixels.
  bool surroundings_from_panoramas = true;
  HemisphereOptions hemisphere;  // the irradiance's gathering pattern over that grid
  // LDR brackets the response curve is recovered from, spread evenly over the session.
  int response_max_brackets = 12;
  // The response curve's recovery from those brackets ([response], with max_brackets).
  ResponseOptions response;
  // How a bracket's frames merge to radiance ([merge]): LDR frames through the response curve
  // (the hat weights' limits, ghost removal), HDR frames (clipping near their maximum).
  MergeOptions merge;
  RadianceMergeOptions radiance_merge;
  // §3.2. Relative residuals (sigma = y) fit the physically based sky better than eq. 10's
  // sigma = y / log y, and their L1 norm keeps the horizon and inner aureole, which eq. 9
  // cannot follow exactly, from pulling the rest of the fit (bench/sky_bench.cc).
  SkyFitOptions sky_fit;
  // §3.2: the sky pixels the fit samples (away from the horizon and the sun), and, for a sky
  // photo without a mask file (`rouen import --sky-mask auto`), how its sky is told apart.
  SkySampleOptions sky_samples;
  SkySegmentOptions sky_segment;
  // §3.1: where the sun disc is looked for and measured in the ND-filtered sun frames, and the
  // value at which a pixel is clipped rather than radiance.
  SunOptions sun;
  EnvOptions environment;  // §3.3
  // Beyond §3.3: the ground around the model as a light field (solve/ground_field.h): the
  // landscape panoramas re-projected onto it, lit per time with the model's cast shadow, seen
  // from where each grid point stands. Off by default.
  GroundFieldOptions ground_field;
  // Beyond §5.2: fit how roughly the ground below the horizon reflects the sun (the scene's
  // environment.ground_retro, used when the environment is predicted for a novel time).
  bool fit_ground_retro = true;
  // §5.2: the environment's photometric stereo, fitted by the solve (for the ground's retro,
  // kept in the scene) and by every prediction for a novel time, which reuses the solve's fit
  // only when these options are the ones it was made with (FitFor). Its ground_retro is not
  // an option: the solve fits it.
  EnvStereoOptions env_stereo;
  AlbedoOptions albedo;   // §4, with the irradiance options
  void Validate() const;  // throws rouen::Error naming the bad field
};

// The defaults; `quick` halves the work where it costs least accuracy (6 response brackets,
// every second panorama pixel).
SolveConfig DefaultSolveConfig(bool quick);

// Every field, keyed as in solve.toml.
nlohmann::json SolveConfigJson(const SolveConfig& config);
// `base` with the fields `j` gives replaced. Unknown keys, wrong types and out-of-range values
// throw rouen::Error naming `where` and the key path (e.g. "solve.toml: sky_fit.norm_p").
SolveConfig ApplySolveConfig(const nlohmann::json& j, SolveConfig base, const std::string& where);
// The same from a TOML file (tables as in SolveConfigJson: [grid], [grid.block_spacing_m],
// [ground], [surroundings], [hemisphere], [response], [sky_fit], [environment], [ground_field],
// [albedo], [albedo.irradiance], [sun], [sky_samples], [sky_segment], [merge]).
SolveConfig ReadSolveConfigFile(const std::string& path, const SolveConfig& base);
// The options a session's solve starts from: the defaults with the session's own
// (session.json extra.solve_config, e.g. from its rig's [solve] table) applied; errors name
// `session_json`.
SolveConfig SessionSolveConfig(const SessionInfo& info, const std::string& session_json,
                               bool quick);

// The options a scene was solved with, as its scene.json records them (`scene_json`: its path,
// for messages); a scene from before they were recorded: the defaults.
SolveConfig SceneSolveConfig(const SceneModel& scene, const std::string& scene_json);

}  // namespace rouen
