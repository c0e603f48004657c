#include "solve/relight.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/angles.h"
#include "core/error.h"

namespace rouen {
namespace {

const Site kSite{37.8722, -122.2578, 60.0};

// A clear sky of the CIE kind (gradation and indicatrix of a clear day), bluish, with the sun
// at `sun_dir`.
SkyModel ClearSky(const Eigen::Vector3d& sun_dir) {
  SkyModel m;
  const double lz[3] = {0.6, 0.8, 1.1};
  for (int c = 0; c < 3; ++c) {
    SkyParams& p = m.channel[c];
    p.Lz = lz[c];
    p.a = -1;
    p.b = -0.32;
    p.c = 10;
    p.d = -3;
    p.e = 0.45;
    p.h = 1;
  }
  m.sun_dir = sun_dir;
  return m;
}

// Measured lighting at local times of 2026-08-25 (PDT): the sun from the ephemeris, its
// radiance through an atmosphere of known extinction, a clear sky, and an environment of sky
// above the horizon and grey ground below.
Lighting Measured(const std::string& local_time, const Eigen::Vector3d& beta,
                  const Eigen::Vector3d& l0) {
  Lighting l;
  l.utc = ParseIso8601("2026-08-25T" + local_time + ":00-07:00");
  const SunPosition sun = ComputeSunPosition(l.utc, kSite);
  l.sun_dir = sun.DirectionEnu();
  l.sun_solid_angle_sr = sun.SolidAngleSr();
  const double m = KastenYoungAirMass(ElevationOf(l.sun_dir));
  for (int c = 0; c < 3; ++c) l.sun_radiance[c] = l0[c] * std::exp(-beta[c] * m);
  l.sky = ClearSky(l.sun_dir);
  l.env = EnvironmentMap::FromSky(EnvOptions{}, l.sky, Eigen::Vector3d::Constant(0.3));
  return l;
}

std::vector<Lighting> Day(const Eigen::Vector3d& beta, const Eigen::Vector3d& l0) {
  std::vector<Lighting> v;
  for (const char* t : {"07:45", "10:30", "13:30", "18:15"}) v.push_back(Measured(t, beta, l0));
  return v;
}

TEST(RelightTest, SunRadianceFollowsTheExtinctionOfTheMeasuredTimes) {
  const Eigen::Vector3d beta(0.10, 0.14, 0.22), l0(4e4, 4.2e4, 4.5e4);
  LightingPredictor predictor(Day(beta, l0), RelightOptions{});
  ASSERT_TRUE(predictor.extinction().has_value());
  // A time between the measured ones and one near sunset: the sun radiance is L0 exp(-beta m)
  // at the new sun's air mass (the fit is exact on noise-free data).
  for (const char* t : {"2026-08-25T16:00:00-07:00", "2026-08-25T19:30:00-07:00"}) {
    RelightSummary rs;
    const Lighting l = predictor.At(ParseIso8601(t), kSite, &rs);
    const SunPosition sun = ComputeSunPosition(ParseIso8601(t), kSite);
    EXPECT_NEAR(std::acos(std::clamp(l.sun_dir.dot(sun.DirectionEnu()), -1.0, 1.0)), 0, 1e-9);
    const double m = KastenYoungAirMass(ElevationOf(sun.DirectionEnu()));
    EXPECT_NEAR(rs.air_mass, m, 1e-9);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(l.sun_radiance[c] / (l0[c] * std::exp(-beta[c] * m)), 1, 1e-6) << t;
    EXPECT_TRUE(rs.sun_from_extinction);
    // 16:00 lies between measured suns (no sky extinction); 19:30 is below them all.
    EXPECT_EQ(rs.extinction_from_air_mass > 0, std::string(t).find("19:30") != std::string::npos)
        << t;
    EXPECT_NEAR(l.sky.sun_dir.dot(l.sun_dir), 1, 1e-9);
    EXPECT_EQ(l.env.num_regions(), EnvOptions{}.bands_below * 2 * EnvOptions{}.sectors);
    for (const Eigen::Vector3d& r : l.env.radiance) EXPECT_TRUE(r.allFinite() && r.minCoeff() >= 0);
  }
  // Lower sun, more air: redder and dimmer (beta grows towards blue).
  const Lighting noon = predictor.At(ParseIso8601("2026-08-25T13:00:00-07:00"), kSite);
  const Lighting late = predictor.At(ParseIso8601("2026-08-25T19:30:00-07:00"), kSite);
  EXPECT_LT(late.sun_radiance[1], noon.sun_radiance[1]);
  EXPECT_GT(late.sun_radiance[0] / late.sun_radiance[2],
            noon.sun_radiance[0] / noon.sun_radiance[2]);
}

TEST(RelightTest, AirMassSkiesFollowTheZenithsLineBelowTheMeasuredSuns) {
  // A sun below every measured one (18:45, about 11 deg; the lowest measured 13 deg), with no
  // extrapolation allowed: the sunset extinction dims the sky from the lowest measured sun's
  // air mass. kAirMass has followed the zenith's own line to the new sun, so its Lz is the
  // interpolation's, not dimmed again; kElevation's held zenith is dimmed.
  const std::vector<Lighting> day = Day({0.1, 0.12, 0.15}, {1e4, 1e4, 1e4});
  const std::vector<TimedSky> skies = TimedSkiesOf(day);
  const UtcTime t = ParseIso8601("2026-08-25T18:45:00-07:00");
  const Eigen::Vector3d sun = ComputeSunPosition(t, kSite).DirectionEnu();
  for (const SkyInterpMode mode : {SkyInterpMode::kAirMass, SkyInterpMode::kElevation}) {
    RelightOptions o;
    o.sky.mode = mode;
    o.sky.max_extrapolation_deg = 0;
    RelightSummary rs;
    const Lighting l = LightingPredictor(day, o).At(t, kSite, &rs);
    ASSERT_GT(rs.extinction_from_air_mass, 0);
    const SkyModel interpolated = InterpolateSky(skies, sun, o.sky, nullptr);
    for (int c = 0; c < 3; ++c) {
      const double lz = interpolated.channel[c].Lz;
      if (mode == SkyInterpMode::kAirMass) {
        EXPECT_NEAR(l.sky.channel[c].Lz, lz, 1e-12 * lz) << c;
      } else {
        EXPECT_LT(l.sky.channel[c].Lz, 0.99 * lz) << c;
      }
    }
  }
}

TEST(RelightTest, AMeasuredTimeGivesBackItsSky) {
  const std::vector<Lighting> day = Day({0.1, 0.1, 0.1}, {1e4, 1e4, 1e4});
  LightingPredictor predictor(day, RelightOptions{});
  RelightSummary rs;
  const Lighting l = predictor.At(day[1].utc, kSite, &rs);
  ASSERT_EQ(rs.sky_weights.size(), 4u);
  EXPECT_NEAR(rs.sky_weights[1], 1, 1e-9);
  // Same air mass as the reference: no extinction change; the sky is that time's.
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(l.sky.channel[c].Lz / day[1].sky.channel[c].Lz, 1, 1e-6);
    EXPECT_NEAR(l.sky.channel[c].c, day[1].sky.channel[c].c, 1e-6 * day[1].sky.channel[c].c);
  }
}

// A scene's stored environment fit (SceneModel::env_stereo) predicts exactly as a fresh fit of
// the same times; one made from other times or options is refused.
TEST(RelightTest, AStoredEnvironmentFitPredictsAsAFreshOne) {
  const std::vector<Lighting> day = Day({0.1, 0.14, 0.2}, {1e4, 1e4, 1e4});
  const LightingPredictor fresh(day, RelightOptions{});
  const EnvStereoResult stored =
      nlohmann::json::parse(nlohmann::json(fresh.environment()).dump()).get<EnvStereoResult>();
  const LightingPredictor again(day, RelightOptions{}, &stored);
  for (const char* t : {"09:00", "12:00", "17:30"}) {
    const UtcTime utc = ParseIso8601(std::string("2026-08-25T") + t + ":00-07:00");
    const Lighting a = fresh.At(utc, kSite), b = again.At(utc, kSite);
    EXPECT_EQ(b.env.radiance, a.env.radiance) << t;
    EXPECT_EQ(b.sun_radiance, a.sun_radiance) << t;
  }
  RelightOptions rough;
  rough.env.ground_retro = 1;
  EXPECT_THROW(LightingPredictor(day, rough, &stored), Error);
  const std::vector<Lighting> fewer(day.begin(), day.begin() + 3);
  EXPECT_THROW(LightingPredictor(fewer, RelightOptions{}, &stored), Error);
}

TEST(RelightTest, BlockedSunlightBlendsTowardsOvercast) {
  const std::vector<Lighting> day = Day({0.1, 0.12, 0.15}, {1e4, 1e4, 1e4});
  const UtcTime t = ParseIso8601("2026-08-25T15:00:00-07:00");
  LightingPredictor clear(day, RelightOptions{});
  RelightOptions o;
  o.pbs = 1;
  o.overcast_colour = Eigen::Vector3d(1, 1, 1);
  LightingPredictor overcast(day, o);
  const Lighting lc = clear.At(t, kSite), lo = overcast.At(t, kSite);
  EXPECT_EQ(lo.sun_radiance, Eigen::Vector3d::Zero());
  // Fully overcast, grey: the zenith is brighter than the horizon by (1 + 2)/(1 + 2 cos 85deg)
  // and the colour is the same in every channel (up to the 7-parameter approximation's error,
  // 2.2% at most per sky_time's fit).
  const Eigen::Vector3d zen = lo.sky.Radiance(Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d low =
      lo.sky.Radiance(Eigen::Vector3d(0, std::sin(85 * kPi / 180), std::cos(85 * kPi / 180)));
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(zen[c] / zen.mean(), 1, 0.03);
    EXPECT_NEAR(low[c] / low.mean(), 1, 0.03);
    EXPECT_NEAR(zen[c] / low[c], 3 / (1 + 2 * std::cos(85 * kPi / 180)), 0.05 * 2.56);
  }
  EXPECT_GT(lc.sun_radiance.minCoeff(), 0);
  EXPECT_THROW(
      {
        RelightOptions bad;
        bad.pbs = 1.5;
        LightingPredictor p(day, bad);
      },
      Error);
}

// Azimuth of a direction, radians from north eastwards.
double Azimuth(const Eigen::Vector3d& d) { return std::atan2(d.x(), d.y()); }

// The day's lighting with every region above the horizon observed: the fitted sky's mean over
// the region times residual(region centre azimuth, sun azimuth, band above the horizon).
std::vector<Lighting> ObservedDay(const std::function<double(double, double, int)>& residual) {
  std::vector<Lighting> day = Day({0.1, 0.12, 0.15}, {1e4, 1e4, 1e4});
  for (Lighting& l : day) {
    EnvironmentMap& m = l.env;
    for (int r = m.bands_below * m.sectors; r < m.num_regions(); ++r) {
      double el_lo, el_hi, az_lo, az_hi;
      m.RegionBounds(r, &el_lo, &el_hi, &az_lo, &az_hi);
      m.radiance[r] *=
          residual(0.5 * (az_lo + az_hi), Azimuth(l.sun_dir), r / m.sectors - m.bands_below);
      m.source[r] = EnvRegionSource::kObserved;
      m.pixel_count[r] = 100;
    }
  }
  return day;
}

// Each sky region of `l`'s map above the horizon over the predicted sky's own mean there.
std::vector<double> OverModel(const Lighting& l, int band_above) {
  const EnvironmentMap model =
      EnvironmentMap::FromSky(EnvOptions{}, l.sky, Eigen::Vector3d::Zero());
  std::vector<double> out;
  const int first = (l.env.bands_below + band_above) * l.env.sectors;
  for (int r = first; r < first + l.env.sectors; ++r)
    out.push_back(l.env.radiance[r][1] / model.radiance[r][1]);
  return out;
}

TEST(RelightTest, TheSkysResidualFollowsTheSunOrStaysWhereItIs) {
  const UtcTime t = ParseIso8601("2026-08-25T16:00:00-07:00");
  const double az_new = Azimuth(ComputeSunPosition(t, kSite).DirectionEnu());
  // The horizon band brightens towards the sun by up to 10% and dims opposite it, as it did at
  // every measured time: the prediction carries the same pattern around the new sun. Linear
  // interpolation between 15-degree sector centres of a 0.1 amplitude cosine errs by at most
  // 0.1 (15 deg)^2 / 8 = 8.6e-4.
  {
    const auto towards_sun = [](double az, double az_sun, int band) {
      return band == 0 ? 1 + 0.1 * std::cos(az - az_sun) : 1.0;
    };
    LightingPredictor p(ObservedDay(towards_sun), RelightOptions{});
    ASSERT_EQ(p.residual_frames().size(), 18u);
    EXPECT_EQ(p.residual_frames()[9], ResidualFrame::kSun);
    for (int b = 10; b < 18; ++b) EXPECT_EQ(p.residual_frames()[b], ResidualFrame::kNone) << b;
    const Lighting l = p.At(t, kSite);
    const std::vector<double> ratio = OverModel(l, 0);
    for (int k = 0; k < 24; ++k) {
      const double az = (k + 0.5) * 2 * kPi / 24;
      EXPECT_NEAR(ratio[k], towards_sun(az, az_new, 0), 9e-4) << k;
    }
    for (double r : OverModel(l, 3)) EXPECT_NEAR(r, 1, 1e-12);
    // Without it: the model alone.
    RelightOptions off;
    off.sky_residual = false;
    for (double r : OverModel(LightingPredictor(ObservedDay(towards_sun), off).At(t, kSite), 0))
      EXPECT_NEAR(r, 1, 1e-12);
  }
  // A skyline three sectors wide, 12% darker than the sky at every time: it stays where it is.
  {
    const auto skyline = [](double az, double, int band) {
      return band == 0 && az > 3 * 2 * kPi / 24 && az < 6 * 2 * kPi / 24 ? 0.88 : 1.0;
    };
    LightingPredictor p(ObservedDay(skyline), RelightOptions{});
    EXPECT_EQ(p.residual_frames()[9], ResidualFrame::kFixed);
    const std::vector<double> ratio = OverModel(p.At(t, kSite), 0);
    for (int k = 0; k < 24; ++k) EXPECT_NEAR(ratio[k], k >= 3 && k < 6 ? 0.88 : 1.0, 1e-9) << k;
  }
}

// A sky region no panorama saw at any time: the measured maps filled it with their model's
// mean times its band's residual (EnvOptions::fill_band_residual), and the new time's takes the
// same ratio over its own model, not the model alone; fills of the model alone stay the model.
TEST(RelightTest, ASkyRegionNoPanoramaSawKeepsTheFillsRatio) {
  const UtcTime t = ParseIso8601("2026-08-25T16:00:00-07:00");
  const auto darker_horizon = [](double, double, int band) { return band == 0 ? 0.8 : 1.0; };
  for (const double fill : {0.8, 1.0}) {
    std::vector<Lighting> day = ObservedDay(darker_horizon);
    for (Lighting& l : day) {
      EnvironmentMap& m = l.env;
      const EnvironmentMap model =
          EnvironmentMap::FromSky(EnvOptions{}, l.sky, Eigen::Vector3d::Zero());
      for (int k = 8; k < 16; ++k) {  // the south of the lowest band, hidden at every time
        const int r = m.bands_below * m.sectors + k;
        m.radiance[r] = fill * model.radiance[r];
        m.source[r] = EnvRegionSource::kSkyModel;
        m.pixel_count[r] = 0;
      }
    }
    const std::vector<double> ratio =
        OverModel(LightingPredictor(day, RelightOptions{}).At(t, kSite), 0);
    for (int k = 8; k < 16; ++k) EXPECT_NEAR(ratio[k], fill, 1e-9) << fill << " sector " << k;
  }
}

TEST(RelightTest, RegionsTheResidualExplainsAreSky) {
  // A bright aureole on the horizon under each time's sun (up to 1.8x the model): the stereo's
  // comparison with the model alone takes the regions under the suns for landscape; the
  // residual carried from the other times explains them, so they are sky and follow the sun.
  const auto aureole = [](double az, double az_sun, int band) {
    return band == 0 ? 1 + 0.8 * std::pow(std::max(0.0, std::cos(az - az_sun)), 16) : 1.0;
  };
  RelightOptions o;
  LightingPredictor p(ObservedDay(aureole), o);
  EXPECT_GT(p.sky_regions_by_residual(), 0);
  for (size_t gi = 9 * 24; gi < 10 * 24; ++gi)
    EXPECT_EQ(p.environment().regions[gi].kind, EnvRegionKind::kSky) << gi;
  const UtcTime t = ParseIso8601("2026-08-25T16:00:00-07:00");
  const double az_new = Azimuth(ComputeSunPosition(t, kSite).DirectionEnu());
  const std::vector<double> ratio = OverModel(p.At(t, kSite), 0);
  // Regions average the peak over 15 degrees and the map is interpolated linearly between
  // sector centres: with f'' = -12.8 / rad^2 at the peak, h^2 / 8 |f''| = 0.11 and h^2 / 24
  // |f''| = 0.04 (h = 15 deg). Within 0.15 of it, and the sector nearest the new sun the
  // brightest.
  int brightest = 0;
  for (int k = 0; k < 24; ++k) {
    EXPECT_NEAR(ratio[k], aureole((k + 0.5) * 2 * kPi / 24, az_new, 0), 0.15) << k;
    if (ratio[k] > ratio[brightest]) brightest = k;
  }
  const double sector = 2 * kPi / 24;
  EXPECT_LE(std::abs(std::remainder((brightest + 0.5) * sector - az_new, 2 * kPi)), sector);
}

// Region gi of `stored` made a sky-only fallback that explains nothing (an albedo of 8, a 40%
// residual).
void MakeUnexplainedFallback(EnvStereoResult* stored, size_t gi) {
  EnvRegionFit& fit = stored->regions[gi];
  fit = EnvRegionFit();
  fit.kind = EnvRegionKind::kSkyOnly;
  fit.rho_sky = Eigen::Vector3d::Constant(8.0);
  fit.rel_rms = 0.4;
  ASSERT_FALSE(SkyOnlyExplains(fit, stored->options));
}

// A sky-only fallback is a surface lit by the sky alone, carried to the new sun by its normal.
// One that does not explain its region (an albedo of 8, a 40% residual: a region partly hidden
// by the building, a haze band) would carry a surface that is not there; the region takes its
// measured radiances instead, weighted as the sky's times are: it brightens with the sun's
// elevation (distant ground, haze), which those weights follow better than the direction's. One
// that explains its region (albedo 0.3, 2% residual) stays a surface.
TEST(RelightTest, ASkyOnlyFallbackThatExplainsNothingTakesItsMeasuredRadiances) {
  std::vector<Lighting> day = Day({0.1, 0.14, 0.2}, {1e4, 1e4, 1e4});
  const EnvironmentMap& m0 = day.front().env;
  const size_t gi = static_cast<size_t>((m0.bands_below - 1) * m0.sectors + 2);  // below
  for (size_t t = 0; t < day.size(); ++t) {
    day[t].env.radiance[gi] = Eigen::Vector3d(40, 50, 60) * (0.2 + ElevationOf(day[t].sun_dir));
    day[t].env.source[gi] = EnvRegionSource::kObserved;
  }
  const EnvStereoResult fresh = LightingPredictor(day, RelightOptions{}).environment();
  const UtcTime utc = ParseIso8601("2026-08-25T17:00:00-07:00");
  for (const bool explains : {false, true}) {
    EnvStereoResult stored = fresh;
    EnvRegionFit& fit = stored.regions[gi];
    fit = EnvRegionFit();
    fit.kind = EnvRegionKind::kSkyOnly;
    fit.normal = Eigen::Vector3d(0, -1, 0.2).normalized();
    fit.rho_sky = Eigen::Vector3d::Constant(explains ? 0.3 : 8.0);
    fit.rel_rms = explains ? 0.02 : 0.4;
    ASSERT_EQ(SkyOnlyExplains(fit, stored.options), explains);
    const LightingPredictor p(day, RelightOptions{}, &stored);
    RelightSummary rs;
    const Lighting l = p.At(utc, kSite, &rs);
    ASSERT_EQ(rs.sky_weights.size(), day.size());
    Eigen::Vector3d want = Eigen::Vector3d::Zero();
    double wsum = 0;
    for (size_t t = 0; t < day.size(); ++t) {
      want += rs.sky_weights[t] * day[t].env.radiance[gi];
      wsum += rs.sky_weights[t];
    }
    want /= wsum;
    if (explains) {
      // rho_sky E_sky / pi: a sky of Lz about 1 lights it with a few units, far below 40.
      EXPECT_LT(l.env.radiance[gi].maxCoeff(), 10) << l.env.radiance[gi].transpose();
    } else {
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(l.env.radiance[gi][c], want[c], 1e-9 * want[c]);
    }
  }
}

// Above the horizon such a region may be sky the model misses (a haze band): its measured
// radiances, taken relative to each time's fitted sky there and put back on the new time's,
// predict the measured times from each other better than the radiances do, so it dims with the
// sky towards a low sun instead of keeping the brightness of the higher suns it was measured
// under. A region whose radiance holds at every time (a skyline) keeps its radiance. (Both
// hold at every time, so the times' weights do not matter.)
TEST(RelightTest, ASkyOnlyFallbackAboveTheHorizonFollowsTheSkyWhereThatPredictsIt) {
  std::vector<Lighting> day = Day({0.1, 0.14, 0.2}, {1e4, 1e4, 1e4});
  const EnvironmentMap& m0 = day.front().env;
  const int r = m0.bands_below * m0.sectors + 2;  // the lowest band above the horizon
  const size_t gi = static_cast<size_t>(r);
  EnvOptions grid;
  grid.bands_below = m0.bands_below;
  grid.bands_above = m0.bands_above;
  grid.sectors = m0.sectors;
  const auto sky_mean = [&](const SkyModel& sky) {
    return EnvironmentMap::FromSky(grid, sky, Eigen::Vector3d::Zero()).radiance[gi];
  };
  std::vector<Eigen::Vector3d> fraction;  // of the fitted sky there, per time
  for (size_t t = 0; t < day.size(); ++t) {
    fraction.push_back(Eigen::Vector3d(0.5, 0.6, 0.7));
    day[t].env.radiance[gi] = fraction.back().cwiseProduct(sky_mean(day[t].sky));
    day[t].env.source[gi] = EnvRegionSource::kObserved;
  }
  const size_t skyline = gi + 5;
  const Eigen::Vector3d held(30, 40, 50);
  for (Lighting& l : day) {
    l.env.radiance[skyline] = held;
    l.env.source[skyline] = EnvRegionSource::kObserved;
  }
  RelightOptions options;
  options.sky_residual = false;  // the regions stay fallbacks (the residual could take them)
  EnvStereoResult stored = LightingPredictor(day, options).environment();
  for (const size_t g : {gi, skyline}) ASSERT_NO_FATAL_FAILURE(MakeUnexplainedFallback(&stored, g));
  const LightingPredictor p(day, options, &stored);
  // After sunset's last measured time (the sky dimmed by extinction) and in the afternoon.
  for (const char* local : {"2026-08-25T19:30:00-07:00", "2026-08-25T15:00:00-07:00"}) {
    RelightSummary rs;
    const Lighting l = p.At(ParseIso8601(local), kSite, &rs);
    ASSERT_EQ(rs.sky_weights.size(), day.size());
    Eigen::Vector3d want = Eigen::Vector3d::Zero(), mean = Eigen::Vector3d::Zero();
    double wsum = 0;
    for (size_t t = 0; t < day.size(); ++t) {
      want += rs.sky_weights[t] * fraction[t];
      mean += rs.sky_weights[t] * day[t].env.radiance[gi];
      wsum += rs.sky_weights[t];
    }
    want = (want / wsum).cwiseProduct(sky_mean(l.sky));
    mean /= wsum;
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(l.env.radiance[gi][c], want[c], 1e-9 * want[c]) << local;
    if (rs.extinction_from_air_mass > 0) {  // the measured times' mean is brighter than the sky now
      EXPECT_GT(mean.minCoeff() / l.env.radiance[gi].minCoeff(), 1.1) << local;
    }
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(l.env.radiance[skyline][c], held[c], 1e-9 * held[c]);
  }
}

// A region the stereo could not explain that is bright only when the sun faces it (a west
// facade among the trees): weighting the times by the sun's elevation would mix the morning's
// dark with the evening's bright; the times weighted by the angular distance between suns (§5.1
// as written) predict each measured time from the others better, and the new time takes them.
TEST(RelightTest, AFallbackLitWhenTheSunFacesItFollowsTheSunsDirection) {
  std::vector<Lighting> day = Day({0.1, 0.14, 0.2}, {1e4, 1e4, 1e4});
  const EnvironmentMap& m0 = day.front().env;
  const size_t gi = static_cast<size_t>((m0.bands_below - 1) * m0.sectors + 2);  // below
  const Eigen::Vector3d west(-1, 0, 0);
  const auto facade = [&](const Eigen::Vector3d& sun) -> Eigen::Vector3d {
    return Eigen::Vector3d(4, 5, 6) + Eigen::Vector3d(60, 50, 40) * std::max(0.0, west.dot(sun));
  };
  for (Lighting& l : day) {
    l.env.radiance[gi] = facade(l.sun_dir);
    l.env.source[gi] = EnvRegionSource::kObserved;
  }
  EnvStereoResult stored = LightingPredictor(day, RelightOptions{}).environment();
  ASSERT_NO_FATAL_FAILURE(MakeUnexplainedFallback(&stored, gi));
  const LightingPredictor p(day, RelightOptions{}, &stored);
  RelightSummary rs;
  const Lighting l = p.At(ParseIso8601("2026-08-25T16:30:00-07:00"), kSite, &rs);
  SkyInterpOptions angular;
  angular.mode = SkyInterpMode::kAngularDistance;
  const std::vector<double> w = SkyInterpWeights(TimedSkiesOf(day), l.sun_dir, angular);
  Eigen::Vector3d want = Eigen::Vector3d::Zero(), by_elevation = Eigen::Vector3d::Zero();
  for (size_t t = 0; t < day.size(); ++t) {
    want += w[t] * day[t].env.radiance[gi];
    by_elevation += rs.sky_weights[t] * day[t].env.radiance[gi];
  }
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(l.env.radiance[gi][c], want[c], 1e-9 * want[c]);
  // Nearer the facade's brightness under this sun than the elevation's weights come.
  const Eigen::Vector3d truth = facade(l.sun_dir);
  EXPECT_LT((want - truth).norm(), 0.5 * (by_elevation - truth).norm())
      << want.transpose() << " | " << by_elevation.transpose() << " | " << truth.transpose();
}

TEST(RelightTest, RefusesNightAndNoData) {
  LightingPredictor predictor(Day({0.1, 0.1, 0.1}, {1e4, 1e4, 1e4}), RelightOptions{});
  try {
    predictor.At(ParseIso8601("2026-08-25T23:00:00-07:00"), kSite);
    FAIL() << "no error at night";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("below the horizon"), std::string::npos) << e.what();
  }
  EXPECT_THROW(LightingPredictor({}, RelightOptions{}), Error);
}

}  // namespace
}  // namespace rouen
