#include "pipeline/viewer.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <system_error>
#include <thread>

#include "core/angles.h"
#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/outputs.h"
#include "core/temporaries.h"
#include "core/version.h"
#include "pipeline/export.h"
#include "pipeline/render_scene.h"
#include "pipeline/session_solve.h"
#include "solve/relight.h"
#include "solve/retro.h"
#include "solve/specular.h"

namespace rouen {
namespace fs = std::filesystem;
namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

double Elevation(UtcTime t, const Site& site) { return ComputeSunPosition(t, site).elevation_deg; }

// The time in [lo, hi] where the elevation crosses `level` (elevation(lo) and elevation(hi) on
// either side of it), to a millisecond.
UtcTime Crossing(UtcTime lo, UtcTime hi, const Site& site, double level) {
  const bool lo_below = Elevation(lo, site) < level;
  while ((hi.ns - lo.ns) > 1000000) {
    const UtcTime mid{lo.ns + (hi.ns - lo.ns) / 2};
    if ((Elevation(mid, site) < level) == lo_below)
      lo = mid;
    else
      hi = mid;
  }
  return UtcTime{lo.ns + (hi.ns - lo.ns) / 2};
}

constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string Base64(const std::string& in) {
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const uint32_t v = (static_cast<uint8_t>(in[i]) << 16) |
                       (static_cast<uint8_t>(in[i + 1]) << 8) | static_cast<uint8_t>(in[i + 2]);
    for (int k = 3; k >= 0; --k) out.push_back(kBase64[(v >> (6 * k)) & 63]);
  }
  if (i < in.size()) {
    uint32_t v = static_cast<uint8_t>(in[i]) << 16;
    if (i + 1 < in.size()) v |= static_cast<uint8_t>(in[i + 1]) << 8;
    out.push_back(kBase64[(v >> 18) & 63]);
    out.push_back(kBase64[(v >> 12) & 63]);
    out.push_back(i + 1 < in.size() ? kBase64[(v >> 6) & 63] : '=');
    out.push_back('=');
  }
  return out;
}

// ENU (x east, y north, z up) as the page's WebGL frame, y up: (east, up, -north), as glTF.
nlohmann::json GlVector(const Eigen::Vector3d& enu) {
  const Eigen::Vector3d g = EnuToGltf(enu);
  return {g.x(), g.y(), g.z()};
}

// The largest value of an image (at least a tiny positive number, so the scale divides).
double MaxValue(const Image& img) {
  double m = 0;
  for (float v : img.data) m = std::max(m, static_cast<double>(v));
  return m > 1e-30 ? m : 1.0;
}

// `img` (channels 1 or 3, non-negative) as an 8-bit PNG data URL, ViewerEncode with `scale`.
std::string PngDataUrl(const Image& img, double scale) {
  Image q(img.width, img.height, img.channels, PixelUnits::kDigital, 0.f);
  for (size_t i = 0; i < img.data.size(); ++i) {
    if (!std::isfinite(img.data[i])) throw Error("viewer: a baked value is not finite");
    q.data[i] = ViewerEncode(img.data[i], scale);
  }
  return "data:image/png;base64," + Base64(EncodeImage("layer.png", q, StoredType::kUint8));
}

}  // namespace

void ViewerOptions::Validate() const {
  if (times < 2 || times > 96) throw Error("--times: must be within 2..96");
  if (texels_per_cell < 1 || texels_per_cell > 16)
    throw Error("--texels-per-cell: must be within 1..16");
  if (shadow_texels_per_cell < 1 || shadow_texels_per_cell > 16)
    throw Error("--shadow-texels-per-cell: must be within 1..16");
  if (!(min_elevation_deg >= 0.1 && min_elevation_deg <= 20))
    throw Error("viewer: the sunrise elevation must be within 0.1..20 deg");
  if (max_atlas_side < 16 || max_atlas_side > 16384)
    throw Error("viewer: the atlas side limit must be within 16..16384");
}

ViewerDay ViewerDayOf(const Site& site, UtcTime day, int n, double min_elevation_deg) {
  if (n < 2) throw Error("viewer: at least two times");
  // Solar noon: the highest sun within 12 h of `day` (10-minute scan, then golden section).
  constexpr double kStep = 600;
  double best_s = -43200, best_e = -1e9;
  for (double s = -43200; s <= 43200; s += kStep) {
    const double e = Elevation(day.PlusSeconds(s), site);
    if (e > best_e) best_e = e, best_s = s;
  }
  double a = best_s - kStep, b = best_s + kStep;
  const double g = (std::sqrt(5.0) - 1) / 2;
  while (b - a > 0.01) {
    const double c = b - g * (b - a), d = a + g * (b - a);
    if (Elevation(day.PlusSeconds(c), site) > Elevation(day.PlusSeconds(d), site))
      b = d;
    else
      a = c;
  }
  ViewerDay out;
  out.noon = day.PlusSeconds((a + b) / 2);
  const double noon_e = Elevation(out.noon, site);
  if (!(noon_e > min_elevation_deg))
    throw Error("the sun stays below " + FormatNumber(min_elevation_deg) + " deg on the day of " +
                day.Iso8601(0) + " at the site (noon elevation " + FormatNumber(noon_e) +
                " deg): nothing to light");
  // Sunrise and sunset: the first 10-minute steps from noon where the sun is below the level.
  out.sunrise = out.noon.PlusSeconds(-43200);
  out.sunset = out.noon.PlusSeconds(43200);
  for (double s = kStep; s <= 43200; s += kStep) {
    if (Elevation(out.noon.PlusSeconds(-s), site) < min_elevation_deg) {
      out.sunrise = Crossing(out.noon.PlusSeconds(-s), out.noon.PlusSeconds(-s + kStep), site,
                             min_elevation_deg);
      break;
    }
  }
  for (double s = kStep; s <= 43200; s += kStep) {
    if (Elevation(out.noon.PlusSeconds(s), site) < min_elevation_deg) {
      out.sunset = Crossing(out.noon.PlusSeconds(s - kStep), out.noon.PlusSeconds(s), site,
                            min_elevation_deg);
      break;
    }
  }
  // The crossings are found to a millisecond: keep the end times where the sun is up.
  if (!(Elevation(out.sunrise, site) > 0)) out.sunrise = out.sunrise.PlusSeconds(0.01);
  if (!(Elevation(out.sunset, site) > 0)) out.sunset = out.sunset.PlusSeconds(-0.01);
  const double span = out.sunset.UnixSeconds() - out.sunrise.UnixSeconds();
  for (int i = 0; i < n; ++i)
    out.times.push_back(i == n - 1 ? out.sunset : out.sunrise.PlusSeconds(span * i / (n - 1)));
  return out;
}

Eigen::Vector2d ViewerAtlas::Texel(int triangle, double u, double v) const {
  const AtlasTile& t = layout.tiles.at(triangle);
  if (t.size == 0) return Eigen::Vector2d(-1, -1);
  return Eigen::Vector2d(block_x[t.block] + t.x + 1 + u * t.size,
                         block_y[t.block] + t.y + 1 + v * t.size);
}

Image ViewerAtlas::Bake(const SurfaceGrid& grid, const std::vector<Eigen::Vector3d>& values) const {
  Image out(width, height, 3, PixelUnits::kOther, 0.f);
  for (size_t b = 0; b < layout.width.size(); ++b) {
    if (layout.width[b] == 0) continue;
    const Image img = BakeAtlas(layout, grid, values, static_cast<int>(b));
    for (int y = 0; y < img.height; ++y)
      std::memcpy(&out.at(block_x[b], block_y[b] + y), img.data.data() + img.index(0, y),
                  sizeof(float) * 3 * img.width);
  }
  return out;
}

ViewerAtlas PackViewerAtlas(const Mesh& mesh, const SurfaceGrid& grid, int texels_per_cell,
                            int max_side) {
  AtlasOptions ao;
  ao.texels_per_cell = texels_per_cell;
  ao.max_side = max_side;
  ViewerAtlas a;
  a.layout = LayoutAtlases(mesh, grid, ao);
  const int nblocks = static_cast<int>(a.layout.width.size());
  a.block_x.assign(nblocks, 0);
  a.block_y.assign(nblocks, 0);
  std::vector<int> order;
  int64_t area = 0;
  int widest = 0;
  for (int b = 0; b < nblocks; ++b) {
    if (a.layout.width[b] == 0) continue;
    order.push_back(b);
    area += static_cast<int64_t>(a.layout.width[b]) * a.layout.height[b];
    widest = std::max(widest, a.layout.width[b]);
  }
  if (order.empty()) throw Error("viewer: the model has no grid points (no albedo to show)");
  // Shelves of block atlases, tallest first.
  std::stable_sort(order.begin(), order.end(),
                   [&](int p, int q) { return a.layout.height[p] > a.layout.height[q]; });
  const int side = std::max(widest, static_cast<int>(std::ceil(std::sqrt(area * 1.2))));
  int x = 0, y = 0, shelf = 0;
  for (int b : order) {
    if (x + a.layout.width[b] > side) {
      x = 0;
      y += shelf;
      shelf = 0;
    }
    a.block_x[b] = x;
    a.block_y[b] = y;
    x += a.layout.width[b];
    shelf = std::max(shelf, a.layout.height[b]);
    a.width = std::max(a.width, x);
  }
  a.height = y + shelf;
  if (a.width > max_side || a.height > max_side)
    throw Error("viewer: the atlas of all blocks needs " + std::to_string(a.width) + "x" +
                std::to_string(a.height) + " texels, more than " + std::to_string(max_side) +
                " (fewer --texels-per-cell)");
  return a;
}

Image SunVisibilityAtlas(const ViewerAtlas& atlas, const Mesh& mesh, const RayCaster& caster,
                         const Eigen::Vector3d& sun_dir) {
  Image out(atlas.width, atlas.height, 1, PixelUnits::kOther, 0.f);
  const Eigen::Vector3d s = sun_dir.normalized();
  const double offset = caster.surface_offset();
  const int ntri = static_cast<int>(atlas.layout.tiles.size());
  // Triangles shared among threads (each writes only its own tile's texels).
  std::atomic<int> next{0};
  auto work = [&] {
    for (int t; (t = next.fetch_add(1)) < ntri;) {
      const AtlasTile& tile = atlas.layout.tiles[t];
      if (tile.size == 0) continue;
      const Eigen::Vector3d n = mesh.Normal(t);
      if (!n.allFinite() || !(n.dot(s) > 0)) continue;  // the sun is behind the face: 0
      const Eigen::Vector3d& a = mesh.vertices[mesh.triangles[t][0]];
      const Eigen::Vector3d& b = mesh.vertices[mesh.triangles[t][1]];
      const Eigen::Vector3d& c = mesh.vertices[mesh.triangles[t][2]];
      const int size = tile.size;
      const int x0 = atlas.block_x[tile.block] + tile.x + 1,
                y0 = atlas.block_y[tile.block] + tile.y + 1;
      for (int j = -1; j <= size; ++j)
        for (int i = -1; i <= size; ++i) {
          double u = (std::clamp(i, 0, size - 1) + 0.5) / size,
                 v = (std::clamp(j, 0, size - 1) + 0.5) / size;
          if (u + v > 1) {  // the upper half mirrors the triangle (solve/atlas.h)
            const double mu = 1 - v, mv = 1 - u;
            u = mu;
            v = mv;
          }
          const Eigen::Vector3d p = a + u * (b - a) + v * (c - a) + offset * n;
          out.at(x0 + i, y0 + j) = caster.Occluded(p, s, 0.0) ? 0.f : 1.f;
        }
    }
  };
  const int threads = std::max(1u, std::min(8u, std::thread::hardware_concurrency()));
  std::vector<std::thread> pool;
  for (int k = 1; k < threads; ++k) pool.emplace_back(work);
  work();
  for (std::thread& th : pool) th.join();
  return out;
}

uint8_t ViewerEncode(double value, double scale) {
  const double x = std::clamp(value / scale, 0.0, 1.0);
  return static_cast<uint8_t>(std::lround(255 * std::pow(x, 1 / kViewerGamma)));
}

double ViewerDecode(uint8_t stored, double scale) {
  return scale * std::pow(stored / 255.0, kViewerGamma);
}

ViewerData ComputeViewerData(const LoadedScene& scene, const ViewerOptions& options,
                             const std::function<void(int, int)>& progress) {
  options.Validate();
  const SolveResult& solved = scene.solved;
  if (solved.slots.empty()) throw Error(scene.dir.string() + ": the scene has no slots");
  // The day: the mean of the captured times.
  double mean = 0;
  for (const SlotSolve& s : solved.slots)
    mean += s.utc.UnixSeconds() - solved.slots[0].utc.UnixSeconds();
  mean /= solved.slots.size();
  ViewerData out;
  out.day = ViewerDayOf(scene.scene.site, solved.slots[0].utc.PlusSeconds(mean), options.times,
                        options.min_elevation_deg);
  // As RequestedLighting: predicted from every slot but the held-out ones.
  std::vector<Lighting> measured;
  std::vector<int> measured_slots;
  for (const SlotSolve& ss : solved.slots)
    if (std::find(scene.scene.holdout_slots.begin(), scene.scene.holdout_slots.end(), ss.slot) ==
        scene.scene.holdout_slots.end()) {
      measured.push_back(ss.lighting);
      measured_slots.push_back(ss.slot);
    }
  if (measured.empty())
    throw Error(scene.dir.string() + ": every slot is held out: no lighting to predict from");
  RelightOptions clear;
  clear.env = scene.config.env_stereo;  // the options the solve fitted with
  clear.env.ground_retro = solved.env_ground_retro;
  RelightOptions overcast = clear;
  overcast.pbs = 1;
  const EnvStereoResult* fitted =
      FitFor(solved.env_stereo, solved.env_stereo_slots, measured_slots, clear.env);
  const LightingPredictor clear_sky(measured, clear, fitted),
      overcast_sky(measured, overcast, fitted);
  const int n = static_cast<int>(out.day.times.size());
  for (int i = 0; i < n; ++i) {
    const UtcTime t = out.day.times[i];
    const Lighting lc = clear_sky.At(t, scene.scene.site);
    const Lighting lo = overcast_sky.At(t, scene.scene.site);
    const std::vector<SlotIrradiance> irr = IrradianceFor(solved, {lc, lo});
    const SlotIrradiance& ic = irr[0];
    const SlotIrradiance& io = irr[1];
    ViewerBasis b;
    b.utc = t;
    b.sun_dir = lc.sun_dir.normalized();
    b.sun_e = lc.sun_radiance * lc.sun_solid_angle_sr;
    b.sun_visibility = ic.sun_visibility;
    b.sun = ic.sun;
    b.se = ic.se;
    b.se_overcast = io.se;
    for (size_t j = 0; j < b.se.size(); ++j)
      if (!b.se[j].allFinite() || !b.se_overcast[j].allFinite() || !b.sun[j].allFinite() ||
          !std::isfinite(b.sun_visibility[j]))
        throw Error("viewer: the irradiance at " + t.Iso8601(0) + " is not finite at grid point " +
                    std::to_string(j));
    if (!b.sun_e.allFinite()) throw Error("viewer: the sun at " + t.Iso8601(0) + " is not finite");
    out.bases.push_back(std::move(b));
    if (progress) progress(i + 1, n);
  }
  // Exposure: the 99th percentile of the diffuse radiance at the basis nearest noon -> 0.9;
  // and each basis's own, clear and overcast.
  const AlbedoResult& al = solved.albedo;
  auto auto_exposure = [&](const ViewerBasis& b, bool overcast) {
    std::vector<double> l;
    for (size_t j = 0; j < b.se.size(); ++j) {
      const Eigen::Vector3d r =
          overcast ? Eigen::Vector3d(al.rho_se[j].cwiseProduct(b.se_overcast[j]) / kPi)
                   : Eigen::Vector3d((al.rho_sun[j].cwiseProduct(b.sun[j]) +
                                      al.rho_se[j].cwiseProduct(b.se[j])) /
                                     kPi);
      for (int c = 0; c < 3; ++c) l.push_back(r[c]);
    }
    if (l.empty()) return 1.0;
    const size_t k = std::min(l.size() - 1, static_cast<size_t>(0.99 * l.size()));
    std::nth_element(l.begin(), l.begin() + k, l.end());
    return l[k] > 0 && std::isfinite(l[k]) ? 0.9 / l[k] : 1.0;
  };
  int noon = 0;
  for (int i = 1; i < n; ++i)
    if (std::abs(out.day.times[i].UnixSeconds() - out.day.noon.UnixSeconds()) <
        std::abs(out.day.times[noon].UnixSeconds() - out.day.noon.UnixSeconds()))
      noon = i;
  out.exposure = auto_exposure(out.bases[noon], false);
  for (ViewerBasis& b : out.bases) {
    b.exposure = auto_exposure(b, false);
    b.exposure_overcast = auto_exposure(b, true);
  }
  return out;
}

void CheckViewerOutput(const fs::path& out) {
  CheckReplaceableFolder("--out " + out.string(), out, "viewer_data.js", "viewer");
}

ViewerSummary WriteViewer(const LoadedScene& scene, const fs::path& out_arg,
                          const ViewerOptions& options,
                          const std::function<void(const std::string&)>& log,
                          const std::function<void(int, int)>& progress) {
  options.Validate();
  fs::path out = out_arg.lexically_normal();
  if (!out.has_filename()) out = out.parent_path();
  CheckViewerOutput(out);
  const SolveResult& solved = scene.solved;
  const auto start = std::chrono::steady_clock::now();
  ViewerSummary summary;
  const ViewerAtlas atlas =
      PackViewerAtlas(solved.mesh, solved.grid, options.texels_per_cell, options.max_atlas_side);
  Log(log, "lighting at " + std::to_string(options.times) + " times (clear and overcast), " +
               std::to_string(solved.grid.size()) + " grid points");
  const ViewerAtlas shadow = PackViewerAtlas(
      solved.mesh, solved.grid, options.shadow_texels_per_cell, options.max_atlas_side);
  const ViewerData data = ComputeViewerData(scene, options, progress);
  summary.seconds_lighting = Seconds(start);
  const auto bake_start = std::chrono::steady_clock::now();
  Log(log,
      "baking " + std::to_string(atlas.width) + "x" + std::to_string(atlas.height) + " atlases");

  nlohmann::json j;
  const Site& site = scene.scene.site;
  j["format"] = "rouen viewer 1";
  j["generator"] = std::string("rouen ") + RouenVersion();
  j["scene"] = scene.dir.filename().string();
  j["site"] = {{"lat_deg", site.lat_deg}, {"lon_deg", site.lon_deg}, {"height_m", site.height_m}};
  j["frame"] = "WebGL (x, y, z) = ENU (east, up, -north), metres";
  j["encoding"] =
      "8-bit PNG: value = scale * (stored / 255)^2.2; irradiance in rouen's relative radiance x "
      "sr";
  j["gamma"] = kViewerGamma;
  j["exposure"] = data.exposure;
  j["atlas"] = {{"width", atlas.width}, {"height", atlas.height}};
  j["shadow_atlas"] = {{"width", shadow.width}, {"height", shadow.height}};
  j["noon"] = data.day.noon.UnixSeconds();
  j["sunrise"] = data.day.sunrise.UnixSeconds();
  j["sunset"] = data.day.sunset.UnixSeconds();
  const AlbedoResult& al = solved.albedo;
  const Image rho_sun = atlas.Bake(solved.grid, al.rho_sun);
  const Image rho_se = atlas.Bake(solved.grid, al.rho_se);
  j["albedo"] = {
      {"sun", {{"scale", MaxValue(rho_sun)}, {"png", PngDataUrl(rho_sun, MaxValue(rho_sun))}}},
      {"se", {{"scale", MaxValue(rho_se)}, {"png", PngDataUrl(rho_se, MaxValue(rho_se))}}}};
  // The camera's recovered response, for the page to tone map as rouen render --png does: a
  // table of digital numbers over ln exposure, and the factor that takes the sRGB exposure
  // (the 99th percentile to 0.9 of white) to the response's (to digital number 230).
  const ResponseCurve& response = scene.scene.response;
  if (response.valid()) {
    double lo = INFINITY, hi = -INFINITY, k = 0;
    for (int c = 0; c < 3; ++c) {
      lo = std::min(lo, response.g[c].front());
      hi = std::max(hi, response.g[c].back());
      k += response.LogExposure(c, 230) / 3;
    }
    if (hi > lo) {
      constexpr int kLut = 1024;
      Image lut(kLut, 1, 3, PixelUnits::kDigital, 0.f);
      for (int i = 0; i < kLut; ++i)
        for (int c = 0; c < 3; ++c)
          lut.at(i, 0, c) = static_cast<float>(std::clamp(
              std::round(response.DigitalValue(c, std::exp(lo + (hi - lo) * i / (kLut - 1)))), 0.0,
              255.0));
      j["response"] = {{"log_lo", lo},
                       {"log_hi", hi},
                       {"exposure_scale", std::exp(k) / 0.9},
                       {"lut", "data:image/png;base64," +
                                   Base64(EncodeImage("lut.png", lut, StoredType::kUint8))}};
    }
  }
  j["bases"] = nlohmann::json::array();
  for (const ViewerBasis& b : data.bases) {
    const Image v = SunVisibilityAtlas(shadow, solved.mesh, *solved.caster, b.sun_dir);
    const Image se = atlas.Bake(solved.grid, b.se);
    const Image so = atlas.Bake(solved.grid, b.se_overcast);
    double az = 0, el = 0;
    AzElFromEnu(b.sun_dir, &az, &el);
    j["bases"].push_back({{"utc", b.utc.Iso8601(0)},
                          {"t", b.utc.UnixSeconds()},
                          {"sun_azimuth_deg", az},
                          {"sun_elevation_deg", el},
                          {"sun_dir", GlVector(b.sun_dir)},
                          {"sun_e", {b.sun_e.x(), b.sun_e.y(), b.sun_e.z()}},
                          {"vis", PngDataUrl(v, 1.0)},
                          {"se_scale", MaxValue(se)},
                          {"se", PngDataUrl(se, MaxValue(se))},
                          {"se_overcast_scale", MaxValue(so)},
                          {"se_overcast", PngDataUrl(so, MaxValue(so))},
                          {"exposure", b.exposure},
                          {"exposure_overcast", b.exposure_overcast}});
  }
  // The mesh: three vertices per triangle, 17 floats each: position (3), normal (3), texture
  // coordinates (2, 0..1 from the atlas's top-left; -1 without albedo), retro, the sun lobe's
  // rho_s (3), kappa (-1 for a microfacet lobe) and exponent, the block, and the shadow atlas's
  // texture coordinates (2).
  const Mesh& mesh = solved.mesh;
  std::vector<float> verts;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (int t = 0; t < static_cast<int>(mesh.triangles.size()); ++t) {
    const int block = mesh.triangle_block[t];
    const Eigen::Vector3d nrm = EnuToGltf(mesh.Normal(t));
    if (!nrm.allFinite()) continue;  // degenerate: nothing to draw
    const double retro = BlockRetro(al.retro, block);
    const SpecularLobe lobe = BlockLobe(al.sun_lobes, block);
    const double corners[3][2] = {{0, 0}, {1, 0}, {0, 1}};
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p_enu = mesh.vertices[mesh.triangles[t][k]];
      lo = lo.cwiseMin(p_enu);
      hi = hi.cwiseMax(p_enu);
      const Eigen::Vector3d p = EnuToGltf(p_enu);
      const Eigen::Vector2d tx = atlas.Texel(t, corners[k][0], corners[k][1]);
      const Eigen::Vector2d sx = shadow.Texel(t, corners[k][0], corners[k][1]);
      const bool textured = tx.x() >= 0;
      const float vals[17] = {
          static_cast<float>(p.x()),
          static_cast<float>(p.y()),
          static_cast<float>(p.z()),
          static_cast<float>(nrm.x()),
          static_cast<float>(nrm.y()),
          static_cast<float>(nrm.z()),
          textured ? static_cast<float>(tx.x() / atlas.width) : -1.f,
          textured ? static_cast<float>(tx.y() / atlas.height) : -1.f,
          static_cast<float>(retro),
          static_cast<float>(lobe.rho_s.x()),
          static_cast<float>(lobe.rho_s.y()),
          static_cast<float>(lobe.rho_s.z()),
          lobe.model == LobeModel::kMicrofacet ? -1.f : static_cast<float>(lobe.kappa),
          static_cast<float>(lobe.n),
          static_cast<float>(block),
          textured ? static_cast<float>(sx.x() / shadow.width) : -1.f,
          textured ? static_cast<float>(sx.y() / shadow.height) : -1.f};
      for (float f : vals) {
        if (!std::isfinite(f)) throw Error("viewer: a vertex value is not finite");
        verts.push_back(f);
      }
    }
    summary.triangles += 1;
  }
  static_assert(sizeof(float) == 4);
  j["mesh"] = {{"floats_per_vertex", 17},
               {"vertices", verts.size() / 17},
               {"blocks", mesh.block_names},
               {"data", Base64(std::string(reinterpret_cast<const char*>(verts.data()),
                                           verts.size() * sizeof(float)))}};
  j["bbox"] = {{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}};
  // The first camera: the scene's first architecture view, looking at the model's centre's
  // depth along its axis; else from the south-west, above.
  const Eigen::Vector3d centre = (lo + hi) / 2;
  Eigen::Vector3d eye = centre + Eigen::Vector3d(-1, -1, 0.5) * (hi - lo).norm(), target = centre;
  double fov_deg = 50;
  for (const auto& [name, v] : scene.scene.views) {
    if (v.target != "architecture" || v.intrinsics.projection != Projection::kPinhole) continue;
    const Eigen::Vector3d forward = v.pose.rotation.col(2).normalized();
    const double depth = (centre - v.pose.position).dot(forward);
    if (!(depth > 0)) continue;
    eye = v.pose.position;
    target = eye + depth * forward;
    fov_deg = 2 * std::atan(v.intrinsics.width / (2 * v.intrinsics.fx)) * 180 / kPi;
    j["camera_from_view"] = name;
    break;
  }
  j["camera"] = {{"eye", {eye.x(), eye.y(), eye.z()}},
                 {"target", {target.x(), target.y(), target.z()}},
                 {"fov_x_deg", fov_deg}};
  const std::string js =
      "// rouen view data (generated; see index.html)\nwindow.ROUEN_VIEWER_DATA = " + j.dump() +
      ";\n";
  const std::string html = ViewerPageHtml();
  summary.seconds_baking = Seconds(bake_start);

  const fs::path parent = out.parent_path().empty() ? fs::path(".") : out.parent_path();
  const fs::path tmp = parent / (out.filename().string() + ".tmp-" + std::to_string(::getpid()));
  std::error_code ec;
  fs::remove_all(tmp, ec);
  WatchForTemporaries(parent);
  try {
    fs::create_directories(tmp);
    WriteFileAtomic(tmp / "viewer_data.js", js);
    WriteFileAtomic(tmp / "index.html", html);
    FsyncDirectory(tmp);
    if (fs::exists(out)) {
      const fs::path old =
          parent / (out.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-old");
      fs::rename(out, old);
      fs::rename(tmp, out);
      fs::remove_all(old);
    } else {
      fs::rename(tmp, out);
    }
    FsyncDirectory(parent);
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(tmp, ec);
    throw Error("--out " + out.string() + ": cannot write the viewer: " + e.code().message());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  summary.times = static_cast<int>(data.bases.size());
  summary.atlas_width = atlas.width;
  summary.atlas_height = atlas.height;
  summary.shadow_width = shadow.width;
  summary.shadow_height = shadow.height;
  summary.bytes = js.size() + html.size();
  Log(log, "wrote " + out.string());
  return summary;
}

}  // namespace rouen
