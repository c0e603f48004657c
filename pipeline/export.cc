#include "pipeline/export.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/error.h"
#include "core/files.h"
#include "core/version.h"
#include "solve/atlas.h"
#include "solve/retro.h"

namespace rouen {
namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

// glTF's numeric constants (glTF 2.0 specification, 5.1 accessors and 5.26 samplers).
constexpr int kFloat = 5126, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kLinear = 9729, kClampToEdge = 33071;

// The sRGB transfer function (IEC 61966-2-1) of a linear value in 0..1.
double SrgbEncode(double linear) {
  const double x = std::clamp(linear, 0.0, 1.0);
  return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
}

// The binary chunk under construction: views aligned to 4 bytes.
class BinaryBuffer {
 public:
  explicit BinaryBuffer(nlohmann::json* gltf) : gltf_(gltf) {}
  // A bufferView of `bytes` (target 0: none, e.g. an image); returns its index.
  int AddView(const void* data, size_t bytes, int target) {
    while (bin_.size() % 4 != 0) bin_.push_back('\0');
    nlohmann::json view = {{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", bytes}};
    if (target != 0) view["target"] = target;
    bin_.append(static_cast<const char*>(data), bytes);
    (*gltf_)["bufferViews"].push_back(view);
    return static_cast<int>((*gltf_)["bufferViews"].size()) - 1;
  }
  // An accessor of `count` float VECn (n = components) or SCALAR unsigned ints over a new view.
  int AddFloats(const std::vector<float>& values, int components, bool with_bounds) {
    const size_t count = values.size() / components;
    const int view = AddView(values.data(), values.size() * sizeof(float), kArrayBuffer);
    nlohmann::json a = {{"bufferView", view},
                        {"componentType", kFloat},
                        {"count", count},
                        {"type", components == 2 ? "VEC2" : "VEC3"}};
    if (with_bounds) {
      std::vector<float> lo(components, INFINITY), hi(components, -INFINITY);
      for (size_t i = 0; i < values.size(); ++i) {
        lo[i % components] = std::min(lo[i % components], values[i]);
        hi[i % components] = std::max(hi[i % components], values[i]);
      }
      a["min"] = lo;
      a["max"] = hi;
    }
    (*gltf_)["accessors"].push_back(a);
    return static_cast<int>((*gltf_)["accessors"].size()) - 1;
  }
  int AddIndices(const std::vector<uint32_t>& indices) {
    const int view =
        AddView(indices.data(), indices.size() * sizeof(uint32_t), kElementArrayBuffer);
    (*gltf_)["accessors"].push_back({{"bufferView", view},
                                     {"componentType", kUnsignedInt},
                                     {"count", indices.size()},
                                     {"type", "SCALAR"}});
    return static_cast<int>((*gltf_)["accessors"].size()) - 1;
  }
  const std::string& bytes() const { return bin_; }

 private:
  nlohmann::json* gltf_;
  std::string bin_;
};

void AppendLe32(std::string* out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

// An atlas of linear albedos as an 8-bit sRGB PNG; counts texels clipped above 1.
std::string AlbedoPng(const Image& atlas, int64_t* clipped) {
  Image png(atlas.width, atlas.height, 3, PixelUnits::kDigital, 0.f);
  for (size_t p = 0; p < static_cast<size_t>(atlas.width) * atlas.height; ++p) {
    bool over = false;
    for (int c = 0; c < 3; ++c) {
      const float v = atlas.data[p * 3 + c];
      over = over || v > 1.f;
      png.data[p * 3 + c] = static_cast<float>(255.0 * SrgbEncode(v));
    }
    *clipped += over;
  }
  return EncodeImage("albedo.png", png, StoredType::kUint8);
}

}  // namespace

Eigen::Vector3d EnuToGltf(const Eigen::Vector3d& enu) {
  return Eigen::Vector3d(enu.x(), enu.z(), -enu.y());
}

void GltfOptions::Validate() const {
  if (texels_per_cell < 1 || texels_per_cell > 64)
    throw Error("glTF export: texels per cell must be within 1..64");
}

std::string EncodeGlb(const Mesh& mesh, const SurfaceGrid& grid, const AlbedoResult& albedo,
                      const nlohmann::json& asset_extras, const GltfOptions& options,
                      GltfSummary* summary) {
  options.Validate();
  if (mesh.triangles.empty()) throw Error("glTF export: the model has no triangles");
  if (albedo.rho_sun.size() != static_cast<size_t>(grid.size()) ||
      albedo.rho_se.size() != static_cast<size_t>(grid.size()))
    throw Error("glTF export: " + std::to_string(albedo.rho_sun.size()) + " albedos for " +
                std::to_string(grid.size()) + " grid points");
  AtlasOptions ao;
  ao.texels_per_cell = options.texels_per_cell;
  const AtlasLayout layout = LayoutAtlases(mesh, grid, ao);
  GltfSummary s;
  nlohmann::json gltf = {
      {"asset",
       {{"version", "2.0"},
        {"generator", std::string("rouen ") + RouenVersion()},
        {"extras", {{"rouen", asset_extras}}}}},
      {"scene", 0},
      {"scenes",
       nlohmann::json::array({{{"name", "building"}, {"nodes", nlohmann::json::array()}}})},
      {"nodes", nlohmann::json::array()},
      {"meshes", nlohmann::json::array()},
      {"materials", nlohmann::json::array()},
      {"accessors", nlohmann::json::array()},
      {"bufferViews", nlohmann::json::array()}};
  BinaryBuffer bin(&gltf);
  nlohmann::json images = nlohmann::json::array(), textures = nlohmann::json::array();
  auto add_texture = [&](const Image& atlas) {
    const std::string png = AlbedoPng(atlas, &s.clipped_texels);
    const int view = bin.AddView(png.data(), png.size(), 0);
    images.push_back({{"bufferView", view}, {"mimeType", "image/png"}});
    textures.push_back({{"sampler", 0}, {"source", images.size() - 1}});
    return static_cast<int>(textures.size()) - 1;
  };
  const std::string encoding =
      "linear albedo clamped to 0..1, 8-bit sRGB transfer function (as glTF base colour)";
  const int nblocks = static_cast<int>(mesh.block_names.size());
  for (int b = 0; b < nblocks; ++b) {
    std::vector<int> tris;
    for (int t = 0; t < static_cast<int>(mesh.triangles.size()); ++t)
      if (mesh.triangle_block[t] == b) tris.push_back(t);
    if (tris.empty()) continue;
    const std::string& name = mesh.block_names[b];
    const bool textured = layout.width[b] > 0;
    std::vector<float> positions, normals, uvs;
    std::vector<uint32_t> indices;
    for (int t : tris) {
      const Eigen::Vector3d n = EnuToGltf(mesh.Normal(t));
      if (!n.allFinite())
        throw Error("glTF export: triangle " + std::to_string(t) + " has no normal");
      const double corners[3][2] = {{0, 0}, {1, 0}, {0, 1}};  // barycentric (u, v) of a, b, c
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d p = EnuToGltf(mesh.vertices[mesh.triangles[t][k]]);
        if (!p.allFinite()) throw Error("glTF export: a vertex is not finite");
        indices.push_back(static_cast<uint32_t>(positions.size() / 3));
        for (int c = 0; c < 3; ++c) {
          positions.push_back(static_cast<float>(p[c]));
          normals.push_back(static_cast<float>(n[c]));
        }
        if (textured) {
          // glTF's texture origin is the top-left corner (OBJ's, Uv's, the bottom-left).
          const Eigen::Vector2d uv = layout.Uv(t, corners[k][0], corners[k][1]);
          uvs.push_back(static_cast<float>(uv.x()));
          uvs.push_back(static_cast<float>(1 - uv.y()));
        }
      }
    }
    nlohmann::json attributes = {{"POSITION", bin.AddFloats(positions, 3, true)},
                                 {"NORMAL", bin.AddFloats(normals, 3, false)}};
    nlohmann::json extras = {{"block", name},
                             {"retro", BlockRetro(albedo.retro, b)},
                             {"frame", "glTF (x, y, z) = ENU (east, up, -north), metres"}};
    // §4.2: the block's lobes of the sun and of the sky and environment, eq. 13 (f_s = rho_s
    // [-kappa (u.v - u_z v_z) + u_z v_z]^n in the face's frame, 1/sr) or the microfacet lobe
    // (solve/specular.h), where it has them.
    for (const auto& [key, lobes] :
         {std::pair{"sun_lobe", &albedo.sun_lobes}, std::pair{"sky_lobe", &albedo.sky_lobes}}) {
      const SpecularLobe lobe = BlockLobe(*lobes, b);
      if (lobe.IsZero()) continue;
      extras[key] = {{"rho_s", {lobe.rho_s[0], lobe.rho_s[1], lobe.rho_s[2]}},
                     {"kappa", lobe.kappa},
                     {"n", lobe.n},
                     {"model", lobe.model == LobeModel::kMicrofacet
                                   ? "microfacet: GGX, Smith G, Schlick F0 0.04, alpha^2 = "
                                     "2 / (n + 2), rho_s at normal incidence"
                                   : "Yu & Malik 1998 eq. 13, isotropic, Cz = 1"}};
    }
    nlohmann::json material = {{"name", name}, {"doubleSided", false}};
    nlohmann::json pbr = {{"metallicFactor", 0.0}, {"roughnessFactor", 1.0}};
    if (textured) {
      attributes["TEXCOORD_0"] = bin.AddFloats(uvs, 2, false);
      const int sun = add_texture(BakeAtlas(layout, grid, albedo.rho_sun, b));
      const int se = add_texture(BakeAtlas(layout, grid, albedo.rho_se, b));
      pbr["baseColorTexture"] = {{"index", sun}, {"texCoord", 0}};
      extras["albedo_sun_texture"] = sun;
      extras["albedo_sky_env_texture"] = se;
      extras["albedo_encoding"] = encoding;
      s.textured_blocks += 1;
      s.texels += static_cast<int64_t>(layout.width[b]) * layout.height[b];
    } else {
      // No grid points: no albedo was recovered there.
      pbr["baseColorFactor"] = {0.5, 0.5, 0.5, 1.0};
      extras["albedo"] = "none (the block has no grid points)";
    }
    material["pbrMetallicRoughness"] = pbr;
    material["extras"] = {{"rouen", extras}};
    gltf["materials"].push_back(material);
    const int m = static_cast<int>(gltf["materials"].size()) - 1;
    gltf["meshes"].push_back({{"name", name},
                              {"primitives",
                               {{{"attributes", attributes},
                                 {"indices", bin.AddIndices(indices)},
                                 {"material", m},
                                 {"mode", 4}}}}});
    gltf["nodes"].push_back({{"name", name}, {"mesh", gltf["meshes"].size() - 1}});
    gltf["scenes"][0]["nodes"].push_back(gltf["nodes"].size() - 1);
    s.blocks += 1;
    s.triangles += static_cast<int64_t>(tris.size());
    s.vertices += static_cast<int64_t>(positions.size() / 3);
  }
  if (!images.empty()) {
    gltf["images"] = images;
    gltf["textures"] = textures;
    gltf["samplers"] = {{{"magFilter", kLinear},
                         {"minFilter", kLinear},
                         {"wrapS", kClampToEdge},
                         {"wrapT", kClampToEdge}}};
  }
  std::string payload = bin.bytes();
  while (payload.size() % 4 != 0) payload.push_back('\0');
  gltf["buffers"] = {{{"byteLength", payload.size()}}};
  std::string json = gltf.dump();
  while (json.size() % 4 != 0) json.push_back(' ');
  const size_t total = 12 + 8 + json.size() + 8 + payload.size();
  if (total > 0xffffffffu) throw Error("glTF export: the model exceeds a GLB's 4 GB");
  std::string glb;
  glb.reserve(total);
  glb += "glTF";
  AppendLe32(&glb, 2);
  AppendLe32(&glb, static_cast<uint32_t>(total));
  AppendLe32(&glb, static_cast<uint32_t>(json.size()));
  glb += "JSON";
  glb += json;
  AppendLe32(&glb, static_cast<uint32_t>(payload.size()));
  glb.append("BIN\0", 4);
  glb += payload;
  s.bytes = glb.size();
  if (summary) *summary = s;
  return glb;
}

GltfSummary WriteSceneGltf(const LoadedScene& scene, const std::filesystem::path& out,
                           const GltfOptions& options) {
  const Site& site = scene.scene.site;
  const nlohmann::json extras = {
      {"frame",
       "glTF (x, y, z) = ENU (east, up, -north), metres, from the site (a local tangent plane)"},
      {"site", {{"lat_deg", site.lat_deg}, {"lon_deg", site.lon_deg}, {"height_m", site.height_m}}},
      {"albedo",
       "baseColorTexture: the sun albedo; extras.rouen.albedo_sky_env_texture: the sky + "
       "environment albedo (Yu & Malik 1998 eqs. 11-12)"},
      {"scene", scene.dir.filename().string()}};
  GltfSummary summary;
  const std::string glb = EncodeGlb(scene.solved.mesh, scene.solved.grid, scene.solved.albedo,
                                    extras, options, &summary);
  WriteFileAtomic(out, glb);
  return summary;
}

SceneEnvmap SceneEnvmapFor(const LoadedScene& scene, const RenderRequest& request,
                           const LatLongOptions& options,
                           const std::function<void(const std::string&)>& log) {
  options.Validate();
  RenderRequest r = request;
  // The lighting needs no camera; RequestedLighting checks one.
  if (r.intrinsics.width <= 0) r.intrinsics = Intrinsics::PinholeFov(2, 2, 60);
  SceneEnvmap out;
  out.lighting = RequestedLighting(scene, r, log);
  Log(log, "baking " + std::to_string(options.width) + "x" + std::to_string(options.width / 2) +
               " latitude-longitude map");
  out.map = BakeLatLong(out.lighting, options);
  const double z = std::isnan(options.height_m)
                       ? (out.lighting.use_env ? out.lighting.env.layer_z.front() : 0.0)
                       : options.height_m;
  out.horizontal_from_map = LatLongIrradiance(out.map, Eigen::Vector3d::UnitZ());
  out.horizontal_rouen = UnoccludedIrradiance(out.lighting, Eigen::Vector3d::UnitZ(), z);
  out.attributes = LightingAttributes(scene, r, out.lighting);
  out.attributes.push_back(
      {"rouen:orientation",
       std::string("Blender equirectangular: u = 0.5 - atan2(y, x) / 2pi, v = 0.5 + elevation / "
                   "pi (row 0 the zenith); x east, y north, z up: north at u = 0.25, east at "
                   "0.5")});
  out.attributes.push_back({"rouen:height_m", static_cast<float>(z)});
  out.attributes.push_back(
      {"rouen:above_horizon",
       std::string(options.sky_model ? "sky model" : "environment regions (as the irradiance)")});
  return out;
}

}  // namespace rouen
