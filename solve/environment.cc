#include "solve/environment.h"

#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/json_text.h"
#include "core/stats.h"
#include "solve/retro.h"

namespace rouen {

namespace {

// A panorama pixel kept for the map: direction from the panorama, solid angle, radiance.
struct UsedPixel {
  Eigen::Vector3d dir;
  double weight;  // solid angle, sr
  Eigen::Vector3d radiance;
  bool ground_shadow;  // its ray meets the ground in the model's shadow
};

struct Chunk {
  std::vector<UsedPixel> pixels;
  int model = 0, sun = 0, invalid = 0, ground_shadow = 0;
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

// Elevation in [-pi/2, pi/2] and azimuth in [0, 2 pi) (from north eastward) of `d` (need not
// be unit), as the map's regions and detail cells take them.
void ElevationAzimuth(const Eigen::Vector3d& d, double* el, double* az) {
  *el = std::atan2(d.z(), std::hypot(d.x(), d.y()));
  *az = std::atan2(d.x(), d.y());
  if (*az < 0) *az += 2 * kPi;
}

void InitMap(const EnvOptions& o, int layers, EnvironmentMap* m) {
  m->bands_below = o.bands_below;
  m->bands_above = o.bands_above;
  m->sectors = o.sectors;
  m->detail = o.sky_detail;
  m->sun_exclusion_rad = o.sun_exclusion_deg * kDeg;
  m->layer_z.assign(layers, 0.0);
  const size_t n = static_cast<size_t>(m->num_regions()) * layers;
  m->radiance.assign(n, Eigen::Vector3d::Zero());
  m->pixel_count.assign(n, 0);
  m->source.assign(n, EnvRegionSource::kConstant);
}

// Fills the unobserved regions of one layer (starting at `base`): sky model above the
// horizon, times its band's residual with `band_residual` (EnvOptions::fill_band_residual);
// below, as FillBelowHorizon.
void FillLayer(const SkyModel& sky, int sky_samples, bool band_residual, int base,
               EnvironmentMap* m) {
  const int S = m->sectors, nreg = m->num_regions();
  for (int band = m->bands_below; band < m->bands_below + m->bands_above; ++band) {
    Eigen::Vector3d scale = Eigen::Vector3d::Ones();
    std::vector<double> ratio[3];
    for (int s = 0; s < S && band_residual; ++s) {
      const int r = band * S + s;
      if (m->source[base + r] != EnvRegionSource::kObserved) continue;
      const Eigen::Vector3d model = SkyMean(sky, *m, r, sky_samples);
      if (!(model.minCoeff() > 0)) continue;
      for (int c = 0; c < 3; ++c) ratio[c].push_back(m->radiance[base + r][c] / model[c]);
    }
    if (band_residual && 4 * static_cast<int>(ratio[0].size()) >= S) {
      for (int c = 0; c < 3; ++c) scale[c] = Median(std::move(ratio[c]));
    }
    for (int s = 0; s < S; ++s) {
      const int r = band * S + s;
      if (m->source[base + r] == EnvRegionSource::kObserved) continue;
      m->radiance[base + r] = SkyMean(sky, *m, r, sky_samples).cwiseProduct(scale);
      m->source[base + r] = EnvRegionSource::kSkyModel;
    }
  }
  FillBelowHorizon(m, base / nreg);
}

}  // namespace

void ZeroBelowHorizon(EnvironmentMap* m) {
  const int below = m->bands_below * m->sectors;
  for (int k = 0; k < m->num_layers(); ++k)
    for (int r = 0; r < below; ++r)
      m->radiance[static_cast<size_t>(k) * m->num_regions() + r] = Eigen::Vector3d::Zero();
}

void FillBelowHorizon(EnvironmentMap* m, int layer) {
  const int S = m->sectors, nreg = m->num_regions();
  const size_t base = static_cast<size_t>(layer) * nreg;
  if (layer < 0 || m->radiance.size() < base + nreg || m->source.size() < base + nreg)
    throw Error("environment map: no layer " + std::to_string(layer) + " to fill");
  auto observed = [&](int r) { return m->source[base + r] == EnvRegionSource::kObserved; };
  std::vector<bool> band_has(m->bands_below, false);
  for (int b = 0; b < m->bands_below; ++b) {
    for (int k = 0; k < S; ++k) band_has[b] = band_has[b] || observed(b * S + k);
  }
  for (int b = 0; b < m->bands_below; ++b) {
    if (!band_has[b]) continue;
    for (int k = 0; k < S; ++k) {
      const int r = b * S + k;
      if (observed(r)) continue;
      for (int dist = 1; dist <= S / 2; ++dist) {
        const int r1 = b * S + (k + dist) % S, r2 = b * S + (k - dist + S) % S;
        const bool o1 = observed(r1), o2 = observed(r2);
        if (!o1 && !o2) continue;
        m->radiance[base + r] = o1 && o2 ? 0.5 * (m->radiance[base + r1] + m->radiance[base + r2])
                                         : (o1 ? m->radiance[base + r1] : m->radiance[base + r2]);
        break;
      }
      m->source[base + r] = EnvRegionSource::kNeighbour;
    }
  }
  for (int b = m->bands_below - 1; b >= 0; --b) {
    if (band_has[b]) continue;
    int from = -1;
    for (int dist = 1; dist < m->bands_below && from < 0; ++dist) {
      if (b + dist < m->bands_below && band_has[b + dist]) {
        from = b + dist;
      } else if (b - dist >= 0 && band_has[b - dist]) {
        from = b - dist;
      }
    }
    for (int k = 0; k < S; ++k) {
      const int r = b * S + k;
      if (from >= 0) {
        m->radiance[base + r] = m->radiance[base + from * S + k];
        m->source[base + r] = EnvRegionSource::kNeighbour;
      } else {
        m->radiance[base + r] = Eigen::Vector3d::Zero();  // nothing below the horizon seen
        m->source[base + r] = EnvRegionSource::kConstant;
      }
    }
  }
}

void EnvOptions::Validate() const {
  if (bands_below < 1 || bands_above < 1 || sectors < 1 || bands_below > 180 || bands_above > 180 ||
      sectors > 720) {
    throw Error("EnvOptions: bands_below, bands_above must be in 1..180 and sectors in 1..720");
  }
  if (!(sun_exclusion_deg >= 0 && sun_exclusion_deg < 90)) {
    throw Error("EnvOptions: sun_exclusion_deg must be in [0, 90)");
  }
  if (pixel_stride < 1) throw Error("EnvOptions: pixel_stride must be >= 1");
  if (min_region_pixels < 1) throw Error("EnvOptions: min_region_pixels must be >= 1");
  if (sky_fill_samples < 1) throw Error("EnvOptions: sky_fill_samples must be >= 1");
  if (!(layer_merge_m > 0)) throw Error("EnvOptions: layer_merge_m must be > 0 (metres)");
  if (sky_detail < 1 || sky_detail > 64) throw Error("EnvOptions: sky_detail must be in 1..64");
  if (int64_t{bands_above} * sectors * sky_detail * sky_detail > kMaxDetailCells)
    throw Error("EnvOptions: more than " + std::to_string(kMaxDetailCells) +
                " sky detail cells (bands_above x sectors x sky_detail^2)");
}

int EnvironmentMap::Region(const Eigen::Vector3d& d) const {
  double el, az;
  ElevationAzimuth(d, &el, &az);
  int band;
  if (el < 0) {
    band = static_cast<int>(std::floor((el + kPi / 2) / (kPi / 2) * bands_below));
    band = std::clamp(band, 0, bands_below - 1);
  } else {
    band = bands_below + std::clamp(static_cast<int>(std::floor(el / (kPi / 2) * bands_above)), 0,
                                    bands_above - 1);
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

int EnvironmentMap::DetailCell(const Eigen::Vector3d& d) const {
  double el, az;
  ElevationAzimuth(d, &el, &az);
  if (!(el >= 0)) return -1;
  const int rows = bands_above * detail, cols = sectors * detail;
  const int row = std::clamp(static_cast<int>(std::floor(el / (kPi / 2) * rows)), 0, rows - 1);
  const int col = std::clamp(static_cast<int>(std::floor(az / (2 * kPi) * cols)), 0, cols - 1);
  return row * cols + col;
}

void EnvironmentMap::CellBounds(int cell, double* el_lo, double* el_hi, double* az_lo,
                                double* az_hi) const {
  const int rows = bands_above * detail, cols = sectors * detail;
  const int row = cell / cols, col = cell % cols;
  *el_lo = row * (kPi / 2) / rows;
  *el_hi = (row + 1) * (kPi / 2) / rows;
  *az_lo = col * 2 * kPi / cols;
  *az_hi = (col + 1) * 2 * kPi / cols;
}

Eigen::Vector3d EnvironmentMap::RegionRadiance(int r, double z) const {
  const int L = num_layers();
  if (L == 1 || z <= layer_z.front()) return radiance[r];
  const int nreg = num_regions();
  if (z >= layer_z.back()) return radiance[static_cast<size_t>(L - 1) * nreg + r];
  int k = 0;
  while (k + 2 < L && z > layer_z[k + 1]) ++k;
  const double a = (z - layer_z[k]) / (layer_z[k + 1] - layer_z[k]);
  return (1 - a) * radiance[static_cast<size_t>(k) * nreg + r] +
         a * radiance[static_cast<size_t>(k + 1) * nreg + r];
}

double EnvironmentMap::ObservedFraction() const {
  if (source.empty()) return 0;
  int n = 0;
  for (int r = 0; r < num_regions(); ++r) n += source[r] == EnvRegionSource::kObserved;
  return static_cast<double>(n) / num_regions();
}

Eigen::Vector3d EnvironmentMap::HorizontalSkyIrradiance() const {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  for (int r = bands_below * sectors; r < num_regions(); ++r) {
    double el0, el1, az0, az1;
    RegionBounds(r, &el0, &el1, &az0, &az1);
    const double s0 = std::sin(el0), s1 = std::sin(el1);
    e += radiance[r] * (az1 - az0) * (s1 * s1 - s0 * s0) / 2;  // projected solid angle
  }
  return e;
}

void EnvironmentMap::Validate() const {
  if (bands_below < 1 || bands_above < 1 || sectors < 1) {
    throw Error("environment map: bands and sectors must be >= 1");
  }
  if (layer_z.empty()) throw Error("environment map: no layers");
  if (!(ground_retro >= kRetroMin && ground_retro <= kRetroMax)) {
    throw Error("environment map: ground_retro must be within [" + std::to_string(kRetroMin) +
                ", " + std::to_string(kRetroMax) + "]");
  }
  for (size_t k = 0; k < layer_z.size(); ++k) {
    if (!std::isfinite(layer_z[k]) || (k > 0 && !(layer_z[k] > layer_z[k - 1]))) {
      throw Error("environment map: layer heights must be finite and increasing");
    }
  }
  const size_t n = static_cast<size_t>(num_regions()) * layer_z.size();
  if (radiance.size() != n || pixel_count.size() != n || source.size() != n) {
    throw Error("environment map: expected " + std::to_string(n) + " region values, got " +
                std::to_string(radiance.size()));
  }
  for (size_t i = 0; i < n; ++i) {
    if (!radiance[i].allFinite() || radiance[i].minCoeff() < 0) {
      throw Error("environment map: region " + std::to_string(i) +
                  " has a negative or non-finite radiance");
    }
  }
  if (detail < 1 || detail > 64) throw Error("environment map: detail must be in 1..64");
  if (int64_t{bands_above} * sectors * detail * detail > kMaxDetailCells)
    throw Error("environment map: more than " + std::to_string(kMaxDetailCells) +
                " sky detail cells (bands_above x sectors x detail^2)");
  if (!sky_detail.empty() && sky_detail.size() != static_cast<size_t>(num_detail_cells())) {
    throw Error("environment map: expected " + std::to_string(num_detail_cells()) +
                " sky detail cells, got " + std::to_string(sky_detail.size()));
  }
  for (size_t i = 0; i < sky_detail.size(); ++i) {
    if (!sky_detail[i].allFinite() || !(sky_detail[i].minCoeff() > 0)) {
      throw Error("environment map: sky detail cell " + std::to_string(i) +
                  " is not a positive finite number");
    }
  }
  if (!(sun_exclusion_rad >= 0 && sun_exclusion_rad < kPi / 2)) {
    throw Error("environment map: sun_exclusion_rad must be in [0, pi/2)");
  }
}

EnvironmentMap EnvironmentMap::Constant(const EnvOptions& options, const Eigen::Vector3d& above,
                                        const Eigen::Vector3d& below) {
  options.Validate();
  EnvironmentMap m;
  InitMap(options, 1, &m);
  m.detail = 1;  // uniform: no shape
  for (int r = 0; r < m.num_regions(); ++r) {
    m.radiance[r] = r / m.sectors < m.bands_below ? below : above;
  }
  return m;
}

EnvironmentMap EnvironmentMap::FromSky(const EnvOptions& options, const SkyModel& sky,
                                       const Eigen::Vector3d& ground) {
  EnvironmentMap m = Constant(options, Eigen::Vector3d::Zero(), ground);
  m.detail = options.sky_detail;  // spread as the model is
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
  for (size_t r = 0; r < m.radiance.size(); ++r) {
    rad.push_back({m.radiance[r].x(), m.radiance[r].y(), m.radiance[r].z()});
    cnt.push_back(m.pixel_count[r]);
    src.push_back(static_cast<int>(m.source[r]));
  }
  j = nlohmann::json{{"bands_below", m.bands_below},
                     {"bands_above", m.bands_above},
                     {"sectors", m.sectors},
                     {"layer_z", m.layer_z},
                     {"radiance", rad},
                     {"pixel_count", cnt},
                     {"source", src},
                     {"ground_retro", m.ground_retro},
                     {"detail", m.detail},
                     {"sun_exclusion_rad", m.sun_exclusion_rad}};
  if (!m.sky_detail.empty()) {
    nlohmann::json cells = nlohmann::json::array();
    // Kept to 1e-4 (as BuildEnvironmentMap quantises it: the same floats read back).
    for (const Eigen::Vector3f& c : m.sky_detail) {
      for (int k = 0; k < 3; ++k)
        cells.push_back(std::round(static_cast<double>(c[k]) * 1e4) / 1e4);
    }
    j["sky_detail"] = std::move(cells);
  }
}

void from_json(const nlohmann::json& j, EnvironmentMap& m) {
  try {
    m = EnvironmentMap();
    m.bands_below = JsonGet<int>(j.at("bands_below"), "bands_below");
    m.bands_above = JsonGet<int>(j.at("bands_above"), "bands_above");
    m.sectors = JsonGet<int>(j.at("sectors"), "sectors");
    if (j.contains("layer_z")) m.layer_z = j.at("layer_z").get<std::vector<double>>();
    m.ground_retro = j.value("ground_retro", 0.0);
    m.detail = j.contains("detail") ? JsonGet<int>(j.at("detail"), "detail") : 1;
    m.sun_exclusion_rad = j.value("sun_exclusion_rad", m.sun_exclusion_rad);
    if (j.contains("sky_detail")) {
      const auto& cells = j.at("sky_detail");
      if (!cells.is_array() || cells.size() % 3 != 0)
        throw Error("environment map: sky_detail is not a list of RGB triples");
      for (size_t k = 0; k < cells.size(); k += 3) {
        m.sky_detail.emplace_back(JsonGet<float>(cells[k], "sky_detail"),
                                  JsonGet<float>(cells[k + 1], "sky_detail"),
                                  JsonGet<float>(cells[k + 2], "sky_detail"));
      }
    }
    for (const auto& r : j.at("radiance")) {
      if (r.size() != 3) throw Error("environment map: a radiance is not 3 numbers");
      m.radiance.emplace_back(r[0].get<double>(), r[1].get<double>(), r[2].get<double>());
    }
    m.pixel_count = JsonGet<std::vector<int>>(j.at("pixel_count"), "pixel_count");
    for (const auto& s : j.at("source")) {
      const int v = static_cast<int>(JsonInteger(s, 0, 3, "environment map: region source"));
      m.source.push_back(static_cast<EnvRegionSource>(v));
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("environment map: ") + e.what());
  }
  m.Validate();
}

namespace {

void CheckPanorama(const EnvPanorama& p, int index) {
  const std::string what = "environment map: panorama " + std::to_string(index);
  if (!p.radiance) throw Error(what + " has no image");
  const Image& pano = *p.radiance;
  p.intrinsics.Validate();
  if (pano.empty() || pano.channels < 3) {
    throw Error(what + " is empty or has fewer than 3 channels");
  }
  if (pano.width != p.intrinsics.width || pano.height != p.intrinsics.height) {
    throw Error(what + " is " + std::to_string(pano.width) + "x" + std::to_string(pano.height) +
                " but its intrinsics say " + std::to_string(p.intrinsics.width) + "x" +
                std::to_string(p.intrinsics.height));
  }
  if (pano.units != PixelUnits::kRadiance) {
    throw Error(what + " must hold radiance (HDR), not digital numbers");
  }
  if (!p.pose.position.allFinite() || !p.pose.rotation.allFinite()) {
    throw Error(what + " has a non-finite pose");
  }
}

// The panorama's usable pixels (fixed chunks of rows, concatenated in order: deterministic); a
// sky photo's (EnvPanorama::sky_only) above the horizon only. With `ground_shadow`, each pixel
// whose ray meets the ground at `ground_z` is marked when the model shades that ground from the
// sun.
void CollectPixels(const EnvPanorama& p, const RayCaster& model, const Eigen::Vector3d& sun,
                   double cos_excl, int stride, bool ground_shadow, double ground_z,
                   std::vector<UsedPixel>* used, EnvSummary* s) {
  const Image& pano = *p.radiance;
  const Intrinsics& intrinsics = p.intrinsics;
  const Eigen::Vector3d c = p.pose.position;
  const double offset = model.surface_offset();
  ground_shadow = ground_shadow && c.z() > ground_z;  // (the caller checks the sun is up)
  const int rows = (pano.height + stride - 1) / stride;
  const int chunk_rows = 8;
  const int nchunks = (rows + chunk_rows - 1) / chunk_rows;
  std::vector<Chunk> chunks(nchunks);
  tbb::parallel_for(0, nchunks, [&](int ci) {
    Chunk& ch = chunks[ci];
    for (int r = ci * chunk_rows; r < std::min(rows, (ci + 1) * chunk_rows); ++r) {
      for (int x = 0; x < pano.width; x += stride) {
        // One pixel per stride x stride block, on the block's diagonal, one step further along
        // it from block to block in either direction: every row and column of a region is read
        // about as often. The block's first pixel alone skips rows (at the horizon, where the sky
        // changes within a pixel or two, the region means came out 2% too bright); a block's
        // mean would mix in the model's pixels beside its silhouette.
        const int o = (x / stride + r) % stride;
        const int sx = std::min(pano.width - 1, x + o);
        const int y = std::min(pano.height - 1, r * stride + o);
        const Eigen::Vector2d px(sx + 0.5, y + 0.5);
        bool finite = true;
        Eigen::Vector3d rad;
        for (int k = 0; k < 3; ++k) {
          rad[k] = pano.at(sx, y, k);
          finite = finite && std::isfinite(rad[k]) && rad[k] >= 0;
        }
        if (!finite) {
          ++ch.invalid;
          continue;
        }
        const Eigen::Vector3d d = (p.pose.rotation * Unproject(intrinsics, px)).normalized();
        if (!d.allFinite()) {
          ++ch.invalid;
          continue;
        }
        if (d.dot(sun) > cos_excl) {
          ++ch.sun;
          continue;
        }
        if (p.sky_only && !(d.z() > 0)) continue;
        if (model.Occluded(c, d, offset)) {
          ++ch.model;
          continue;
        }
        // Solid angle of the pixel from the unprojected footprint (any projection).
        const Eigen::Vector3d dx = Unproject(intrinsics, px + Eigen::Vector2d(0.5 * stride, 0)) -
                                   Unproject(intrinsics, px - Eigen::Vector2d(0.5 * stride, 0));
        const Eigen::Vector3d dy = Unproject(intrinsics, px + Eigen::Vector2d(0, 0.5 * stride)) -
                                   Unproject(intrinsics, px - Eigen::Vector2d(0, 0.5 * stride));
        double w = dx.cross(dy).norm();
        if (!std::isfinite(w) || w <= 0) w = 1e-12;
        bool shaded = false;
        if (ground_shadow && d.z() < -1e-3) {
          // As the irradiance's ground shadow tests it (solve/irradiance.cc).
          const Eigen::Vector3d q = c + ((c.z() - ground_z) / -d.z()) * d;
          shaded = model.Occluded(q + Eigen::Vector3d(0, 0, offset), sun, 0.0);
          ch.ground_shadow += shaded;
        }
        ch.pixels.push_back({d, w, rad, shaded});
      }
    }
  });
  for (const Chunk& ch : chunks) {
    used->insert(used->end(), ch.pixels.begin(), ch.pixels.end());
    s->pixels_used += static_cast<int>(ch.pixels.size());
    s->pixels_model += ch.model;
    s->pixels_sun += ch.sun;
    s->pixels_invalid += ch.invalid;
    s->pixels_ground_shadow += ch.ground_shadow;
  }
}

}  // namespace

// §3.3: average the panoramas' pixels over coarse lat-long regions, one layer per height.
EnvironmentMap BuildEnvironmentMap(const std::vector<EnvPanorama>& panoramas,
                                   const RayCaster& model, const EnvSun& sun_at,
                                   const SkyModel& sky, const EnvOptions& options,
                                   EnvSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  options.Validate();
  if (std::none_of(panoramas.begin(), panoramas.end(),
                   [](const EnvPanorama& p) { return !p.sky_only; }))
    throw Error("environment map: no landscape panorama given");
  for (size_t i = 0; i < panoramas.size(); ++i) CheckPanorama(panoramas[i], static_cast<int>(i));
  if (!sun_at.dir.allFinite() || sun_at.dir.norm() < 0.5) {
    throw Error("environment map: sun direction is not a unit vector");
  }
  if (!sun_at.irradiance.allFinite() || sun_at.irradiance.minCoeff() < 0) {
    throw Error("environment map: the sun's irradiance is negative or not finite");
  }
  const Eigen::Vector3d sun = sun_at.dir.normalized();
  const double cos_excl =
      std::cos(std::max(options.sun_exclusion_deg * kPi / 180.0, sun_at.angular_radius_rad));
  const bool lit_ground = options.lit_ground && sun_at.irradiance.maxCoeff() > 0 && sun.z() > 0;
  const double ground_z = GroundLevel(model);

  // Layers: the landscape panoramas by height; those within layer_merge_m of the layer's lowest
  // join it.
  std::vector<int> order;
  for (size_t i = 0; i < panoramas.size(); ++i)
    if (!panoramas[i].sky_only) order.push_back(static_cast<int>(i));
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return panoramas[a].pose.position.z() < panoramas[b].pose.position.z();
  });
  std::vector<std::vector<int>> layer_panos;
  for (int i : order) {
    const double z = panoramas[i].pose.position.z();
    if (layer_panos.empty() ||
        z - panoramas[layer_panos.back().front()].pose.position.z() >= options.layer_merge_m) {
      layer_panos.emplace_back();
    }
    layer_panos.back().push_back(i);
  }
  const int layers = static_cast<int>(layer_panos.size());
  EnvironmentMap m;
  InitMap(options, layers, &m);
  const int nreg = m.num_regions();
  EnvSummary s;
  // Per region of every layer: the weighted radiance of its pixels and their weight; the
  // pixels on ground in the model's shadow also apart, to be read as sunlit once the sky is
  // known.
  std::vector<Eigen::Vector3d> sum(m.radiance.size(), Eigen::Vector3d::Zero());
  std::vector<double> wsum(m.radiance.size(), 0.0);
  std::vector<std::pair<size_t, UsedPixel>> shaded;
  m.ground_retro = sun_at.ground_retro;
  // Above the horizon, pooled over the layers: per detail cell and per region, the pixels'
  // weighted radiance and the sky model's over the same pixels (the sky's residual).
  const bool detail = m.detail > 1;
  std::vector<Eigen::Vector3d> cell_obs, cell_model, region_obs, region_model;
  if (detail) {
    cell_obs.assign(m.num_detail_cells(), Eigen::Vector3d::Zero());
    cell_model = cell_obs;
    region_obs.assign(nreg, Eigen::Vector3d::Zero());
    region_model = region_obs;
  }
  // The sky photos' pixels above the horizon, per region and detail cell, for the sky regions
  // the landscape panoramas do not see.
  std::vector<UsedPixel> sky_used;
  for (const EnvPanorama& p : panoramas)
    if (p.sky_only)
      CollectPixels(p, model, sun, cos_excl, options.pixel_stride, false, ground_z, &sky_used, &s);
  std::vector<Eigen::Vector3d> sky_sum(nreg, Eigen::Vector3d::Zero());
  std::vector<double> sky_wsum(nreg, 0.0);
  std::vector<int> sky_count(nreg, 0);
  for (const UsedPixel& u : sky_used) {
    const int r = m.Region(u.dir);
    sky_sum[r] += u.weight * u.radiance;
    sky_wsum[r] += u.weight;
    ++sky_count[r];
  }
  for (int k = 0; k < layers; ++k) {
    double zsum = 0;
    std::vector<UsedPixel> used;
    for (int i : layer_panos[k]) {
      zsum += panoramas[i].pose.position.z();
      CollectPixels(panoramas[i], model, sun, cos_excl, options.pixel_stride, lit_ground, ground_z,
                    &used, &s);
    }
    m.layer_z[k] = zsum / layer_panos[k].size();
    const size_t base = static_cast<size_t>(k) * nreg;
    std::vector<int> count(nreg, 0);
    for (const UsedPixel& u : used) {
      const size_t r = base + m.Region(u.dir);
      sum[r] += u.weight * u.radiance;
      wsum[r] += u.weight;
      count[r - base] += 1;
      if (u.ground_shadow) shaded.emplace_back(r, u);
      if (const int c = detail ? m.DetailCell(u.dir) : -1; c >= 0) {
        const Eigen::Vector3d model = u.weight * sky.Radiance(u.dir);
        cell_obs[c] += u.weight * u.radiance;
        cell_model[c] += model;
        region_obs[m.RegionOfCell(c)] += u.weight * u.radiance;
        region_model[m.RegionOfCell(c)] += model;
      }
    }
    for (int r = 0; r < nreg; ++r) {
      if (count[r] >= options.min_region_pixels && wsum[base + r] > 0) {
        m.radiance[base + r] = sum[base + r] / wsum[base + r];
        m.pixel_count[base + r] = count[r];
        m.source[base + r] = EnvRegionSource::kObserved;
      } else if (sky_count[r] >= options.min_region_pixels && sky_wsum[r] > 0) {
        m.radiance[base + r] = sky_sum[r] / sky_wsum[r];
        m.pixel_count[base + r] = sky_count[r];
        m.source[base + r] = EnvRegionSource::kObserved;
      }
    }
    FillLayer(sky, options.sky_fill_samples, options.fill_band_residual, static_cast<int>(base),
              &m);
  }
  if (!shaded.empty()) {
    // Each shaded pixel as the same ground sunlit, by the ratio from the finished map's sky (the
    // lowest layer) seen along the pixel's ray, as the irradiance puts the shadow back; the
    // regions below the horizon filled from observed ones are filled again.
    const Eigen::Vector3d e_sky = m.HorizontalSkyIrradiance();
    for (const auto& [r, u] : shaded) {
      if (m.source[r] != EnvRegionSource::kObserved) continue;
      const Eigen::Vector3d ratio =
          GroundShadowRatio(m.ground_retro, e_sky, sun_at.irradiance, sun, -u.dir);
      const Eigen::Vector3d lit =
          u.radiance.binaryExpr(ratio, [](double l, double q) { return q > 0 ? l / q : l; });
      m.radiance[r] += (u.weight / wsum[r]) * (lit - u.radiance);
    }
    for (int k = 0; k < layers; ++k)
      FillLayer(sky, options.sky_fill_samples, options.fill_band_residual, k * nreg, &m);
  }
  if (detail) {
    // The sky photos' pixels give the detail of the regions no landscape panorama saw.
    std::vector<bool> landscape_saw(nreg);
    for (int r = 0; r < nreg; ++r) landscape_saw[r] = region_model[r].maxCoeff() > 0;
    for (const UsedPixel& u : sky_used) {
      const int c = m.DetailCell(u.dir);
      if (c < 0 || landscape_saw[m.RegionOfCell(c)]) continue;
      const Eigen::Vector3d model = u.weight * sky.Radiance(u.dir);
      cell_obs[c] += u.weight * u.radiance;
      cell_model[c] += model;
      region_obs[m.RegionOfCell(c)] += u.weight * u.radiance;
      region_model[m.RegionOfCell(c)] += model;
    }
    // Each cell's residual against the model relative to its region's; 1 where a cell or its
    // region saw nothing the model lights. Quantised to 1e-4 (as scene.json keeps it).
    m.sky_detail.assign(m.num_detail_cells(), Eigen::Vector3f::Ones());
    bool any = false;
    for (int c = 0; c < m.num_detail_cells(); ++c) {
      const int r = m.RegionOfCell(c);
      for (int k = 0; k < 3; ++k) {
        const double cell = cell_model[c][k] > 0 ? cell_obs[c][k] / cell_model[c][k] : 0;
        const double region = region_model[r][k] > 0 ? region_obs[r][k] / region_model[r][k] : 0;
        if (!(cell > 0 && region > 0)) continue;
        const double rel = std::clamp(cell / region, 1.0 / 16, 16.0);
        m.sky_detail[c][k] = static_cast<float>(std::round(rel * 1e4) / 1e4);
        any = true;
      }
    }
    if (!any) m.sky_detail.clear();
  }
  for (size_t r = 0; r < m.source.size(); ++r) {
    s.regions_observed += m.source[r] == EnvRegionSource::kObserved;
    s.regions_sky += m.source[r] == EnvRegionSource::kSkyModel;
    s.regions_neighbour += m.source[r] == EnvRegionSource::kNeighbour;
  }
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (summary) *summary = s;
  m.Validate();
  return m;
}

Eigen::Vector3d GroundShadowRatio(double ground_retro, const Eigen::Vector3d& e_sky,
                                  const Eigen::Vector3d& sun_e, const Eigen::Vector3d& sun_dir,
                                  const Eigen::Vector3d& view) {
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d sky = e_sky * AmbientRetroFactor(ground_retro, up, view);
  const Eigen::Vector3d sun =
      sun_e * (std::max(0.0, sun_dir.z()) * RetroFactor(ground_retro, up, sun_dir, view));
  Eigen::Vector3d ratio = Eigen::Vector3d::Ones();
  for (int c = 0; c < 3; ++c) {
    const double total = sky[c] + std::max(0.0, sun[c]);
    if (total > 0) ratio[c] = sky[c] / total;
  }
  return ratio;
}

SkyShape::SkyShape(const EnvironmentMap& env, const SkyModel& sky) : env_(&env) {
  if (env.detail <= 1) return;
  const int cells = env.num_detail_cells(), first = env.bands_below * env.sectors;
  const int above = env.num_regions() - first;
  if (!env.sky_detail.empty() && env.sky_detail.size() != static_cast<size_t>(cells)) {
    throw Error("sky shape: the map's sky detail does not match its cells");
  }
  const Eigen::Vector3d sun = sky.sun_dir.normalized();
  const double cos_excl = std::cos(env.sun_exclusion_rad);
  std::vector<Eigen::Vector3d> q(cells), f(cells);
  std::vector<double> omega(cells);
  std::vector<uint8_t> known(cells);
  std::vector<Eigen::Vector3d> mean(above, Eigen::Vector3d::Zero());
  std::vector<double> area(above, 0.0);
  for (int c = 0; c < cells; ++c) {
    double el0, el1, az0, az1;
    env.CellBounds(c, &el0, &el1, &az0, &az1);
    // The model's mean over the cell (kSub x kSub samples, solid-angle weighted), none taken
    // nearer the sun than the panoramas were averaged.
    constexpr int kSub = 4;
    Eigen::Vector3d mean_model = Eigen::Vector3d::Zero();
    double wsum = 0;
    for (int a = 0; a < kSub; ++a) {
      const double el = el0 + (a + 0.5) / kSub * (el1 - el0);
      for (int b = 0; b < kSub; ++b) {
        const double az = az0 + (b + 0.5) / kSub * (az1 - az0);
        const Eigen::Vector3d d(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az),
                                std::sin(el));
        if (d.dot(sun) > cos_excl) continue;
        mean_model += std::cos(el) * sky.Radiance(d);
        wsum += std::cos(el);
      }
    }
    // A cell wholly within the exclusion holds what the sun's measurement took for the local
    // sky, not the model's aureole: its region's mean over the other cells (below).
    known[c] = wsum > 0;
    q[c] = known[c] ? Eigen::Vector3d((mean_model / wsum).cwiseMax(0.0)) : Eigen::Vector3d::Zero();
    if (!env.sky_detail.empty()) q[c] = q[c].cwiseProduct(env.sky_detail[c].cast<double>());
    // The cell's solid angle and first moment (the integral of w over it), exactly.
    const double s0 = std::sin(el0), s1 = std::sin(el1);
    omega[c] = (az1 - az0) * (s1 - s0);
    const double cos2 = 0.5 * (el1 - el0) + 0.25 * (std::sin(2 * el1) - std::sin(2 * el0));
    f[c] = Eigen::Vector3d(cos2 * (std::cos(az0) - std::cos(az1)),
                           cos2 * (std::sin(az1) - std::sin(az0)),
                           0.5 * (s1 * s1 - s0 * s0) * (az1 - az0));
    if (!known[c]) continue;
    const int r = env.RegionOfCell(c) - first;
    mean[r] += omega[c] * q[c];
    area[r] += omega[c];
  }
  // Per region, the mean over its known cells (which filling the others with it leaves as it
  // is), or 1 when the exclusion hides the whole region.
  for (int r = 0; r < above; ++r)
    mean[r] = area[r] > 0 ? Eigen::Vector3d(mean[r] / area[r]) : Eigen::Vector3d::Ones();
  shape_.resize(cells);
  moment_.assign(above, Eigen::Matrix3d::Zero());
  flux_.assign(above, Eigen::Vector3d::Zero());
  for (int c = 0; c < cells; ++c) {
    const int r = env.RegionOfCell(c) - first;
    if (!known[c]) q[c] = mean[r];
    Eigen::Vector3d s;
    for (int k = 0; k < 3; ++k) s[k] = mean[r][k] > 0 ? q[c][k] / mean[r][k] : 1.0;
    shape_[c] = s.cast<float>();
    moment_[r] += s * f[c].transpose();
    flux_[r] += f[c];
  }
}

Eigen::Vector3d SkyShape::InRegion(const Eigen::Vector3d& d, int region) const {
  if (shape_.empty() || region < env_->bands_below * env_->sectors) return Eigen::Vector3d::Ones();
  const int det = env_->detail, cols = env_->sectors * det;
  const int band = region / env_->sectors - env_->bands_below, sector = region % env_->sectors;
  double el, az;
  ElevationAzimuth(d, &el, &az);
  const int row = std::clamp(static_cast<int>(std::floor(el / (kPi / 2) * env_->bands_above * det)),
                             band * det, band * det + det - 1);
  // The column nearest in azimuth (around the circle) among the sector's.
  const double x = az / (2 * kPi) * cols - sector * det;  // in cells from the sector's start
  const double wrapped = x - cols * std::round((x - 0.5 * det) / cols);
  const int col = sector * det + std::clamp(static_cast<int>(std::floor(wrapped)), 0, det - 1);
  return OfCell(row * cols + col);
}

Eigen::Matrix3d SkyShape::Moment(int region, const Eigen::Vector3d& region_flux) const {
  const int r = region - env_->bands_below * env_->sectors;
  Eigen::Matrix3d m = region_flux.transpose().replicate<3, 1>();
  if (shape_.empty() || r < 0) return m;
  // Where the shape is 1 this is the polygon's own flux; the cells only move light within it.
  return m + moment_[r] - flux_[r].transpose().replicate<3, 1>();
}

double GroundLevel(const RayCaster& model) {
  return model.bounds().isEmpty() ? 0.0 : model.bounds().min().z();
}

}  // namespace rouen
