#include "app/pipeline.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "calib/hdr.h"
#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

void Log(const PipelineOptions& o, const std::string& s) {
  if (o.log) o.log(s);
}

// Sky and aureole brackets of a slot share the sky camera's view: they merge together.
std::string MergeKey(const FrameRecord& f) {
  if (f.target == Target::kAureole) return "slot" + std::to_string(f.slot) + "/sky/view0";
  return f.group;
}

double EffectiveExposure(const FrameRecord& f) {
  return f.exposure_s * f.gain * std::pow(10.0, -f.nd_density);
}

std::string SafeName(std::string s) {
  std::replace(s.begin(), s.end(), '/', '_');
  return s;
}

}  // namespace

Site SessionSite(const Session& session) {
  double lat = 0, lon = 0, h = 0;
  int n = 0;
  for (const FrameRecord& f : session.frames()) {
    if (f.gps && f.gps->valid()) {
      lat += f.gps->lat_deg;
      lon += f.gps->lon_deg;
      h += f.gps->height_m;
      ++n;
    }
  }
  if (n == 0) return session.info().site;
  return Site{lat / n, lon / n, h / n};
}

CalibResult CalibrateSession(const Session& session, const PipelineOptions& options) {
  CalibResult out;
  std::map<std::string, std::vector<const FrameRecord*>> groups;
  for (const FrameRecord& f : session.frames()) {
    if (f.hdr) throw Error(session.dir().string() + ": frame " + std::to_string(f.id) +
                           " is HDR; mixed LDR/HDR sessions are not supported yet");
    groups[MergeKey(f)].push_back(&f);
  }
  if (groups.empty()) throw Error(session.dir().string() + ": the session has no frames");

  // Response curve (Debevec-Malik) from the architecture and landscape brackets, unless one
  // is given.
  if (options.response) {
    out.response = *options.response;
    Log(options, "response curve given");
  } else {
    std::vector<Bracket> brackets;
    std::vector<std::string> names;
    for (const auto& [name, frames] : groups) {
      Target t = frames.front()->target;
      if (t != Target::kArchitecture && t != Target::kLandscape) continue;
      std::set<double> exps;
      for (const FrameRecord* f : frames) exps.insert(EffectiveExposure(*f));
      if (exps.size() >= 2) names.push_back(name);
    }
    const size_t max_brackets = options.quick ? 6 : 12;
    for (size_t i = 0; i < names.size() && brackets.size() < max_brackets;
         i += std::max<size_t>(1, names.size() / max_brackets)) {
      Bracket br;
      for (const FrameRecord* f : groups[names[i]]) {
        br.frames.push_back(session.LoadFrame(*f));
        br.exposures.push_back(EffectiveExposure(*f));
      }
      brackets.push_back(std::move(br));
    }
    if (brackets.empty())
      throw Error(session.dir().string() +
                  ": no bracket with two or more exposures to recover the response curve from");
    Log(options, "response curve from " + std::to_string(brackets.size()) + " brackets");
    out.response = RecoverResponse(brackets, ResponseOptions{}, &out.response_summary);
  }
  std::filesystem::create_directories(options.work_dir / "calib" / "hdr");
  WriteResponseCurve((options.work_dir / "calib" / "response.json").string(), out.response);

  // HDR radiance per bracket.
  for (const auto& [name, frames] : groups) {
    std::vector<Image> images;
    std::vector<double> exposures;
    std::vector<UtcTime> times;
    for (const FrameRecord* f : frames) {
      images.push_back(session.LoadFrame(*f));
      exposures.push_back(EffectiveExposure(*f));
      times.push_back(f->utc);
    }
    std::vector<const Image*> ptrs;
    for (const Image& im : images) ptrs.push_back(&im);
    HdrGroup g;
    g.name = name;
    const FrameRecord& first = *frames.front();
    g.slot = first.slot;
    g.target = first.target == Target::kAureole ? Target::kSky : first.target;
    g.nd_density = first.nd_density;
    if (!first.intrinsics || !first.pose)
      throw Error(session.dir().string() + ": frame " + std::to_string(first.id) +
                  " has no intrinsics/pose; calibrate the camera geometry first");
    g.intrinsics = *first.intrinsics;
    g.pose = *first.pose;
    std::sort(times.begin(), times.end());
    g.utc = times[times.size() / 2];
    MergeSummary ms;
    g.radiance = MergeHdr(ptrs, exposures, out.response, MergeOptions{}, &ms, &g.valid);
    WriteImage((options.work_dir / "calib" / "hdr" / (SafeName(name) + ".exr")).string(),
               g.radiance, StoredType::kFloat);
    out.groups.emplace(name, std::move(g));
  }
  Log(options, "merged " + std::to_string(out.groups.size()) + " brackets to radiance");
  return out;
}

SolveResult SolveSession(const Session& session, const CalibResult& calib,
                         const PipelineOptions& options) {
  SolveResult r;
  if (session.info().model.empty())
    throw Error(session.dir().string() + "/session.json: no building model ('model') given");
  r.mesh = ReadObj(ResolveInside(session.dir(), session.info().model).string());
  r.caster = std::make_unique<RayCaster>(r.mesh);
  const Site site = SessionSite(session);

  int nslots = 0;
  for (const auto& [name, g] : calib.groups) nslots = std::max(nslots, g.slot + 1);
  auto group = [&](int slot, const char* target, int view) -> const HdrGroup* {
    auto it = calib.groups.find("slot" + std::to_string(slot) + "/" + target + "/view" +
                                std::to_string(view));
    return it == calib.groups.end() ? nullptr : &it->second;
  };

  for (int s = 0; s < nslots; ++s) {
    SlotSolve ss;
    ss.slot = s;
    const HdrGroup* sun_g = group(s, "sun", 0);
    const HdrGroup* sky_g = group(s, "sky", 0);
    std::vector<EnvPanorama> panoramas;
    for (int v = 0; const HdrGroup* g = group(s, "landscape", v); ++v) {
      panoramas.push_back({&g->radiance, g->intrinsics, g->pose});
    }
    if (!sun_g || !sky_g || panoramas.empty())
      throw Error(session.dir().string() + ": slot " + std::to_string(s) +
                  " lacks a sun, sky or landscape bracket");
    ss.utc = sky_g->utc;
    ss.sun = ComputeSunPosition(ss.utc, site);
    const Eigen::Vector3d sun_dir = ss.sun.DirectionEnu();
    // §3.1: sun radiance from the ND frames and the sun's solid angle for the date.
    SunPosition at_sun_frame = ComputeSunPosition(sun_g->utc, site);
    ss.sun_measured = MeasureSun(sun_g->radiance, sun_g->intrinsics, sun_g->pose,
                                 at_sun_frame.DirectionEnu(), at_sun_frame.SolidAngleSr(),
                                 SunOptions{});
    // §3.2: the seven-parameter sky per channel.
    SkySampleOptions so;
    std::vector<SkySample> samples = ExtractSkySamples(sky_g->radiance, &sky_g->valid,
                                                       sky_g->intrinsics, sky_g->pose, sun_dir, so);
    SkyModel sky;
    ss.sky_summary = FitSky(samples, sun_dir, SkyFitOptions{}, &sky);
    // §3.3: the environment from the landscape panoramas, one layer per height (e.g. from the
    // ground and from a mast at the top of the building).
    EnvOptions eo;
    if (options.quick) eo.pixel_stride = 2;
    EnvironmentMap env = BuildEnvironmentMap(panoramas, *r.caster, sun_dir,
                                             ss.sun.angular_radius_deg * M_PI / 180, sky, eo);
    ss.lighting.utc = ss.utc;
    ss.lighting.sun_dir = sun_dir;
    ss.lighting.sun_radiance = ss.sun_measured.radiance;
    ss.lighting.sun_solid_angle_sr = ss.sun.SolidAngleSr();
    ss.lighting.sky = sky;
    ss.lighting.env = std::move(env);
    Log(options, "slot " + std::to_string(s) + ": sun elevation " +
                     std::to_string(ss.sun.elevation_deg) + " deg, sky fit median error " +
                     std::to_string(ss.sky_summary.channel[1].rel_error_median));
    r.slots.push_back(std::move(ss));
  }

  // Surface grid and geometry-only visibility, computed once.
  GridOptions go;
  go.spacing_m = 0.6;
  go.block_spacing_m["plaza"] = 1.5;
  r.grid = BuildSurfaceGrid(r.mesh, go);
  HemisphereOptions ho;
  ho.directions = 256;
  r.hemisphere = BuildHemisphereCache(r.grid, *r.caster, ho);
  Log(options, "surface grid: " + std::to_string(r.grid.size()) + " points");

  // Observations from the architecture photos of the training slots.
  std::vector<ArchitecturePhoto> photos;
  for (const auto& [name, g] : calib.groups) {
    if (g.target != Target::kArchitecture) continue;
    if (std::find(options.exclude_albedo_slots.begin(), options.exclude_albedo_slots.end(),
                  g.slot) != options.exclude_albedo_slots.end())
      continue;
    ArchitecturePhoto ph;
    ph.image = g.radiance;
    ph.intrinsics = g.intrinsics;
    ph.pose = g.pose;
    ph.slot = g.slot;
    ph.mask = g.valid;
    ph.name = name;
    photos.push_back(std::move(ph));
  }
  ObservationSummary os;
  // Sun directions per slot let footprints that straddle a shadow edge be dropped.
  std::vector<Eigen::Vector3d> sun_dirs;
  for (const SlotSolve& ss : r.slots) sun_dirs.push_back(ss.lighting.sun_dir);
  std::vector<Observation> obs =
      CollectObservations(r.grid, *r.caster, photos, {}, &os, &sun_dirs);
  Log(options, std::to_string(obs.size()) + " observations of " +
                   std::to_string(os.points_observed) + " grid points in " +
                   std::to_string(photos.size()) + " photos");
  std::vector<Lighting> lighting;
  for (const SlotSolve& ss : r.slots) lighting.push_back(ss.lighting);
  AlbedoOptions ao;
  r.albedo = SolveAlbedo(r.grid, r.hemisphere, *r.caster, lighting, obs, ao, &r.irradiance);
  Log(options, "pseudo-albedos: " + r.albedo.summary.BriefReport());
  return r;
}

}  // namespace rouen
