#include "pipeline/viewer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/solar.h"
#include "pipeline/export_test_util.h"
#include "pipeline/render_scene.h"
#include "pipeline/session_solve.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

double Elevation(UtcTime t, const Site& site) { return ComputeSunPosition(t, site).elevation_deg; }

TEST(ViewerDay, RunsFromSunriseToSunsetAtTheGivenElevation) {
  const Site site;  // Berkeley
  const ViewerDay d = ViewerDayOf(site, ParseIso8601("2026-06-21T16:00:00Z"), 24, 1.0);
  ASSERT_EQ(d.times.size(), 24u);
  EXPECT_EQ(d.times.front(), d.sunrise);
  EXPECT_EQ(d.times.back(), d.sunset);
  EXPECT_NEAR(Elevation(d.sunrise, site), 1.0, 0.01);
  EXPECT_NEAR(Elevation(d.sunset, site), 1.0, 0.01);
  // Noon is the day's highest sun: about 12:10 local solar time at 122.26 W (20:10 UTC).
  EXPECT_GT(Elevation(d.noon, site), Elevation(d.noon.PlusSeconds(-600), site));
  EXPECT_GT(Elevation(d.noon, site), Elevation(d.noon.PlusSeconds(600), site));
  EXPECT_NEAR(d.noon.UnixSeconds(), ParseIso8601("2026-06-21T20:11:00Z").UnixSeconds(), 300);
  EXPECT_LT(d.sunrise, d.noon);
  EXPECT_LT(d.noon, d.sunset);
  // Midsummer at 38 N: some 14.4 hours with the sun above 1 degree.
  const double hours = (d.sunset.UnixSeconds() - d.sunrise.UnixSeconds()) / 3600;
  EXPECT_GT(hours, 13.8);
  EXPECT_LT(hours, 14.8);
  // Evenly spaced, all in daylight.
  const double step = (d.sunset.UnixSeconds() - d.sunrise.UnixSeconds()) / 23;
  for (size_t i = 1; i < d.times.size(); ++i) {
    EXPECT_NEAR(d.times[i].UnixSeconds() - d.times[i - 1].UnixSeconds(), step, 1e-3);
    EXPECT_GT(Elevation(d.times[i], site), 0.9);
  }
  // Any time of the same day gives the same day.
  const ViewerDay later = ViewerDayOf(site, ParseIso8601("2026-06-22T01:00:00Z"), 24, 1.0);
  EXPECT_NEAR(later.noon.UnixSeconds(), d.noon.UnixSeconds(), 1);
}

TEST(ViewerDay, PolarNightIsRefusedAndPolarDayTakesTheWholeDay) {
  Site arctic;
  arctic.lat_deg = 80;
  arctic.lon_deg = 15;
  try {
    ViewerDayOf(arctic, ParseIso8601("2026-12-21T12:00:00Z"), 8, 1.0);
    FAIL() << "no error for a polar night";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the sun stays below"), std::string::npos) << e.what();
  }
  const ViewerDay d = ViewerDayOf(arctic, ParseIso8601("2026-06-21T12:00:00Z"), 8, 1.0);
  EXPECT_NEAR(d.sunset.UnixSeconds() - d.sunrise.UnixSeconds(), 86400, 0.1);
}

TEST(ViewerEncoding, RoundTripsWithinItsQuantisation) {
  EXPECT_EQ(ViewerEncode(0, 3), 0);
  EXPECT_EQ(ViewerEncode(3, 3), 255);
  EXPECT_EQ(ViewerEncode(7, 3), 255);  // above the scale: clipped
  EXPECT_DOUBLE_EQ(ViewerDecode(255, 3), 3);
  for (double v : {0.01, 0.1, 0.5, 1.0, 2.9}) {
    const double back = ViewerDecode(ViewerEncode(v, 3), 3);
    // One step of 255 (x/scale)^(1/2.2) is a relative step of 2.2 / (255 (x/scale)^(1/2.2)).
    const double rel = 2.2 / (255 * std::pow(v / 3, 1 / 2.2));
    EXPECT_NEAR(back, v, v * rel / 2 + 1e-12) << v;
  }
}

// A solved scene (WriteExportTestScene: a tower on a plaza, one slot), loaded as render loads it.
class ViewerScene : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("rouen_viewer_test_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    testing::WriteExportTestScene(*dir_ / "scene");
    scene_ = new LoadedScene(LoadScene(*dir_ / "scene"));
  }
  static void TearDownTestSuite() {
    delete scene_;
    fs::remove_all(*dir_);
    delete dir_;
  }
  static fs::path* dir_;
  static LoadedScene* scene_;
};
fs::path* ViewerScene::dir_ = nullptr;
LoadedScene* ViewerScene::scene_ = nullptr;

// Every triangle's tile holds the grid's values interpolated at its texels' centres, and the
// blocks' tiles do not overlap in the one atlas.
TEST_F(ViewerScene, TheAtlasHoldsTheGridsValuesAtEachTexel) {
  const SolveResult& s = scene_->solved;
  for (int k : {1, 3}) {
    const ViewerAtlas atlas = PackViewerAtlas(s.mesh, s.grid, k, 4096);
    ASSERT_GT(atlas.width, 0);
    std::vector<Eigen::Vector3d> values, ids;
    for (const GridPoint& p : s.grid.points) {
      values.push_back(p.position + Eigen::Vector3d(100, 100, 100));  // varies smoothly
      ids.push_back(Eigen::Vector3d::Constant(p.block + 1));
    }
    const Image baked = atlas.Bake(s.grid, values), block = atlas.Bake(s.grid, ids);
    ASSERT_EQ(baked.width, atlas.width);
    int64_t checked = 0;
    for (int t = 0; t < static_cast<int>(s.mesh.triangles.size()); ++t) {
      const AtlasTile& tile = atlas.layout.tiles[t];
      if (tile.size == 0) continue;
      const Eigen::Vector2d origin = atlas.Texel(t, 0, 0), corner = atlas.Texel(t, 1, 1);
      ASSERT_LE(corner.x(), atlas.width);
      ASSERT_LE(corner.y(), atlas.height);
      // Every texel whose centre is inside the triangle, at its barycentric coordinates.
      for (int y = static_cast<int>(origin.y()); y < corner.y(); ++y)
        for (int x = static_cast<int>(origin.x()); x < corner.x(); ++x) {
          const double u = (x + 0.5 - origin.x()) / tile.size,
                       v = (y + 0.5 - origin.y()) / tile.size;
          if (u + v > 1) continue;
          const Eigen::Vector3d expect = s.grid.Interpolate(values, t, u, v);
          for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(baked.at(x, y, ch), expect[ch], 1e-3);
          ASSERT_EQ(block.at(x, y, 0), s.mesh.triangle_block[t] + 1) << "triangle " << t;
          ++checked;
        }
    }
    EXPECT_GT(checked, 500);
  }
}

// The page's sun visibility, ray-cast per texel of the finer atlas, agrees with the grid's
// (ComputeIrradiance's) at the texels holding the grid points, but for shadow edges.
TEST_F(ViewerScene, TexelVisibilityAgreesWithTheGrids) {
  const SolveResult& s = scene_->solved;
  const ViewerAtlas shadow = PackViewerAtlas(s.mesh, s.grid, 4, 4096);
  for (const Eigen::Vector3d& sun : {EnuFromAzEl(100, 30), EnuFromAzEl(250, 15)}) {
    Lighting l = s.slots[0].lighting;
    l.sun_dir = sun;
    const SlotIrradiance irr = ComputeIrradiance(s.grid, s.hemisphere, *s.caster, l);
    const Image vis = SunVisibilityAtlas(shadow, s.mesh, *s.caster, sun);
    // Each grid point's texel: the grid point is the centroid of its sub-triangle, found as
    // the texel of the triangle's barycentric coordinates of the point.
    int agree = 0, total = 0, lit = 0, dark = 0;
    for (int j = 0; j < s.grid.size(); ++j) {
      const GridPoint& p = s.grid.points[j];
      const Eigen::Vector3i& tri = s.mesh.triangles[p.triangle];
      const Eigen::Vector3d a = s.mesh.vertices[tri[0]], e1 = s.mesh.vertices[tri[1]] - a,
                            e2 = s.mesh.vertices[tri[2]] - a, d = p.position - a;
      // Barycentric (u, v) of the point: least squares on the triangle's plane.
      Eigen::Matrix<double, 3, 2> m;
      m << e1, e2;
      const Eigen::Vector2d uv = m.colPivHouseholderQr().solve(d);
      const Eigen::Vector2d t = shadow.Texel(p.triangle, uv.x(), uv.y());
      const float v = vis.at(static_cast<int>(t.x()), static_cast<int>(t.y()));
      agree += (v > 0.5f) == (irr.sun_visibility[j] > 0.5f);
      lit += v > 0.5f;
      dark += p.normal.dot(sun) > 0 && v < 0.5f;
      ++total;
    }
    EXPECT_GT(agree, 0.97 * total) << agree << " of " << total;
    EXPECT_GT(lit, 0);
    EXPECT_GT(dark, 0) << "no shadow";
  }
}

// The bases are rouen's own irradiance: the lighting RequestedLighting predicts for the time
// (clear, and with pbs 1) and IrradianceFor's E_sun and E_se with the interreflection.
TEST_F(ViewerScene, TheBasesAreRouensIrradianceAtTheirTimes) {
  ViewerOptions o;
  o.times = 3;
  const ViewerData data = ComputeViewerData(*scene_, o);
  ASSERT_EQ(data.bases.size(), 3u);
  const SolveResult& s = scene_->solved;
  for (int i = 0; i < 3; ++i) {
    const ViewerBasis& b = data.bases[i];
    RenderRequest r;
    r.time = data.day.times[i];
    r.intrinsics = Intrinsics::PinholeFov(2, 2, 60);
    const Lighting clear = RequestedLighting(*scene_, r);
    r.relight.pbs = 1;
    const Lighting overcast = RequestedLighting(*scene_, r);
    const SlotIrradiance ic = IrradianceFor(s, clear), io = IrradianceFor(s, overcast);
    EXPECT_LT((b.sun_dir - clear.sun_dir).norm(), 1e-12);
    EXPECT_LT((b.sun_e - clear.sun_radiance * clear.sun_solid_angle_sr).norm(), 1e-9);
    ASSERT_EQ(b.se.size(), static_cast<size_t>(s.grid.size()));
    int lit = 0, shadowed = 0;
    for (int j = 0; j < s.grid.size(); ++j) {
      EXPECT_LT((b.se[j] - ic.se[j]).norm(), 1e-9 * (1 + ic.se[j].norm())) << j;
      EXPECT_LT((b.se_overcast[j] - io.se[j]).norm(), 1e-9 * (1 + io.se[j].norm())) << j;
      EXPECT_LT((b.sun[j] - ic.sun[j]).norm(), 1e-9 * (1 + ic.sun[j].norm())) << j;
      // What the page computes from the visibility: E_sun = sun_e max(0, n.s) V.
      const double cosi = std::max(0.0, s.grid.points[j].normal.dot(b.sun_dir));
      const Eigen::Vector3d e = b.sun_e * (cosi * b.sun_visibility[j]);
      EXPECT_LT((e - ic.sun[j]).norm(), 1e-9 * (1 + ic.sun[j].norm())) << j;
      lit += cosi > 0 && b.sun_visibility[j] == 1;
      shadowed += cosi > 0 && b.sun_visibility[j] == 0;
    }
    EXPECT_GT(lit, 0);
    EXPECT_GT(shadowed, 0) << "the tower casts a shadow on the plaza";
  }
  EXPECT_GT(data.exposure, 0);
}

// The page blends E_se linearly between the clear and the overcast basis; rouen's E_se at pbs
// 0.5 (the §6.3 sky refitted) is close to that blend.
TEST_F(ViewerScene, OvercastBlendIsNearRouensPartlyCloudyIrradiance) {
  ViewerOptions o;
  o.times = 3;
  const ViewerData data = ComputeViewerData(*scene_, o);
  const ViewerBasis& b = data.bases[1];
  RenderRequest r;
  r.time = data.day.times[1];
  r.intrinsics = Intrinsics::PinholeFov(2, 2, 60);
  r.relight.pbs = 0.5;
  const SlotIrradiance half = IrradianceFor(scene_->solved, RequestedLighting(*scene_, r));
  double err = 0, total = 0;
  for (size_t j = 0; j < b.se.size(); ++j) {
    err += (0.5 * (b.se[j] + b.se_overcast[j]) - half.se[j]).norm();
    total += half.se[j].norm();
  }
  std::printf("E_se at pbs 0.5 against the linear blend: %.2f%% mean relative difference\n",
              100 * err / total);
  EXPECT_LT(err / total, 0.02);
}

}  // namespace
}  // namespace rouen
