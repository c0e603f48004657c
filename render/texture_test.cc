#include "render/texture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "core/error.h"
#include "render/metrics.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

// A checker of 0.5 m squares on every face (each face's two varying coordinates), 1 +- 0.35:
// far finer than the model grid's 2 m, whose points hold its mean (1).
double Texture(const Eigen::Vector3d& p) {
  double s = 1;
  for (int k = 0; k < 3; ++k) s *= std::sin(2 * M_PI * (p[k] + 0.25)) >= 0 ? 1 : -1;
  return 1 + 0.35 * s;
}

// One scene two ways: the truth (a 0.1 m grid with the checker, shaded at the nearest grid
// point so the checker stays crisp) and the model a solve would hold (a 2 m grid with the
// checker's mean). A 1.5 x 1.5 x 3 m pillar on a 12 x 12 m plaza; the pillar has a sun lobe.
struct World {
  Mesh mesh;
  std::unique_ptr<RayCaster> rc;
  SurfaceGrid fine, coarse;
  HemisphereCache fine_cache, coarse_cache;
  AlbedoResult fine_albedo, coarse_albedo;
};

const Eigen::Vector3d kRhoSun(0.5, 0.45, 0.4), kRhoSe(0.4, 0.33, 0.3);

World MakeWorld() {
  World w;
  const int plaza = w.mesh.AddBlock("plaza");
  const int pillar = w.mesh.AddBlock("pillar");
  testing::AddHorizontalRect(&w.mesh, -6, 6, -6, 6, 0, true, plaza);
  testing::AddBox(&w.mesh, {-0.75, -0.75, 0}, {0.75, 0.75, 3}, pillar);
  w.rc = std::make_unique<RayCaster>(w.mesh);
  HemisphereOptions ho;
  ho.directions = 64;
  GridOptions go;
  go.spacing_m = 0.1;
  w.fine = BuildSurfaceGrid(w.mesh, go);
  w.fine_cache = BuildHemisphereCache(w.fine, *w.rc, ho);
  go.spacing_m = 2.0;
  w.coarse = BuildSurfaceGrid(w.mesh, go);
  w.coarse_cache = BuildHemisphereCache(w.coarse, *w.rc, ho);
  for (const GridPoint& p : w.fine.points) {
    w.fine_albedo.rho_sun.push_back(kRhoSun * Texture(p.position));
    w.fine_albedo.rho_se.push_back(kRhoSe * Texture(p.position));
  }
  w.coarse_albedo.rho_sun.assign(w.coarse.size(), kRhoSun);
  w.coarse_albedo.rho_se.assign(w.coarse.size(), kRhoSe);
  SpecularLobe lobe;
  lobe.rho_s = Eigen::Vector3d(0.3, 0.3, 0.3);
  lobe.kappa = 1;
  lobe.n = 20;
  for (AlbedoResult* a : {&w.fine_albedo, &w.coarse_albedo}) a->sun_lobes = {{}, lobe};
  return w;
}

Lighting SunAt(double azimuth_deg, double elevation_deg, double sky_scale) {
  const double az = azimuth_deg * M_PI / 180, el = elevation_deg * M_PI / 180;
  Lighting l;
  l.sun_dir =
      Eigen::Vector3d(std::sin(az) * std::cos(el), std::cos(az) * std::cos(el), std::sin(el));
  l.sun_radiance = Eigen::Vector3d(1.5e5, 1.4e5, 1.3e5);
  l.sun_solid_angle_sr = 6.8e-5;
  l.sky = testing::ClearSky(l.sun_dir);
  for (auto& c : l.sky.channel) c.Lz *= sky_scale;
  l.env = EnvironmentMap::Constant(EnvOptions(), {1, 1, 1}, {0.2, 0.2, 0.2});
  return l;
}

Image Rgb(const Image& rgba) {
  Image out(rgba.width, rgba.height, 3, rgba.units);
  for (size_t p = 0; p < static_cast<size_t>(rgba.width) * rgba.height; ++p)
    for (int c = 0; c < 3; ++c) out.data[p * 3 + c] = rgba.data[p * rgba.channels + c];
  return out;
}

class PhotoTextureTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { world_ = new World(MakeWorld()); }
  static void TearDownTestSuite() { delete world_; }

  // The truth under `l` through the test camera: what a photograph would record.
  Image Truth(const Lighting& l) const {
    const World& w = *world_;
    RenderOptions ro;
    ro.interpolate = false;
    const SlotIrradiance irr = ComputeIrradiance(w.fine, w.fine_cache, *w.rc, l);
    return RenderView(w.mesh, w.fine, *w.rc, w.fine_albedo, l, irr, k_, pose_, ro);
  }
  PhotoTextureResult Textured(const Image& photo, const Lighting& photo_l, const Lighting& novel_l,
                              const PhotoTextureOptions& o = {}) const {
    const World& w = *world_;
    const SlotIrradiance pi = ComputeIrradiance(w.coarse, w.coarse_cache, *w.rc, photo_l);
    const SlotIrradiance ni = ComputeIrradiance(w.coarse, w.coarse_cache, *w.rc, novel_l);
    return RenderWithPhotoTexture(w.mesh, w.coarse, *w.rc, w.coarse_albedo, photo, {}, photo_l, pi,
                                  novel_l, ni, k_, pose_, o);
  }

  static World* world_;
  const Intrinsics k_ = Intrinsics::PinholeFov(200, 150, 50);
  const Pose pose_ = Pose::LookAt({2, -9, 6}, {0, 0, 0.8});
  const Lighting morning_ = SunAt(120, 35, 1.0);  // sun in the south-east
  const Lighting evening_ = SunAt(260, 20, 0.7);  // in the west, lower
};
World* PhotoTextureTest::world_ = nullptr;

TEST_F(PhotoTextureTest, ReproducesThePhotoUnderItsOwnLighting) {
  const Image photo = Truth(morning_);
  const PhotoTextureResult r = Textured(photo, morning_, morning_);
  ASSERT_EQ(r.textured.channels, 4);
  ASSERT_GT(r.building_pixels, 150 * 200 / 2);
  // Every building pixel takes the texture (the model is the truth's geometry: no shadow or
  // occluder disagrees) but for the few where the checker's dark squares in the pillar's
  // shadow and its lobe's rim meet the limits: at least 99%.
  EXPECT_GE(r.textured_pixels, 0.99 * r.building_pixels);
  // t = (I - S) / D and t D + S in double from float inputs, stored as float: I back to float
  // rounding, a relative 2^-24 (6e-8) per operation; 1e-6 leaves room for a few.
  int64_t checked = 0;
  for (int y = 0; y < k_.height; ++y) {
    for (int x = 0; x < k_.width; ++x) {
      const size_t p = static_cast<size_t>(y) * k_.width + x;
      if (!r.textured_mask[p]) continue;
      ++checked;
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(r.textured.at(x, y, c), photo.at(x, y, c), 1e-6 * photo.at(x, y, c) + 1e-12)
            << x << "," << y << " channel " << c;
    }
  }
  EXPECT_EQ(checked, r.textured_pixels);
  // The grid render alone misses the checker: 1 +- 0.35 against its mean is a relative error
  // of 0.26 or 0.54 on every pixel away from shading differences.
  const RenderMetrics grid = CompareRadiance(Rgb(r.grid), photo, r.textured_mask);
  EXPECT_GT(grid.median_rel_error, 0.2);
}

TEST_F(PhotoTextureTest, BeatsTheGridRenderUnderOtherLighting) {
  const Image photo = Truth(morning_);
  const Image truth = Truth(evening_);
  const PhotoTextureResult r = Textured(photo, morning_, evening_);
  const std::vector<uint8_t> building = ErodeMask(r.textured_mask, k_.width, k_.height, 1);
  const RenderMetrics tex = CompareRadiance(Rgb(r.textured), truth, building);
  const RenderMetrics grid = CompareRadiance(Rgb(r.grid), truth, building);
  std::printf(
      "evening from the morning photo: texture PSNR %.2f dB, median rel %.4f; grid PSNR "
      "%.2f dB, median rel %.4f (%lld pixels)\n",
      tex.psnr_db, tex.median_rel_error, grid.psnr_db, grid.median_rel_error,
      static_cast<long long>(tex.pixels));
  // The grid render's error is the checker's (0.26 or 0.54). Eq. 19's is the texture's ratio
  // between the lightings less the model's: the same sun term, and E_se interpolated on the
  // 2 m grid where the truth's is on the 0.1 m one (a few percent beside the pillar, where the
  // sky's occlusion changes fast), and pixels straddling a checker edge as the shadows move.
  EXPECT_GT(grid.median_rel_error, 0.2);
  EXPECT_LT(tex.median_rel_error, 0.05);
  EXPECT_GT(tex.psnr_db, grid.psnr_db + 6);
}

TEST_F(PhotoTextureTest, KeepsThePlainRenderWhereEq19CannotHold) {
  Image photo = Truth(morning_);
  // A photographed occluder the model lacks: 10x brighter than the model's prediction.
  for (int y = 60; y < 70; ++y)
    for (int x = 90; x < 100; ++x)
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) *= 10;
  // An unexposed pixel, and a non-finite one marked valid.
  std::vector<uint8_t> valid(static_cast<size_t>(k_.width) * k_.height, 1);
  valid[static_cast<size_t>(75) * k_.width + 50] = 0;
  photo.at(60, 80, 1) = NAN;
  const World& w = *world_;
  const SlotIrradiance pi = ComputeIrradiance(w.coarse, w.coarse_cache, *w.rc, morning_);
  const SlotIrradiance ni = ComputeIrradiance(w.coarse, w.coarse_cache, *w.rc, evening_);
  const PhotoTextureResult r =
      RenderWithPhotoTexture(w.mesh, w.coarse, *w.rc, w.coarse_albedo, photo, valid, morning_, pi,
                             evening_, ni, k_, pose_);
  for (int y = 60; y < 70; ++y) {
    for (int x = 90; x < 100; ++x) {
      EXPECT_FALSE(r.textured_mask[static_cast<size_t>(y) * k_.width + x]);
      for (int c = 0; c < 4; ++c) EXPECT_EQ(r.textured.at(x, y, c), r.grid.at(x, y, c));
    }
  }
  EXPECT_FALSE(r.textured_mask[static_cast<size_t>(75) * k_.width + 50]);
  EXPECT_FALSE(r.textured_mask[static_cast<size_t>(80) * k_.width + 60]);
  // Off the building (coverage 0: the sky above the plaza's far edge) the plain render too.
  for (size_t p = 0; p < r.textured_mask.size(); ++p) {
    if (r.grid.data[p * 4 + 3] < 0.999) {
      ASSERT_FALSE(r.textured_mask[p]);
    }
  }
  for (float v : r.textured.data) ASSERT_TRUE(std::isfinite(v));
}

TEST_F(PhotoTextureTest, RefusesAPhotoOfAnotherSize) {
  const Image photo(100, 75, 3, PixelUnits::kRadiance, 1.f);
  try {
    Textured(photo, morning_, evening_);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("100x75"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("200x150"), std::string::npos) << e.what();
  }
  PhotoTextureOptions o;
  o.max_texture_gain = 0;
  EXPECT_THROW(Textured(Truth(morning_), morning_, evening_, o), Error);
}

}  // namespace
}  // namespace rouen
