#include "solve/environment.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include "core/error.h"

namespace rouen {

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Accum {
  std::vector<Eigen::Vector3d> sum;  // solid-angle weighted radiance
  std::vector<double> weight;
  std::vector<int> count;
  int used = 0, model = 0, sun = 0, invalid = 0;
  explicit Accum(int n) : sum(n, Eigen::Vector3d::Zero()), weight(n, 0), count(n, 0) {}
  void Add(const Accum& o) {
    for (size_t i = 0; i < sum.size(); ++i) {
      sum[i] += o.sum[i];
      weight[i] += o.weight[i];
      count[i] += o.count[i];
    }
    used += o.used;
    model += o.model;
    sun += o.sun;
    invalid += o.invalid;
  }
};

Eigen::Vector3d SkyMean(const SkyModel& sky, const EnvironmentMap& m, int region, int samples) {
  double el_lo, el_hi, az_lo, az_hi;
  m.RegionBounds(region, &el_lo, &el_hi, &az_lo, &az_hi);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (int a = 0; a < samples; ++a) {
    const double el = el_lo + (a + 0.5) / samples * (el_hi - el_lo);
    const double w = std::cos(el);
    for (int b = 0; b < samples; ++b) {
      const double az = az_lo + (b + 0.5) / samples * (az_hi - az_lo);
      const Eigen::Vector3d d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az),
                              std::sin(el));
      sum += w * sky.Radiance(d);
      wsum += w;
    }
  }
  return sum / wsum;
}

void InitMap(const EnvOptions& o, EnvironmentMap* m) {
  m->bands_below = o.bands_below;
  m->bands_above = o.bands_above;
  m->sectors = o.sectors;
  m->radiance.assign(m->num_regions(), Eigen::Vector3d::Zero());
  m->pixel_count.assign(m->num_regions(), 0);
  m->source.assign(m->num_regions(), EnvRegionSource::kConstant);
}

}  // namespace

void EnvOptions::Validate() const {
  if (bands_below < 1 || bands_above < 1 || sectors < 1 || bands_below > 180 ||
      bands_above > 180 || sectors > 720) {
    throw Error("EnvOptions: bands_below, bands_above must be in 1..180 and sectors in 1..720");
  }
  if (!(sun_exclusion_deg >= 0 && sun_exclusion_deg < 90)) {
    throw Error("EnvOptions: sun_exclusion_deg must be in [0, 90)");
  }
  if (pixel_stride < 1) throw Error("EnvOptions: pixel_stride must be >= 1");
  if (sky_fill_samples < 1) throw Error("EnvOptions: sky_fill_samples must be >= 1");
}

int EnvironmentMap::Region(const Eigen::Vector3d& d) const {
  const double horiz = std::hypot(d.x(), d.y());
  const double el = std::atan2(d.z(), horiz);
  double az = std::atan2(d.x(), d.y());
  if (az < 0) az += 2 * kPi;
  int band;
  if (el < 0) {
    band = static_cast<int>(std::floor((el + kPi / 2) / (kPi / 2) * bands_below));
    band = std::clamp(band, 0, bands_below - 1);
  } else {
    band = bands_below + std::clamp(static_cast<int>(std::floor(el / (kPi / 2) * bands_above)),
                                    0, bands_above - 1);
  }
  const int sector =
      std::clamp(static_cast<int>(std::floor(az / (2 * kPi) * sectors)), 0, sectors - 1);
  return band * sectors + sector;
}

void EnvironmentMap::RegionBounds(int region, double* el_lo, double* el_hi, double* az_lo,
                                  double* az_hi) const {
  const int band = region / sectors, sector = region % sectors;
  if (band < bands_below) {
    *el_lo = -kPi / 2 + band * (kPi / 2) / bands_below;
    *el_hi = -kPi / 2 + (band + 1) * (kPi / 2) / bands_below;
  } else {
    *el_lo = (band - bands_below) * (kPi / 2) / bands_above;
    *el_hi = (band - bands_below + 1) * (kPi / 2) / bands_above;
  }
  *az_lo = sector * 2 * kPi / sectors;
  *az_hi = (sector + 1) * 2 * kPi / sectors;
}

double EnvironmentMap::ObservedFraction() const {
  if (source.empty()) return 0;
  int n = 0;
  for (auto s : source) n += s == EnvRegionSource::kObserved;
  return static_cast<double>(n) / source.size();
}

void EnvironmentMap::Validate() const {
  if (bands_below < 1 || bands_above < 1 || sectors < 1) {
    throw Error("environment map: bands and sectors must be >= 1");
  }
  const size_t n = static_cast<size_t>(num_regions());
  if (radiance.size() != n || pixel_count.size() != n || source.size() != n) {
    throw Error("environment map: expected " + std::to_string(n) + " regions, got " +
                std::to_string(radiance.size()));
  }
  for (size_t i = 0; i < n; ++i) {
    if (!radiance[i].allFinite() || radiance[i].minCoeff() < 0) {
      throw Error("environment map: region " + std::to_string(i) +
                  " has a negative or non-finite radiance");
    }
  }
}

EnvironmentMap EnvironmentMap::Constant(const EnvOptions& options, const Eigen::Vector3d& above,
                                        const Eigen::Vector3d& below) {
  options.Validate();
  EnvironmentMap m;
  InitMap(options, &m);
  for (int r = 0; r < m.num_regions(); ++r) {
    m.radiance[r] = r / m.sectors < m.bands_below ? below : above;
  }
  return m;
}

EnvironmentMap EnvironmentMap::FromSky(const EnvOptions& options, const SkyModel& sky,
                                       const Eigen::Vector3d& ground) {
  EnvironmentMap m = Constant(options, Eigen::Vector3d::Zero(), ground);
  for (int r = m.bands_below * m.sectors; r < m.num_regions(); ++r) {
    m.radiance[r] = SkyMean(sky, m, r, options.sky_fill_samples);
    m.source[r] = EnvRegionSource::kSkyModel;
  }
  return m;
}

void to_json(nlohmann::json& j, const EnvironmentMap& m) {
  nlohmann::json rad = nlohmann::json::array();
  nlohmann::json cnt = nlohmann::json::array();
  nlohmann::json src = nlohmann::json::array();
  for (int r = 0; r < m.num_regions(); ++r) {
    rad.push_back({m.radiance[r].x(), m.radiance[r].y(), m.radiance[r].z()});
    cnt.push_back(m.pixel_count[r]);
    src.push_back(static_cast<int>(m.source[r]));
  }
  j = nlohmann::json{{"bands_below", m.bands_below}, {"bands_above", m.bands_above},
                     {"sectors", m.sectors},         {"radiance", rad},
                     {"pixel_count", cnt},           {"source", src}};
}

void from_json(const nlohmann::json& j, EnvironmentMap& m) {
  try {
    m = EnvironmentMap();
    m.bands_below = j.at("bands_below").get<int>();
    m.bands_above = j.at("bands_above").get<int>();
    m.sectors = j.at("sectors").get<int>();
    for (const auto& r : j.at("radiance")) {
      if (r.size() != 3) throw Error("environment map: a radiance is not 3 numbers");
      m.radiance.emplace_back(r[0].get<double>(), r[1].get<double>(), r[2].get<double>());
    }
    m.pixel_count = j.at("pixel_count").get<std::vector<int>>();
    for (const auto& s : j.at("source")) {
      const int v = s.get<int>();
      if (v < 0 || v > 3) throw Error("environment map: unknown region source " + std::to_string(v));
      m.source.push_back(static_cast<EnvRegionSource>(v));
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("environment map: ") + e.what());
  }
  m.Validate();
}

// §3.3: average the panorama's pixels over coarse lat-long regions.
EnvironmentMap BuildEnvironmentMap(const Image& pano, const Intrinsics& intrinsics,
                                   const Pose& pose, const RayCaster& model,
                                   const Eigen::Vector3d& sun_dir, double sun_angular_radius_rad,
                                   const SkyModel& sky, const EnvOptions& options,
                                   EnvSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  intrinsics.Validate();
  if (pano.empty() || pano.channels < 3) {
    throw Error("environment map: the panorama is empty or has fewer than 3 channels");
  }
  if (pano.width != intrinsics.width || pano.height != intrinsics.height) {
    throw Error("environment map: panorama is " + std::to_string(pano.width) + "x" +
                std::to_string(pano.height) + " but its intrinsics say " +
                std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height));
  }
  if (pano.units != PixelUnits::kRadiance) {
    throw Error("environment map: the panorama must hold radiance (HDR), not digital numbers");
  }
  if (!sun_dir.allFinite() || sun_dir.norm() < 0.5) {
    throw Error("environment map: sun direction is not a unit vector");
  }
  EnvironmentMap m;
  InitMap(options, &m);
  const int nreg = m.num_regions();
  const Eigen::Vector3d sun = sun_dir.normalized();
  const double cos_excl =
      std::cos(std::max(options.sun_exclusion_deg * kPi / 180.0, sun_angular_radius_rad));
  const double offset = model.surface_offset();
  const int stride = options.pixel_stride;

  // Fixed chunks of rows, summed in order: deterministic for any thread count.
  const int rows = (pano.height + stride - 1) / stride;
  const int chunk_rows = 8;
  const int nchunks = (rows + chunk_rows - 1) / chunk_rows;
  std::vector<Accum> chunks(nchunks, Accum(0));
  tbb::parallel_for(0, nchunks, [&](int c) {
    Accum acc(nreg);
    for (int r = c * chunk_rows; r < std::min(rows, (c + 1) * chunk_rows); ++r) {
      const int y = r * stride;
      for (int x = 0; x < pano.width; x += stride) {
        const Eigen::Vector2d px(x + 0.5, y + 0.5);
        bool finite = true;
        Eigen::Vector3d rad;
        for (int k = 0; k < 3; ++k) {
          rad[k] = pano.at(x, y, k);
          finite = finite && std::isfinite(rad[k]) && rad[k] >= 0;
        }
        if (!finite) {
          ++acc.invalid;
          continue;
        }
        const Eigen::Vector3d d = (pose.rotation * Unproject(intrinsics, px)).normalized();
        if (!d.allFinite()) {
          ++acc.invalid;
          continue;
        }
        if (d.dot(sun) > cos_excl) {
          ++acc.sun;
          continue;
        }
        if (model.Occluded(pose.position, d, offset)) {
          ++acc.model;
          continue;
        }
        // Solid angle of the pixel from the unprojected footprint (any projection).
        const Eigen::Vector3d dx = Unproject(intrinsics, px + Eigen::Vector2d(0.5 * stride, 0)) -
                                   Unproject(intrinsics, px - Eigen::Vector2d(0.5 * stride, 0));
        const Eigen::Vector3d dy = Unproject(intrinsics, px + Eigen::Vector2d(0, 0.5 * stride)) -
                                   Unproject(intrinsics, px - Eigen::Vector2d(0, 0.5 * stride));
        double w = dx.cross(dy).norm();
        if (!std::isfinite(w) || w <= 0) w = 1e-12;
        const int region = m.Region(d);
        acc.sum[region] += w * rad;
        acc.weight[region] += w;
        acc.count[region] += 1;
        ++acc.used;
      }
    }
    chunks[c] = std::move(acc);
  });
  Accum total(nreg);
  for (const Accum& a : chunks) total.Add(a);

  EnvSummary s;
  s.pixels_used = total.used;
  s.pixels_model = total.model;
  s.pixels_sun = total.sun;
  s.pixels_invalid = total.invalid;
  for (int r = 0; r < nreg; ++r) {
    if (total.count[r] > 0 && total.weight[r] > 0) {
      m.radiance[r] = total.sum[r] / total.weight[r];
      m.pixel_count[r] = total.count[r];
      m.source[r] = EnvRegionSource::kObserved;
      ++s.regions_observed;
    }
  }
  // Above the horizon: the sky model's mean over unobserved regions.
  for (int r = m.bands_below * m.sectors; r < nreg; ++r) {
    if (m.source[r] == EnvRegionSource::kObserved) continue;
    m.radiance[r] = SkyMean(sky, m, r, options.sky_fill_samples);
    m.source[r] = EnvRegionSource::kSkyModel;
    ++s.regions_sky;
  }
  // Below: nearest observed sector in the same band (ties averaged) ...
  const int S = m.sectors;
  std::vector<bool> band_has(m.bands_below, false);
  for (int b = 0; b < m.bands_below; ++b) {
    for (int k = 0; k < S; ++k) band_has[b] = band_has[b] || total.count[b * S + k] > 0;
  }
  for (int b = 0; b < m.bands_below; ++b) {
    if (!band_has[b]) continue;
    for (int k = 0; k < S; ++k) {
      const int r = b * S + k;
      if (m.source[r] == EnvRegionSource::kObserved) continue;
      for (int dist = 1; dist <= S / 2; ++dist) {
        const int r1 = b * S + (k + dist) % S, r2 = b * S + (k - dist + S) % S;
        const bool o1 = m.source[r1] == EnvRegionSource::kObserved;
        const bool o2 = m.source[r2] == EnvRegionSource::kObserved;
        if (!o1 && !o2) continue;
        m.radiance[r] = o1 && o2 ? 0.5 * (m.radiance[r1] + m.radiance[r2])
                                 : (o1 ? m.radiance[r1] : m.radiance[r2]);
        break;
      }
      m.source[r] = EnvRegionSource::kNeighbour;
      ++s.regions_neighbour;
    }
  }
  // ... and for bands without any observation, the nearest band that has some (the band
  // towards the horizon first), sector by sector.
  for (int b = m.bands_below - 1; b >= 0; --b) {
    if (band_has[b]) continue;
    int from = -1;
    for (int dist = 1; dist < m.bands_below && from < 0; ++dist) {
      if (b + dist < m.bands_below && band_has[b + dist]) from = b + dist;
      else if (b - dist >= 0 && band_has[b - dist]) from = b - dist;
    }
    for (int k = 0; k < S; ++k) {
      const int r = b * S + k;
      if (from >= 0) {
        m.radiance[r] = m.radiance[from * S + k];
        m.source[r] = EnvRegionSource::kNeighbour;
        ++s.regions_neighbour;
      } else {
        m.radiance[r] = Eigen::Vector3d::Zero();  // nothing below the horizon was observed
        m.source[r] = EnvRegionSource::kConstant;
      }
    }
  }
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (summary) *summary = s;
  m.Validate();
  return m;
}

}  // namespace rouen
