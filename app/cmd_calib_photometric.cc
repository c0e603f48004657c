// rouen calib nd / rouen calib vignetting: ND filter transmission per channel and lens
// vignetting from flat fields.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "app/commands.h"
#include "app/options.h"
#include "calib/nd.h"
#include "calib/vignetting.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/outputs.h"
#include "core/response_curve.h"
#include "core/session.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rouen {
namespace {

struct NdArgs {
  std::string with, without, response, out, session, filter = "sun";
  double min_level = -1;
};

struct VignettingArgs {
  std::string flat, response, out, lens, session, camera;
  std::vector<std::string> images;
  int bin = 8;
  bool no_gradient = false, fit_centre = false;
};

// One listed set of frames, all LDR (digital) or all float radiance, of one size.
struct LoadedList {
  std::vector<Image> frames;
  std::vector<double> seconds;
  bool digital = false;
};

LoadedList LoadList(const std::string& list, const char* option) {
  const std::vector<ListedExposure> listed = ReadExposureList(list);
  LoadedList out;
  for (size_t k = 0; k < listed.size(); ++k) {
    Image im = ReadImage(listed[k].path);
    const bool digital = im.units == PixelUnits::kDigital;
    if (im.channels != 3) throw Error(listed[k].path + ": expected an RGB image");
    if (k == 0) {
      out.digital = digital;
    } else {
      if (digital != out.digital)
        throw Error(listed[k].path + ": mixes LDR and float images in " + option + " " + list);
      if (im.width != out.frames[0].width || im.height != out.frames[0].height)
        throw Error(listed[k].path + ": size " + std::to_string(im.width) + "x" +
                    std::to_string(im.height) + " differs from " + listed[0].path + " (" +
                    std::to_string(out.frames[0].width) + "x" +
                    std::to_string(out.frames[0].height) + ")");
    }
    out.frames.push_back(std::move(im));
    out.seconds.push_back(listed[k].seconds);
  }
  return out;
}

// Float frames: exposure-normalised mean (a flat weight per frame, longest exposures favoured
// when several are listed; no clipping is expected in float files).
Image AverageRadiance(const LoadedList& l) {
  Image out(l.frames[0].width, l.frames[0].height, 3, PixelUnits::kRadiance);
  double total = 0;
  for (double s : l.seconds) total += s;
  for (size_t k = 0; k < l.frames.size(); ++k)
    for (size_t i = 0; i < out.data.size(); ++i)
      out.data[i] += static_cast<float>(l.frames[k].data[i] / total);
  return out;
}

// Updates session.json as the session's one writer (refused while a capture holds the
// session, whose own session.json updates would otherwise undo this one).
void UpdateSessionInfo(const std::string& dir, const std::function<void(SessionInfo*)>& edit) {
  SessionWriter w = SessionWriter::Resume(dir);
  SessionInfo info = w.info();
  edit(&info);
  w.UpdateInfo(info);
}

void RunNd(const NdArgs& a) {
  if (a.out.empty() && a.session.empty())
    throw Error("give --out ND.json and/or --session DIR to store the result");
  OutputSet outputs;
  const std::string out = a.out.empty() ? "" : outputs.Add("--out", a.out, OutputKind::kFile);
  const LoadedList with = LoadList(a.with, "--with");
  const LoadedList without = LoadList(a.without, "--without");
  NdOptions opts;
  if (a.min_level >= 0) opts.min_relative_level = a.min_level;
  NdCalibration cal;
  if (with.digital || without.digital) {
    if (with.digital != without.digital)
      throw Error(a.with + " and " + a.without +
                  ": one lists LDR images, the other float images; use one kind for both");
    if (a.response.empty())
      throw Error(a.with +
                  ": 8-bit images need --response R.json (rouen calib response) to be "
                  "linearised");
    const ResponseCurve curve = ReadResponseCurve(a.response);
    Bracket bw, bo;
    bw.frames = with.frames;
    bw.exposures = with.seconds;
    bo.frames = without.frames;
    bo.exposures = without.seconds;
    if (bw.frames[0].width != bo.frames[0].width || bw.frames[0].height != bo.frames[0].height)
      throw Error(a.with + " and " + a.without + ": the images differ in size");
    cal = EstimateNdTransmission(bw, bo, curve, opts);
  } else {
    const Image lw = AverageRadiance(with), lo = AverageRadiance(without);
    if (lw.width != lo.width || lw.height != lo.height)
      throw Error(a.with + " and " + a.without + ": the images differ in size");
    cal = EstimateNdTransmission(lw, nullptr, lo, nullptr, opts);
  }
  for (int c = 0; c < 3; ++c) {
    const NdChannel& ch = cal.channel[c];
    if (ch.density < -ch.density_ci95 - 0.005)
      throw Error("channel " + std::to_string(c) + " is brighter through the filter (density " +
                  std::to_string(ch.density) + "); are --with and --without swapped, or the " +
                  "exposure times wrong?");
  }
  json j = cal;
  j["with"] = a.with;
  j["without"] = a.without;
  if (!a.out.empty()) WriteFileAtomic(out, j.dump(2) + "\n");
  if (!a.session.empty())
    UpdateSessionInfo(a.session, [&](SessionInfo* info) {
      info->nd_filters[a.filter] = NdFilter{cal.DensityRgb(), nullptr};
    });
  outputs.Commit();
  std::printf(
      "%s: ND density R %.4f G %.4f B %.4f (95%% +-%.4f %.4f %.4f; transmission %.3g %.3g "
      "%.3g) from %lld pixels\n",
      a.out.empty() ? a.session.c_str() : a.out.c_str(), cal.channel[0].density,
      cal.channel[1].density, cal.channel[2].density, cal.channel[0].density_ci95,
      cal.channel[1].density_ci95, cal.channel[2].density_ci95, cal.channel[0].transmission,
      cal.channel[1].transmission, cal.channel[2].transmission,
      static_cast<long long>(cal.channel[1].pixels));
  std::printf("rig TOML: [nd] sun_density = [%.4f, %.4f, %.4f]\n", cal.channel[0].density,
              cal.channel[1].density, cal.channel[2].density);
}

void RunVignetting(const VignettingArgs& a) {
  if (a.out.empty() && a.lens.empty() && a.session.empty())
    throw Error("give --out V.json, --lens LENS.json and/or --session DIR to store the result");
  if (!a.session.empty() && a.camera.empty())
    throw Error("--session needs --camera (the frames' device, device/target, or *)");
  OutputSet outputs;
  const std::string out = a.out.empty() ? "" : outputs.Add("--out", a.out, OutputKind::kFile);
  std::vector<std::string> paths;
  if (!a.flat.empty())
    for (const ListedExposure& e : ReadExposureList(a.flat)) paths.push_back(e.path);
  paths.insert(paths.end(), a.images.begin(), a.images.end());
  if (paths.empty()) throw Error("no flat-field images: give --flat LIST or image files");
  std::vector<Image> flats;
  for (const std::string& p : paths) {
    flats.push_back(ReadImage(p));
    const Image& im = flats.back();
    if (im.width != flats[0].width || im.height != flats[0].height)
      throw Error(p + ": size " + std::to_string(im.width) + "x" + std::to_string(im.height) +
                  " differs from " + paths[0] + " (" + std::to_string(flats[0].width) + "x" +
                  std::to_string(flats[0].height) + ")");
  }
  std::optional<ResponseCurve> curve;
  if (!a.response.empty()) curve = ReadResponseCurve(a.response);
  for (size_t k = 0; k < flats.size(); ++k)
    if (flats[k].units == PixelUnits::kDigital && !curve)
      throw Error(paths[k] + ": an 8-bit image needs --response R.json to be linearised");
  VignettingOptions o;
  o.bin = a.bin;
  o.fit_gradient = !a.no_gradient;
  o.fit_centre = a.fit_centre;
  if (o.fit_centre && o.fit_gradient)
    throw Error(
        "--fit-centre needs --no-gradient (a centre offset and an illumination "
        "gradient look the same to first order)");
  std::vector<const Image*> ptrs;
  for (const Image& f : flats) ptrs.push_back(&f);
  VignettingSummary s;
  const VignettingModel m = FitVignetting(ptrs, o, curve ? &*curve : nullptr, &s);
  if (!a.lens.empty()) {
    json lens;
    try {
      lens = json::parse(ReadFileToString(a.lens));
    } catch (const json::exception& e) {
      throw Error(a.lens + ": not JSON: " + e.what());
    }
    Intrinsics k;
    try {
      k = lens.get<Intrinsics>();
    } catch (const Error& e) {
      throw Error(a.lens + ": " + e.what());
    }
    if (std::abs(double(k.width) / k.height - double(m.width) / m.height) >
        0.01 * k.width / k.height)
      throw Error(a.lens + ": the lens is " + std::to_string(k.width) + "x" +
                  std::to_string(k.height) + ", the flat fields " + std::to_string(m.width) + "x" +
                  std::to_string(m.height) + " (another aspect ratio)");
    lens["vignetting"] = m;
    WriteFileAtomic(a.lens, lens.dump(2) + "\n");
  }
  if (!a.out.empty()) WriteFileAtomic(out, json(m).dump(2) + "\n");
  if (!a.session.empty())
    UpdateSessionInfo(a.session, [&](SessionInfo* info) { info->vignetting[a.camera] = m; });
  outputs.Commit();
  std::printf(
      "vignetting from %d flat frame%s (%d bins): V = 1 %+.4f r^2 %+.4f r^4 %+.4f r^6 about "
      "(%.1f, %.1f) px; corner fall-off %.3f; residual %.4f rms (relative)\n",
      s.frames, s.frames == 1 ? "" : "s", s.bins_used, m.a[0], m.a[1], m.a[2], m.cx, m.cy,
      s.corner_falloff, s.residual_rms);
}

}  // namespace

void RegisterCalibPhotometric(CLI::App* calib) {
  auto n = std::make_shared<NdArgs>();
  CLI::App* c = calib->add_subcommand(
      "nd", "ND filter transmission per channel from frames with and without the filter");
  c->footer(
      "Photograph one static, evenly lit scene with the filter (--with) and without it\n"
      "(--without), on a tripod, at exposures that leave most of it neither dark nor\n"
      "saturated (a single frame each is enough; brackets are merged). LISTs hold\n"
      "'image seconds' per line, paths relative to the list; seconds are the real exposure\n"
      "times (x gain if it changed), not corrected for the filter. 8-bit images need\n"
      "--response; float (EXR) images are linear and divided by their seconds (list 1 for\n"
      "images already normalised). The density per channel is the\n"
      "median of log10(L_with / L_without) over pixels well exposed in both, with a 95%\n"
      "interval. --session stores it in session.json extra.nd_filters.FILTER, which the\n"
      "pipeline applies per channel to frames of that (mean) density.\n"
      "Example: rouen calib nd --with nd.txt --without open.txt --response response.json \\\n"
      "           --out nd.json --session s1 --filter sun");
  c->add_option("--with", n->with, "Exposure list of the frames through the filter")->required();
  c->add_option("--without", n->without, "Exposure list of the frames without it")->required();
  c->add_option("--response", n->response, "Response curve JSON (for 8-bit images)");
  c->add_option("--out", n->out, "ND calibration JSON to write");
  c->add_option("--session", n->session, "Session folder whose nd_filters to update");
  c->add_option("--filter", n->filter, "Filter name in the session (default: sun)");
  c->add_option("--min-level", n->min_level,
                "Ignore pixels below this fraction of the image median (default 0.05)")
      ->check(Within(0, 0.999));
  c->callback([n] { RunNd(*n); });

  auto v = std::make_shared<VignettingArgs>();
  CLI::App* d = calib->add_subcommand("vignetting",
                                      "Lens vignetting (radial fall-off) from flat-field frames");
  d->footer(
      "Flat fields: frames of a uniform field filling the view (an overcast sky through a\n"
      "diffuser, a light panel), each exposed without clipping; several frames average the\n"
      "noise. Model: V(r) = 1 + a1 r^2 + a2 r^4 + a3 r^6, r from the optical centre over the\n"
      "half-diagonal. Each frame is scaled by its own level and a linear illumination\n"
      "gradient (disable with --no-gradient); the centre is the image centre unless\n"
      "--fit-centre (with --no-gradient: an offset centre and a gradient look alike).\n"
      "8-bit images need --response. --lens adds \"vignetting\" to a lens JSON; --session\n"
      "stores it in session.json extra.vignetting.CAMERA (a device id, device/target, or *),\n"
      "which the pipeline divides out of every bracket of that camera.\n"
      "Example: rouen calib vignetting --flat flats.txt --response response.json \\\n"
      "           --out vignetting.json --lens rigs/lenses/uvc-1080p-78deg.json");
  d->add_option("--flat", v->flat, "List of flat-field images ('image seconds' per line)");
  d->add_option("images", v->images, "Flat-field images (instead of or besides --flat)");
  d->add_option("--response", v->response, "Response curve JSON (for 8-bit images)");
  d->add_option("--out", v->out, "Vignetting model JSON to write");
  d->add_option("--lens", v->lens, "Lens JSON to add the model to (rewritten atomically)");
  d->add_option("--session", v->session, "Session folder to store the model in");
  d->add_option("--camera", v->camera, "With --session: device id, device/target or *");
  d->add_option("--bin", v->bin, "Bin size in pixels, 1..256 (default 8)")
      ->check(CLI::Range(1, 256));
  d->add_flag("--no-gradient", v->no_gradient, "Do not fit an illumination gradient");
  d->add_flag("--fit-centre", v->fit_centre, "Fit the optical centre (needs --no-gradient)");
  d->callback([v] { RunVignetting(*v); });
}

}  // namespace rouen
