// Validation of a solved scene against photographs (§6 compares re-renderings with real
// photographs): every architecture bracket of a slot is rendered at its camera and time and
// compared with its merged radiance over the building's pixels, once under the lighting
// measured at that slot and once under lighting predicted from the other slots only (§5).
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/session.h"
#include "pipeline/scene.h"
#include "render/metrics.h"
#include "solve/relight.h"

namespace rouen {

struct ValidateOptions {
  // Model blocks (OBJ groups) left out of the scored pixels, e.g. the ground around the
  // building, which photographs see at grazing angles. The ground a solve modelled itself
  // (SolveConfig::ground) and the session's surroundings are never scored.
  std::vector<std::string> exclude_blocks;
  // The scored mask is eroded by this many pixels: silhouette and block-edge pixels mix two
  // surfaces in a photograph.
  int erode_px = 1;
  bool predicted = true;   // also render under lighting predicted from the other slots
  RelightOptions relight;  // for the prediction
  // Also split the measured lighting's irradiance on the shaded faces into its terms
  // (ShadedTerms); costs one more pass of the irradiance.
  bool terms = false;
  void Validate() const;  // throws rouen::Error
};

// What lights the faces the sun does not reach at the slot's time (E_sun = 0: facing away from
// the sun or in a cast shadow), per block among the scored ones and over all of them: each
// term's share of the summed irradiance per channel (RGB) at their observed grid points, under
// the slot's measured lighting. The sky is the direct light from above the horizon, the
// environment from below it (the ground and landscape, with the model's shadow on the ground),
// the interreflection what other model faces send (§4.1).
struct ShadedTerms {
  std::string block;  // "all": every scored block
  int points = 0;
  Eigen::Vector3d irradiance = Eigen::Vector3d::Zero();  // mean E_se over the points
  Eigen::Vector3d sky = Eigen::Vector3d::Zero(), environment = Eigen::Vector3d::Zero(),
                  interreflection = Eigen::Vector3d::Zero();
};

struct PhotoValidation {
  std::string view;  // the bracket, e.g. "slot4/architecture/view0"
  RenderMetrics measured;
  std::optional<RenderMetrics> predicted;
  Image photo;  // the bracket merged to radiance
  Image rendered_measured;
  Image rendered_predicted;   // empty without the prediction
  std::vector<uint8_t> mask;  // the scored pixels
};

struct Validation {
  int slot = 0;
  bool held_out = false;  // the albedos did not use this slot's photos
  std::vector<PhotoValidation> photos;
  // Photos left out because none of their pixels is scored (the blocks they see excluded,
  // or nothing of the model in view or exposed), with the reason.
  std::vector<std::string> skipped;
  RenderMetrics measured;  // pooled over every photo
  std::optional<RenderMetrics> predicted;
  // The lighting the photos were rendered under: the slot's measured one and, with the
  // prediction, the one predicted from the other slots (§5).
  Lighting measured_lighting;
  std::optional<Lighting> predicted_lighting;
  std::vector<ShadedTerms> shaded_terms;  // with ValidateOptions::terms: "all" first
};

// Validates slot `slot` of `scene` against the architecture photos of `session` (the session
// the scene was solved from: each photo's bracket must be one of the scene's views). The
// photos are merged through the scene's response curve; the PSNR is measured through it too
// (render/metrics.h). A photo with no pixel to score is skipped (Validation::skipped, and a
// log line); none left to score is an error. Throws rouen::Error naming the scene, session or
// bracket.
Validation ValidateSlot(const LoadedScene& scene, const Session& session, int slot,
                        const ValidateOptions& options,
                        const std::function<void(const std::string&)>& log = {});

// The figures as JSON (what `rouen validate --json` writes): slot, held_out, measured and
// predicted metrics pooled and per photo.
nlohmann::json ValidationToJson(const Validation& v);

}  // namespace rouen
