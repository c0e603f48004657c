#include "pipeline/solve_config.h"

#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

#include "capture/rig.h"
#include "core/error.h"
#include "core/files.h"
#include "core/json_text.h"
#include "core/mesh.h"

namespace rouen {
namespace {

using nlohmann::json;

// Reads the fields of one table strictly: each key known, of the right type, in range; the
// keys not read are errors naming the table's path and what it accepts.
class Fields {
 public:
  Fields(const json& j, std::string where, std::string path)
      : j_(j), where_(std::move(where)), path_(std::move(path)) {
    if (!j_.is_object()) Fail(path_.empty() ? "the configuration" : path_, "must be a table");
  }
  [[noreturn]] void Fail(const std::string& key, const std::string& what) const {
    throw Error(where_ + ": " + key + " " + what);
  }
  std::string Path(const char* key) const { return path_.empty() ? key : path_ + "." + key; }
  const json* Find(const char* key) {
    known_.insert(key);
    const auto it = j_.find(key);
    return it == j_.end() ? nullptr : &*it;
  }
  void Number(const char* key, double* v, double lo, double hi) {
    const json* n = Find(key);
    if (!n) return;
    if (!n->is_number() || !std::isfinite(n->get<double>()) || n->get<double>() < lo ||
        n->get<double>() > hi)
      Fail(Path(key), "must be a number within " + Range(lo, hi));
    *v = n->get<double>();
  }
  void Int(const char* key, int* v, int lo, int hi) {
    int64_t w = *v;
    Int64(key, &w, lo, hi);
    *v = static_cast<int>(w);
  }
  void Int64(const char* key, int64_t* v, int64_t lo, int64_t hi) {
    const json* n = Find(key);
    if (!n) return;
    try {
      *v = JsonInteger(*n, lo, hi);
    } catch (const Error&) {
      Fail(Path(key),
           "must be an integer within " + std::to_string(lo) + ".." + std::to_string(hi));
    }
  }
  void Seed(const char* key, uint64_t* v) {
    int64_t w = static_cast<int64_t>(*v);
    Int64(key, &w, 0, std::numeric_limits<int64_t>::max());
    *v = static_cast<uint64_t>(w);
  }
  void Bool(const char* key, bool* v) {
    const json* n = Find(key);
    if (!n) return;
    if (!n->is_boolean()) Fail(Path(key), "must be true or false");
    *v = n->get<bool>();
  }
  void String(const char* key, std::string* v) {
    const json* n = Find(key);
    if (!n) return;
    if (!n->is_string() || n->get<std::string>().empty())
      Fail(Path(key), "must be a non-empty string");
    *v = n->get<std::string>();
  }
  template <typename E>
  void Enum(const char* key, E* v, const std::vector<std::pair<const char*, E>>& names) {
    const json* n = Find(key);
    if (!n) return;
    std::string list;
    for (const auto& [name, e] : names) {
      list += (list.empty() ? "" : ", ") + std::string(name);
      if (n->is_string() && n->get<std::string>() == name) {
        *v = e;
        return;
      }
    }
    Fail(Path(key), "must be one of " + list);
  }
  // A sub-table, or nullptr when absent.
  const json* Table(const char* key) {
    const json* n = Find(key);
    if (n && !n->is_object()) Fail(Path(key), "must be a table");
    return n;
  }
  void Finish() const {
    for (const auto& [key, value] : j_.items()) {
      if (known_.count(key)) continue;
      std::string list;
      for (const std::string& k : known_) list += (list.empty() ? "" : ", ") + k;
      Fail(path_.empty() ? key : path_ + "." + key,
           "is not a known key (" + (path_.empty() ? std::string("tables") : path_) +
               " takes: " + list + ")");
    }
  }
  const std::string& where() const { return where_; }

 private:
  static std::string Range(double lo, double hi) {
    std::ostringstream os;
    os << lo << ".." << hi;
    return os.str();
  }
  const json& j_;
  std::string where_, path_;
  std::set<std::string> known_;
};

constexpr double kInf = std::numeric_limits<double>::infinity();

const std::vector<std::pair<const char*, SkyWeighting>> kWeightings = {
    {"paper", SkyWeighting::kPaper}, {"relative", SkyWeighting::kRelative}};
const std::vector<std::pair<const char*, SkyModelKind>> kSkyModels = {
    {"seven", SkyModelKind::kSevenParam},
    {"perez5", SkyModelKind::kPerez5},
    {"cie", SkyModelKind::kCie}};
const std::vector<std::pair<const char*, RobustLoss>> kLosses = {
    {"none", RobustLoss::kNone}, {"huber", RobustLoss::kHuber}, {"paper", RobustLoss::kPaper}};
const std::vector<std::pair<const char*, IrradianceMethod>> kMethods = {
    {"monte_carlo", IrradianceMethod::kMonteCarlo}, {"vector_flux", IrradianceMethod::kVectorFlux}};
const std::vector<std::pair<const char*, GridSubdivision>> kSubdivisions = {
    {"longest_edge", GridSubdivision::kLongestEdge},
    {"equivalent_area", GridSubdivision::kEquivalentArea}};

const std::vector<std::pair<const char*, EnvSkyIrradiance>> kEnvSkyIrradiance = {
    {"ambient", EnvSkyIrradiance::kAmbient}, {"plane", EnvSkyIrradiance::kPlane}};
const std::vector<std::pair<const char*, std::optional<LobeModel>>> kLobeModels = {
    {"auto", std::nullopt},
    {"lafortune", LobeModel::kLafortune},
    {"microfacet", LobeModel::kMicrofacet}};
const std::vector<std::pair<const char*, SkyLobeOptions::Source>> kSkyLobeSources = {
    {"sun", SkyLobeOptions::Source::kSun}, {"fit", SkyLobeOptions::Source::kFit}};
const std::vector<std::pair<const char*, ResponseMethod>> kResponseMethods = {
    {"debevec", ResponseMethod::kDebevecMalik},
    {"robertson", ResponseMethod::kRobertson},
    {"mitsunaga", ResponseMethod::kMitsunagaNayar}};

template <typename E>
const char* NameOf(E v, const std::vector<std::pair<const char*, E>>& names) {
  for (const auto& [name, e] : names)
    if (e == v) return name;
  return "?";
}

}  // namespace

void SolveConfig::Validate() const {
  grid.Validate();
  ground.Validate();
  if (!(surroundings_spacing_m >= 0.01 && surroundings_spacing_m <= 100))
    throw Error("surroundings.spacing_m must be within 0.01..100 metres");
  hemisphere.Validate();
  if (response_max_brackets < 1 || response_max_brackets > 1000)
    throw Error("response.max_brackets must be within 1..1000");
  response.Validate();
  merge.Validate();
  radiance_merge.Validate();
  sky_fit.Validate();
  sky_samples.Validate();
  sky_segment.Validate();
  sun.Validate();
  environment.Validate();
  ground_field.Validate();
  env_stereo.Validate();
  albedo.Validate();  // the model the vector-flux irradiance needs is given at solve time
}

SolveConfig DefaultSolveConfig(bool quick) {
  SolveConfig c;
  c.grid.spacing_m = 0.6;
  if (quick) {
    c.response_max_brackets = 6;
    c.environment.pixel_stride = 2;
  }
  return c;
}

json SolveConfigJson(const SolveConfig& c) {
  const AlbedoOptions& a = c.albedo;
  const IrradianceOptions& ir = a.irradiance;
  const ObservationOptions& ob = a.observation;
  return {{"grid",
           {{"spacing_m", c.grid.spacing_m},
            {"block_spacing_m", c.grid.block_spacing_m},
            {"subdivision", NameOf(c.grid.subdivision, kSubdivisions)},
            {"max_subdivision", c.grid.max_subdivision}}},
          {"ground",
           {{"radius_m", c.ground.radius_m},
            {"cell_m", c.ground.cell_m},
            {"max_face_m", c.ground.max_face_m},
            {"block", c.ground.block},
            {"spacing_m", c.ground.spacing_m}}},
          {"surroundings",
           {{"spacing_m", c.surroundings_spacing_m},
            {"from_panoramas", c.surroundings_from_panoramas}}},
          {"hemisphere", {{"directions", c.hemisphere.directions}, {"seed", c.hemisphere.seed}}},
          {"response",
           {{"max_brackets", c.response_max_brackets},
            {"method", NameOf(c.response.method, kResponseMethods)},
            {"samples_per_bracket", c.response.samples_per_bracket},
            {"scan_pixels", c.response.scan_pixels},
            {"lambda", c.response.lambda},
            {"seed", c.response.seed},
            {"weight_epsilon", c.response.weight_epsilon},
            {"monotone_tolerance", c.response.monotone_tolerance},
            {"min_slope", c.response.min_slope},
            {"robertson_min_samples_per_bracket", c.response.robertson_min_samples_per_bracket},
            {"max_iterations", c.response.max_iterations},
            {"convergence_tolerance", c.response.convergence_tolerance},
            {"max_polynomial_order", c.response.max_polynomial_order},
            {"mn_fit_low", c.response.mn_fit_low},
            {"mn_fit_high", c.response.mn_fit_high}}},
          {"merge",
           {{"dark_level", c.merge.dark_level},
            {"saturation_level", c.merge.saturation_level},
            {"ghost_removal", c.merge.ghost_removal},
            {"ghost_threshold", c.merge.ghost_threshold},
            {"ghost_noise_dn", c.merge.ghost_noise_dn},
            {"hdr_clip_min_pixels", c.radiance_merge.clip_min_pixels},
            {"hdr_clip_divisor", c.radiance_merge.clip_divisor},
            {"hdr_clip_ramp", c.radiance_merge.clip_ramp}}},
          {"sun",
           {{"search_radius_deg", c.sun.search_radius_deg},
            {"disc_radius_factor", c.sun.disc_radius_factor},
            {"annulus_inner_factor", c.sun.annulus_inner_factor},
            {"annulus_outer_factor", c.sun.annulus_outer_factor},
            {"disc_min_pixels", c.sun.disc_min_pixels},
            {"annulus_inner_min_pixels", c.sun.annulus_inner_min_pixels},
            {"annulus_outer_min_pixels", c.sun.annulus_outer_min_pixels},
            {"clip_radiance", c.sun.clip_radiance},
            {"centroid_iterations", c.sun.centroid_iterations}}},
          {"sky_samples",
           {{"min_elevation_deg", c.sky_samples.min_elevation_deg},
            {"min_sun_distance_deg", c.sky_samples.min_sun_distance_deg},
            {"max_samples", c.sky_samples.max_samples},
            {"seed", c.sky_samples.seed}}},
          {"sky_segment",
           {{"min_elevation_deg", c.sky_segment.min_elevation_deg},
            {"sun_exclusion_deg", c.sky_segment.sun_exclusion_deg},
            {"max_log_gradient_per_deg", c.sky_segment.max_log_gradient_per_deg},
            {"min_relative_brightness", c.sky_segment.min_relative_brightness},
            {"min_relative_blue_ratio", c.sky_segment.min_relative_blue_ratio},
            {"seed_cone_deg", c.sky_segment.seed_cone_deg}}},
          {"sky_fit",
           {{"model", NameOf(c.sky_fit.model, kSkyModels)},
            {"weighting", NameOf(c.sky_fit.weighting, kWeightings)},
            {"norm_p", c.sky_fit.norm_p},
            {"norm_eps", c.sky_fit.norm_eps},
            {"max_iterations", c.sky_fit.max_iterations},
            {"min_directions", c.sky_fit.min_directions},
            {"min_spread_deg", c.sky_fit.min_spread_deg},
            {"multiple_starts", c.sky_fit.multiple_starts},
            {"random_starts", c.sky_fit.random_starts},
            {"seed", c.sky_fit.seed}}},
          {"environment",
           {{"bands_below", c.environment.bands_below},
            {"bands_above", c.environment.bands_above},
            {"sectors", c.environment.sectors},
            {"sun_exclusion_deg", c.environment.sun_exclusion_deg},
            {"pixel_stride", c.environment.pixel_stride},
            {"min_region_pixels", c.environment.min_region_pixels},
            {"sky_fill_samples", c.environment.sky_fill_samples},
            {"layer_merge_m", c.environment.layer_merge_m},
            {"lit_ground", c.environment.lit_ground},
            {"sky_detail", c.environment.sky_detail},
            {"fill_band_residual", c.environment.fill_band_residual},
            {"fit_ground_retro", c.fit_ground_retro}}},
          {"ground_field", c.ground_field},
          {"env_stereo",
           {{"alpha", c.env_stereo.alpha},
            {"fixed_channel", c.env_stereo.fixed_channel},
            {"fixed_rho_sun", c.env_stereo.fixed_rho_sun},
            {"sky_irradiance", NameOf(c.env_stereo.sky_irradiance, kEnvSkyIrradiance)},
            {"ground_albedo", c.env_stereo.ground_albedo},
            {"sky_quadrature", c.env_stereo.sky_quadrature},
            {"min_times", c.env_stereo.min_times},
            {"sky_match_tolerance", c.env_stereo.sky_match_tolerance},
            {"fit_sky_fraction", c.env_stereo.fit_sky_fraction},
            {"fallback_rel_error", c.env_stereo.fallback_rel_error},
            {"max_albedo", c.env_stereo.max_albedo},
            {"sigma_relative", c.env_stereo.sigma_relative},
            {"smoothing_weight", c.env_stereo.smoothing_weight},
            {"ground_normal_prior", c.env_stereo.ground_normal_prior},
            {"max_iterations", c.env_stereo.max_iterations},
            {"starts", c.env_stereo.starts}}},
          {"albedo",
           {{"loss", NameOf(a.loss, kLosses)},
            {"huber_k", a.huber_k},
            {"min_scale", a.min_scale},
            {"irls_iterations", a.irls_iterations},
            {"irls_tolerance", a.irls_tolerance},
            {"relative_error_floor", a.relative_error_floor},
            {"outer_iterations", a.outer_iterations},
            {"outer_tolerance", a.outer_tolerance},
            {"outer_quantile", a.outer_quantile},
            {"outer_newton", a.outer_newton},
            {"outer_aitken", a.outer_aitken},
            {"bounces", a.bounces},
            {"sunlit_threshold", a.sunlit_threshold},
            {"never_shadowed_prior", a.never_shadowed_prior},
            {"ratio_prior", a.ratio_prior},
            {"fill_radius_m", a.fill_radius_m},
            {"slot_weighting", a.slot_weighting},
            {"fit_retro", a.fit_retro},
            {"retro_min_observations", a.retro_min_observations},
            {"retro_residual_cap", a.retro_residual_cap},
            {"retro_min_gain", a.retro_min_gain},
            {"sun_lobe",
             {{"fit", a.sun_lobe.fit},
              {"model", NameOf(a.sun_lobe.model, kLobeModels)},
              {"min_samples", a.sun_lobe.min_samples},
              {"max_samples", a.sun_lobe.max_samples},
              {"min_gain", a.sun_lobe.min_gain},
              {"kappa_steps", a.sun_lobe.kappa_steps},
              {"exponent_steps", a.sun_lobe.exponent_steps},
              {"simplex_iterations", a.sun_lobe.simplex_iterations}}},
            {"sky_lobe",
             {{"fit", a.sky_lobe.fit},
              {"source", NameOf(a.sky_lobe.source, kSkyLobeSources)},
              {"min_samples", a.sky_lobe.min_samples},
              {"max_samples", a.sky_lobe.max_samples},
              {"min_gain", a.sky_lobe.min_gain},
              {"max_iterations", a.sky_lobe.max_iterations},
              {"mirror_samples", a.sky_lobe.mirror_samples}}},
            {"observation",
             {{"margin_px", ob.margin_px},
              {"occlusion_tolerance", ob.occlusion_tolerance},
              {"min_cos_view", ob.min_cos_view},
              {"check_footprint", ob.check_footprint},
              {"nearest_pixel_fallback", ob.nearest_pixel_fallback},
              {"plane_tolerance_m", ob.plane_tolerance_m}}},
            {"irradiance",
             {{"method", NameOf(ir.method, kMethods)},
              {"sun_samples", ir.sun_samples},
              {"ground_shadow", ir.ground_shadow},
              {"sky_tolerance", ir.vector_flux.sky_tolerance},
              {"sky_tree_levels", ir.vector_flux.sky_tree_levels}}}}}};
}

SolveConfig ApplySolveConfig(const json& j, SolveConfig c, const std::string& where) {
  Fields root(j, where, "");
  if (const json* t = root.Table("grid")) {
    Fields f(*t, where, "grid");
    f.Number("spacing_m", &c.grid.spacing_m, 0.01, 100);
    // Blocks named here are set; the others keep their spacing (a rig's [solve] table, then
    // a user's file, each add to what came before).
    if (const json* b = f.Table("block_spacing_m")) {
      for (const auto& [block, v] : b->items()) {
        if (!v.is_number() || !(v.get<double>() >= 0.01 && v.get<double>() <= 100))
          f.Fail("grid.block_spacing_m." + block, "must be a number within 0.01..100");
        c.grid.block_spacing_m[block] = v.get<double>();
      }
    }
    f.Enum("subdivision", &c.grid.subdivision, kSubdivisions);
    f.Int("max_subdivision", &c.grid.max_subdivision, 1, 4096);
    f.Finish();
  }
  if (const json* t = root.Table("ground")) {
    Fields f(*t, where, "ground");
    f.Number("radius_m", &c.ground.radius_m, 0, 10000);
    f.Number("cell_m", &c.ground.cell_m, 0.01, 100);
    f.Number("max_face_m", &c.ground.max_face_m, 0.01, 10000);
    f.String("block", &c.ground.block);
    f.Number("spacing_m", &c.ground.spacing_m, 0.01, 100);
    f.Finish();
  }
  if (const json* t = root.Table("surroundings")) {
    Fields f(*t, where, "surroundings");
    f.Number("spacing_m", &c.surroundings_spacing_m, 0.01, 100);
    f.Bool("from_panoramas", &c.surroundings_from_panoramas);
    f.Finish();
  }
  if (const json* t = root.Table("hemisphere")) {
    Fields f(*t, where, "hemisphere");
    f.Int("directions", &c.hemisphere.directions, 1, 65536);
    f.Seed("seed", &c.hemisphere.seed);
    f.Finish();
  }
  if (const json* t = root.Table("response")) {
    Fields f(*t, where, "response");
    f.Int("max_brackets", &c.response_max_brackets, 1, 1000);
    ResponseOptions& r = c.response;
    f.Enum("method", &r.method, kResponseMethods);
    f.Int("samples_per_bracket", &r.samples_per_bracket, 8, 1000000);
    f.Int64("scan_pixels", &r.scan_pixels, 10000, int64_t{1} << 40);
    f.Number("lambda", &r.lambda, 1e-6, 1e12);
    f.Seed("seed", &r.seed);
    f.Number("weight_epsilon", &r.weight_epsilon, 1e-9, 10);
    f.Number("monotone_tolerance", &r.monotone_tolerance, 0, 255);
    f.Number("min_slope", &r.min_slope, 0, 0.01);
    f.Int("robertson_min_samples_per_bracket", &r.robertson_min_samples_per_bracket, 0, 1000000);
    f.Int("max_iterations", &r.max_iterations, 1, 100000);
    f.Number("convergence_tolerance", &r.convergence_tolerance, 1e-15, 0.99);
    f.Int("max_polynomial_order", &r.max_polynomial_order, 1, 15);
    f.Number("mn_fit_low", &r.mn_fit_low, 1, 254);
    f.Number("mn_fit_high", &r.mn_fit_high, 1, 254);
    f.Finish();
  }
  if (const json* t = root.Table("merge")) {
    Fields f(*t, where, "merge");
    f.Number("dark_level", &c.merge.dark_level, 0, 255);
    f.Number("saturation_level", &c.merge.saturation_level, 0, 255);
    f.Bool("ghost_removal", &c.merge.ghost_removal);
    f.Number("ghost_threshold", &c.merge.ghost_threshold, 0, 100);
    f.Number("ghost_noise_dn", &c.merge.ghost_noise_dn, 0, 255);
    f.Int64("hdr_clip_min_pixels", &c.radiance_merge.clip_min_pixels, 1, int64_t{1} << 40);
    f.Int64("hdr_clip_divisor", &c.radiance_merge.clip_divisor, 1, int64_t{1} << 40);
    f.Number("hdr_clip_ramp", &c.radiance_merge.clip_ramp, 1e-6, 1);
    f.Finish();
  }
  if (const json* t = root.Table("sun")) {
    Fields f(*t, where, "sun");
    f.Number("search_radius_deg", &c.sun.search_radius_deg, 0.01, 45);
    f.Number("disc_radius_factor", &c.sun.disc_radius_factor, 1, 10);
    f.Number("annulus_inner_factor", &c.sun.annulus_inner_factor, 1, 50);
    f.Number("annulus_outer_factor", &c.sun.annulus_outer_factor, 1, 50);
    f.Number("disc_min_pixels", &c.sun.disc_min_pixels, 1, 100);
    f.Number("annulus_inner_min_pixels", &c.sun.annulus_inner_min_pixels, 0, 199);
    f.Number("annulus_outer_min_pixels", &c.sun.annulus_outer_min_pixels, 1, 200);
    f.Number("clip_radiance", &c.sun.clip_radiance, 0, std::numeric_limits<float>::max());
    f.Int("centroid_iterations", &c.sun.centroid_iterations, 1, 1000);
    f.Finish();
  }
  if (const json* t = root.Table("sky_samples")) {
    Fields f(*t, where, "sky_samples");
    f.Number("min_elevation_deg", &c.sky_samples.min_elevation_deg, 0, 88.99);
    f.Number("min_sun_distance_deg", &c.sky_samples.min_sun_distance_deg, 0, 90);
    f.Int("max_samples", &c.sky_samples.max_samples, 1, 100000000);
    f.Seed("seed", &c.sky_samples.seed);
    f.Finish();
  }
  if (const json* t = root.Table("sky_segment")) {
    Fields f(*t, where, "sky_segment");
    f.Number("min_elevation_deg", &c.sky_segment.min_elevation_deg, -10, 88.99);
    f.Number("sun_exclusion_deg", &c.sky_segment.sun_exclusion_deg, 0, 90);
    f.Number("max_log_gradient_per_deg", &c.sky_segment.max_log_gradient_per_deg, 1e-6, 100);
    f.Number("min_relative_brightness", &c.sky_segment.min_relative_brightness, 0, 1);
    f.Number("min_relative_blue_ratio", &c.sky_segment.min_relative_blue_ratio, 0, 1);
    f.Number("seed_cone_deg", &c.sky_segment.seed_cone_deg, 0.01, 90);
    f.Finish();
  }
  if (const json* t = root.Table("sky_fit")) {
    Fields f(*t, where, "sky_fit");
    f.Enum("model", &c.sky_fit.model, kSkyModels);
    f.Enum("weighting", &c.sky_fit.weighting, kWeightings);
    f.Number("norm_p", &c.sky_fit.norm_p, 1, 16);
    f.Number("norm_eps", &c.sky_fit.norm_eps, 1e-12, 1);
    f.Int("max_iterations", &c.sky_fit.max_iterations, 1, 100000);
    f.Int("min_directions", &c.sky_fit.min_directions, 7, 1000000);
    f.Number("min_spread_deg", &c.sky_fit.min_spread_deg, 0, 90);
    f.Bool("multiple_starts", &c.sky_fit.multiple_starts);
    f.Int("random_starts", &c.sky_fit.random_starts, 0, 10000);
    f.Seed("seed", &c.sky_fit.seed);
    f.Finish();
  }
  if (const json* t = root.Table("environment")) {
    Fields f(*t, where, "environment");
    EnvOptions& e = c.environment;
    f.Int("bands_below", &e.bands_below, 1, 180);
    f.Int("bands_above", &e.bands_above, 1, 180);
    f.Int("sectors", &e.sectors, 1, 720);
    f.Number("sun_exclusion_deg", &e.sun_exclusion_deg, 0, 90);
    f.Int("pixel_stride", &e.pixel_stride, 1, 64);
    f.Int("min_region_pixels", &e.min_region_pixels, 1, 1000000);
    f.Int("sky_fill_samples", &e.sky_fill_samples, 1, 1000);
    f.Number("layer_merge_m", &e.layer_merge_m, 0, 1000);
    f.Bool("lit_ground", &e.lit_ground);
    f.Int("sky_detail", &e.sky_detail, 1, 64);
    f.Bool("fill_band_residual", &e.fill_band_residual);
    f.Bool("fit_ground_retro", &c.fit_ground_retro);
    f.Finish();
  }
  if (const json* t = root.Table("env_stereo")) {
    Fields f(*t, where, "env_stereo");
    EnvStereoOptions& e = c.env_stereo;
    f.Number("alpha", &e.alpha, 0, kInf);
    f.Int("fixed_channel", &e.fixed_channel, 0, 2);
    f.Number("fixed_rho_sun", &e.fixed_rho_sun, 1e-6, 10);
    f.Enum("sky_irradiance", &e.sky_irradiance, kEnvSkyIrradiance);
    f.Number("ground_albedo", &e.ground_albedo, 0, 1);
    f.Int("sky_quadrature", &e.sky_quadrature, 1, 1000);
    f.Int("min_times", &e.min_times, 1, 1000);
    f.Number("sky_match_tolerance", &e.sky_match_tolerance, 0, kInf);
    f.Bool("fit_sky_fraction", &e.fit_sky_fraction);
    f.Number("fallback_rel_error", &e.fallback_rel_error, 0, kInf);
    f.Number("max_albedo", &e.max_albedo, 0, kInf);
    f.Number("sigma_relative", &e.sigma_relative, 0, 1);
    f.Number("smoothing_weight", &e.smoothing_weight, 0, kInf);
    f.Number("ground_normal_prior", &e.ground_normal_prior, 0, kInf);
    f.Int("max_iterations", &e.max_iterations, 1, 100000);
    f.Int("starts", &e.starts, 1, 3);
    f.Finish();
  }
  if (const json* t = root.Table("ground_field")) {
    Fields f(*t, where, "ground_field");
    GroundFieldOptions& g = c.ground_field;
    if (const json* e = f.Find("enabled")) {
      if (e->is_boolean())
        g.use = e->get<bool>() ? GroundFieldUse::kAlways : GroundFieldUse::kNever;
      else if (e->is_string() && e->get<std::string>() == "with_surroundings")
        g.use = GroundFieldUse::kWithSurroundings;
      else
        f.Fail(f.Path("enabled"), "must be true, false or \"with_surroundings\"");
    }
    f.Number("cell_m", &g.cell_m, 0.05, 100);
    f.Number("radius_factor", &g.radius_factor, 0, 100);
    f.Number("min_radius_m", &g.min_radius_m, 0, 1e5);
    f.Int64("max_cells", &g.max_cells, 1, int64_t{1} << 30);
    f.Int("sky_rays", &g.sky_rays, 1, 4096);
    f.Number("open_sky", &g.open_sky, 0, 1);
    f.Bool("walls", &g.walls);
    f.Bool("fit_retro", &g.fit_retro);
    f.Finish();
  }
  if (const json* t = root.Table("albedo")) {
    Fields f(*t, where, "albedo");
    AlbedoOptions& a = c.albedo;
    f.Enum("loss", &a.loss, kLosses);
    f.Number("huber_k", &a.huber_k, 1e-6, 100);
    f.Number("min_scale", &a.min_scale, 1e-9, 10);
    f.Int("irls_iterations", &a.irls_iterations, 1, 1000);
    f.Number("irls_tolerance", &a.irls_tolerance, 0, 0.5);
    f.Number("relative_error_floor", &a.relative_error_floor, 0, 1);
    f.Int("outer_iterations", &a.outer_iterations, 1, 100);
    f.Number("outer_tolerance", &a.outer_tolerance, 0, 0.5);
    f.Number("outer_quantile", &a.outer_quantile, 0.5, 1);
    f.Bool("outer_newton", &a.outer_newton);
    f.Bool("outer_aitken", &a.outer_aitken);
    f.Int("bounces", &a.bounces, 0, 16);
    f.Number("sunlit_threshold", &a.sunlit_threshold, 0, kInf);
    f.Number("never_shadowed_prior", &a.never_shadowed_prior, 0, kInf);
    f.Number("ratio_prior", &a.ratio_prior, 0, kInf);
    f.Number("fill_radius_m", &a.fill_radius_m, 0, 1000);
    f.Bool("slot_weighting", &a.slot_weighting);
    f.Bool("fit_retro", &a.fit_retro);
    f.Int("retro_min_observations", &a.retro_min_observations, 1, 1 << 30);
    f.Number("retro_residual_cap", &a.retro_residual_cap, 1e-6, 100);
    f.Number("retro_min_gain", &a.retro_min_gain, 0, 100);
    if (const json* o = f.Table("sun_lobe")) {
      Fields g(*o, where, "albedo.sun_lobe");
      SunLobeOptions& l = a.sun_lobe;
      g.Bool("fit", &l.fit);
      g.Enum("model", &l.model, kLobeModels);
      g.Int("min_samples", &l.min_samples, 1, 1 << 30);
      g.Int("max_samples", &l.max_samples, 1, 1 << 30);
      g.Number("min_gain", &l.min_gain, 0, 1);
      g.Int("kappa_steps", &l.kappa_steps, 1, 100);
      g.Int("exponent_steps", &l.exponent_steps, 2, 200);
      g.Int("simplex_iterations", &l.simplex_iterations, 0, 10000);
      g.Finish();
    }
    if (const json* o = f.Table("sky_lobe")) {
      Fields g(*o, where, "albedo.sky_lobe");
      SkyLobeOptions& l = a.sky_lobe;
      g.Bool("fit", &l.fit);
      g.Enum("source", &l.source, kSkyLobeSources);
      g.Int("min_samples", &l.min_samples, 1, 1 << 30);
      g.Int("max_samples", &l.max_samples, 1, 1 << 30);
      g.Number("min_gain", &l.min_gain, 0, 1);
      g.Int("max_iterations", &l.max_iterations, 1, 10000);
      g.Int("mirror_samples", &l.mirror_samples, 0, 4096);
      g.Finish();
    }
    if (const json* o = f.Table("observation")) {
      Fields g(*o, where, "albedo.observation");
      ObservationOptions& ob = a.observation;
      g.Number("margin_px", &ob.margin_px, 0, 1000);
      g.Number("occlusion_tolerance", &ob.occlusion_tolerance, 0, 0.5);
      g.Number("min_cos_view", &ob.min_cos_view, 0, 1);
      g.Bool("check_footprint", &ob.check_footprint);
      g.Bool("nearest_pixel_fallback", &ob.nearest_pixel_fallback);
      g.Number("plane_tolerance_m", &ob.plane_tolerance_m, 0, 100);
      g.Finish();
    }
    if (const json* o = f.Table("irradiance")) {
      Fields g(*o, where, "albedo.irradiance");
      IrradianceOptions& ir = a.irradiance;
      g.Enum("method", &ir.method, kMethods);
      g.Int("sun_samples", &ir.sun_samples, 1, 4096);
      g.Bool("ground_shadow", &ir.ground_shadow);
      g.Number("sky_tolerance", &ir.vector_flux.sky_tolerance, 1e-6, 10);
      g.Int("sky_tree_levels", &ir.vector_flux.sky_tree_levels, 0, 12);
      g.Finish();
    }
    f.Finish();
  }
  root.Finish();
  // The modelled ground's grid, unless grid.block_spacing_m names its block.
  if (c.ground.radius_m > 0) c.grid.block_spacing_m.try_emplace(c.ground.block, c.ground.spacing_m);
  try {
    c.Validate();
  } catch (const Error& e) {
    throw Error(where + ": " + e.what());
  }
  return c;
}

SolveConfig ReadSolveConfigFile(const std::string& path, const SolveConfig& base) {
  return ApplySolveConfig(ParseTomlAsJson(ReadFileToString(path), path), base, path);
}

SolveConfig SessionSolveConfig(const SessionInfo& info, const std::string& session_json,
                               bool quick) {
  return ApplySolveConfig(info.solve_config, DefaultSolveConfig(quick),
                          session_json + ": extra.solve_config");
}

SolveConfig SceneSolveConfig(const SceneModel& scene, const std::string& scene_json) {
  const SolveConfig defaults = DefaultSolveConfig(false);
  if (!scene.options.contains("config")) return defaults;
  return ApplySolveConfig(scene.options.at("config"), defaults,
                          scene_json + ": provenance.options.config");
}

}  // namespace rouen
