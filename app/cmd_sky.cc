// rouen sky fit / rouen sky render: the sky model of Yu & Malik 1998 §3.2 (eq. 9) fitted to
// an equirectangular sky panorama, and drawn back from a fit.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "core/angles.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/outputs.h"
#include "core/solar.h"
#include "core/stats.h"
#include "pipeline/solve_config.h"
#include "solve/sky_cie.h"
#include "solve/sky_fit.h"
#include "solve/sky_model.h"
#include "solve/sky_segment.h"

namespace rouen {
namespace {

struct SkyFitArgs {
  std::string image, projection = "equirect", mask, out, model = "7", weighting;
  std::string residuals;
  double sun_azimuth = 0, sun_elevation = 0, azimuth_offset = 0;
  double min_elevation = 3, sun_exclusion = 3;
  int max_samples = 20000;
  double norm_p = 0;  // 0: the solve's default
  bool no_segment = false;
};

struct SkyRenderArgs {
  std::string fit, out;
  int width = 1024;
  double azimuth_offset = 0;
};

// Equirect convention of `rouen sky`: row 0 the zenith, the last row the nadir, column x at
// azimuth (x + 0.5) / W * 360 deg + offset from north through east (Pose::Level, azimuth 0).
Pose EquirectPose(double azimuth_offset_deg) {
  return Pose::Level(Eigen::Vector3d::Zero(), azimuth_offset_deg, 0);
}

void RunFit(const SkyFitArgs& a) {
  if (a.projection != "equirect") {
    throw Error("sky fit: projection '" + a.projection + "' is not supported (only equirect)");
  }
  if (!std::isfinite(a.sun_elevation) || a.sun_elevation < -5 || a.sun_elevation > 90) {
    throw Error("sky fit: --sun-elevation " + std::to_string(a.sun_elevation) +
                " deg is outside [-5, 90] (a sky with the sun further below the horizon has no "
                "sun-centred structure to fit)");
  }
  if (!std::isfinite(a.sun_azimuth) || !std::isfinite(a.azimuth_offset))
    throw Error("sky fit: --sun-azimuth and --azimuth-offset must be finite");
  // The fit `rouen solve` makes, unless told otherwise.
  SkyFitOptions fo = DefaultSolveConfig(false).sky_fit;
  fo.model = ParseSkyModelKind(a.model);
  if (a.weighting == "paper") {
    fo.weighting = SkyWeighting::kPaper;
  } else if (a.weighting == "relative") {
    fo.weighting = SkyWeighting::kRelative;
  } else if (!a.weighting.empty()) {
    throw Error("sky fit: --weighting '" + a.weighting + "' is not one of paper, relative");
  }
  if (a.norm_p > 0) fo.norm_p = a.norm_p;
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  const std::string residuals =
      a.residuals.empty() ? "" : outputs.Add("--residuals", a.residuals, OutputKind::kRadiance);
  Image img = ReadImage(a.image);
  if (img.units != PixelUnits::kRadiance) {
    throw Error(a.image + ": not a floating-point radiance image (use EXR or HDR, not 8/16-bit)");
  }
  if (img.channels == 1) {
    Image rgb(img.width, img.height, 3, PixelUnits::kRadiance);
    for (size_t p = 0; p < img.data.size(); ++p)
      for (int c = 0; c < 3; ++c) rgb.data[p * 3 + c] = img.data[p];
    img = std::move(rgb);
  } else if (img.channels >= 3) {
    if (img.channels > 3) {  // drop alpha
      Image rgb(img.width, img.height, 3, PixelUnits::kRadiance);
      for (size_t p = 0; p < static_cast<size_t>(img.width) * img.height; ++p)
        for (int c = 0; c < 3; ++c) rgb.data[p * 3 + c] = img.data[p * img.channels + c];
      img = std::move(rgb);
    }
  } else {
    throw Error(a.image + ": has " + std::to_string(img.channels) + " channels, need 1 or 3");
  }
  if (img.width < 8 || img.height < 4)
    throw Error(a.image + ": " + std::to_string(img.width) + "x" + std::to_string(img.height) +
                " is too small for a sky panorama");
  const Intrinsics k = Intrinsics::Equirect(img.width, img.height);
  const Pose pose = EquirectPose(a.azimuth_offset);
  const Eigen::Vector3d sun = EnuFromAzEl(a.sun_azimuth, a.sun_elevation).normalized();
  const size_t np = static_cast<size_t>(img.width) * img.height;

  // Sky mask: the user's (nonzero = sky), automatic segmentation, or every pixel.
  std::vector<uint8_t> mask;
  std::string mask_source;
  if (!a.mask.empty()) {
    mask = ReadMask(a.mask, img.width, img.height, "the image " + a.image);
    mask_source = "user";
  } else if (!a.no_segment) {
    SkySegmentOptions so;
    so.sun_exclusion_deg = a.sun_exclusion;
    mask = SegmentSky(img, k, pose, sun, so);
    mask_source = "automatic";
  } else {
    mask.assign(np, 1);
    mask_source = "none";
  }

  SkySampleOptions sso;
  sso.min_elevation_deg = a.min_elevation;
  sso.min_sun_distance_deg = a.sun_exclusion;
  sso.max_samples = a.max_samples;
  const std::vector<SkySample> samples = ExtractSkySamples(img, &mask, k, pose, sun, sso);
  if (static_cast<int>(samples.size()) < fo.min_samples) {
    throw Error(a.image + ": only " + std::to_string(samples.size()) +
                " usable sky pixels (mask: " + mask_source + "), need at least " +
                std::to_string(fo.min_samples));
  }
  SkyModel fit;
  const SkyFitSummary summary = FitSky(samples, sun, fo, &fit);

  // Residuals over every fitted pixel (the same selection as the samples, not thinned).
  const double z0 = std::sin(a.min_elevation * kDeg), cos_sun = std::cos(a.sun_exclusion * kDeg);
  Image res(img.width, img.height, 3, PixelUnits::kOther, 0.f);
  std::array<std::vector<double>, 3> rel;
  std::vector<double> pooled;
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const size_t p = static_cast<size_t>(y) * img.width + x;
      if (!mask[p]) continue;
      const Eigen::Vector3d d =
          (pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
      if (d.z() < z0 || d.dot(sun) > cos_sun) continue;
      bool ok = true;
      for (int c = 0; c < 3; ++c) {
        ok = ok && std::isfinite(img.data[p * 3 + c]) && img.data[p * 3 + c] > 0;
      }
      if (!ok) continue;
      const Eigen::Vector3d l = fit.Radiance(d);
      for (int c = 0; c < 3; ++c) {
        const double r = (l[c] - img.data[p * 3 + c]) / img.data[p * 3 + c];
        res.at(x, y, c) = static_cast<float>(r);
        rel[c].push_back(std::abs(r));
        pooled.push_back(std::abs(r));
      }
    }
  }

  nlohmann::json j = fit;
  j["model"] = SkyModelKindName(summary.model);
  if (summary.model == SkyModelKind::kCie) {
    j["cie_type"] = summary.cie_type;
    j["cie_name"] = CieStandardSky(summary.cie_type).name;
  }
  j["weighting"] = fo.weighting == SkyWeighting::kPaper ? "paper" : "relative";
  j["norm_p"] = fo.norm_p;
  j["projection"] = "equirect";
  j["image"] = a.image;
  j["width"] = img.width;
  j["height"] = img.height;
  j["azimuth_offset_deg"] = a.azimuth_offset;
  j["sun_azimuth_deg"] = a.sun_azimuth;
  j["sun_elevation_deg"] = a.sun_elevation;
  j["mask"] = mask_source;
  j["samples"] = summary.samples;
  j["fitted_pixels"] = rel[0].size();
  j["seconds"] = summary.seconds;
  for (int c = 0; c < 3; ++c) {
    j["channels"][c]["rel_error_median"] = Quantile(rel[c], 0.5);
    j["channels"][c]["rel_error_p90"] = Quantile(rel[c], 0.9);
    j["channels"][c]["iterations"] = summary.channel[c].iterations;
  }
  j["rel_error_median"] = Quantile(pooled, 0.5);
  j["rel_error_p90"] = Quantile(pooled, 0.9);
  if (!a.residuals.empty()) {
    WriteImage(residuals, res, StoredType::kFloat);
    j["residual_map"] = a.residuals;
  }
  WriteFileAtomic(out, j.dump(2) + "\n");
  outputs.Commit();
  std::printf("sky fit (%s): %d samples, %zu fitted pixels (mask: %s)\n",
              SkyModelKindName(summary.model), summary.samples, rel[0].size(), mask_source.c_str());
  if (summary.model == SkyModelKind::kCie)
    std::printf("  best CIE standard sky: type %d (%s)\n", summary.cie_type,
                CieStandardSky(summary.cie_type).name);
  const char* names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    const SkyParams& p = fit.channel[c];
    std::printf(
        "  %s  Lz %.5g a %.4f b %.4f c %.4f d %.4f e %.4f h %.4f   rel error median "
        "%.4f p90 %.4f\n",
        names[c], p.Lz, p.a, p.b, p.c, p.d, p.e, p.h, Quantile(rel[c], 0.5), Quantile(rel[c], 0.9));
  }
  std::printf("wrote %s\n", a.out.c_str());
}

void RunRender(const SkyRenderArgs& a) {
  if (a.width < 8 || a.width > 16384 || a.width % 2 != 0)
    throw Error("sky render: --width must be even and in [8, 16384], got " +
                std::to_string(a.width));
  OutputSet outputs;
  const std::string out = outputs.Add("--out", a.out, OutputKind::kRadiance);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(ReadFileToString(a.fit));
  } catch (const nlohmann::json::exception& e) {
    throw Error(a.fit + ": not valid JSON (" + e.what() + ")");
  }
  SkyModel m;
  try {
    m = j.get<SkyModel>();
  } catch (const Error& e) {
    throw Error(a.fit + ": " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw Error(a.fit + ": " + e.what());
  }
  const int w = a.width, h = a.width / 2;
  const Intrinsics k = Intrinsics::Equirect(w, h);
  const Pose pose = EquirectPose(a.azimuth_offset);
  Image img(w, h, 3, PixelUnits::kRadiance);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      const Eigen::Vector3d l = m.Radiance(d.normalized());
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(l[c]) || l[c] < 0)
          throw Error(a.fit + ": the sky model gives a non-finite or negative radiance");
        img.at(x, y, c) = static_cast<float>(l[c]);
      }
    }
  }
  WriteImage(out, img, StoredType::kFloat);
  outputs.Commit();
  std::printf("wrote %s (%dx%d)\n", a.out.c_str(), w, h);
}

}  // namespace

void RegisterSky(CLI::App& app) {
  CLI::App* sky = app.add_subcommand("sky", CommandSummary("sky"));
  sky->require_subcommand(1);

  auto f = std::make_shared<SkyFitArgs>();
  CLI::App* c = sky->add_subcommand("fit", "Fit the sky model per colour channel to a panorama");
  c->footer(
      "Equirect convention: row 0 is the zenith, the last row the nadir, column x looks at\n"
      "azimuth (x + 0.5) / W * 360 deg (+ --azimuth-offset) from north through east.\n"
      "Sky pixels: --mask PNG (nonzero = sky) if given, else automatic segmentation (smooth,\n"
      "bright, blue regions connected to the zenith), or every pixel with --no-segment; always\n"
      "above --min-elevation and more than --sun-exclusion from the sun.\n"
      "FIT.json: per channel Lz,a,b,c,d,e,h of eq. 9 (angles in radians inside the model),\n"
      "rel_error_median and rel_error_p90 over the fitted pixels; the model kind.\n"
      "Example: rouen sky fit --image sky.exr --projection equirect --sun-azimuth 190\n"
      "           --sun-elevation 62 --out fit.json");
  c->add_option("--image", f->image, "Sky panorama, floating-point radiance (EXR/HDR)")->required();
  c->add_option("--projection", f->projection, "Image projection (only 'equirect')")->required();
  c->add_option("--sun-azimuth", f->sun_azimuth, "Sun azimuth, degrees from north eastward")
      ->required();
  c->add_option("--sun-elevation", f->sun_elevation, "Sun elevation, degrees (>= -5)")->required();
  c->add_option("--azimuth-offset", f->azimuth_offset,
                "Azimuth of the image's left edge, degrees (rotates the panorama)")
      ->check(Within(-360, 360, "deg"));
  c->add_option("--mask", f->mask, "Sky mask PNG of the image's size, nonzero = sky");
  c->add_flag("--no-segment", f->no_segment, "Without --mask: use every pixel, no segmentation");
  c->add_option("--model", f->model, "7 (eq. 9), perez5 (h = 1) or cie (best CIE standard sky)");
  c->add_option("--weighting", f->weighting,
                "paper (eq. 10, sigma = y / log y) or relative (sigma = y; the default, as in "
                "rouen solve)");
  c->add_option("--norm", f->norm_p,
                "Exponent p of the residuals' norm: 2 is eq. 10's least squares, 1 (the "
                "default, as in rouen solve) is robust to regions eq. 9 cannot follow")
      ->check(Within(1, 16));
  c->add_option("--min-elevation", f->min_elevation, "Skip pixels below this elevation, deg")
      ->check(Within(-90, 90, "deg"));
  c->add_option("--sun-exclusion", f->sun_exclusion, "Skip pixels this close to the sun, deg")
      ->check(Within(0, 180, "deg"));
  c->add_option("--max-samples", f->max_samples, "Pixels fitted, spread over solid angle")
      ->check(CLI::Range(1, 100000000));
  c->add_option("--residuals", f->residuals,
                "Write the residual map (model - y) / y per channel here (EXR; 0 = not fitted)");
  c->add_option("--out", f->out, "FIT.json to write")->required();
  c->callback([f] { RunFit(*f); });

  auto r = std::make_shared<SkyRenderArgs>();
  CLI::App* rc = sky->add_subcommand("render", "Draw a fitted sky as an equirect panorama");
  rc->footer(
      "Example: rouen sky render fit.json --out sky.exr --width 1024\n"
      "Below the horizon each column shows its horizon value.");
  rc->add_option("fit", r->fit, "FIT.json from `rouen sky fit`")->required();
  rc->add_option("--out", r->out, "Radiance to write (.exr, or .hdr, .pfm, .tif)")->required();
  rc->add_option("--width", r->width,
                 "Panorama width in pixels, even, 8..16384 (height = width / 2)")
      ->check(CLI::Range(8, 16384));
  rc->add_option("--azimuth-offset", r->azimuth_offset, "Azimuth of the left edge, degrees")
      ->check(Within(-360, 360, "deg"));
  rc->callback([r] { RunRender(*r); });
}

}  // namespace rouen
