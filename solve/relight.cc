#include "solve/relight.h"

#include <cmath>
#include <cstdio>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {

void RelightOptions::Validate() const {
  if (!(pbs >= 0 && pbs <= 1)) throw Error("relight: pbs must be within 0..1");
  if (!overcast_colour.allFinite() || overcast_colour.minCoeff() <= 0)
    throw Error("relight: the overcast colour must be three positive numbers");
  if (!(overcast_brightness > 0) || !std::isfinite(overcast_brightness))
    throw Error("relight: the overcast brightness must be positive");
  sky.Validate();
  env.Validate();
}

std::string RelightSummary::Describe() const {
  char buf[256];
  std::snprintf(
      buf, sizeof buf,
      "sun elevation %.2f deg, air mass %.2f (measured times: %.2f), sun radiance %s, "
      "sky refit p90 error %.4f%s",
      sun_elevation_deg, air_mass, reference_air_mass,
      sun_from_extinction ? "from extinction" : "interpolated", sky_refit_rel_error_p90,
      extinction_from_air_mass > 0 ? ", sky dimmed for a sun below the measured ones" : "");
  std::string s = buf;
  s += ", weights";
  for (double w : sky_weights) {
    std::snprintf(buf, sizeof buf, " %.3f", w);
    s += buf;
  }
  return s;
}

std::vector<EnvObservation> EnvObservationsOf(const std::vector<Lighting>& measured) {
  std::vector<EnvObservation> envs;
  for (const Lighting& l : measured) {
    EnvObservation eo;
    eo.env = l.env;
    eo.lighting.sun_dir = l.sun_dir;
    eo.lighting.sun_radiance = l.sun_radiance;
    eo.lighting.sun_solid_angle_sr = l.sun_solid_angle_sr;
    eo.lighting.sky = l.sky;
    envs.push_back(std::move(eo));
  }
  return envs;
}

LightingPredictor::LightingPredictor(std::vector<Lighting> measured, const RelightOptions& options)
    : measured_(std::move(measured)), options_(options) {
  options_.Validate();
  if (measured_.empty()) throw Error("relight: no measured time of day to predict from");
  std::vector<SunObservation> suns;
  for (const Lighting& l : measured_) {
    TimedSky ts;
    ts.sky = l.sky;
    ts.sky.sun_dir = l.sun_dir;
    ts.sun_radiance = l.sun_radiance;
    skies_.push_back(ts);
    if (l.sun_dir.z() > 0 && l.sun_radiance.minCoeff() > 0)
      suns.push_back({l.sun_dir, l.sun_radiance});
  }
  // §5.1: extinction needs the sun seen through at least two distinct air masses.
  if (suns.size() >= 2) {
    try {
      extinction_ = FitSunExtinction(suns);
    } catch (const Error&) {
      extinction_.reset();  // e.g. every time at the same air mass: interpolate instead
    }
  }
  env_ = SolveEnvStereo(EnvObservationsOf(measured_), options_.env);
}

Lighting LightingPredictor::At(UtcTime utc, const Site& site, RelightSummary* summary) const {
  const SunPosition sun = ComputeSunPosition(utc, site);
  if (!(sun.elevation_deg > 0))
    throw Error("relight: the sun is below the horizon at " + utc.Iso8601(0) + " (elevation " +
                std::to_string(sun.elevation_deg) + " deg); rouen renders daylight only");
  const Eigen::Vector3d sun_dir = sun.DirectionEnu();
  RelightSummary rs;
  rs.sun_elevation_deg = sun.elevation_deg;
  SkyInterpSummary is;
  Lighting out;
  out.utc = utc;
  out.sun_dir = sun_dir;
  out.sun_solid_angle_sr = sun.SolidAngleSr();
  // §5.1: during the main part of the day the sky is interpolated by its three parts (Lz
  // "almost a constant"); the sun's radiance follows the extinction fitted to the measured
  // suns when there is one, else the inverse-distance average.
  out.sky = InterpolateSky(skies_, sun_dir, options_.sky, &is);
  rs.air_mass = KastenYoungAirMass(ElevationOf(sun_dir));
  rs.reference_air_mass = is.reference_air_mass;
  if (extinction_) {
    out.sun_radiance = extinction_->SunRadiance(rs.air_mass);
    rs.sun_from_extinction = true;
    // Sunrise/sunset: a sun lower than the sky interpolation reaches (the lowest measured sun,
    // or as far below it as the elevation mode follows its line) sees the sky through more air;
    // the aureole reddens with the sun's beta, the background dims with the mean beta. Counted
    // from that elevation, so the sky is continuous there.
    const double reached_air_mass = KastenYoungAirMass(std::max(0.0, is.evaluated_elevation_rad));
    if (rs.air_mass > reached_air_mass) {
      out.sky = ApplyExtinction(out.sky, *extinction_, reached_air_mass, rs.air_mass);
      rs.extinction_from_air_mass = reached_air_mass;
    }
  } else {
    out.sun_radiance = is.sun_radiance;
  }
  rs.sky_weights = is.weights;
  rs.sky_refit_rel_error_p90 = is.rel_error_p90;

  if (options_.pbs > 0) {
    // §6.3: a cloud layer blocks pbs of the sunlight; the sky blends towards a CIE overcast sky
    // whose horizontal irradiance is overcast_brightness x the clear sky's.
    const Eigen::Vector3d clear_e = HorizontalIrradiance(out.sky);
    const Eigen::Vector3d colour = options_.overcast_colour / options_.overcast_colour.mean();
    OvercastSky overcast;
    // CIE overcast: E_horizontal = 7 pi Lz / 9.
    overcast.zenith_radiance =
        colour * (options_.overcast_brightness * clear_e.mean() * 9 / (7 * kPi));
    IntermediateSky blend = MakeIntermediateSky(out.sky, overcast, options_.pbs);
    IntermediateFitSummary fs;
    // Its sun_dir is the zenith when pbs = 1 (the overcast form of eq. 9 is fitted that way).
    out.sky = IntermediateAsSkyModel(blend, 40, 80, &fs);
    out.sun_radiance = blend.SunRadiance(out.sun_radiance);
  }

  // §5.2: the environment from its recovered normals and albedos under the new sun and sky.
  EnvLighting el;
  el.sun_dir = sun_dir;
  el.sun_radiance = out.sun_radiance;
  el.sun_solid_angle_sr = out.sun_solid_angle_sr;
  el.sky = out.sky;
  out.env = PredictEnvironment(env_, el);
  out.use_env = true;
  if (!out.sun_radiance.allFinite() || out.sun_radiance.minCoeff() < 0)
    throw Error("relight: the predicted sun radiance is not finite");
  if (summary) *summary = rs;
  return out;
}

}  // namespace rouen
