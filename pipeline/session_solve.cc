#include "pipeline/session_solve.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <optional>
#include <set>
#include <sstream>

#include "calib/hdr.h"
#include "calib/nd.h"
#include "calib/vignetting.h"
#include "core/angles.h"
#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/memory.h"
#include "core/temporaries.h"
#include "core/text.h"
#include "core/version.h"
#include "solve/relight.h"
#include "solve/sky_segment.h"

namespace rouen {
namespace {

void Log(const PipelineOptions& o, const std::string& s) {
  if (o.log) o.log(s);
}

// Records the time since the previous lap as a stage and tells it.
class StageClock {
 public:
  StageClock(const PipelineOptions& options, std::vector<StageTime>* stages)
      : options_(options), stages_(stages), last_(std::chrono::steady_clock::now()) {}
  // Throws Cancelled when a cancellation was requested during the stage.
  void Lap(const std::string& stage) {
    ThrowIfCancelled(options_.cancel);
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - last_).count();
    stages_->push_back({stage, s});
    last_ = now;
    std::ostringstream line;
    line << "done: " << stage << " (" << std::fixed << std::setprecision(2) << s << " s)";
    Log(options_, line.str());
  }

 private:
  const PipelineOptions& options_;
  std::vector<StageTime>* stages_;
  std::chrono::steady_clock::time_point last_;
};

// "<session>/frames.jsonl: frame <id> (<file>, bracket <group>)", for messages.
std::string FrameWhere(const Session& session, const FrameRecord& f) {
  return (session.dir() / "frames.jsonl").string() + ": frame " + std::to_string(f.id) + " (" +
         f.file + ", bracket " + f.group + ")";
}

std::string SizeOf(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// A frame's pixels, checked against the size its intrinsics give and, when `first` is given,
// against the first frame of its bracket (`first_frame`).
Image LoadCheckedFrame(const Session& session, const FrameRecord& f, const Image* first = nullptr,
                       const FrameRecord* first_frame = nullptr) {
  Image im = session.LoadFrame(f);
  if (f.intrinsics && (im.width != f.intrinsics->width || im.height != f.intrinsics->height))
    throw Error(FrameWhere(session, f) + ": the image is " + SizeOf(im.width, im.height) +
                " but its intrinsics are " + SizeOf(f.intrinsics->width, f.intrinsics->height));
  if (first && (im.width != first->width || im.height != first->height))
    throw Error(FrameWhere(session, f) + ": the image is " + SizeOf(im.width, im.height) +
                " but frame " + std::to_string(first_frame->id) + " of the bracket is " +
                SizeOf(first->width, first->height));
  return im;
}

double EffectiveExposure(const FrameRecord& f) {
  return f.exposure_s * f.gain * std::pow(10.0, -f.nd_density);
}

std::string SafeName(std::string s) {
  std::replace(s.begin(), s.end(), '/', '_');
  return s;
}

// LDR bracket through the response curve (Debevec-Malik eq. 6 in calib/hdr), each channel
// divided by its own ND transmission.
Image MergeLdrFrames(const std::vector<Image>& images, const std::vector<double>& exposures,
                     const std::vector<std::array<double, 3>>& transmission,
                     const ResponseCurve& response, const MergeOptions& merge,
                     std::vector<uint8_t>* valid) {
  std::vector<const Image*> ptrs;
  for (const Image& im : images) ptrs.push_back(&im);
  // Same filter colour in every frame (the usual case): merge with channel 0's factor and
  // rescale the others by their ratio to it.
  bool same_colour = true;
  for (const auto& t : transmission)
    for (int c = 1; c < 3; ++c)
      if (std::abs(t[c] / t[0] - transmission[0][c] / transmission[0][0]) >
          1e-9 * transmission[0][c] / transmission[0][0])
        same_colour = false;
  if (same_colour || images.front().channels != 3) {
    std::vector<double> x(exposures.size());
    for (size_t k = 0; k < x.size(); ++k) x[k] = exposures[k] * transmission[k][0];
    Image r = MergeHdr(ptrs, x, response, merge, nullptr, valid);
    if (r.channels == 3) {
      for (size_t i = 0; i < r.data.size(); ++i) {
        const int c = static_cast<int>(i % 3);
        if (c > 0) r.data[i] /= static_cast<float>(transmission[0][c] / transmission[0][0]);
      }
    }
    return r;
  }
  // Frames behind filters of different colours: merge each channel with its own exposures.
  Image out(images.front().width, images.front().height, 3, PixelUnits::kRadiance);
  if (valid) valid->assign(static_cast<size_t>(out.width) * out.height, 1);
  for (int c = 0; c < 3; ++c) {
    std::vector<Image> planes;
    std::vector<double> x;
    for (size_t k = 0; k < images.size(); ++k) {
      Image p(images[k].width, images[k].height, 1, PixelUnits::kDigital);
      for (size_t i = 0; i < p.data.size(); ++i) p.data[i] = images[k].data[i * 3 + c];
      planes.push_back(std::move(p));
      x.push_back(exposures[k] * transmission[k][c]);
    }
    std::vector<const Image*> pp;
    for (const Image& p : planes) pp.push_back(&p);
    ResponseCurve rc;
    for (int k = 0; k < 3; ++k) rc.g[k] = response.g[c];
    std::vector<uint8_t> vc;
    const Image r = MergeHdr(pp, x, rc, merge, nullptr, &vc);
    for (size_t i = 0; i < r.data.size(); ++i) {
      out.data[i * 3 + c] = r.data[i];
      if (valid && !vc[i]) (*valid)[i] = 0;
    }
  }
  return out;
}

// HDR frames (kRadiance, already divided by seconds x gain as `rouen import` stores them,
// not by the ND filter): calib's MergeRadiance; its errors are given the frames' ids.
Image MergeRadianceFrames(const std::vector<Image>& images,
                          const std::vector<const FrameRecord*>& frames,
                          const std::vector<double>& exposures,
                          const std::vector<std::array<double, 3>>& transmission,
                          const RadianceMergeOptions& merge, std::vector<uint8_t>* valid) {
  std::vector<const Image*> ptrs;
  for (const Image& im : images) ptrs.push_back(&im);
  try {
    return MergeRadiance(ptrs, exposures, transmission, merge, valid);
  } catch (const Error& e) {
    std::string ids;
    for (const FrameRecord* f : frames) ids += (ids.empty() ? "" : ", ") + std::to_string(f->id);
    throw Error("HDR frames " + ids + ": " + e.what());
  }
}

// A bracket's name, slot, target, camera (its first frame's) and time (its median frame's),
// without its pixels.
HdrGroup BracketCameraAndTime(const Session& session, const std::string& name,
                              const std::vector<const FrameRecord*>& frames) {
  HdrGroup g;
  g.name = name;
  const FrameRecord& first = *frames.front();
  g.slot = first.slot;
  g.target = first.target == Target::kAureole ? Target::kSky : first.target;
  g.nd_density = first.nd_density;
  if (!first.intrinsics || !first.pose)
    throw Error(session.dir().string() + ": frame " + std::to_string(first.id) +
                " has no intrinsics/pose; calibrate the camera geometry first (rouen calib "
                "intrinsics, rouen calib pose, then rouen import --cameras)");
  g.intrinsics = *first.intrinsics;
  g.pose = *first.pose;
  std::vector<UtcTime> times;
  for (const FrameRecord* f : frames) times.push_back(f->utc);
  std::sort(times.begin(), times.end());
  g.utc = times[times.size() / 2];
  return g;
}

// One bracket merged to radiance: LDR frames through `response`, HDR frames averaged (as
// `config` merges them); each channel divided by its ND filter's transmission, then the
// vignetting removed.
HdrGroup MergeGroup(const Session& session, const std::string& name,
                    const std::vector<const FrameRecord*>& frames, bool hdr,
                    const ResponseCurve& response, const SolveConfig& config) {
  const std::string where = session.dir().string();
  std::vector<Image> images;
  std::vector<double> exposures;  // seconds x gain (the ND filter is applied per channel)
  std::vector<std::array<double, 3>> transmission;
  std::vector<UtcTime> times;
  const VignettingModel* vmodel = nullptr;
  for (size_t k = 0; k < frames.size(); ++k) {
    const FrameRecord* f = frames[k];
    images.push_back(LoadCheckedFrame(session, *f, k ? &images[0] : nullptr, frames[0]));
    exposures.push_back(f->exposure_s * f->gain);
    transmission.push_back(session.info().NdTransmissionRgb(f->nd_density));
    times.push_back(f->utc);
    const VignettingModel* v = session.info().FindVignetting(f->device, f->target);
    if (k > 0 && v != vmodel)
      throw Error(where + ": bracket " + name +
                  " mixes frames with different vignetting models (frame " + std::to_string(f->id) +
                  ")");
    vmodel = v;
  }
  HdrGroup g = BracketCameraAndTime(session, name, frames);
  if (hdr) {
    g.radiance = MergeRadianceFrames(images, frames, exposures, transmission, config.radiance_merge,
                                     &g.valid);
  } else {
    if (!response.valid())
      throw Error(where + ": bracket " + name + " is LDR but no response curve is known");
    g.radiance = MergeLdrFrames(images, exposures, transmission, response, config.merge, &g.valid);
  }
  // Vignetting multiplies every frame of a bracket alike, so dividing the merge is dividing
  // each frame before merging (for LDR frames: ln L = g(z) - ln X - ln V).
  if (vmodel) {
    try {
      RemoveVignetting(*vmodel, &g.radiance);
    } catch (const Error& e) {
      throw Error(where + ": bracket " + name + ": " + e.what());
    }
  }
  return g;
}

// The session's brackets by merge key (sky and aureole of a slot together), frames in journal
// order.
std::map<std::string, std::vector<const FrameRecord*>> SessionBrackets(const Session& session) {
  std::map<std::string, std::vector<const FrameRecord*>> groups;
  for (const FrameRecord& f : session.frames()) groups[MergedBracketName(f)].push_back(&f);
  return groups;
}

// The merged bracket's valid mask as an 8-bit image: 255 where some frame was well exposed.
Image ValidMaskImage(const HdrGroup& g) {
  Image m(g.radiance.width, g.radiance.height, 1, PixelUnits::kDigital, 0.f);
  for (size_t p = 0; p < g.valid.size(); ++p) m.data[p] = g.valid[p] ? 255.f : 0.f;
  return m;
}

// What a calibration depends on: the session's files, the response curve given (if any), the
// response's and the merge's options, rouen's version.
std::string CalibInputsSha256(const Session& session, const PipelineOptions& options) {
  const nlohmann::json config = SolveConfigJson(options.config);
  nlohmann::json j = {
      {"version", RouenVersion()},
      {"response_options", config.at("response")},
      {"merge", config.at("merge")},
      {"response", options.response ? nlohmann::json(*options.response) : nlohmann::json(nullptr)}};
  return Sha256Hex(j.dump() + "\n" + SessionFilesStamp(session));
}

// The calibration in `dir` when its manifest says it was made from `inputs` and every file it
// names reads back whole; else nothing (the calibration is then made again).
std::optional<CalibResult> ReadCalibration(
    const Session& session, const std::filesystem::path& dir, const std::string& inputs,
    const std::map<std::string, std::vector<const FrameRecord*>>& groups) {
  try {
    const nlohmann::json m = nlohmann::json::parse(ReadFileToString(dir / "manifest.json"));
    if (m.at("inputs_sha256").get<std::string>() != inputs) return std::nullopt;
    CalibResult out;
    if (m.at("response").get<bool>())
      out.response = ReadResponseCurve((dir / "response.json").string());
    if (m.at("brackets").size() != groups.size()) return std::nullopt;
    for (const auto& [name, frames] : groups) {
      HdrGroup g = BracketCameraAndTime(session, name, frames);
      const std::string base = (dir / "hdr" / SafeName(name)).string();
      g.radiance = ReadImage(base + ".exr");
      if (g.radiance.channels != 3 || g.radiance.units != PixelUnits::kRadiance ||
          g.radiance.width != g.intrinsics.width || g.radiance.height != g.intrinsics.height)
        return std::nullopt;
      g.valid = ReadMask(base + ".valid.png", g.radiance.width, g.radiance.height, name);
      out.groups.emplace(name, std::move(g));
    }
    return out;
  } catch (const std::exception&) {
    return std::nullopt;  // missing, partial or unreadable: calibrate again
  }
}

}  // namespace

std::string MergedBracketName(const FrameRecord& f) {
  if (f.target == Target::kAureole) return BracketName(f.slot, Target::kSky, 0);
  return f.group;
}

std::string SessionFilesStamp(const Session& session) {
  // Paths in order, so the walk's order does not matter.
  std::map<std::string, std::string> files;
  std::error_code ec;
  namespace fs = std::filesystem;
  for (auto it = fs::recursive_directory_iterator(session.dir(), ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (!it->is_regular_file()) continue;
    const std::string name = it->path().filename().string();
    // The capture lock and temporaries are not inputs.
    if (name == "session.lock" || name.find(".tmp-") != std::string::npos) continue;
    files[fs::relative(it->path(), session.dir()).generic_string()] =
        std::to_string(it->file_size()) + " " +
        std::to_string(it->last_write_time().time_since_epoch().count());
  }
  if (ec) throw Error(session.dir().string() + ": cannot list the session: " + ec.message());
  std::string text;
  for (const auto& [path, stamp] : files) text += path + " " + stamp + "\n";
  return text;
}

std::vector<uint8_t> SkyMaskFor(const Session& session, const HdrGroup& group,
                                const Eigen::Vector3d& sun_dir, const SkySegmentOptions& segment,
                                std::string* source) {
  const std::string json = (session.dir() / "session.json").string();
  const size_t np = static_cast<size_t>(group.radiance.width) * group.radiance.height;
  if (group.valid.size() != np)
    throw Error(group.name + ": the valid mask does not match the merged image");
  const SkyMaskSpec* spec = session.info().FindSkyMask(group.name);
  std::vector<uint8_t> mask;
  if (!spec) {
    mask.assign(np, 1);
    if (source) *source = "all";
  } else if (spec->automatic) {
    try {
      mask = SegmentSky(group.radiance, group.intrinsics, group.pose, sun_dir, segment);
    } catch (const Error& e) {
      throw Error(group.name + ": " + e.what() + " (give a mask file in " + json +
                  " extra.sky_masks, or rouen import --sky-mask FILE)");
    }
    if (source) *source = "automatic";
  } else {
    const std::string path = ResolveInside(session.dir(), spec->file).string();
    mask = ReadMask(path, group.radiance.width, group.radiance.height, "the merged " + group.name);
    if (source) *source = path;
  }
  for (size_t p = 0; p < np; ++p) mask[p] = mask[p] && group.valid[p];
  return mask;
}

std::vector<SkySample> SlotSkySamples(const Session& session, const CalibResult& calib, int slot,
                                      const Eigen::Vector3d& sun_dir,
                                      const SkySegmentOptions& segment,
                                      const SkySampleOptions& sampling, std::string* sources) {
  std::vector<SkySample> samples;
  if (sources) sources->clear();
  for (int v = 0;; ++v) {
    const auto it = calib.groups.find(BracketName(slot, Target::kSky, v));
    if (it == calib.groups.end()) break;
    const HdrGroup& g = it->second;
    std::string source;
    const std::vector<uint8_t> mask = SkyMaskFor(session, g, sun_dir, segment, &source);
    const std::vector<SkySample> part =
        ExtractSkySamples(g.radiance, &mask, g.intrinsics, g.pose, sun_dir, sampling);
    samples.insert(samples.end(), part.begin(), part.end());
    if (sources) *sources += (v ? ", " : "") + g.name + ": " + source;
  }
  if (samples.empty())
    throw Error(session.dir().string() + ": slot " + std::to_string(slot) +
                " has no sky pixels to fit (no sky photo, or masks that leave nothing)");
  return samples;
}

Site SessionSite(const Session& session) {
  return SessionSite(session.dir(), session.info(), session.frames());
}

Site SessionSite(const std::filesystem::path& dir, const SessionInfo& info,
                 const std::vector<FrameRecord>& frames) {
  double lat = 0, lon = 0, h = 0;
  int n = 0;
  for (const FrameRecord& f : frames) {
    if (f.gps && f.gps->valid()) {
      lat += f.gps->lat_deg;
      lon += f.gps->lon_deg;
      h += f.gps->height_m;
      ++n;
    }
  }
  if (n == 0) {
    CheckSite(info.site, (dir / "session.json").string() + ": site");
    return info.site;
  }
  const Site mean{lat / n, lon / n, h / n};
  CheckSite(mean,
            (dir / "frames.jsonl").string() + ": the mean of " + std::to_string(n) + " GPS fixes");
  return mean;
}

std::vector<std::optional<UtcTime>> SlotTimes(const std::vector<FrameRecord>& frames,
                                              std::vector<bool>* from_sky) {
  int nslots = 0;
  for (const FrameRecord& f : frames) nslots = std::max(nslots, f.slot + 1);
  std::vector<std::vector<UtcTime>> sky(nslots), all(nslots);
  for (const FrameRecord& f : frames) {
    if (f.slot < 0) continue;
    all[f.slot].push_back(f.utc);
    if (MergedBracketName(f) == BracketName(f.slot, Target::kSky, 0)) sky[f.slot].push_back(f.utc);
  }
  std::vector<std::optional<UtcTime>> times(nslots);
  if (from_sky) from_sky->assign(nslots, false);
  for (int k = 0; k < nslots; ++k) {
    std::vector<UtcTime>& t = sky[k].empty() ? all[k] : sky[k];
    if (t.empty()) continue;
    std::sort(t.begin(), t.end());
    times[k] = t[t.size() / 2];  // the median, as BracketCameraAndTime takes a bracket's
    if (from_sky) (*from_sky)[k] = !sky[k].empty();
  }
  return times;
}

std::string NightSlotProblem(int slot, const UtcTime& utc, const Site& site) {
  const std::string night = SunDownProblem(utc, site);
  if (night.empty()) return "";
  return "slot " + std::to_string(slot) + " (" + utc.Iso8601(0) + "): " + night +
         "; every slot needs the sun up (its sun, sky and landscape photographs): check the "
         "photos' clock and time zone, and the site";
}

std::string FrameValuesProblem(const FrameRecord& f) {
  // HDR frames are radiance already; their exposure is provenance, unused.
  if (!f.hdr) {
    const std::string p = ExposureProblem(f.exposure_s);
    if (!p.empty()) return p;
  }
  const std::string p = NdDensityProblem(f.nd_density);
  if (!p.empty()) return p;
  if (!(f.gain > 0) || !std::isfinite(f.gain))
    return "gain " + FormatNumber(f.gain) + " is not positive";
  return "";
}

void CheckSessionFrames(const Session& session) {
  for (const FrameRecord& f : session.frames())
    Require(FrameValuesProblem(f), FrameWhere(session, f));
}

Mesh ReadSessionModel(const Session& session, std::vector<std::string>* surroundings) {
  return ReadSessionModel(session.dir(), session.info(), surroundings);
}

Mesh ReadSessionModel(const std::filesystem::path& dir, const SessionInfo& info,
                      std::vector<std::string>* surroundings) {
  if (info.model.empty())
    throw Error(dir.string() +
                "/session.json: no building model ('model') given (rouen import --model "
                "BUILDING.obj adds one; rouen status lists what the session lacks)");
  Mesh mesh = ReadObj(ResolveInside(dir, info.model).string());
  std::vector<std::string> blocks;
  if (!info.surroundings.empty())
    blocks = AppendObj(ResolveInside(dir, info.surroundings).string(), &mesh);
  if (surroundings) *surroundings = std::move(blocks);
  return mesh;
}

CalibResult CalibrateSession(const Session& session, const PipelineOptions& options) {
  CheckSessionFrames(session);
  CalibResult out;
  StageClock clock(options, &out.stages);
  const std::string where = session.dir().string();
  std::map<std::string, std::vector<const FrameRecord*>> groups = SessionBrackets(session);
  if (groups.empty()) throw Error(where + ": the session has no frames");
  // A bracket is all LDR (merged through the response curve) or all HDR (radiance frames,
  // e.g. imported RAW/EXR, averaged); mixing both in one bracket is refused.
  std::map<std::string, bool> group_hdr;
  for (const auto& [name, frames] : groups) {
    const bool hdr = frames.front()->hdr;
    for (const FrameRecord* f : frames)
      if (f->hdr != hdr)
        throw Error(where + ": bracket " + name + " mixes LDR and HDR frames (frames " +
                    std::to_string(frames.front()->id) + " and " + std::to_string(f->id) + ")");
    group_hdr[name] = hdr;
  }

  // An earlier calibration of the same session files with the same options is read back.
  const std::filesystem::path calib_dir = options.work_dir / "calib";
  const std::string inputs = CalibInputsSha256(session, options);
  if (std::optional<CalibResult> done = ReadCalibration(session, calib_dir, inputs, groups)) {
    Log(options, calib_dir.string() +
                     " is up to date (same session files and options): "
                     "the response curve and " +
                     std::to_string(done->groups.size()) + " merged brackets read back");
    clock.Lap("calibration read back");
    done->stages = std::move(out.stages);
    return std::move(*done);
  }
  std::error_code ec;
  std::filesystem::remove(calib_dir / "manifest.json", ec);

  // Response curve (Debevec-Malik) from the LDR architecture and landscape brackets, unless
  // one is given. A session of HDR frames only needs none.
  bool any_ldr = false;
  for (const auto& [name, hdr] : group_hdr) any_ldr = any_ldr || !hdr;
  if (options.response) {
    out.response = *options.response;
    Log(options, "response curve given");
  } else if (any_ldr) {
    std::vector<Bracket> brackets;
    std::vector<std::string> names;
    for (const auto& [name, frames] : groups) {
      if (group_hdr[name]) continue;
      Target t = frames.front()->target;
      if (t != Target::kArchitecture && t != Target::kLandscape) continue;
      std::set<double> exps;
      for (const FrameRecord* f : frames) exps.insert(EffectiveExposure(*f));
      if (exps.size() >= 2) names.push_back(name);
    }
    const size_t max_brackets = static_cast<size_t>(options.config.response_max_brackets);
    for (size_t i = 0; i < names.size() && brackets.size() < max_brackets;
         i += std::max<size_t>(1, names.size() / max_brackets)) {
      Bracket br;
      const std::vector<const FrameRecord*>& frames = groups[names[i]];
      for (const FrameRecord* f : frames) {
        br.frames.push_back(
            LoadCheckedFrame(session, *f, br.frames.empty() ? nullptr : &br.frames[0], frames[0]));
        br.exposures.push_back(EffectiveExposure(*f));
      }
      brackets.push_back(std::move(br));
    }
    if (brackets.empty())
      throw Error(where +
                  ": no LDR bracket with two or more exposures to recover the response curve "
                  "from");
    Log(options, "response curve from " + std::to_string(brackets.size()) + " brackets");
    out.response = RecoverResponse(brackets, options.config.response, &out.response_summary);
  } else {
    Log(options, "all frames are HDR: no response curve needed");
  }
  std::filesystem::create_directories(options.work_dir / "calib" / "hdr");
  WatchForTemporaries(options.work_dir / "calib");
  WatchForTemporaries(options.work_dir / "calib" / "hdr");
  if (out.response.valid())
    WriteResponseCurve((options.work_dir / "calib" / "response.json").string(), out.response);
  clock.Lap("response curve");

  // HDR radiance per bracket, brackets in parallel (reading, merging and writing each).
  std::vector<std::pair<const std::string*, const std::vector<const FrameRecord*>*>> todo;
  for (const auto& [name, frames] : groups) todo.emplace_back(&name, &frames);
  std::vector<HdrGroup> merged(todo.size());
  tbb::parallel_for(size_t{0}, todo.size(), [&](size_t k) {
    if (IsCancelled(options.cancel)) return;
    const std::string& name = *todo[k].first;
    merged[k] = MergeGroup(session, name, *todo[k].second, group_hdr.at(name), out.response,
                           options.config);
    const std::string base = (calib_dir / "hdr" / SafeName(name)).string();
    // Uncompressed: zip shrinks noisy float radiance by a tenth for six times the writing time.
    WriteImage(base + ".exr", merged[k].radiance, StoredType::kFloat,
               {{"compression", std::string("none")}});
    WriteImage(base + ".valid.png", ValidMaskImage(merged[k]), StoredType::kUint8);
  });
  for (size_t k = 0; k < todo.size(); ++k) out.groups.emplace(*todo[k].first, std::move(merged[k]));
  Log(options, "merged " + std::to_string(out.groups.size()) + " brackets to radiance");
  clock.Lap("merge brackets to radiance");
  // Written last: the files above are whole when the manifest names them.
  nlohmann::json names = nlohmann::json::array();
  for (const auto& [name, g] : out.groups) names.push_back(name);
  WriteFileAtomic(calib_dir / "manifest.json", nlohmann::json{{"inputs_sha256", inputs},
                                                              {"rouen_version", RouenVersion()},
                                                              {"response", out.response.valid()},
                                                              {"brackets", names}}
                                                       .dump(1) +
                                                   "\n");
  return out;
}

HdrGroup MergeSessionBracket(const Session& session, const std::string& name,
                             const ResponseCurve& response, const SolveConfig& config) {
  CheckSessionFrames(session);
  const auto groups = SessionBrackets(session);
  const auto it = groups.find(name);
  if (it == groups.end())
    throw Error(session.dir().string() + ": the session has no bracket " + name);
  const bool hdr = it->second.front()->hdr;
  for (const FrameRecord* f : it->second)
    if (f->hdr != hdr)
      throw Error(session.dir().string() + ": bracket " + name + " mixes LDR and HDR frames");
  return MergeGroup(session, name, it->second, hdr, response, config);
}

}  // namespace rouen
