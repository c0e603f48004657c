#include "solve/scene.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/json_text.h"
#include "core/limits.h"
#include "solve/atlas.h"

namespace rouen {

namespace {

nlohmann::json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

Eigen::Vector3d ReadVec(const nlohmann::json& j, const char* key) {
  const auto& a = j.at(key);
  if (!a.is_array() || a.size() != 3) throw Error(std::string("'") + key + "' is not 3 numbers");
  Eigen::Vector3d v(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
  if (!v.allFinite()) throw Error(std::string("'") + key + "' is not finite");
  return v;
}

nlohmann::json SummaryJson(const AlbedoSummary& s) {
  return {{"points", s.points},
          {"points_observed", s.points_observed},
          {"points_sun_unobserved", s.points_sun_unobserved},
          {"points_never_shadowed", s.points_never_shadowed},
          {"points_clamped", s.points_clamped},
          {"observations", s.observations},
          {"outer_iterations", s.outer_iterations},
          {"change_per_iteration", s.change_per_iteration},
          {"residual_rms_rel", s.residual_rms_rel},
          {"residual_median_rel", s.residual_median_rel},
          {"residual_p90_rel", s.residual_p90_rel},
          {"downweighted_fraction", s.downweighted_fraction},
          {"slot_weights", s.slot_weights},
          {"points_filled_neighbours", s.points_filled_neighbours},
          {"retro_cost_lambert", s.retro_cost_lambert},
          {"retro_cost_fitted", s.retro_cost_fitted},
          {"lobe_samples", s.lobe_samples},
          {"lobe_cost_zero", s.lobe_cost_zero},
          {"lobe_cost_fitted", s.lobe_cost_fitted},
          {"sky_lobe_samples", s.sky_lobe_samples},
          {"sky_lobe_cost_zero", s.sky_lobe_cost_zero},
          {"sky_lobe_cost_fitted", s.sky_lobe_cost_fitted},
          {"seconds", s.seconds}};
}

// Lobes per block name (blocks with a lobe only).
nlohmann::json LobesJson(const std::vector<SpecularLobe>& lobes, const Mesh& m) {
  nlohmann::json out = nlohmann::json::object();
  for (int b = 0; b < static_cast<int>(m.block_names.size()); ++b) {
    const SpecularLobe l = BlockLobe(lobes, b);
    if (l.IsZero()) continue;
    out[m.block_names[b]] = {{"rho_s", {l.rho_s[0], l.rho_s[1], l.rho_s[2]}},
                             {"kappa", l.kappa},
                             {"n", l.n},
                             {"model", LobeModelName(l.model)}};
  }
  return out;
}

// LobesJson read back and checked against `mesh`'s blocks; errors start with `key` (the file
// and the key).
std::vector<SpecularLobe> ReadLobes(const nlohmann::json& j, const Mesh& mesh,
                                    const std::string& key,
                                    const std::filesystem::path& model_path) {
  std::vector<SpecularLobe> lobes(mesh.block_names.size());
  for (const auto& [name, value] : j.items()) {
    const auto it = std::find(mesh.block_names.begin(), mesh.block_names.end(), name);
    const std::string what = key + "." + name;
    if (it == mesh.block_names.end()) {
      throw Error(what + ": " + model_path.string() + " has no block '" + name + "'");
    }
    SpecularLobe l;
    try {
      const auto& rho = value.at("rho_s");
      if (!rho.is_array() || rho.size() != 3) throw Error("rho_s must be three numbers");
      for (int c = 0; c < 3; ++c) l.rho_s[c] = rho[c].get<double>();
      l.kappa = value.at("kappa").get<double>();
      l.n = value.at("n").get<double>();
      // Scenes written before the microfacet lobe have eq. 13's.
      if (value.contains("model"))
        l.model = ParseLobeModel(value.at("model").get<std::string>(), "model");
    } catch (const nlohmann::json::exception& e) {
      throw Error(what + ": " + e.what());
    } catch (const Error& e) {
      throw Error(what + ": " + e.what());
    }
    l.Validate(what);
    lobes[it - mesh.block_names.begin()] = l;
  }
  return lobes;
}

AlbedoSummary ReadSummary(const nlohmann::json& j) {
  AlbedoSummary s;
  // Each figure as written (JsonGet: an integer that does not fit is refused, not wrapped).
  auto get = [&](const char* key, auto fallback) {
    return j.contains(key)
               ? JsonGet<decltype(fallback)>(j.at(key), std::string("albedo.summary.") + key)
               : fallback;
  };
  s.points = get("points", 0);
  s.points_observed = get("points_observed", 0);
  s.points_sun_unobserved = get("points_sun_unobserved", 0);
  s.points_never_shadowed = get("points_never_shadowed", 0);
  s.points_clamped = get("points_clamped", 0);
  s.observations = get("observations", int64_t{0});
  s.outer_iterations = get("outer_iterations", 0);
  s.change_per_iteration = get("change_per_iteration", std::vector<double>{});
  s.residual_rms_rel = get("residual_rms_rel", 0.0);
  s.residual_median_rel = get("residual_median_rel", 0.0);
  s.residual_p90_rel = get("residual_p90_rel", 0.0);
  s.downweighted_fraction = get("downweighted_fraction", 0.0);
  s.slot_weights = get("slot_weights", std::vector<double>{});
  s.points_filled_neighbours = get("points_filled_neighbours", 0);
  s.retro_cost_lambert = get("retro_cost_lambert", std::vector<double>{});
  s.retro_cost_fitted = get("retro_cost_fitted", std::vector<double>{});
  s.lobe_samples = get("lobe_samples", std::vector<int>{});
  s.lobe_cost_zero = get("lobe_cost_zero", std::vector<double>{});
  s.lobe_cost_fitted = get("lobe_cost_fitted", std::vector<double>{});
  s.sky_lobe_samples = get("sky_lobe_samples", std::vector<int>{});
  s.sky_lobe_cost_zero = get("sky_lobe_cost_zero", std::vector<double>{});
  s.sky_lobe_cost_fitted = get("sky_lobe_cost_fitted", std::vector<double>{});
  s.seconds = get("seconds", 0.0);
  return s;
}

}  // namespace

Lighting SlotModel::ToLighting() const {
  Lighting l;
  l.utc = utc;
  l.sun_dir = sun_dir;
  l.sun_radiance = sun_radiance;
  l.sun_solid_angle_sr = sun_solid_angle_sr;
  l.sky = sky;
  l.env = env;
  l.use_env = true;
  return l;
}

SlotModel SlotModel::FromLighting(const Lighting& l) {
  SlotModel s;
  s.utc = l.utc;
  s.sun_dir = l.sun_dir;
  s.sun_radiance = l.sun_radiance;
  s.sun_solid_angle_sr = l.sun_solid_angle_sr;
  s.sky = l.sky;
  s.env = l.env;
  return s;
}

Image PackPointValues(const std::vector<Eigen::Vector3d>& values, int width) {
  const int n = static_cast<int>(values.size());
  const int rows = std::max(1, (n + width - 1) / width);
  Image img(width, rows, 3, PixelUnits::kOther, 0.f);
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) img.at(i % width, i / width, c) = static_cast<float>(values[i][c]);
  }
  return img;
}

std::vector<Eigen::Vector3d> UnpackPointValues(const Image& image, int count) {
  if (image.channels < 3 || static_cast<int64_t>(image.width) * image.height < count) {
    throw Error("point values: image " + std::to_string(image.width) + "x" +
                std::to_string(image.height) + "x" + std::to_string(image.channels) +
                " cannot hold " + std::to_string(count) + " RGB values");
  }
  std::vector<Eigen::Vector3d> out(count);
  for (int i = 0; i < count; ++i) {
    for (int c = 0; c < 3; ++c) out[i][c] = image.at(i % image.width, i / image.width, c);
  }
  return out;
}

namespace {

// A block's name as a file name: letters, digits, '-' and '_' kept, anything else '_', after
// the block's index (names need not be unique or non-empty).
std::string BlockFileName(int index, const std::string& name) {
  std::string out = std::to_string(index) + "_";
  for (char c : name) out += std::isalnum(static_cast<unsigned char>(c)) || c == '-' ? c : '_';
  return out;
}

// What other tools read without rouen's grid: the grid points' positions and normals beside
// the packed albedos, each block's albedos as texture atlases (solve/atlas.h) and the model
// with texture coordinates into them. Returns scene.json's "atlas" entry.
nlohmann::json WriteAlbedoAtlases(const std::filesystem::path& dir, const SceneModel& scene,
                                  const Mesh& mesh) {
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, scene.grid_options);
  const AlbedoResult& a = scene.albedo;
  if (static_cast<size_t>(grid.size()) != a.rho_sun.size())
    throw Error(dir.string() + ": the model's grid has " + std::to_string(grid.size()) +
                " points, the albedos " + std::to_string(a.rho_sun.size()));
  std::vector<Eigen::Vector3d> positions, normals;
  for (const GridPoint& p : grid.points) {
    positions.push_back(p.position);
    normals.push_back(p.normal);
  }
  WriteImage((dir / "points.exr").string(), PackPointValues(positions), StoredType::kFloat);
  WriteImage((dir / "normals.exr").string(), PackPointValues(normals), StoredType::kFloat);
  const AtlasOptions options;
  const AtlasLayout layout = LayoutAtlases(mesh, grid, options);
  std::filesystem::create_directories(dir / "atlas");
  std::vector<std::string> textures(mesh.block_names.size());
  nlohmann::json blocks = nlohmann::json::object();
  for (int b = 0; b < static_cast<int>(mesh.block_names.size()); ++b) {
    if (layout.width[b] == 0) continue;
    const std::string base = "atlas/" + BlockFileName(b, mesh.block_names[b]);
    WriteImage((dir / (base + "_sun.exr")).string(), BakeAtlas(layout, grid, a.rho_sun, b),
               StoredType::kHalf);
    WriteImage((dir / (base + "_se.exr")).string(), BakeAtlas(layout, grid, a.rho_se, b),
               StoredType::kHalf);
    textures[b] = base + "_sun.exr";
    blocks[mesh.block_names[b]] = {{"sun", base + "_sun.exr"},
                                   {"se", base + "_se.exr"},
                                   {"width", layout.width[b]},
                                   {"height", layout.height[b]}};
  }
  WriteTexturedObj(dir / "model_textured.obj", mesh, layout, textures);
  return {{"model", "model_textured.obj"},
          {"texels_per_cell", options.texels_per_cell},
          {"blocks", blocks},
          {"points", "points.exr"},
          {"normals", "normals.exr"}};
}

}  // namespace

Mesh SceneMesh(const std::filesystem::path& dir, const SceneModel& scene, const Mesh* building,
               std::vector<std::string>* surroundings) {
  Mesh m = building ? *building : ReadObj(ResolveInside(dir, scene.model_file).string());
  std::vector<std::string> blocks;
  if (!scene.surroundings_file.empty())
    blocks = AppendObj(ResolveInside(dir, scene.surroundings_file).string(), &m);
  if (surroundings) *surroundings = std::move(blocks);
  return WithGroundApron(std::move(m), scene.ground);
}

void WriteScene(const std::filesystem::path& dir, const SceneModel& scene, const Mesh* mesh) {
  if (scene.model_file.empty()) throw Error(dir.string() + ": scene has no model_file");
  std::filesystem::create_directories(dir);
  const std::filesystem::path model_path = ResolveInside(dir, scene.model_file);
  if (mesh) {
    std::filesystem::create_directories(model_path.parent_path());
    WriteObj(model_path.string(), *mesh);
  }
  const AlbedoResult& a = scene.albedo;
  const size_t n = a.rho_sun.size();
  if (a.rho_se.size() != n || a.observations.size() != n || a.flags.size() != n) {
    throw Error(dir.string() + ": albedo arrays have different sizes");
  }
  for (size_t i = 0; i < n; ++i) {
    if (!a.rho_sun[i].allFinite() || !a.rho_se[i].allFinite()) {
      throw Error(dir.string() + ": albedo of grid point " + std::to_string(i) + " is not finite");
    }
  }
  nlohmann::json j;
  j["format_version"] = scene.format_version;
  j["site"] = {{"lat_deg", scene.site.lat_deg},
               {"lon_deg", scene.site.lon_deg},
               {"height_m", scene.site.height_m}};
  if (scene.response.valid()) {
    j["response"] = scene.response;
  } else {
    j["response"] = nullptr;
  }
  j["grid"] = scene.grid_options;
  j["ground"] = scene.ground;
  j["hemisphere"] = {{"directions", scene.hemisphere.directions}, {"seed", scene.hemisphere.seed}};
  j["model_file"] = scene.model_file;
  j["model_sha256"] = Sha256File(model_path);
  if (!scene.surroundings_file.empty()) {
    j["surroundings_file"] = scene.surroundings_file;
    j["surroundings_sha256"] = Sha256File(ResolveInside(dir, scene.surroundings_file));
  }
  j["points"] = n;
  nlohmann::json slots = nlohmann::json::array();
  for (const SlotModel& s : scene.slots) {
    slots.push_back({{"utc", s.utc.Iso8601(9)},
                     {"sun_dir", Vec(s.sun_dir)},
                     {"sun_radiance", Vec(s.sun_radiance)},
                     {"sun_solid_angle_sr", s.sun_solid_angle_sr},
                     {"sky", s.sky},
                     {"env", s.env}});
  }
  j["slots"] = slots;
  nlohmann::json views = nlohmann::json::object();
  for (const auto& [name, v] : scene.views) {
    views[name] = {{"slot", v.slot},
                   {"target", v.target},
                   {"utc", v.utc.Iso8601(9)},
                   {"intrinsics", v.intrinsics},
                   {"pose", v.pose}};
  }
  j["views"] = views;
  j["holdout_slots"] = scene.holdout_slots;
  j["environment"] = {{"ground_retro", scene.env_ground_retro}};
  if (scene.env_stereo)
    j["environment"]["stereo"] = {{"slots", scene.env_stereo_slots}, {"fit", *scene.env_stereo}};
  if (scene.ground_field) j["environment"]["ground_field"] = *scene.ground_field;
  j["timings"] = scene.timings;
  j["provenance"] = {{"inputs_sha256", scene.inputs_sha256},
                     {"session", scene.session_dir},
                     {"rouen_version", scene.rouen_version},
                     {"options", scene.options}};
  j["albedo"] = {{"sun", "albedo_sun.exr"},
                 {"se", "albedo_se.exr"},
                 {"info", "albedo_info.exr"},
                 {"width", kAlbedoImageWidth},
                 {"summary", SummaryJson(a.summary)}};
  WriteImage((dir / "albedo_sun.exr").string(), PackPointValues(a.rho_sun), StoredType::kFloat);
  WriteImage((dir / "albedo_se.exr").string(), PackPointValues(a.rho_se), StoredType::kFloat);
  std::vector<Eigen::Vector3d> info(n);
  for (size_t i = 0; i < n; ++i) info[i] = Eigen::Vector3d(a.observations[i], a.flags[i], 0);
  WriteImage((dir / "albedo_info.exr").string(), PackPointValues(info), StoredType::kFloat);
  const Mesh m = SceneMesh(dir, scene, mesh);
  // Per block by name: the retro parameter of the sun term (solve/retro.h; 0 is Lambert).
  nlohmann::json retro = nlohmann::json::object();
  for (int b = 0; b < static_cast<int>(m.block_names.size()); ++b) {
    retro[m.block_names[b]] = BlockRetro(a.retro, b);
  }
  j["albedo"]["retro"] = retro;
  // Per block by name: the specular lobes (solve/specular.h) of the sun (§4.2.2) and of the sky
  // and environment (§4.2.1), blocks with one only.
  j["albedo"]["sun_lobes"] = LobesJson(a.sun_lobes, m);
  j["albedo"]["sky_lobes"] = LobesJson(a.sky_lobes, m);
  j["atlas"] = WriteAlbedoAtlases(dir, scene, m);
  WriteFileAtomic(dir / "scene.json", JsonText(j));
}

SceneJson ParseSceneJson(std::string_view text, const std::string& name) {
  SceneJson out;
  SceneModel& scene = out.scene;
  const nlohmann::json j = ParseJsonText(text, name);
  try {
    scene.format_version = JsonGet<int>(j.at("format_version"), "format_version");
    if (scene.format_version != 1) {
      throw Error("unsupported format_version " + std::to_string(scene.format_version));
    }
    const auto& site = j.at("site");
    scene.site.lat_deg = site.at("lat_deg").get<double>();
    scene.site.lon_deg = site.at("lon_deg").get<double>();
    scene.site.height_m = site.at("height_m").get<double>();
    CheckSite(scene.site, "site");
    if (!j.at("response").is_null()) scene.response = j.at("response").get<ResponseCurve>();
    scene.grid_options = j.at("grid").get<GridOptions>();
    // Scenes written before the ground could be modelled have none.
    if (j.contains("ground")) scene.ground = j.at("ground").get<GroundApronOptions>();
    scene.hemisphere.directions =
        JsonGet<int>(j.at("hemisphere").at("directions"), "hemisphere.directions");
    scene.hemisphere.seed = JsonGet<uint64_t>(j.at("hemisphere").at("seed"), "hemisphere.seed");
    scene.hemisphere.Validate();
    scene.model_file = j.at("model_file").get<std::string>();
    out.model_sha256 = j.at("model_sha256").get<std::string>();
    if (j.contains("surroundings_file")) {
      scene.surroundings_file = j.at("surroundings_file").get<std::string>();
      out.surroundings_sha256 = j.at("surroundings_sha256").get<std::string>();
    }
    out.points = JsonGet<size_t>(j.at("points"), "points");
    for (const auto& s : j.at("slots")) {
      SlotModel m;
      m.utc = ParseIso8601(s.at("utc").get<std::string>());
      m.sun_dir = ReadVec(s, "sun_dir");
      m.sun_radiance = ReadVec(s, "sun_radiance");
      m.sun_solid_angle_sr = s.at("sun_solid_angle_sr").get<double>();
      m.sky = s.at("sky").get<SkyModel>();
      m.env = s.at("env").get<EnvironmentMap>();
      if (std::abs(m.sun_dir.norm() - 1) > 1e-6 || m.sun_radiance.minCoeff() < 0 ||
          !(m.sun_solid_angle_sr > 0 && m.sun_solid_angle_sr < 1)) {
        throw Error("slot at " + m.utc.Iso8601() + ": invalid sun direction, radiance or size");
      }
      scene.slots.push_back(std::move(m));
    }
    for (const auto& [name, v] : j.at("views").items()) {
      SceneView view;
      view.slot = JsonGet<int>(v.at("slot"), "view " + name + ": slot");
      if (view.slot < 0 || view.slot >= static_cast<int>(scene.slots.size())) {
        throw Error("view " + name + ": slot " + std::to_string(view.slot) +
                    " is not in the scene");
      }
      view.target = v.at("target").get<std::string>();
      view.utc = ParseIso8601(v.at("utc").get<std::string>());
      view.intrinsics = v.at("intrinsics").get<Intrinsics>();
      view.pose = v.at("pose").get<Pose>();
      scene.views.emplace(name, std::move(view));
    }
    for (const auto& h : j.at("holdout_slots")) {
      const int slot = JsonGet<int>(h, "holdout_slots");
      if (slot < 0) throw Error("holdout slot " + std::to_string(slot) + " is negative");
      scene.holdout_slots.push_back(slot);
    }
    if (j.contains("timings")) scene.timings = j.at("timings");
    if (j.contains("environment")) {
      scene.env_ground_retro = j.at("environment").value("ground_retro", 0.0);
      if (!(scene.env_ground_retro >= kRetroMin && scene.env_ground_retro <= kRetroMax))
        throw Error("environment.ground_retro must be in [" + std::to_string(kRetroMin) + ", " +
                    std::to_string(kRetroMax) + "]");
      if (j.at("environment").contains("stereo")) {
        const nlohmann::json& st = j.at("environment").at("stereo");
        scene.env_stereo_slots =
            JsonGet<std::vector<int>>(st.at("slots"), "environment.stereo.slots");
        for (int s : scene.env_stereo_slots)
          if (s < 0 || s >= static_cast<int>(scene.slots.size()))
            throw Error("environment.stereo.slots: slot " + std::to_string(s) +
                        " is not in the scene");
        scene.env_stereo = st.at("fit").get<EnvStereoResult>();
        if (scene.env_stereo->summary.times != static_cast<int>(scene.env_stereo_slots.size()))
          throw Error("environment.stereo: fitted from " +
                      std::to_string(scene.env_stereo->summary.times) + " times but names " +
                      std::to_string(scene.env_stereo_slots.size()) + " slots");
      }
      if (j.at("environment").contains("ground_field")) {
        try {
          scene.ground_field = std::make_shared<const GroundField>(
              j.at("environment").at("ground_field").get<GroundField>());
        } catch (const Error& e) {
          throw Error(std::string("environment.ground_field: ") + e.what());
        }
      }
    }
    if (j.contains("provenance")) {
      const auto& p = j.at("provenance");
      scene.inputs_sha256 = p.at("inputs_sha256").get<std::string>();
      scene.session_dir = p.value("session", "");
      scene.rouen_version = p.at("rouen_version").get<std::string>();
      scene.options = p.at("options");
      if (!scene.options.is_object()) throw Error("provenance.options is not an object");
    }
    const auto& a = j.at("albedo");
    out.albedo_files[0] = a.at("sun").get<std::string>();
    out.albedo_files[1] = a.at("se").get<std::string>();
    out.albedo_files[2] = a.at("info").get<std::string>();
    scene.albedo.summary = ReadSummary(a.value("summary", nlohmann::json::object()));
    out.retro = a.value("retro", nlohmann::json::object());
    if (!out.retro.is_object()) throw Error("albedo.retro is not an object");
    out.sun_lobes = a.value("sun_lobes", nlohmann::json::object());
    if (!out.sun_lobes.is_object()) throw Error("albedo.sun_lobes is not an object");
    out.sky_lobes = a.value("sky_lobes", nlohmann::json::object());
    if (!out.sky_lobes.is_object()) throw Error("albedo.sky_lobes is not an object");
  } catch (const nlohmann::json::exception& e) {
    throw Error(name + ": " + e.what());
  } catch (const Error& e) {
    throw Error(name + ": " + e.what());
  }
  return out;
}

SceneModel ReadScene(const std::filesystem::path& dir, Mesh* mesh_out, SurfaceGrid* grid_out) {
  const std::filesystem::path json_path = dir / "scene.json";
  SceneJson parsed = ParseSceneJson(ReadFileToString(json_path), json_path.string());
  SceneModel scene = std::move(parsed.scene);
  const size_t points = parsed.points;
  const std::filesystem::path model_path = ResolveInside(dir, scene.model_file);
  // The grid's points are numbered by triangle: the albedos belong to this very file.
  if (Sha256File(model_path) != parsed.model_sha256) {
    throw Error(json_path.string() + ": " + model_path.string() +
                " is not the model the scene was solved with (its sha256 differs)");
  }
  if (!scene.surroundings_file.empty() &&
      Sha256File(ResolveInside(dir, scene.surroundings_file)) != parsed.surroundings_sha256) {
    throw Error(json_path.string() + ": " + scene.surroundings_file +
                " is not the surroundings the scene was solved with (its sha256 differs)");
  }
  Mesh mesh = SceneMesh(dir, scene, nullptr, &scene.surrounding_blocks);
  scene.albedo.retro.assign(mesh.block_names.size(), 0.0);
  for (const auto& [name, value] : parsed.retro.items()) {
    const auto it = std::find(mesh.block_names.begin(), mesh.block_names.end(), name);
    if (it == mesh.block_names.end()) {
      throw Error(json_path.string() + ": albedo.retro names block '" + name + "', which " +
                  model_path.string() + " does not have");
    }
    const double r = value.is_number() ? value.get<double>() : std::nan("");
    if (!(r >= kRetroMin && r <= kRetroMax)) {
      throw Error(json_path.string() + ": albedo.retro of block '" + name +
                  "' must be a number in [" + std::to_string(kRetroMin) + ", " +
                  std::to_string(kRetroMax) + "]");
    }
    scene.albedo.retro[it - mesh.block_names.begin()] = r;
  }
  scene.albedo.sun_lobes =
      ReadLobes(parsed.sun_lobes, mesh, json_path.string() + ": albedo.sun_lobes", model_path);
  scene.albedo.sky_lobes =
      ReadLobes(parsed.sky_lobes, mesh, json_path.string() + ": albedo.sky_lobes", model_path);
  SurfaceGrid grid = BuildSurfaceGrid(mesh, scene.grid_options);
  if (static_cast<size_t>(grid.size()) != points) {
    throw Error(json_path.string() + ": says " + std::to_string(points) + " grid points but " +
                model_path.string() + " with the stored grid options gives " +
                std::to_string(grid.size()));
  }
  std::vector<Eigen::Vector3d> vals[3];
  for (int f = 0; f < 3; ++f) {
    const std::filesystem::path p = ResolveInside(dir, parsed.albedo_files[f]);
    const Image img = ReadImage(p.string());
    if (img.channels < 3 || img.width != kAlbedoImageWidth ||
        img.height != std::max<int>(1, (points + kAlbedoImageWidth - 1) / kAlbedoImageWidth)) {
      throw Error(p.string() + ": expected " + std::to_string(kAlbedoImageWidth) + " x " +
                  std::to_string((points + kAlbedoImageWidth - 1) / kAlbedoImageWidth) +
                  " RGB for " + std::to_string(points) + " grid points, got " +
                  std::to_string(img.width) + "x" + std::to_string(img.height) + "x" +
                  std::to_string(img.channels));
    }
    vals[f] = UnpackPointValues(img, static_cast<int>(points));
    for (size_t i = 0; i < points; ++i) {
      if (!vals[f][i].allFinite() || vals[f][i].minCoeff() < 0) {
        throw Error(p.string() + ": value of grid point " + std::to_string(i) +
                    " is negative or not finite");
      }
    }
  }
  scene.albedo.rho_sun = std::move(vals[0]);
  scene.albedo.rho_se = std::move(vals[1]);
  scene.albedo.observations.resize(points);
  scene.albedo.flags.resize(points);
  for (size_t i = 0; i < points; ++i) {
    scene.albedo.observations[i] = static_cast<int>(std::lround(vals[2][i][0]));
    scene.albedo.flags[i] = static_cast<uint8_t>(std::lround(vals[2][i][1]));
  }
  if (mesh_out) *mesh_out = std::move(mesh);
  if (grid_out) *grid_out = std::move(grid);
  return scene;
}

}  // namespace rouen
