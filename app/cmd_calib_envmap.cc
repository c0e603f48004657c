// rouen calib envmap / rouen calib orient: environment map assembly from oriented HDR photos,
// and the orientation of sky photos from the sun.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "app/commands.h"
#include "app/options.h"
#include "calib/envmap.h"
#include "calib/sky_orientation.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/lens.h"
#include "core/limits.h"
#include "core/outputs.h"
#include "core/solar.h"
#include "core/time.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

// "a,b,c" -> n numbers; throws naming the option.
// Replaces the extension of `out`: ENV.exr -> ENV<suffix>.
std::string Beside(const std::string& out, const std::string& suffix) {
  fs::path p(out);
  p.replace_extension();
  return p.string() + suffix;
}

struct EnvmapArgs {
  std::string list, out, mask, coverage, summary;
  int width = 1024, supersample = 1;
  double feather = 0;
};

void RunEnvmap(const EnvmapArgs& a) {
  struct Loaded {
    Image image;
    Intrinsics lens;
    Pose pose;
    double max_field_deg;
    std::string name;
  };
  const std::string mask_path = a.mask.empty() ? Beside(a.out, ".mask.png") : a.mask;
  const std::string cov_path = a.coverage.empty() ? Beside(a.out, ".coverage.exr") : a.coverage;
  const std::string sum_path = a.summary.empty() ? Beside(a.out, ".json") : a.summary;
  // The four outputs are checked now and written together at the end.
  OutputSet outputs;
  const std::string out_tmp = outputs.Add("--out", a.out, OutputKind::kRadiance);
  const std::string cov_tmp = outputs.Add("--coverage", cov_path, OutputKind::kRadiance);
  const std::string mask_tmp = outputs.Add("--mask", mask_path, OutputKind::kImage);
  const std::string sum_tmp = outputs.Add("--summary", sum_path, OutputKind::kFile);
  std::vector<Loaded> loaded;
  const fs::path base = fs::path(a.list).parent_path();
  auto resolve = [&](const std::string& w) {
    fs::path p(w);
    return (p.is_relative() ? base / p : p).string();
  };
  ForEachListLine(a.list, [&](const std::vector<std::string>& words, const std::string& where) {
    if (words.size() != 3) {
      throw Error(where + ": expected 'image.exr lens.json pose.json', got " +
                  std::to_string(words.size()) + " words");
    }
    Loaded l;
    l.name = resolve(words[0]);
    const LensFile lens = ReadLensFile(resolve(words[1]));
    l.lens = lens.intrinsics;
    l.max_field_deg = lens.max_field_deg;
    l.pose = ReadPoseFile(resolve(words[2]));
    l.image = ReadImage(l.name);
    if (l.image.units != PixelUnits::kRadiance) {
      throw Error(l.name +
                  ": not an HDR radiance image (float EXR expected; merge brackets "
                  "with `rouen hdr` first)");
    }
    if (l.image.channels > 3) {  // drop alpha
      Image rgb(l.image.width, l.image.height, 3, PixelUnits::kRadiance);
      for (int y = 0; y < rgb.height; ++y) {
        for (int x = 0; x < rgb.width; ++x) {
          for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = l.image.at(x, y, c);
        }
      }
      l.image = std::move(rgb);
    }
    loaded.push_back(std::move(l));
  });
  std::vector<EnvmapPhoto> photos;
  for (const Loaded& l : loaded) {
    photos.push_back({&l.image, l.lens, l.pose, l.max_field_deg, l.name});
  }
  EnvmapOptions opt;
  opt.width = a.width;
  opt.supersample = a.supersample;
  opt.edge_feather = a.feather;
  EnvmapResult r;
  try {
    r = AssembleEnvmap(photos, opt);
  } catch (const Error& e) {
    throw Error(a.list + ": " + e.what());
  }
  Image mask(r.coverage.width, r.coverage.height, 1, PixelUnits::kDigital, 0.f);
  for (size_t i = 0; i < mask.data.size(); ++i) mask.data[i] = r.coverage.data[i] > 0 ? 255.f : 0.f;
  WriteImage(out_tmp, r.radiance, StoredType::kFloat);
  WriteImage(cov_tmp, r.coverage, StoredType::kFloat);
  WriteImage(mask_tmp, mask, StoredType::kUint8);
  nlohmann::json j = EnvmapSummaryJson(r, photos);
  j["radiance"] = a.out;
  j["coverage"] = cov_path;
  j["mask"] = mask_path;
  WriteFileAtomic(sum_tmp, j.dump(2) + "\n");
  outputs.Commit();
  std::printf(
      "%s: %dx%d lat-long radiance from %zu photos; %.1f%% of the sphere seen "
      "(%.1f%% of the sky), %.2f s (%.1f output Mpx/s)\n",
      a.out.c_str(), r.radiance.width, r.radiance.height, photos.size(), 100 * r.coverage_fraction,
      100 * r.sky_coverage_fraction, r.seconds,
      r.radiance.width * 1e-6 * r.radiance.height / std::max(r.seconds, 1e-9));
  std::printf("  coverage %s, mask %s, summary %s\n", cov_path.c_str(), mask_path.c_str(),
              sum_path.c_str());
}

struct OrientArgs {
  std::string image, lens, time, site, out, position;
  std::vector<std::string> landmarks, horizon;
  bool level = false;
  double landmark_sigma = 0.1, horizon_sigma = 0.1;
};

void RunOrient(const OrientArgs& a) {
  if (a.landmarks.empty() && a.horizon.empty() && !a.level) {
    throw Error(
        "calib orient: give --landmark, --horizon or --level (the sun alone leaves the "
        "roll about the sun axis free)");
  }
  const Site site = ParseSiteOption(a.site, "--site");
  const UtcTime t = ParseIso8601(a.time);
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  const SunPosition sun = ComputeSunPosition(t, site);
  if (sun.elevation_deg < -1) {
    throw Error("calib orient: the sun is " + std::to_string(sun.elevation_deg) +
                " deg below the horizon at " + a.time + "; check --time and --site");
  }
  const Intrinsics k = ReadLensFile(a.lens).intrinsics;
  const Image img = ReadImage(a.image);
  SunDiscOptions so;
  so.sun_radius_deg = sun.angular_radius_deg;
  const SunDisc d = DetectSunDisc(img, k, so, a.image);
  std::vector<SkyLandmark> lms;
  for (const std::string& l : a.landmarks) {
    const std::vector<double> v = ParseNumberList(l, 4, "--landmark");
    lms.push_back({{v[0], v[1]}, EnuFromAzEl(v[2], v[3]), a.landmark_sigma});
  }
  std::vector<HorizonPoint> hz;
  for (const std::string& h : a.horizon) {
    const std::vector<double> v = ParseNumberList(h, 2, "--horizon");
    hz.push_back({{v[0], v[1]}, a.horizon_sigma});
  }
  OrientOptions oo;
  oo.level = a.level;
  SkyOrientation o;
  try {
    o = OrientFromSun(k, d.ray_cam, d.sigma_deg, sun.DirectionEnu(), lms, hz, oo);
  } catch (const Error& e) {
    throw Error(a.image + ": " + e.what());
  }
  if (!a.position.empty()) {
    const std::vector<double> p = ParseNumberList(a.position, 3, "--position");
    o.pose.position = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  nlohmann::json j = o.pose;
  j["orientation"] = {{"method", "sun"},
                      {"time", t.Iso8601()},
                      {"site", {site.lat_deg, site.lon_deg, site.height_m}},
                      {"sun_azimuth_deg", sun.azimuth_deg},
                      {"sun_elevation_deg", sun.elevation_deg},
                      {"sun_pixel", {d.pixel.x(), d.pixel.y()}},
                      {"sun_radius_px", d.radius_px},
                      {"sun_expected_radius_px", d.expected_radius_px},
                      {"sun_sigma_deg", d.sigma_deg},
                      {"sun_residual_deg", o.sun_residual_deg},
                      {"landmark_residual_deg", o.landmark_residual_deg},
                      {"horizon_residual_deg", o.horizon_residual_deg},
                      {"level", a.level},
                      {"level_residual_deg", o.level_residual_deg},
                      {"rotation_sigma_deg", o.rotation_sigma_deg},
                      {"mirror_solution", o.had_mirror_solution}};
  WriteFileAtomic(out, j.dump(2) + "\n");
  outputs.Commit();
  double az, el;
  AzElFromEnu(o.pose.rotation.col(2), &az, &el);
  std::printf(
      "%s: sun at pixel (%.2f, %.2f) (radius %.2f px, expected %.2f); camera looks at "
      "azimuth %.3f deg, elevation %.3f deg; rotation sigma %.4f deg\n",
      a.out.c_str(), d.pixel.x(), d.pixel.y(), d.radius_px, d.expected_radius_px, az, el,
      o.rotation_sigma_deg);
  for (size_t i = 0; i < o.landmark_residual_deg.size(); ++i) {
    std::printf("  landmark %zu residual %.4f deg\n", i + 1, o.landmark_residual_deg[i]);
  }
  for (size_t i = 0; i < o.horizon_residual_deg.size(); ++i) {
    std::printf("  horizon point %zu elevation %.4f deg\n", i + 1, o.horizon_residual_deg[i]);
  }
  if (o.had_mirror_solution) {
    std::printf("  note: a second (mirrored) rotation fits as well; the upright one was chosen\n");
  }
}

}  // namespace

void RegisterCalibEnvmap(CLI::App* calib) {
  auto e = std::make_shared<EnvmapArgs>();
  CLI::App* c = calib->add_subcommand(
      "envmap", "Assemble a lat-long environment map from oriented HDR photos (paper 3.3)");
  c->footer(
      "LIST has one photo per line: 'image.exr lens.json pose.json' (paths relative to LIST;\n"
      "'#' comments). Lens files are core/camera.h intrinsics (pinhole, fisheye or equirect),\n"
      "optionally with \"max_field_deg\"; pose files hold \"rotation\" (camera to ENU) and\n"
      "\"position\" as `rouen calib pose` / `rouen calib orient` write them.\n"
      "Output: ENV.exr (W x W/2 float RGB; row 0 zenith, last row nadir, column x at azimuth\n"
      "(x+0.5)/W*360 deg from north through east), ENV.coverage.exr (photos per pixel),\n"
      "ENV.mask.png (255 seen, 0 never seen; radiance 0 there) and ENV.json (summary).\n"
      "Example: rouen calib envmap --list env/photos.txt --width 1024 --out env.exr");
  c->add_option("--list", e->list, "Photo list file")->required();
  c->add_option("--out", e->out, "Radiance to write (.exr, or .hdr, .pfm, .tif)")->required();
  // The ranges of EnvmapOptions::Validate, told before the photos are read.
  c->add_option("--width", e->width, "Map width in pixels (even, 8..65536; height = width/2)")
      ->check(CLI::Range(8, 65536))
      ->capture_default_str();
  c->add_option("--supersample", e->supersample, "Sub-samples per pixel and axis (1..8)")
      ->check(CLI::Range(1, 8))
      ->capture_default_str();
  c->add_option("--feather", e->feather,
                "Fraction of each photo's half-size over which its weight falls to its edge")
      ->check(Within(0, 1))
      ->capture_default_str();
  c->add_option("--mask", e->mask, "Mask PNG (default: OUT with .mask.png)");
  c->add_option("--coverage", e->coverage, "Coverage count EXR (default: OUT with .coverage.exr)");
  c->add_option("--summary", e->summary, "Summary JSON (default: OUT with .json)");
  c->callback([e] { RunEnvmap(*e); });

  auto o = std::make_shared<OrientArgs>();
  CLI::App* r = calib->add_subcommand(
      "orient", "Orient a sky photo from its sun disc plus a landmark, the horizon or --level");
  r->footer(
      "The sun's disc is found in an HDR or ND-filtered image; its direction comes from --time\n"
      "and --site. The roll about the sun axis needs one more constraint: --landmark u,v,az,el\n"
      "(a pixel and its known azimuth/elevation, deg), --horizon u,v (pixels on the true\n"
      "horizon; repeat), or --level (the image rows are horizontal).\n"
      "Example: rouen calib orient --image sky.exr --lens fisheye.json\n"
      "  --time 2026-08-25T13:30:00-07:00 --site 37.8722,-122.2578,60 --landmark 812,990,41.5,2.1\n"
      "  --out sky.pose.json");
  r->add_option("--image", o->image, "Sky photo (HDR EXR, or an ND-filtered LDR frame)")
      ->required();
  r->add_option("--lens", o->lens, "Lens file (intrinsics JSON)")->required();
  r->add_option("--time", o->time, "ISO 8601 time of the photo with a zone")->required();
  r->add_option("--site", o->site, "LAT,LON,H (deg, deg, m)")->required();
  r->add_option("--landmark", o->landmarks, "u,v,azimuth,elevation (repeatable)");
  r->add_option("--horizon", o->horizon, "u,v of a horizon pixel (repeatable)");
  r->add_flag("--level", o->level, "Assume the camera is level (image rows horizontal)");
  r->add_option("--landmark-sigma", o->landmark_sigma, "Landmark uncertainty, deg")
      ->check(Within(1e-6, 90, "deg"))
      ->capture_default_str();
  r->add_option("--horizon-sigma", o->horizon_sigma, "Horizon point uncertainty, deg")
      ->check(Within(1e-6, 90, "deg"))
      ->capture_default_str();
  r->add_option("--position", o->position, "Camera position x,y,z in ENU metres (default 0)");
  r->add_option("--out", o->out, "Pose JSON to write")->required();
  r->callback([o] { RunOrient(*o); });
}

}  // namespace rouen
