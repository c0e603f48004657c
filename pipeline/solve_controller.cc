#include "pipeline/solve_controller.h"

#include <algorithm>
#include <chrono>
#include <iomanip>
#include <sstream>

#include "core/angles.h"
#include "core/error.h"
#include "core/memory.h"
#include "solve/env_stereo.h"
#include "solve/ground_apron.h"
#include "solve/ground_field.h"
#include "solve/relight.h"

namespace rouen {
namespace {

enum Stage {
  kModel,
  kLighting,
  kGroundReflection,
  kGroundField,
  kGrid,
  kObservations,
  kAlbedos,
  kStageCount
};

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

bool Contains(const std::vector<int>& v, int x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

}  // namespace

const std::vector<std::string>& SolveController::Stages() {
  static const std::vector<std::string> stages = {
      "model",        "lighting",     "ground reflection", "ground field",
      "surface grid", "observations", "pseudo-albedos"};
  return stages;
}

SolveController::SolveController(const Session& session, const CalibResult& calib,
                                 const PipelineOptions& options)
    : session_(session), calib_(calib), options_(options) {}

void SolveController::Log(const std::string& line) const {
  if (options_.log) options_.log(line);
}

void SolveController::Lap(const std::string& stage, double seconds) {
  r_.stages.push_back({stage, seconds});
  std::ostringstream line;
  line << "done: " << stage << " (" << std::fixed << std::setprecision(2) << seconds << " s)";
  Log(line.str());
}

void SolveController::Begin(int stage) {
  const std::string& name = Stages()[stage];
  if (stage != next_) {
    throw Error("solve: stage '" + name + "' asked for " +
                (stage < next_ ? "again" : "before stage '" + Stages()[next_] + "'"));
  }
  ThrowIfCancelled(options_.cancel);
  stage_start_ = Now();
  Tell(0, name);
}

void SolveController::Tell(double fraction, const std::string& message) {
  if (!options_.progress || fraction >= 1) return;  // a stage's end is told by End
  SolveEvent e;
  e.stage = Stages()[next_];
  e.index = next_ + 1;
  e.count = kStageCount;
  e.fraction = fraction;
  e.message = message;
  options_.progress(e);
}

void SolveController::End(int stage, std::vector<std::pair<std::string, double>> figures) {
  ThrowIfCancelled(options_.cancel);
  const double seconds = Now() - stage_start_;
  figures.insert(figures.begin(), {"seconds", seconds});
  std::ostringstream line;
  line << std::fixed << std::setprecision(2) << Stages()[stage] << " done in " << seconds << " s";
  if (options_.progress) {
    SolveEvent e;
    e.stage = Stages()[stage];
    e.index = stage + 1;
    e.count = kStageCount;
    e.fraction = 1;
    e.message = line.str();
    e.figures = std::move(figures);
    options_.progress(e);
  }
  ++next_;
}

void SolveController::ReadModel() {
  Begin(kModel);
  r_.mesh = ReadSessionModel(session_, &r_.surrounding_blocks);
  // The surroundings on their coarser grid, unless grid.block_spacing_m names a block.
  r_.grid_options = options_.config.grid;
  for (const std::string& b : r_.surrounding_blocks)
    r_.grid_options.block_spacing_m.try_emplace(b, options_.config.surroundings_spacing_m);
  if (!r_.surrounding_blocks.empty()) {
    Log("surroundings: " + std::to_string(r_.surrounding_blocks.size()) + " blocks from " +
        session_.info().surroundings + " (not scored)");
  }
  // The panoramas' environment (§3.3) leaves out the pixels of the building only: what they see
  // of the modelled ground is the environment's ground, which rays escaping beyond it meet.
  if (options_.config.ground.radius_m > 0) {
    building_only_ = std::make_unique<RayCaster>(r_.mesh);
    const GroundApronSummary ground =
        AddGroundApron(*building_only_, options_.config.ground, &r_.mesh);
    std::ostringstream line;
    line << std::fixed << std::setprecision(0) << "ground: " << ground.area_m2
         << " m2 around the model modelled as block '" << options_.config.ground.block << "' ("
         << ground.faces << " faces at z " << std::setprecision(2) << ground.level_z << " m)";
    Log(line.str());
  }
  r_.caster = std::make_unique<RayCaster>(r_.mesh);
  End(kModel, {{"triangles", static_cast<double>(r_.mesh.triangles.size())},
               {"blocks", static_cast<double>(r_.mesh.block_names.size())},
               {"surrounding_blocks", static_cast<double>(r_.surrounding_blocks.size())}});
}

void SolveController::SolveLighting() {
  Begin(kLighting);
  const RayCaster& env_caster = building_only_ ? *building_only_ : *r_.caster;
  const Site site = SessionSite(session_);
  int nslots = 0;
  for (const auto& [name, g] : calib_.groups) nslots = std::max(nslots, g.slot + 1);
  auto group = [&](int slot, Target target, int view) -> const HdrGroup* {
    auto it = calib_.groups.find(BracketName(slot, target, view));
    return it == calib_.groups.end() ? nullptr : &it->second;
  };
  auto lap = std::chrono::steady_clock::now();
  for (int s = 0; s < nslots; ++s) {
    SlotSolve ss;
    ss.slot = s;
    const HdrGroup* sun_g = group(s, Target::kSun, 0);
    const HdrGroup* sky_g = group(s, Target::kSky, 0);
    std::vector<EnvPanorama> panoramas;
    for (int v = 0; const HdrGroup* g = group(s, Target::kLandscape, v); ++v) {
      panoramas.push_back({&g->radiance, g->intrinsics, g->pose});
    }
    if (!sky_g || panoramas.empty())
      throw Error(session_.dir().string() + ": slot " + std::to_string(s) +
                  " lacks a sky or landscape bracket (rouen status " + session_.dir().string() +
                  " lists each slot's brackets and the command that adds a missing one)");
    // The sky photo sees the sky the building hides from the landscape panoramas.
    panoramas.push_back({&sky_g->radiance, sky_g->intrinsics, sky_g->pose, true});
    ss.utc = sky_g->utc;
    ss.sun = ComputeSunPosition(ss.utc, site);
    const Eigen::Vector3d sun_dir = ss.sun.DirectionEnu();
    // §3.1: sun radiance from the ND frames and the sun's solid angle for the date; without a
    // sun bracket, from the first sky or landscape photo whose HDR disc is whole.
    std::vector<const HdrGroup*> sun_sources;
    if (sun_g) {
      sun_sources.push_back(sun_g);
    } else {
      // Only HDR photos: an LDR bracket's disc is saturated, and its merge a lower bound.
      auto hdr = [&](const HdrGroup* g) {
        for (const FrameRecord& f : session_.frames()) {
          if (MergedBracketName(f) == g->name) return f.hdr;
        }
        return false;
      };
      if (hdr(sky_g)) sun_sources.push_back(sky_g);
      for (int v = 0; const HdrGroup* g = group(s, Target::kLandscape, v); ++v) {
        if (hdr(g)) sun_sources.push_back(g);
      }
    }
    std::string sun_problems;
    const HdrGroup* sun_from = nullptr;
    for (const HdrGroup* g : sun_sources) {
      const SunPosition at = ComputeSunPosition(g->utc, site);
      try {
        // No validity mask: a sun frame's sky is underexposed through the ND filter (invalid in
        // the merge's mask, yet a fine zero background); a clipped disc is caught by its value.
        const SunMeasurement m = MeasureSun(g->radiance, g->intrinsics, g->pose, at.DirectionEnu(),
                                            at.SolidAngleSr(), options_.config.sun);
        if (m.any_invalid && !sun_g) {
          sun_problems += "; " + g->name + ": the disc is clipped or saturated";
          continue;
        }
        if (m.any_invalid) {
          Log("warning: slot " + std::to_string(s) + ": the sun disc in " + g->name +
              " is partly saturated or invalid in every frame; its radiance is a "
              "lower bound (a denser ND filter or a shorter exposure fixes it)");
        }
        ss.sun_measured = m;
        sun_from = g;
        break;
      } catch (const Error& e) {
        if (sun_g) throw;
        sun_problems += "; " + g->name + ": " + e.what();
      }
    }
    if (!sun_from) {
      throw Error(session_.dir().string() + ": slot " + std::to_string(s) +
                  " has no sun bracket and no HDR sky or landscape photo with a whole sun disc" +
                  sun_problems + " (rouen status " + session_.dir().string() +
                  " names the command that adds a sun bracket)");
    }
    {
      std::ostringstream line;
      line << "slot " << s << ": sun from " << sun_from->name << ", uncertainty "
           << std::setprecision(2) << 100 * ss.sun_measured.radiance_uncertainty.maxCoeff() << "%";
      Log(line.str());
    }
    // §3.2: the seven-parameter sky per channel, from every sky photo of the slot.
    std::string mask_source;
    const std::vector<SkySample> samples =
        SlotSkySamples(session_, calib_, s, sun_dir, options_.config.sky_segment,
                       options_.config.sky_samples, &mask_source);
    SkyModel sky;
    ss.sky_summary = FitSky(samples, sun_dir, options_.config.sky_fit, &sky);
    // §3.3: the environment from the landscape panoramas, one layer per height (e.g. from the
    // ground and from a mast at the top of the building).
    const EnvSun env_sun{sun_dir, ss.sun.angular_radius_deg * kPi / 180,
                         ss.sun_measured.radiance * ss.sun.SolidAngleSr()};
    EnvironmentMap env =
        BuildEnvironmentMap(panoramas, env_caster, env_sun, sky, options_.config.environment);
    slot_panoramas_.push_back(panoramas);
    slot_env_sun_.push_back(env_sun);
    ss.lighting.utc = ss.utc;
    ss.lighting.sun_dir = sun_dir;
    ss.lighting.sun_radiance = ss.sun_measured.radiance;
    ss.lighting.sun_solid_angle_sr = ss.sun.SolidAngleSr();
    ss.lighting.sky = sky;
    ss.lighting.env = std::move(env);
    Log("slot " + std::to_string(s) + ": sun elevation " + std::to_string(ss.sun.elevation_deg) +
        " deg, sky from " + mask_source + ", sky fit median error " +
        std::to_string(ss.sky_summary.channel[1].rel_error_median));
    r_.slots.push_back(std::move(ss));
    if (!Contains(options_.exclude_albedo_slots, s)) env_slot_ids_.push_back(s);
    // Each slot's time, as scene.json has always kept them.
    const auto now = std::chrono::steady_clock::now();
    Lap("slot " + std::to_string(s) + " lighting (sun, sky, environment)",
        std::chrono::duration<double>(now - lap).count());
    lap = now;
    ThrowIfCancelled(options_.cancel);
    Tell(static_cast<double>(s + 1) / nslots,
         "slot " + std::to_string(s + 1) + " of " + std::to_string(nslots) + " lit");
  }
  End(kLighting, {{"slots", static_cast<double>(nslots)}});
}

void SolveController::FitGroundReflection() {
  Begin(kGroundReflection);
  // Beyond §5.2: how roughly the ground reflects the sun, from the slots the albedos use, for
  // the environment at novel times (too few slots: the photometric stereo cannot tell). With
  // it the ground in the model's shadow is read as sunlit again (EnvOptions::lit_ground): a
  // rough ground seen with the sun behind is brighter sunlit than Lambert's, its shadow darker.
  const RayCaster& env_caster = building_only_ ? *building_only_ : *r_.caster;
  std::vector<Lighting> env_slots;
  for (const SlotSolve& ss : r_.slots)
    if (Contains(env_slot_ids_, ss.slot)) env_slots.push_back(ss.lighting);
  const EnvStereoOptions& env_options = options_.config.env_stereo;
  if (options_.config.fit_ground_retro &&
      static_cast<int>(env_slots.size()) >= env_options.min_times) {
    GroundRetroFit g = FitGroundRetro(EnvObservationsOf(env_slots), env_options, options_.cancel);
    r_.env_ground_retro = g.retro;
    // Kept with the scene: predictions from these slots read it instead of fitting again.
    r_.env_stereo = std::move(g.result);
    r_.env_stereo_slots = env_slot_ids_;
    std::ostringstream line;
    line << std::fixed << std::setprecision(3) << "environment: ground retro " << g.retro
         << " (median region residual " << 100 * g.cost_lambert << "% -> " << 100 * g.cost << "%)";
    Log(line.str());
    if (g.retro != 0 && options_.config.environment.lit_ground) {
      env_slots.clear();
      for (size_t k = 0; k < r_.slots.size(); ++k) {
        slot_env_sun_[k].ground_retro = g.retro;
        r_.slots[k].lighting.env =
            BuildEnvironmentMap(slot_panoramas_[k], env_caster, slot_env_sun_[k],
                                r_.slots[k].lighting.sky, options_.config.environment);
        if (Contains(env_slot_ids_, r_.slots[k].slot)) env_slots.push_back(r_.slots[k].lighting);
        Tell(static_cast<double>(k + 1) / r_.slots.size(),
             "slot " + std::to_string(k + 1) + " of " + std::to_string(r_.slots.size()) +
                 "'s environment read again");
      }
      // The kept fit is of the maps the scene keeps: those with the ground read at this retro.
      r_.env_stereo =
          SolveEnvStereo(EnvObservationsOf(env_slots), r_.env_stereo->options, options_.cancel);
    }
  }
  Lap("environment ground reflection", Now() - stage_start_);
  End(kGroundReflection, {{"ground_retro", r_.env_ground_retro}});
}

void SolveController::BuildGroundField() {
  Begin(kGroundField);
  // Beyond §3.3: the ground as a light field, from the landscape panoramas of the slots the
  // albedos use (a held-out slot's photos do not shape what predicts it). By default only with
  // the surroundings, whose walls the field, being ground, cannot hold (GroundFieldUse).
  const GroundFieldUse use = options_.config.ground_field.use;
  if (use == GroundFieldUse::kAlways ||
      (use == GroundFieldUse::kWithSurroundings && !r_.surrounding_blocks.empty())) {
    const RayCaster& env_caster = building_only_ ? *building_only_ : *r_.caster;
    const double ground_z = GroundLevel(env_caster);
    for (size_t k = 0; k < r_.slots.size(); ++k) {
      if (!Contains(env_slot_ids_, r_.slots[k].slot)) continue;
      const Lighting& l = r_.slots[k].lighting;
      GroundFieldTime& t = field_times_.emplace_back();
      t.panoramas = slot_panoramas_[k];
      t.sun_dir = l.sun_dir;
      t.sun_e = l.sun_radiance * l.sun_solid_angle_sr;
      t.sky_e = l.env.HorizontalSkyIrradiance();
      t.sky = [lighting = &l, ground_z](const Eigen::Vector3d& d) {
        return lighting->EscapedRadiance(d, ground_z);
      };
      field_slots_.push_back(k);
    }
    MakeGroundField();
    Lap("ground field", Now() - stage_start_);
  }
  End(kGroundField,
      {{"cells",
        r_.ground_field ? static_cast<double>(r_.ground_field->nx) * r_.ground_field->ny : 0.0}});
}

void SolveController::MakeGroundField() {
  const RayCaster& env_caster = building_only_ ? *building_only_ : *r_.caster;
  GroundFieldSummary gs;
  r_.ground_field = std::make_shared<const GroundField>(rouen::BuildGroundField(
      field_times_, env_caster, r_.env_ground_retro, options_.config.ground_field, &gs));
  for (SlotSolve& ss : r_.slots) ss.lighting.ground = r_.ground_field;
  Log("ground field: " + std::to_string(gs.cells_observed) + " of " + std::to_string(gs.cells) +
      " cells of " + std::to_string(options_.config.ground_field.cell_m) + " m seen in " +
      std::to_string(gs.pixels_used) + " panorama pixels (" + std::to_string(gs.pixels_model) +
      " on the model, " + std::to_string(gs.pixels_far) + " beyond the field)");
  if (options_.config.ground_field.fit_retro) {
    std::ostringstream line;
    line << std::fixed << std::setprecision(3) << "ground field: ground retro " << gs.retro
         << " (the environment's " << gs.retro_given << "; median albedo spread over "
         << gs.retro_cells << " cells seen twice " << 100 * gs.retro_cost_given << "% -> "
         << 100 * gs.retro_cost << "%)";
    Log(line.str());
  }
}

void SolveController::BuildGrid() {
  Begin(kGrid);
  // Memory known before the grid is made: about 4.3 KB per point over the whole solve
  // (bench/scene_bench.cc: the demo's 319,000 points at 0.15 m took 1.37 GB).
  constexpr int64_t kSolveBytesPerGridPoint = 4400;
  const int64_t points = CountGridPoints(r_.mesh, r_.grid_options);
  CheckMemory(points * kSolveBytesPerGridPoint,
              "the solve's surface grid of " + std::to_string(points) + " points",
              "a larger grid.spacing_m, or grid.block_spacing_m coarser on the largest blocks");
  r_.grid = BuildSurfaceGrid(r_.mesh, r_.grid_options);
  HemisphereOptions hemisphere = options_.config.hemisphere;
  hemisphere.cancel = options_.cancel;
  r_.hemisphere = BuildHemisphereCache(r_.grid, *r_.caster, hemisphere);
  Log("surface grid: " + std::to_string(r_.grid.size()) + " points");
  Lap("surface grid and visibility", Now() - stage_start_);
  End(kGrid, {{"grid_points", static_cast<double>(r_.grid.size())}});
}

void SolveController::CollectObservations() {
  Begin(kObservations);
  // Observations from the architecture photos of the training slots, and of the surroundings
  // alone from their landscape panoramas (SolveConfig::surroundings_from_panoramas).
  const auto add_photos = [&](Target target, const std::vector<uint8_t>& blocks) {
    for (const auto& [name, g] : calib_.groups) {
      if (g.target != target || Contains(options_.exclude_albedo_slots, g.slot)) continue;
      ArchitecturePhoto ph;
      ph.image = g.radiance;
      ph.intrinsics = g.intrinsics;
      ph.pose = g.pose;
      ph.slot = g.slot;
      ph.mask = g.valid;
      ph.name = name;
      ph.blocks = blocks;
      photos_.push_back(std::move(ph));
    }
  };
  add_photos(Target::kArchitecture, {});
  const size_t panoramas_from = photos_.size();
  if (options_.config.surroundings_from_panoramas && !r_.surrounding_blocks.empty()) {
    std::vector<uint8_t> surrounding(r_.mesh.block_names.size(), 0);
    for (size_t b = 0; b < r_.mesh.block_names.size(); ++b)
      surrounding[b] = std::find(r_.surrounding_blocks.begin(), r_.surrounding_blocks.end(),
                                 r_.mesh.block_names[b]) != r_.surrounding_blocks.end();
    add_photos(Target::kLandscape, surrounding);
  }
  ObservationSummary os;
  // Sun directions per slot let footprints that straddle a shadow edge be dropped.
  std::vector<Eigen::Vector3d> sun_dirs;
  for (const SlotSolve& ss : r_.slots) sun_dirs.push_back(ss.lighting.sun_dir);
  observations_ = rouen::CollectObservations(r_.grid, *r_.caster, photos_,
                                             options_.config.albedo.observation, &os, &sun_dirs);
  if (photos_.size() > panoramas_from) {
    const auto from_panoramas = std::count_if(
        observations_.begin(), observations_.end(),
        [&](const Observation& o) { return static_cast<size_t>(o.photo) >= panoramas_from; });
    Log(std::to_string(from_panoramas) + " observations of the surroundings in " +
        std::to_string(photos_.size() - panoramas_from) + " landscape panoramas");
  }
  Log(std::to_string(observations_.size()) + " observations of " +
      std::to_string(os.points_observed) + " grid points in " + std::to_string(photos_.size()) +
      " photos");
  Lap("observations", Now() - stage_start_);
  End(kObservations, {{"observations", static_cast<double>(observations_.size())},
                      {"points_observed", static_cast<double>(os.points_observed)},
                      {"photos", static_cast<double>(photos_.size())}});
}

void SolveController::SolveAlbedos() {
  Begin(kAlbedos);
  std::vector<Lighting> lighting;
  for (const SlotSolve& ss : r_.slots) lighting.push_back(ss.lighting);
  r_.albedo_options = options_.config.albedo;
  // Trees are a kind of their own: one no photo saw takes the trees' albedos, not the walls'.
  r_.albedo_options.block_kind.assign(r_.mesh.block_names.size(), 0);
  for (const std::string& tree : session_.info().trees) {
    const auto it = std::find(r_.mesh.block_names.begin(), r_.mesh.block_names.end(), tree);
    if (it == r_.mesh.block_names.end())
      throw Error("session.json: tree '" + tree + "' is no block of " +
                  session_.info().surroundings);
    r_.albedo_options.block_kind[it - r_.mesh.block_names.begin()] = 1;
  }
  AlbedoOptions with_model = r_.albedo_options;  // the vector-flux irradiance projects its faces
  with_model.irradiance.mesh = &r_.mesh;
  with_model.irradiance.cancel = options_.cancel;
  r_.albedo = SolveAlbedo(r_.grid, r_.hemisphere, *r_.caster, lighting, observations_, with_model,
                          &r_.irradiance);
  Log("pseudo-albedos: " + r_.albedo.summary.BriefReport());
  Lap("irradiance and pseudo-albedos", Now() - stage_start_);
  // The walls' light on the ground: the field above holds it in its albedos as it was at the
  // training times (several times the albedo in a street). Read again with the walls' light
  // from the model just solved, the field's albedos are the ground's own and the
  // interreflection lights the ground from the walls at any time (GroundBounce).
  if (r_.ground_field && options_.config.ground_field.walls) {
    const double again_start = Now();
    Tell(0.5, "the ground field read again with the walls' light");
    const GroundBounce bounce =
        BuildGroundBounce(*r_.ground_field, *r_.caster, r_.grid, r_.hemisphere);
    if (!bounce.empty()) {
      for (size_t t = 0; t < field_times_.size(); ++t) {
        const size_t k = field_slots_[t];
        field_times_[t].walls_e = GroundWallsIrradiance(
            bounce, r_.grid, r_.albedo.rho_sun, r_.albedo.rho_se, r_.irradiance[k], r_.albedo.retro,
            r_.slots[k].lighting.sun_dir, r_.albedo.sun_lobes);
      }
      Log("ground field: read again with the light of the walls " +
          std::to_string(bounce.cells.size()) + " cells see");
      MakeGroundField();
      for (size_t k = 0; k < r_.slots.size(); ++k) lighting[k].ground = r_.ground_field;
      r_.albedo = SolveAlbedo(r_.grid, r_.hemisphere, *r_.caster, lighting, observations_,
                              with_model, &r_.irradiance, &r_.albedo);
      Log("pseudo-albedos with the walls' light on the ground: " + r_.albedo.summary.BriefReport());
      Lap("ground field and pseudo-albedos with the walls' light", Now() - again_start);
    }
  }
  LogFitted();
  End(kAlbedos, {{"points_observed", static_cast<double>(r_.albedo.summary.points_observed)}});
}

// The rough diffuse and the specular lobes each block was given, with their fits' costs.
void SolveController::LogFitted() const {
  if (r_.albedo_options.fit_retro) {
    std::ostringstream line;
    line << "rough diffuse (retro, 0 = Lambert) per block:" << std::fixed << std::setprecision(3);
    const auto& cost0 = r_.albedo.summary.retro_cost_lambert;
    const auto& cost1 = r_.albedo.summary.retro_cost_fitted;
    for (size_t b = 0; b < r_.mesh.block_names.size(); ++b) {
      line << " " << r_.mesh.block_names[b] << " "
           << BlockRetro(r_.albedo.retro, static_cast<int>(b));
      if (b < cost0.size() && b < cost1.size()) {
        line << " (residual " << 100 * cost0[b] << "% -> " << 100 * cost1[b] << "%)";
      }
    }
    Log(line.str());
  }
  // Each block's lobe, its samples and its fit's cost without and with it.
  auto log_lobes = [&](const char* title, const std::vector<SpecularLobe>& lobes,
                       const std::vector<int>& samples, const std::vector<double>& cost0,
                       const std::vector<double>& cost1) {
    std::ostringstream line;
    line << title;
    for (size_t b = 0; b < r_.mesh.block_names.size(); ++b) {
      const SpecularLobe l = BlockLobe(lobes, static_cast<int>(b));
      line << " " << r_.mesh.block_names[b];
      if (l.IsZero()) {
        line << " none";
      } else {
        line << " " << l.Text();
      }
      if (b < samples.size() && samples[b] > 0 && b < cost0.size() && b < cost1.size()) {
        line << " (" << samples[b] << " samples, cost " << std::fixed << std::setprecision(0)
             << cost0[b] << " -> " << cost1[b] << ")";
      }
    }
    Log(line.str());
  };
  const AlbedoSummary& as = r_.albedo.summary;
  if (r_.albedo_options.sun_lobe.fit) {
    log_lobes("sun specular lobe per block (§4.2.2, eq. 15):", r_.albedo.sun_lobes, as.lobe_samples,
              as.lobe_cost_zero, as.lobe_cost_fitted);
  }
  if (r_.albedo_options.sun_lobe.fit && r_.albedo_options.sky_lobe.fit) {
    log_lobes("sky and environment lobe per block (§4.2.1, eq. 14; blocks with a sun lobe):",
              r_.albedo.sky_lobes, as.sky_lobe_samples, as.sky_lobe_cost_zero,
              as.sky_lobe_cost_fitted);
  }
}

SolveResult SolveController::Run() {
  ReadModel();
  SolveLighting();
  FitGroundReflection();
  BuildGroundField();
  BuildGrid();
  CollectObservations();
  SolveAlbedos();
  return TakeResult();
}

SolveResult SolveSession(const Session& session, const CalibResult& calib,
                         const PipelineOptions& options) {
  return SolveController(session, calib, options).Run();
}

}  // namespace rouen
