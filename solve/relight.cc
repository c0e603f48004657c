#include "solve/relight.h"

#include <algorithm>
#include <array>
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
  if (!(sky_residual_max >= 1) || !std::isfinite(sky_residual_max))
    throw Error("relight: sky_residual_max must be a number >= 1");
  if (!(sky_residual_tolerance >= 0) || !std::isfinite(sky_residual_tolerance))
    throw Error("relight: sky_residual_tolerance must be a number >= 0");
  if (!(sky_residual_min_gain >= 0 && sky_residual_min_gain <= 1))
    throw Error("relight: sky_residual_min_gain must be within 0..1");
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

std::vector<TimedSky> TimedSkiesOf(const std::vector<Lighting>& measured) {
  std::vector<TimedSky> skies;
  for (const Lighting& l : measured) {
    TimedSky ts;
    ts.sky = l.sky;
    ts.sky.sun_dir = l.sun_dir;
    ts.sun_radiance = l.sun_radiance;
    skies.push_back(ts);
  }
  return skies;
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

namespace {

// Azimuth of a direction, radians from north eastwards, in [0, 2 pi).
double AzimuthOf(const Eigen::Vector3d& d) {
  const double az = std::atan2(d.x(), d.y());
  return az < 0 ? az + 2 * kPi : az;
}

// The residual of one measured time at azimuth `az` in the band of region `region` of layer
// `layer`: linear between the two sector centres around it, or the one of them that holds a
// residual; false when neither does.
bool SampleResidual(const std::vector<Eigen::Vector3d>& residual, const EnvironmentMap& map,
                    int layer, int band, double az, Eigen::Vector3d* out) {
  const double u = az / (2 * kPi / map.sectors) - 0.5;
  const double k0 = std::floor(u), f = u - k0;
  auto at = [&](double k) -> const Eigen::Vector3d& {
    const int sector =
        static_cast<int>(((static_cast<long>(k) % map.sectors) + map.sectors) % map.sectors);
    return residual[static_cast<size_t>(layer) * map.num_regions() + band * map.sectors + sector];
  };
  const Eigen::Vector3d &a = at(k0), &b = at(k0 + 1);
  const bool ok_a = a.minCoeff() > 0, ok_b = b.minCoeff() > 0;
  if (ok_a && ok_b) {
    *out = (1 - f) * a + f * b;
  } else if (ok_a || ok_b) {
    *out = ok_a ? a : b;
  } else {
    return false;
  }
  return true;
}

// The sky residual of region `gi` (layer x region index of `map`) for a sun at azimuth `az_sun`,
// averaged over the measured times with weights[t] > 0, each sampled at the same azimuth from
// its own sun (kSun) or at the same azimuth (kFixed); false when no time holds one there.
bool CarryResidual(const std::vector<std::vector<Eigen::Vector3d>>& residual,
                   const std::vector<double>& sun_az, const std::vector<double>& weights,
                   const EnvironmentMap& map, size_t gi, double az_sun, ResidualFrame frame,
                   Eigen::Vector3d* out) {
  const int nreg = map.num_regions();
  const int layer = static_cast<int>(gi / nreg), region = static_cast<int>(gi % nreg);
  double el_lo, el_hi, az_lo, az_hi;
  map.RegionBounds(region, &el_lo, &el_hi, &az_lo, &az_hi);
  const double centre = 0.5 * (az_lo + az_hi);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (size_t t = 0; t < residual.size() && t < weights.size(); ++t) {
    if (!(weights[t] > 0) || residual[t].size() != map.radiance.size()) continue;
    double az = frame == ResidualFrame::kSun ? centre - az_sun + sun_az[t] : centre;
    az = std::fmod(std::fmod(az, 2 * kPi) + 2 * kPi, 2 * kPi);
    Eigen::Vector3d r;
    if (!SampleResidual(residual[t], map, layer, region / map.sectors, az, &r)) continue;
    sum += weights[t] * r;
    wsum += weights[t];
  }
  if (!(wsum > 0)) return false;
  *out = sum / wsum;
  return true;
}

// `sky` weighting its times by the angular distance between suns (§5.1 as written).
SkyInterpOptions ByDirection(SkyInterpOptions sky) {
  sky.mode = SkyInterpMode::kAngularDistance;
  return sky;
}

// The sky model's mean radiance over each region of `map`'s grid (0 below the horizon).
EnvironmentMap SkyMeans(const EnvironmentMap& map, const SkyModel& sky) {
  EnvOptions grid;
  grid.bands_below = map.bands_below;
  grid.bands_above = map.bands_above;
  grid.sectors = map.sectors;
  return EnvironmentMap::FromSky(grid, sky, Eigen::Vector3d::Zero());
}

}  // namespace

LightingPredictor::LightingPredictor(std::vector<Lighting> measured, const RelightOptions& options,
                                     const EnvStereoResult* fitted)
    : measured_(std::move(measured)), options_(options) {
  options_.Validate();
  if (measured_.empty()) throw Error("relight: no measured time of day to predict from");
  skies_ = TimedSkiesOf(measured_);
  std::vector<SunObservation> suns;
  for (const Lighting& l : measured_) {
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
  if (fitted) {
    const EnvironmentMap& m = measured_.front().env;
    if (!(fitted->options == options_.env) ||
        fitted->summary.times != static_cast<int>(measured_.size()) ||
        fitted->bands_below != m.bands_below || fitted->bands_above != m.bands_above ||
        fitted->sectors != m.sectors || fitted->layer_z != m.layer_z)
      throw Error(
          "relight: the environment fit given was made from other times, options or regions");
    env_ = *fitted;
  } else {
    env_ = SolveEnvStereo(EnvObservationsOf(measured_), options_.env);
  }
  for (const Lighting& l : measured_) {
    SkyModel sky = l.sky;
    sky.sun_dir = l.sun_dir;
    sky_means_.push_back(SkyMeans(l.env, sky));
  }
  for (size_t gi = 0; gi < env_.regions.size(); ++gi) {
    if (env_.regions[gi].kind != EnvRegionKind::kSky) continue;
    bool seen = false;
    for (const Lighting& l : measured_)
      seen = seen || (gi < l.env.source.size() && l.env.source[gi] == EnvRegionSource::kObserved);
    if (!seen) never_seen_.push_back(gi);
  }
  for (size_t t = 0; t < measured_.size(); ++t) {
    const EnvironmentMap& env = measured_[t].env;
    std::vector<Eigen::Vector3d>& ratio = fill_ratio_.emplace_back();
    for (size_t gi : never_seen_) {
      const Eigen::Vector3d model = sky_means_[t].radiance[gi % env.num_regions()];
      ratio.push_back(gi < env.radiance.size() && model.minCoeff() > 0
                          ? Eigen::Vector3d(env.radiance[gi].cwiseQuotient(model))
                          : Eigen::Vector3d::Constant(-1));
    }
  }
  const std::vector<std::vector<double>> loo = LeaveOneOutWeights(options_.sky);
  if (options_.sky_residual) {
    for (const Lighting& l : measured_) {
      sun_az_.push_back(AzimuthOf(l.sun_dir));
      sky_residual_.emplace_back(l.env.radiance.size(), Eigen::Vector3d::Constant(-1));
    }
    for (size_t gi = 0; gi < env_.regions.size(); ++gi) {
      if (env_.regions[gi].kind == EnvRegionKind::kSky) SetResidual(gi);
    }
    // Each region found lends its residual to the next: until none is found.
    for (int pass = 0; pass < 8 && FindSkyByResidual(loo) > 0; ++pass) {
    }
    ChooseResidualFrames(loo);
  }
  ChooseFallbackWays(loo, LeaveOneOutWeights(ByDirection(options_.sky)));
}

bool LightingPredictor::IsMeasuredFallback(size_t gi) const {
  return gi < env_.regions.size() && env_.regions[gi].kind == EnvRegionKind::kSkyOnly &&
         !SkyOnlyExplains(env_.regions[gi], options_.env);
}

// The measured radiances of region gi averaged with `weights` over the times that saw it (or
// had it filled from its neighbours); with `sky_now`, each relative to that time's fitted sky
// over the region and put back on sky_now. False when no time counts (or, relative, a time's
// sky there is not positive).
bool LightingPredictor::MeasuredFallback(size_t gi, const std::vector<double>& weights,
                                         const Eigen::Vector3d* sky_now,
                                         Eigen::Vector3d* out) const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (size_t t = 0; t < measured_.size() && t < weights.size(); ++t) {
    const EnvironmentMap& m = measured_[t].env;
    if (!(weights[t] > 0) || gi >= m.radiance.size() ||
        (m.source[gi] != EnvRegionSource::kObserved && m.source[gi] != EnvRegionSource::kNeighbour))
      continue;
    if (sky_now) {
      const Eigen::Vector3d& sky_then = sky_means_[t].radiance[gi % m.num_regions()];
      if (!(sky_then.minCoeff() > 0)) return false;
      sum += weights[t] * m.radiance[gi].cwiseQuotient(sky_then);
    } else {
      sum += weights[t] * m.radiance[gi];
    }
    wsum += weights[t];
  }
  if (!(wsum > 0)) return false;
  *out = sky_now ? Eigen::Vector3d(sum.cwiseProduct(*sky_now) / wsum) : Eigen::Vector3d(sum / wsum);
  return true;
}

// Per measured fallback region: which of its ways predicts every measured time that saw it from
// the others with the least squared log error: its radiance or its ratio to the sky (above the
// horizon), averaged with §5.1's weights for the sky or with the paper's inverse angular distance
// between suns. Sky the model misses (a haze band) keeps its ratio to the sky, which dims and
// reddens towards a low sun; the aureole the model misses near the horizon, and a surface the
// stereo could not explain, follow the sun's direction (a facade lit only when the sun faces
// it); distant ground and haze follow the sky's weights (by default the sun's elevation).
void LightingPredictor::ChooseFallbackWays(const std::vector<std::vector<double>>& loo_sky,
                                           const std::vector<std::vector<double>>& loo_sun) {
  fallback_way_.assign(env_.regions.size(), 0);
  const EnvironmentMap& m0 = measured_.front().env;
  const int nreg = m0.num_regions(), first_above = m0.bands_below * m0.sectors;
  for (size_t gi = 0; gi < env_.regions.size(); ++gi) {
    if (!IsMeasuredFallback(gi)) continue;
    // Below the horizon the sky is no reference: its radiance only.
    const bool above = static_cast<int>(gi % nreg) >= first_above;
    const auto allowed = [&](int way) { return above || !(way & kFallbackRelative); };
    std::array<double, 4> err{0, 0, 0, 0};
    for (size_t t = 0; t < measured_.size() && t < loo_sky.size(); ++t) {
      const EnvironmentMap& m = measured_[t].env;
      if (m.source[gi] != EnvRegionSource::kObserved || !(m.radiance[gi].minCoeff() > 0)) continue;
      std::array<Eigen::Vector3d, 4> pred;
      bool all = true;
      for (int way = 0; way < 4 && all; ++way) {
        if (!allowed(way)) continue;
        const std::vector<double>& w = (way & kFallbackBySun) ? loo_sun[t] : loo_sky[t];
        const Eigen::Vector3d* sky =
            (way & kFallbackRelative) ? &sky_means_[t].radiance[gi % nreg] : nullptr;
        all = MeasuredFallback(gi, w, sky, &pred[way]) && pred[way].minCoeff() > 0;
      }
      if (!all) continue;
      const Eigen::Array3d log_observed = m.radiance[gi].array().log();
      for (int way = 0; way < 4; ++way)
        if (allowed(way)) err[way] += (pred[way].array().log() - log_observed).square().sum();
    }
    int best = 0;
    for (int way = 1; way < 4; ++way)
      if (allowed(way) && err[way] < err[best]) best = way;
    fallback_way_[gi] = static_cast<uint8_t>(best);
  }
}

// Whether time t's panoramas saw region gi and its fitted sky there is positive.
bool LightingPredictor::SeenAgainstModel(size_t t, size_t gi) const {
  const EnvironmentMap& env = measured_[t].env;
  return gi < env.radiance.size() && env.source[gi] == EnvRegionSource::kObserved &&
         env.pixel_count[gi] > 0 && sky_means_[t].radiance[gi % env.num_regions()].minCoeff() > 0;
}

// Region gi's residual at every time its panoramas saw it: observed / the fitted sky's mean.
void LightingPredictor::SetResidual(size_t gi) {
  for (size_t t = 0; t < measured_.size(); ++t) {
    if (!SeenAgainstModel(t, gi)) continue;
    const EnvironmentMap& env = measured_[t].env;
    const Eigen::Vector3d ratio =
        env.radiance[gi].cwiseQuotient(sky_means_[t].radiance[gi % env.num_regions()]);
    sky_residual_[t][gi] =
        ratio.cwiseMax(1 / options_.sky_residual_max).cwiseMin(options_.sky_residual_max);
  }
}

// Per measured time, the §5.1 weights of the other times for its sun (0 for itself).
std::vector<std::vector<double>> LightingPredictor::LeaveOneOutWeights(
    const SkyInterpOptions& sky) const {
  const size_t T = measured_.size();
  std::vector<std::vector<double>> out(T, std::vector<double>(T, 0.0));
  for (size_t t = 0; t < T && T > 1; ++t) {
    std::vector<TimedSky> others;
    std::vector<size_t> index;
    for (size_t u = 0; u < T; ++u) {
      if (u == t) continue;
      others.push_back(skies_[u]);
      index.push_back(u);
    }
    const std::vector<double> w = SkyInterpWeights(others, measured_[t].sun_dir, sky);
    for (size_t k = 0; k < index.size(); ++k) out[t][index[k]] = w[k];
  }
  return out;
}

// The stereo's sky detection compares a region with the smooth model, so the aureole next to a
// time's sun (which the model misses) can make a region of sky look like landscape. Such a
// region is sky after all when, at every time its panoramas saw it, it matches the model times
// the other times' residual carried relative to the sun, within sky_residual_tolerance (the
// mean over the times of the worst channel's relative error). Returns how many it found.
int LightingPredictor::FindSkyByResidual(const std::vector<std::vector<double>>& loo) {
  const size_t T = measured_.size();
  if (T < 2) return 0;
  const EnvironmentMap& m0 = measured_.front().env;
  const int nreg = m0.num_regions(), first_above = m0.bands_below * m0.sectors;
  std::vector<size_t> found;
  for (size_t gi = 0; gi < env_.regions.size(); ++gi) {
    const EnvRegionKind kind = env_.regions[gi].kind;
    if (static_cast<int>(gi % nreg) < first_above ||
        (kind != EnvRegionKind::kLandscape && kind != EnvRegionKind::kSkyOnly))
      continue;
    double err_sum = 0;
    int n = 0;
    bool carried_everywhere = true;
    for (size_t t = 0; t < T && carried_everywhere; ++t) {
      if (!SeenAgainstModel(t, gi)) continue;
      const Eigen::Vector3d& model = sky_means_[t].radiance[gi % nreg];
      Eigen::Vector3d carried;
      carried_everywhere = CarryResidual(sky_residual_, sun_az_, loo[t], m0, gi, sun_az_[t],
                                         ResidualFrame::kSun, &carried);
      if (!carried_everywhere) break;
      const Eigen::Vector3d expected = model.cwiseProduct(carried);
      const Eigen::Vector3d& observed = measured_[t].env.radiance[gi];
      err_sum += ((observed - expected).cwiseAbs().cwiseQuotient(expected)).maxCoeff();
      ++n;
    }
    if (carried_everywhere && n > 0 && err_sum / n <= options_.sky_residual_tolerance)
      found.push_back(gi);
  }
  for (size_t gi : found) {
    EnvRegionFit& fit = env_.regions[gi];
    fit = EnvRegionFit();
    fit.kind = EnvRegionKind::kSky;
    fit.sky_fraction = 1;
    SetResidual(gi);
  }
  sky_by_residual_ += static_cast<int>(found.size());
  return static_cast<int>(found.size());
}

// Per band of every layer, how its residual carries to a new time: each measured time's residual
// is predicted from the other times (their §5.1 weights for its sun) relative to the sun, at the
// same azimuth, or not at all (1), and the band takes the way with the least squared log error,
// when it removes at least sky_residual_min_gain of the error of not carrying it.
// Sky structure that follows the sun (the aureole, the horizon brightening towards it) carries
// relative to the sun; a distant skyline the sky detection let through stays where it is; noise
// carries not at all.
void LightingPredictor::ChooseResidualFrames(const std::vector<std::vector<double>>& loo) {
  const EnvironmentMap& m0 = measured_.front().env;
  const int nb = m0.num_bands(), nreg = m0.num_regions();
  const size_t T = measured_.size();
  std::vector<std::array<double, 3>> err(static_cast<size_t>(m0.num_layers()) * nb, {0, 0, 0});
  for (size_t t = 0; t < T && T > 1; ++t) {
    const std::vector<double>& w = loo[t];
    for (size_t gi = 0; gi < sky_residual_[t].size(); ++gi) {
      const Eigen::Vector3d& r = sky_residual_[t][gi];
      if (!(r.minCoeff() > 0)) continue;
      const size_t lb = (gi / nreg) * nb + (gi % nreg) / m0.sectors;
      const Eigen::Vector3d log_r = r.array().log().matrix();
      err[lb][0] += log_r.squaredNorm();
      for (const ResidualFrame f : {ResidualFrame::kSun, ResidualFrame::kFixed}) {
        Eigen::Vector3d pred = Eigen::Vector3d::Ones();
        CarryResidual(sky_residual_, sun_az_, w, m0, gi, sun_az_[t], f, &pred);
        err[lb][static_cast<int>(f)] += (log_r - pred.array().log().matrix()).squaredNorm();
      }
    }
  }
  residual_frame_.assign(err.size(), ResidualFrame::kNone);
  for (size_t lb = 0; lb < err.size(); ++lb) {
    int best = 0;
    const double most = (1 - options_.sky_residual_min_gain) * err[lb][0];
    for (int f = 1; f < 3; ++f)
      if (err[lb][f] <= most && err[lb][f] < err[lb][best]) best = f;
    residual_frame_[lb] = static_cast<ResidualFrame>(best);
  }
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
      // kAirMass followed the zenith's own line to the new sun: it is not dimmed twice.
      out.sky = ApplyExtinction(out.sky, *extinction_, reached_air_mass, rs.air_mass,
                                /*dim_zenith=*/options_.sky.mode != SkyInterpMode::kAirMass);
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
  // A sky-only fallback that does not explain its region (SkyOnlyExplains) is not carried to
  // the new sun as a surface: the region takes its measured radiances (or what the maps filled
  // it with from their neighbours at times no panorama saw it), or their ratios to the sky,
  // weighted as the sky's times are (§5.1; by default by the sun's elevation, which sets how
  // bright the haze and the distant ground near the horizon are) or by the angular distance
  // between suns, as predicts the measured times best (ChooseFallbackWays).
  const bool any_relative = std::any_of(fallback_way_.begin(), fallback_way_.end(),
                                        [](uint8_t way) { return way & kFallbackRelative; });
  const EnvironmentMap sky_now = any_relative ? SkyMeans(out.env, out.sky) : EnvironmentMap();
  const std::vector<double> sun_weights =
      SkyInterpWeights(skies_, sun_dir, ByDirection(options_.sky));
  for (size_t gi = 0; gi < out.env.radiance.size(); ++gi) {
    if (!IsMeasuredFallback(gi)) continue;
    Eigen::Vector3d r;
    const std::vector<double>& w = (fallback_way_[gi] & kFallbackBySun) ? sun_weights : is.weights;
    const Eigen::Vector3d* sky = (fallback_way_[gi] & kFallbackRelative)
                                     ? &sky_now.radiance[gi % sky_now.num_regions()]
                                     : nullptr;
    if ((sky && sky->minCoeff() > 0 && MeasuredFallback(gi, w, sky, &r)) ||
        MeasuredFallback(gi, w, nullptr, &r))
      out.env.radiance[gi] = r;
  }
  out.env.ground_retro = options_.env.ground_retro;  // as the shadow on it is put back
  // Each sky region spread over itself as the new time's model is (no residual per cell: that
  // was measured at other times), at the measured maps' detail.
  out.env.detail = measured_.front().env.detail;
  out.env.sun_exclusion_rad = measured_.front().env.sun_exclusion_rad;
  if (!sky_residual_.empty()) {
    // The measured sky's residual carried to the new sun as its band carries best, weighted as
    // the sky's parts (§5.1's weights); under a cloud layer it fades with the blocked sunlight
    // (§6.3).
    const EnvironmentMap& m = out.env;
    const int nreg = m.num_regions(), nb = m.num_bands();
    const double az_sun = AzimuthOf(sun_dir);
    for (size_t gi = 0; gi < m.radiance.size() && gi < env_.regions.size(); ++gi) {
      if (env_.regions[gi].kind != EnvRegionKind::kSky) continue;
      const ResidualFrame frame = residual_frame_[(gi / nreg) * nb + (gi % nreg) / m.sectors];
      Eigen::Vector3d r;
      if (frame == ResidualFrame::kNone ||
          !CarryResidual(sky_residual_, sun_az_, is.weights, m, gi, az_sun, frame, &r))
        continue;
      const Eigen::Vector3d residual =
          Eigen::Vector3d::Ones() + (1 - options_.pbs) * (r - Eigen::Vector3d::Ones());
      out.env.radiance[gi] = out.env.radiance[gi].cwiseProduct(residual);
    }
  }
  // A sky region no panorama saw at any time: the measured maps filled it with their sky
  // model's mean times its band's residual (EnvOptions::fill_band_residual; 1 without it), and
  // the new time's takes the same ratio, weighted as the sky's times are (§5.1).
  for (size_t k = 0; k < never_seen_.size(); ++k) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double wsum = 0;
    for (size_t t = 0; t < fill_ratio_.size() && t < is.weights.size(); ++t) {
      if (!(is.weights[t] > 0) || !(fill_ratio_[t][k].minCoeff() > 0)) continue;
      sum += is.weights[t] * fill_ratio_[t][k];
      wsum += is.weights[t];
    }
    const size_t gi = never_seen_[k];
    if (wsum > 0 && gi < out.env.radiance.size())
      out.env.radiance[gi] = out.env.radiance[gi].cwiseProduct(sum / wsum);
  }
  out.use_env = true;
  out.ground = measured_.front().ground;  // the ground's albedos hold at any time
  if (!out.sun_radiance.allFinite() || out.sun_radiance.minCoeff() < 0)
    throw Error("relight: the predicted sun radiance is not finite");
  if (summary) *summary = rs;
  return out;
}

}  // namespace rouen
