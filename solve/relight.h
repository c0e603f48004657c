// Lighting at a time of day that was not captured (Yu & Malik 1998 §5 and §6.3): the sun's
// position from the site and time; its radiance from the measured sun radiances against air
// mass; the sky interpolated between the measured skies by sun position (§5.1) and, for a sun
// lower than every measured one, dimmed and reddened through the extra air mass; the environment
// from its recovered per-region normals and albedos (§5.2); optionally part of the sunlight blocked
// by a cloud layer, blending towards an overcast sky (§6.3).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/solar.h"
#include "core/time.h"
#include "solve/env_stereo.h"
#include "solve/irradiance.h"
#include "solve/sky_time.h"

namespace rouen {

struct RelightOptions {
  // Blocked-sunlight fraction (§6.3): 0 a clear sky, 1 fully overcast.
  double pbs = 0;
  // Colour of the overcast sky (any positive RGB; only its ratios matter). Usually near grey.
  Eigen::Vector3d overcast_colour = Eigen::Vector3d::Ones();
  // Brightness of the overcast sky: its horizontal irradiance as a multiple of the clear sky's
  // (sky only, no sun) at the same time.
  double overcast_brightness = 1.0;
  SkyInterpOptions sky;
  EnvStereoOptions env;
  // Beyond the paper's §5.1: the sky regions of the predicted environment map are the new
  // time's interpolated model times the measured sky's residual against its fitted model
  // (observed / model, per region and channel), taken from each measured time at the same
  // elevation and either the same azimuth from the sun or the same azimuth, and averaged with
  // the sky's §5.1 weights. The seven-parameter model misses structure the photos show (the
  // horizon band brightens towards the sun and dims opposite it); the residual keeps it. Each
  // band of the map carries it the way that best predicts every measured time from the others,
  // or not at all. false: the model alone.
  bool sky_residual = true;
  // A band carries the residual only when that removes at least this fraction of the squared
  // log error of the model alone, over the measured times each predicted from the others. With
  // three to five times that comparison is noisy; a band the residual explains only in part
  // keeps the model (the demo world's mast layer: a gain of 0.5-0.64 there made its held-out
  // prediction 0.1-0.2 points worse; the Blender world's horizon band gains 0.86).
  double sky_residual_min_gain = 2.0 / 3;
  // A region the stereo took for landscape is sky when the model times the residual carried
  // relative to the sun from the other times matches it at every time within this mean
  // relative error (worst channel). Half the stereo's own sky_match_tolerance: the residual can
  // also fit the edge of a skyline, and each region found lends its residual to the next (at
  // the stereo's 0.15 the demo world's skyline became sky and its held-out prediction lost 0.3
  // dB; at 0.075 none did, and the Blender world's horizon region beside the morning sun is
  // found).
  double sky_residual_tolerance = 0.075;
  // Residual ratios are clamped to [1 / max, max] (a region the model misses by more is not
  // sky structure but something the sky detection let through).
  double sky_residual_max = 2.0;

  void Validate() const;  // throws rouen::Error naming the bad field
};

struct RelightSummary {
  double sun_elevation_deg = 0;
  double air_mass = 0;              // Kasten-Young, of the new sun
  double reference_air_mass = 0;    // inverse-distance weighted over the measured times
  std::vector<double> sky_weights;  // per measured time (§5.1)
  double sky_refit_rel_error_p90 = 0;
  bool sun_from_extinction = false;  // false: interpolated sun radiance (too few air masses)
  // > 0 when the sun is lower than every measured one: the sky was dimmed and reddened from
  // this air mass (the lowest measured sun's) to the new sun's (§5.1 sunrise/sunset).
  double extinction_from_air_mass = 0;
  std::string Describe() const;
};

// The measured times' fitted skies with their suns, as §5.1's interpolation takes them.
std::vector<TimedSky> TimedSkiesOf(const std::vector<Lighting>& measured);
// The environment maps of measured times with their sun and sky, as §5.2's photometric stereo
// takes them.
std::vector<EnvObservation> EnvObservationsOf(const std::vector<Lighting>& measured);

// Fitted once from the measured times, then asked for any number of times.
// How a band of the environment map carries the measured sky's residual to a new time.
enum class ResidualFrame : uint8_t {
  kNone = 0,   // not at all (the model alone)
  kSun = 1,    // at the same azimuth from the sun
  kFixed = 2,  // at the same azimuth
};

class LightingPredictor {
 public:
  // `measured` holds the lighting solved at each captured time (sun, fitted sky, environment
  // map). Fits the sun's extinction when the sun was seen through at least two distinct air
  // masses and the environment's photometric stereo (§5.2). Throws rouen::Error for no
  // measured time or inconsistent environment maps. `fitted` (optional): the environment's
  // stereo already fitted from these maps with options.env (a scene keeps its solve's,
  // SceneModel::env_stereo); it is taken instead of fitting again, and refused (rouen::Error)
  // when its options, times or region layout differ.
  LightingPredictor(std::vector<Lighting> measured, const RelightOptions& options,
                    const EnvStereoResult* fitted = nullptr);

  // Lighting at `utc` seen from `site`. Throws rouen::Error when the sun is below the horizon
  // (the models are fitted to daylight) or the options are bad.
  Lighting At(UtcTime utc, const Site& site, RelightSummary* summary = nullptr) const;

  const EnvStereoResult& environment() const { return env_; }
  const std::optional<SunExtinction>& extinction() const { return extinction_; }
  // Per layer, then band (above and below the horizon, as EnvironmentMap): how the band carries
  // the sky residual (RelightOptions::sky_residual); empty without it.
  const std::vector<ResidualFrame>& residual_frames() const { return residual_frame_; }
  // Regions the stereo took for landscape that the sky residual explains, now predicted as sky.
  int sky_regions_by_residual() const { return sky_by_residual_; }

 private:
  std::vector<Lighting> measured_;
  std::vector<TimedSky> skies_;
  RelightOptions options_;
  std::optional<SunExtinction> extinction_;
  EnvStereoResult env_;
  // Per measured time, per layer and region of the environment map: the sky residual
  // (observed / model mean over the region, RGB), or -1 where the region is not sky observed at
  // that time.
  std::vector<std::vector<Eigen::Vector3d>> sky_residual_;
  std::vector<EnvironmentMap> sky_means_;  // per measured time: its fitted sky per region
  // The sky regions (layer x region) no measured time observed, and per measured time each one's
  // filled radiance over that time's model mean (EnvOptions::fill_band_residual; 1 without it).
  std::vector<size_t> never_seen_;
  std::vector<std::vector<Eigen::Vector3d>> fill_ratio_;
  std::vector<double> sun_az_;  // per measured time, radians from north eastwards
  std::vector<ResidualFrame> residual_frame_;
  // Per layer and region (0 for all but measured fallbacks), how a measured fallback carries to
  // a new time: bits kFallbackRelative
  // (its ratio to the sky, else its radiance) and kFallbackBySun (the times weighted by the
  // angular distance between suns, else as the sky's).
  static constexpr uint8_t kFallbackRelative = 1, kFallbackBySun = 2;
  std::vector<uint8_t> fallback_way_;
  int sky_by_residual_ = 0;
  bool SeenAgainstModel(size_t time, size_t region) const;
  void SetResidual(size_t region);
  // Per measured time, the other times' weights for its sun with `sky`'s mode (0 for itself).
  std::vector<std::vector<double>> LeaveOneOutWeights(const SkyInterpOptions& sky) const;
  int FindSkyByResidual(const std::vector<std::vector<double>>& loo);
  // A sky-only fallback region that explains nothing: predicted from its measured radiances.
  bool IsMeasuredFallback(size_t region) const;
  bool MeasuredFallback(size_t region, const std::vector<double>& weights,
                        const Eigen::Vector3d* sky_now, Eigen::Vector3d* out) const;
  void ChooseFallbackWays(const std::vector<std::vector<double>>& loo_sky,
                          const std::vector<std::vector<double>>& loo_sun);
  void ChooseResidualFrames(const std::vector<std::vector<double>>& loo);
};

}  // namespace rouen
