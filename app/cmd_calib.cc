// rouen calib response / rouen hdr: response curve and HDR merge from a list of exposures.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/command_list.h"
#include "app/commands.h"
#include "app/options.h"
#include "calib/hdr.h"
#include "calib/response.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/limits.h"
#include "core/list_file.h"
#include "core/outputs.h"
#include "core/response_curve.h"
#include "core/text.h"

namespace rouen {

void ForEachListLine(const std::string& list,
                     const std::function<void(const std::vector<std::string>& words,
                                              const std::string& where)>& line) {
  for (const ListLine& l : ReadListFile(list)) line(l.words, l.where);
}

nlohmann::json ReadJsonFile(const std::string& path, const char* what) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw Error(path + ": no such " + what + " file");
  try {
    return nlohmann::json::parse(ReadFileToString(path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not valid JSON (" + e.what() + ")");
  }
}

std::vector<ListedExposure> ReadExposureList(const std::string& list) {
  const std::filesystem::path base = std::filesystem::path(list).parent_path();
  std::vector<ListedExposure> out;
  ForEachListLine(list, [&](const std::vector<std::string>& words, const std::string& where) {
    if (words.size() != 2) throw Error(where + ": expected 'image seconds'");
    double s = 0;
    if (!ParseDecimal(words[1], &s))
      throw Error(where + ": exposure '" + words[1] + "' is not a number of seconds");
    Require(ExposureProblem(s), where);
    std::filesystem::path p(words[0]);
    if (p.is_relative()) p = base / p;
    out.push_back({p.string(), s});
  });
  return out;
}

Bracket LoadBracket(const std::vector<ListedExposure>& listed) {
  Bracket b;
  for (const ListedExposure& e : listed) {
    Image im = ReadImage(e.path);
    if (im.units != PixelUnits::kDigital)
      throw Error(e.path + ": expected an 8- or 16-bit LDR photograph, got a float image");
    if (im.channels != 3) throw Error(e.path + ": expected an RGB image");
    if (!b.frames.empty() && (im.width != b.frames[0].width || im.height != b.frames[0].height))
      throw Error(e.path + ": size " + std::to_string(im.width) + "x" + std::to_string(im.height) +
                  " differs from " + listed[0].path);
    b.frames.push_back(std::move(im));
    b.exposures.push_back(e.seconds);
  }
  return b;
}

namespace {

struct ResponseArgs {
  std::string list, out, method = "debevec";
  int samples = 0;
  double lambda = 0;
};
struct HdrArgs {
  std::string list, response, out;
};

void RunResponse(const ResponseArgs& a) {
  ResponseOptions opts;
  if (a.samples > 0) opts.samples_per_bracket = a.samples;
  if (a.lambda > 0) opts.lambda = a.lambda;
  if (a.method == "debevec") {
    opts.method = ResponseMethod::kDebevecMalik;
  } else if (a.method == "robertson") {
    opts.method = ResponseMethod::kRobertson;
  } else if (a.method == "mitsunaga") {
    opts.method = ResponseMethod::kMitsunagaNayar;
  } else {
    throw Error("--method '" + a.method + "': expected debevec, robertson or mitsunaga");
  }
  OutputSet outputs;
  outputs.Protect("--list", a.list);
  const std::string out = outputs.Add("--out", a.out, OutputKind::kFile);
  std::vector<Bracket> brackets{LoadBracket(ReadExposureList(a.list))};
  ResponseSummary summary;
  ResponseCurve curve = RecoverResponse(brackets, opts, &summary);
  WriteResponseCurve(out, curve);
  outputs.Commit();
  std::printf(
      "%s: %s response curve from %zu images, %d samples, fit residual %.4f (ln units; "
      "method's own residual %.4g), %.2f s\n",
      a.out.c_str(), ResponseMethodName(summary.method), brackets[0].frames.size(),
      summary.samples_used, summary.residual_rms, summary.method_residual, summary.seconds);
}

void RunHdr(const HdrArgs& a) {
  OutputSet outputs;
  outputs.Protect("--list", a.list);
  outputs.Protect("--response", a.response);
  const std::string out = outputs.Add("--out", a.out, OutputKind::kRadiance);
  ResponseCurve curve = ReadResponseCurve(a.response);
  Bracket b = LoadBracket(ReadExposureList(a.list));
  std::vector<const Image*> frames;
  for (const Image& im : b.frames) frames.push_back(&im);
  MergeSummary summary;
  Image hdr = MergeHdr(frames, b.exposures, curve, MergeOptions{}, &summary);
  WriteImage(out, hdr, StoredType::kFloat);
  outputs.Commit();
  std::printf("%s: %dx%d radiance from %zu exposures; %lld pixels saturated in every frame\n",
              a.out.c_str(), hdr.width, hdr.height, frames.size(),
              static_cast<long long>(summary.saturated_pixels));
}

// `rouen hdr` and `rouen calib hdr` are the same command.
void AddHdrCommand(CLI::App& parent, const std::string& example_prefix) {
  auto a = std::make_shared<HdrArgs>();
  CLI::App* c = parent.add_subcommand("hdr", CommandSummary("hdr"));
  c->footer("Example: " + example_prefix +
            " hdr --list exposures.txt --response response.json --out radiance.exr");
  c->add_option("--list", a->list, "Exposure list file ('image seconds' per line)")->required();
  c->add_option("--response", a->response, "Response curve JSON (rouen calib response)")
      ->required();
  c->add_option("--out", a->out, "Radiance to write (.exr, or .hdr, .pfm, .tif)")->required();
  c->callback([a] { RunHdr(*a); });
}

}  // namespace

void RegisterCalib(CLI::App& app) {
  CLI::App* calib = app.add_subcommand("calib", CommandSummary("calib"));
  calib->require_subcommand(1);
  auto r = std::make_shared<ResponseArgs>();
  CLI::App* c =
      calib->add_subcommand("response", "Recover the camera response curve from one bracket");
  c->footer(
      "FILE lists one image per line: 'image seconds' (paths relative to FILE).\n"
      "Example: rouen calib response --list memorial/exposures.txt --out response.json");
  c->add_option("--list", r->list, "Exposure list file")->required();
  c->add_option("--out", r->out, "Response curve JSON to write")->required();
  c->add_option("--samples", r->samples, "Pixel samples per bracket (default: automatic)")
      ->check(CLI::Range(1, 1000000));
  c->add_option("--lambda", r->lambda, "Smoothness weight (default: automatic)")->check(Positive());
  c->add_option("--method", r->method,
                "debevec (Debevec-Malik 1997, sparse least squares), robertson (Robertson et "
                "al. 2003, iterative) or mitsunaga (Mitsunaga-Nayar 1999, polynomial)")
      ->capture_default_str();
  c->callback([r] { RunResponse(*r); });
  AddHdrCommand(*calib, "rouen calib");
  RegisterCalibGeometry(calib);     // rouen calib intrinsics|pose
  RegisterCalibPhotometric(calib);  // rouen calib nd|vignetting
  RegisterCalibEnvmap(calib);       // rouen calib envmap|orient
}

void RegisterHdr(CLI::App& app) { AddHdrCommand(app, "rouen"); }

}  // namespace rouen
