// rouen sky fit / rouen sky render: the sky model of Yu & Malik 1998 §3.2 (eq. 9) fitted to
// an equirectangular sky panorama or to measured directions (CSV), and drawn back from a fit.
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
  std::string image, samples, projection, mask, out, model = "7", weighting;
  std::string residuals;
  double sun_azimuth = 0, sun_elevation = 0, azimuth_offset = 0;
  double min_elevation = 3, sun_exclusion = 3;
  int max_samples = 20000;
  int min_directions = SkyFitOptions{}.min_directions;
  double min_spread = SkyFitOptions{}.min_spread_deg;
  double norm_p = 0;    // 0: the solve's default
  double norm_eps = 0;  // 0: the solve's default
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

// The samples of a fit and what its error figures are taken over (FIT.json's
// rel_error_median/p90): for an image every fitted pixel, weighted by its solid angle (`pixel`
// its index, for the residual map); for a CSV its directions, each once.
struct FitInput {
  std::vector<SkySample> samples, scored;
  std::vector<size_t> pixel;
  std::string source, mask_source;  // the file named in messages; "user", "automatic", "none"
  int width = 0, height = 0, left_out = 0;
};

FitInput ImageInput(const SkyFitArgs& a, const Eigen::Vector3d& sun, const SkySampleOptions& sso) {
  FitInput in;
  in.source = a.image;
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
  in.width = img.width;
  in.height = img.height;
  const Intrinsics k = Intrinsics::Equirect(img.width, img.height);
  const Pose pose = EquirectPose(a.azimuth_offset);
  const size_t np = static_cast<size_t>(img.width) * img.height;

  // Sky mask: the user's (nonzero = sky), automatic segmentation, or every pixel.
  std::vector<uint8_t> mask;
  if (!a.mask.empty()) {
    mask = ReadMask(a.mask, img.width, img.height, "the image " + a.image);
    in.mask_source = "user";
  } else if (!a.no_segment) {
    SkySegmentOptions so;
    so.sun_exclusion_deg = a.sun_exclusion;
    mask = SegmentSky(img, k, pose, sun, so);
    in.mask_source = "automatic";
  } else {
    mask.assign(np, 1);
    in.mask_source = "none";
  }
  in.samples = ExtractSkySamples(img, &mask, k, pose, sun, sso);

  // Every fitted pixel (the samples' selection, not thinned), weighted by its solid angle.
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const size_t p = static_cast<size_t>(y) * img.width + x;
      if (!mask[p]) continue;
      const Eigen::Vector3d d =
          (pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5))).normalized();
      if (!InSkyFitRegion(d, sun, sso)) continue;
      const Eigen::Vector3d y3(img.data[p * 3], img.data[p * 3 + 1], img.data[p * 3 + 2]);
      if (!y3.allFinite() || !(y3.minCoeff() > 0)) continue;
      in.scored.push_back({d, y3, PixelSolidAngle(k, x, y)});
      in.pixel.push_back(p);
    }
  }
  return in;
}

FitInput CsvInput(const SkyFitArgs& a, const Eigen::Vector3d& sun, const SkySampleOptions& sso) {
  FitInput in;
  in.source = a.samples;
  for (const SkySample& s : ReadSkySamplesCsv(a.samples)) {
    if (InSkyFitRegion(s.dir, sun, sso)) {
      in.samples.push_back(s);
    } else {
      ++in.left_out;
    }
  }
  in.scored = in.samples;
  return in;
}

void RunFit(const SkyFitArgs& a) {
  if (a.image.empty() == a.samples.empty()) {
    throw Error("sky fit: give either --image (a sky panorama) or --samples (a CSV of directions)");
  }
  const bool csv = !a.samples.empty();
  if (csv && (!a.mask.empty() || a.no_segment || !a.residuals.empty() || a.azimuth_offset != 0 ||
              !a.projection.empty())) {
    throw Error(
        "sky fit: --projection, --mask, --no-segment, --azimuth-offset and --residuals apply to "
        "--image, not to --samples");
  }
  if (!csv && a.projection != "equirect") {
    throw Error("sky fit: projection '" + a.projection +
                "' is not supported (only equirect; --projection is required with --image)");
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
  if (a.norm_eps > 0) fo.norm_eps = a.norm_eps;
  fo.min_directions = a.min_directions;
  fo.min_spread_deg = a.min_spread;
  fo.Validate();
  OutputSet outputs;
  outputs.Protect("--image", a.image);
  outputs.Protect("--mask", a.mask);
  outputs.Protect("--samples", a.samples);
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  const std::string residuals =
      a.residuals.empty() ? "" : outputs.Add("--residuals", a.residuals, OutputKind::kRadiance);
  const Eigen::Vector3d sun = EnuFromAzEl(a.sun_azimuth, a.sun_elevation).normalized();
  SkySampleOptions sso;
  sso.min_elevation_deg = a.min_elevation;
  sso.min_sun_distance_deg = a.sun_exclusion;
  sso.max_samples = a.max_samples;
  const FitInput in = csv ? CsvInput(a, sun, sso) : ImageInput(a, sun, sso);

  if (const std::string problem = SkyCoverageProblem(MeasureSkyCoverage(in.samples), fo);
      !problem.empty()) {
    std::string where = in.samples.size() == 1
                            ? "1 usable sample"
                            : std::to_string(in.samples.size()) + " usable samples";
    if (csv) {
      where += ", " + std::to_string(in.left_out) +
               " directions left out (below --min-elevation or within --sun-exclusion of the sun)";
    } else {
      where += ", mask: " + in.mask_source;
    }
    std::string hint;
    if (in.mask_source == "automatic") {
      hint = "; the automatic segmentation kept this little sky: give the sky pixels with --mask";
    }
    throw Error(in.source + ": " + problem + " (" + where + ")" + hint);
  }
  SkyModel fit;
  const SkyFitSummary summary = FitSky(in.samples, sun, fo, &fit);

  // Relative residuals over what is scored, weighted (solid angle, or per direction).
  Image res;
  if (!csv) res = Image(in.width, in.height, 3, PixelUnits::kOther, 0.f);
  std::array<std::vector<double>, 3> rel;
  std::vector<double> pooled, w, pooled_w;
  for (size_t i = 0; i < in.scored.size(); ++i) {
    const SkySample& s = in.scored[i];
    const Eigen::Vector3d l = fit.Radiance(s.dir);
    w.push_back(s.weight);
    for (int c = 0; c < 3; ++c) {
      const double r = (l[c] - s.radiance[c]) / s.radiance[c];
      if (!csv) res.data[in.pixel[i] * 3 + c] = static_cast<float>(r);
      rel[c].push_back(std::abs(r));
      pooled.push_back(std::abs(r));
      pooled_w.push_back(s.weight);
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
  j["norm_eps"] = fo.norm_eps;
  if (csv) {
    j["samples_file"] = a.samples;
    j["directions_left_out"] = in.left_out;
    j["error_weighting"] = "per direction";
  } else {
    j["projection"] = "equirect";
    j["image"] = a.image;
    j["width"] = in.width;
    j["height"] = in.height;
    j["azimuth_offset_deg"] = a.azimuth_offset;
    j["mask"] = in.mask_source;
    j["fitted_pixels"] = in.scored.size();
    j["error_weighting"] = "solid angle";
  }
  j["sun_azimuth_deg"] = a.sun_azimuth;
  j["sun_elevation_deg"] = a.sun_elevation;
  j["samples"] = summary.samples;
  j["seconds"] = summary.seconds;
  for (int c = 0; c < 3; ++c) {
    j["channels"][c]["rel_error_median"] = WeightedQuantile(rel[c], w, 0.5);
    j["channels"][c]["rel_error_p90"] = WeightedQuantile(rel[c], w, 0.9);
    j["channels"][c]["iterations"] = summary.channel[c].iterations;
  }
  j["rel_error_median"] = WeightedQuantile(pooled, pooled_w, 0.5);
  j["rel_error_p90"] = WeightedQuantile(pooled, pooled_w, 0.9);
  if (!a.residuals.empty()) {
    WriteImage(residuals, res, StoredType::kFloat);
    j["residual_map"] = a.residuals;
  }
  WriteFileAtomic(out, j.dump(2) + "\n");
  outputs.Commit();
  if (csv) {
    std::printf("sky fit (%s): %d directions of %s (%d left out near the sun or horizon)\n",
                SkyModelKindName(summary.model), summary.samples, a.samples.c_str(), in.left_out);
  } else {
    std::printf("sky fit (%s): %d samples, %zu fitted pixels (mask: %s)\n",
                SkyModelKindName(summary.model), summary.samples, in.scored.size(),
                in.mask_source.c_str());
  }
  if (summary.model == SkyModelKind::kCie)
    std::printf("  best CIE standard sky: type %d (%s)\n", summary.cie_type,
                CieStandardSky(summary.cie_type).name);
  const char* names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    const SkyParams& p = fit.channel[c];
    std::printf(
        "  %s  Lz %.5g a %.4f b %.4f c %.4f d %.4f e %.4f h %.4f   rel error median "
        "%.4f p90 %.4f\n",
        names[c], p.Lz, p.a, p.b, p.c, p.d, p.e, p.h,
        j["channels"][c]["rel_error_median"].get<double>(),
        j["channels"][c]["rel_error_p90"].get<double>());
  }
  std::printf("wrote %s\n", a.out.c_str());
}

void RunRender(const SkyRenderArgs& a) {
  if (a.width < 8 || a.width > 16384 || a.width % 2 != 0)
    throw Error("sky render: --width must be even and in [8, 16384], got " +
                std::to_string(a.width));
  OutputSet outputs;
  outputs.Protect("--fit", a.fit);
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
  CLI::App* c = sky->add_subcommand(
      "fit", "Fit the sky model per colour channel to a panorama or to measured directions");
  c->footer(
      "Input: --image (a sky panorama) or --samples (measured directions), one of them.\n"
      "Equirect convention: row 0 is the zenith, the last row the nadir, column x looks at\n"
      "azimuth (x + 0.5) / W * 360 deg (+ --azimuth-offset) from north through east.\n"
      "Sky pixels: --mask PNG (nonzero = sky) if given, else automatic segmentation (smooth,\n"
      "bright, blue regions connected to the zenith), or every pixel with --no-segment; always\n"
      "above --min-elevation and more than --sun-exclusion from the sun. Every pixel counts by\n"
      "its solid angle (an equirect's rows near the zenith hold many pixels per steradian), in\n"
      "the fit and in the error figures; --max-samples thins them evenly over solid angle.\n"
      "--samples FILE.csv: one direction per line, 'azimuth_deg, elevation_deg, R, G, B'\n"
      "(compass azimuth from north through east, elevation in [0, 90], linear radiance > 0 per\n"
      "channel), or 'idx, azimuth_deg, elevation_deg, R, G, B' as sky scanners write them; every\n"
      "line has the field count of the first; a first line that does not start with a number\n"
      "is a header; blank lines and '#' lines are skipped; two lines within 0.01 deg of each\n"
      "other are an error. Directions below --min-elevation or within --sun-exclusion of the\n"
      "sun are left out, as pixels are; each direction counts once.\n"
      "Refused as too little sky: fewer than --min-directions distinct directions (3 per model\n"
      "parameter, 21 for eq. 9: a least-squares fit's in-sample error is then at least\n"
      "1/sqrt(2) of its error on fresh measurements; directions count once per ~10 x 10 deg\n"
      "cell of the sky and once per distinct radiance), or directions as concentrated as a\n"
      "cap of radius below --min-spread (60 deg: half the hemisphere).\n"
      "FIT.json: per channel Lz,a,b,c,d,e,h of eq. 9 (angles in radians inside the model),\n"
      "rel_error_median and rel_error_p90 of |model - y| / y per direction of the sky: over\n"
      "the fitted pixels weighted by solid angle (image), or over the fitted directions\n"
      "(CSV); error_weighting says which; the model kind.\n"
      "Examples: rouen sky fit --image sky.exr --projection equirect --sun-azimuth 190\n"
      "            --sun-elevation 62 --out fit.json\n"
      "          rouen sky fit --samples scan.csv --sun-azimuth 99.8 --sun-elevation 9.7\n"
      "            --sun-exclusion 12 --out fit.json");
  c->add_option("--image", f->image, "Sky panorama, floating-point radiance (EXR/HDR)");
  c->add_option("--samples", f->samples,
                "CSV of measured directions: [idx,] azimuth_deg, elevation_deg, R, G, B");
  c->add_option("--projection", f->projection, "Image projection (only 'equirect'; with --image)");
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
  c->add_option("--norm-eps", f->norm_eps,
                "Relative error below which the norm is smoothed to a square (default 0.005, as "
                "in rouen solve; scipy's soft_l1 with f_scale 0.01 is 0.01)")
      ->check(Within(1e-6, 0.1));
  c->add_option("--min-elevation", f->min_elevation, "Skip samples below this elevation, deg")
      ->check(Within(0, 89, "deg"));
  c->add_option("--sun-exclusion", f->sun_exclusion, "Skip samples this close to the sun, deg")
      ->check(Within(0, 90, "deg"));
  c->add_option("--max-samples", f->max_samples,
                "Pixels fitted at most, spread evenly over solid angle")
      ->check(CLI::Range(1, 100000000));
  c->add_option("--min-directions", f->min_directions,
                "Fewest distinct directions accepted (default 21: 3 per parameter)")
      ->check(CLI::Range(7, 1000000));
  c->add_option("--min-spread", f->min_spread,
                "Least spread of the directions accepted, as a cap radius, deg (default 60)")
      ->check(Within(0, 90, "deg"));
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
