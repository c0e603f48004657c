#include "solve/ground_field.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/angles.h"
#include "core/error.h"
#include "solve/irradiance.h"
#include "solve/retro.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

Eigen::Vector3d SunAt(double az_deg, double el_deg) {
  const double a = az_deg * kDeg, e = el_deg * kDeg;
  return {std::cos(e) * std::sin(a), std::cos(e) * std::cos(a), std::sin(e)};
}

// The ground's albedo in the test world: 0.2 0.3 0.4 west of x = 0, 0.5 0.4 0.3 east of it.
Eigen::Vector3d TrueAlbedo(const Eigen::Vector3d& q) {
  return q.x() < 0 ? Eigen::Vector3d(0.2, 0.3, 0.4) : Eigen::Vector3d(0.5, 0.4, 0.3);
}

// An equirect panorama at `eye` of a sunlit rough ground (retro) with the model's cast shadow,
// no sky light: each pixel below the horizon the ground's radiance along its ray, the model's
// pixels 7 (not ground), the sky 1.
// With `field`, the sky lights the ground too (sky_e, the field's sky visibility per cell) and
// the ground in shadow also gets `unmodelled` x the sky's light (the walls around it).
Image RenderPanorama(const RayCaster& model, const Eigen::Vector3d& eye, const Intrinsics& k,
                     const Pose& pose, const Eigen::Vector3d& sun, double sun_e, double retro,
                     const GroundField* field = nullptr, double sky_e = 0, double unmodelled = 0) {
  Image im(k.width, k.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < k.height; ++y) {
    for (int x = 0; x < k.width; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      Eigen::Vector3d l = Eigen::Vector3d::Ones();
      const RayHit h = model.Intersect(eye, d);
      if (h.hit && (d.z() >= 0 || h.t < eye.z() / -d.z())) {
        l.setConstant(7);
      } else if (d.z() < 0) {
        const Eigen::Vector3d q = eye + (eye.z() / -d.z()) * d;
        const bool lit = !model.Occluded(q + Eigen::Vector3d(0, 0, 1e-3), sun, 0.0);
        double e = lit ? sun_e * sun.z() * RetroFactor(retro, {0, 0, 1}, sun, -d) : 0.0;
        if (field) {
          const double sky =
              sky_e * field->SkyVisibility(q) * AmbientRetroFactor(retro, {0, 0, 1}, -d);
          e += lit ? sky : sky * (1 + unmodelled);
        }
        l = TrueAlbedo(q) * (e / kPi);
      }
      for (int c = 0; c < 3; ++c) im.at(x, y, c) = static_cast<float>(l[c]);
    }
  }
  return im;
}

// A 30 m tower, and at two times an equirect panorama at eye height 30 m south of it of the
// ground around it (RenderPanorama), as the field's times.
class GroundFieldPanoramaTest : public ::testing::Test {
 protected:
  static constexpr double kSunE = 100;
  GroundFieldPanoramaTest() {
    k.projection = Projection::kEquirect;
    k.width = 360;
    k.height = 180;
    options.cell_m = 1;
    options.min_radius_m = 40;
    options.radius_factor = 1;
  }
  static Mesh Tower() {
    Mesh m;
    testing::AddBox(&m, {-5, -5, 0}, {5, 5, 30}, m.AddBlock("tower"));
    return m;
  }
  // The panoramas under suns[0] and suns[1]; the other arguments as RenderPanorama's.
  void Render(const std::array<Eigen::Vector3d, 2>& suns, double retro,
              const GroundField* field = nullptr, double sky_e = 0, double unmodelled = 0) {
    images.clear();
    images.reserve(2);  // the times point into it
    times.assign(2, GroundFieldTime{});
    for (int t = 0; t < 2; ++t) {
      images.push_back(RenderPanorama(model, pose.position, k, pose, suns[t], kSunE, retro, field,
                                      sky_e, unmodelled));
      times[t].panoramas.push_back({&images[t], k, pose});
      times[t].sun_dir = suns[t];
      times[t].sun_e = Eigen::Vector3d::Constant(kSunE);
      times[t].sky_e = Eigen::Vector3d::Constant(sky_e);
    }
  }
  const Mesh mesh = Tower();
  const RayCaster model{mesh};
  Intrinsics k;
  const Pose pose = Pose::Level({0, -30, 1.7}, 0, 0);
  GroundFieldOptions options;
  std::vector<Image> images;
  std::vector<GroundFieldTime> times;
};

TEST_F(GroundFieldPanoramaTest, PanoramaPixelsBecomeTheGroundsAlbedoWhereTheModelLeavesThem) {
  const Eigen::Vector3d eye = pose.position;
  const double retro = 0.5;
  // Two times: the tower's shadow falls north-west, then north-east; no sky light, so ground in
  // the shadow gives nothing and is seen sunlit at the other time.
  const std::array<Eigen::Vector3d, 2> suns = {SunAt(120, 35), SunAt(230, 40)};
  Render(suns, retro);
  GroundFieldOptions o = options;
  o.fit_retro = false;
  GroundFieldSummary s;
  const GroundField f = BuildGroundField(times, model, retro, o, &s);
  EXPECT_EQ(s.retro, retro);
  EXPECT_GT(s.pixels_model, 0);
  EXPECT_GT(s.pixels_used, 1000);
  EXPECT_EQ(f.level_z, 0);
  // Every observed cell holds its side's albedo (a cell straddling x = 0 the mix of both), up to
  // float rounding: the model and the renderer agree exactly.
  int checked = 0;
  for (int c = 0; c < f.nx * f.ny; ++c) {
    if (!f.observed[c]) continue;
    const Eigen::Vector3d q = f.CellCentre(c);
    if (std::abs(q.x()) < 1) continue;
    EXPECT_LT((f.Albedo(c) - TrueAlbedo(q)).cwiseAbs().maxCoeff(), 1e-4) << q.transpose();
    ++checked;
  }
  EXPECT_GT(checked, 500);
  // The ground the tower hides from the panorama (north of it) was not observed; it is filled.
  const int behind = f.Cell(0.5, 20);
  ASSERT_GE(behind, 0);
  EXPECT_EQ(f.observed[behind], 0);
  EXPECT_GT(f.Albedo(behind).minCoeff(), 0.19);
  // The sky the tower leaves: most of it at 30 m, little more than half at its foot.
  EXPECT_GT(f.sky_visibility[f.Cell(0.5, -35)], 0.9);
  EXPECT_LT(f.sky_visibility[f.Cell(0.5, -5.5)], 0.7);

  // Lit at the first time, the field gives the panorama's pixels back, the shadow included.
  const GroundLight g(f, model, suns[0], Eigen::Vector3d::Constant(kSunE), Eigen::Vector3d::Zero());
  int lit = 0, dark = 0;
  for (int y = 91; y < 180; ++y) {
    for (int x = 0; x < 360; ++x) {
      const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
      if (model.Intersect(eye, d).hit) continue;
      const Eigen::Vector3d q = eye + (eye.z() / -d.z()) * d;
      const int c = f.Cell(q.x(), q.y());
      if (c < 0 || !f.observed[c] || std::abs(q.x()) < 1) continue;
      // The shadow is cast from where the ray meets the ground, as the panorama has it: in
      // shadow both are black, lit both are the albedo's light (float rounding).
      const Eigen::Vector3d want(images[0].at(x, y, 0), images[0].at(x, y, 1),
                                 images[0].at(x, y, 2));
      const Eigen::Vector3d got = g.Arriving(eye, d);
      EXPECT_EQ(got.maxCoeff() > 0, want.maxCoeff() > 0) << x << " " << y;
      if (want.maxCoeff() > 0) {
        ++lit;
        EXPECT_NEAR(got.x() / want.x(), 1.0, 1e-4) << x << " " << y;
      } else {
        ++dark;
      }
    }
  }
  EXPECT_GT(lit, 100);
  EXPECT_GT(dark, 10);

  // The JSON round trip keeps every cell.
  const GroundField back = nlohmann::json(f).get<GroundField>();
  EXPECT_EQ(back.nx, f.nx);
  EXPECT_EQ(back.albedo[behind], f.albedo[behind]);
  EXPECT_EQ(back.sky_visibility, f.sky_visibility);
  EXPECT_EQ(back.far_albedo, f.far_albedo);
}

TEST(GroundFieldTest, BadInputIsRefusedByName) {
  Mesh m;
  testing::AddBox(&m, {-5, -5, 0}, {5, 5, 30}, m.AddBlock("tower"));
  const RayCaster model(m);
  GroundFieldOptions o;
  o.cell_m = 0;
  EXPECT_THROW(BuildGroundField({}, model, 0, o), Error);
  o = GroundFieldOptions{};
  o.max_cells = 10;
  try {
    BuildGroundField({}, model, 0, o);
    ADD_FAILURE() << "too many cells were accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("max_cells"), std::string::npos) << e.what();
  }
  // No panorama pixel meets the ground.
  try {
    BuildGroundField({}, model, 0, GroundFieldOptions{});
    ADD_FAILURE() << "a field without pixels was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no landscape panorama pixel"), std::string::npos);
  }
  nlohmann::json j = nlohmann::json(GroundField{});
  j["albedo"] = {1, 2};
  EXPECT_THROW(j.get<GroundField>(), Error);
}

// Two times of one panorama of a rough ground (retro 0.8) read by a field told the ground is
// Lambertian: the cells seen at both times disagree unless the retro is right, and the fit finds
// it. The cost is V-shaped about the truth (exact pixels), sampled every 0.25 and refined by a
// parabola through three samples: within a fifth of a step, 0.05.
TEST_F(GroundFieldPanoramaTest, TheGroundsRetroIsFittedFromThePanoramas) {
  const double truth = 0.8;
  Render({SunAt(120, 35), SunAt(230, 40)}, truth);
  GroundFieldOptions o = options;
  GroundFieldSummary s;
  const GroundField f = BuildGroundField(times, model, 0.0, o, &s);
  EXPECT_EQ(s.retro_given, 0.0);
  EXPECT_NEAR(s.retro, truth, 0.05);
  EXPECT_EQ(f.retro, s.retro);
  EXPECT_GT(s.retro_cells, 100);
  EXPECT_LT(s.retro_cost, s.retro_cost_given / 4);
  // Told nothing, the field reads the ground as Lambertian and keeps it.
  o.fit_retro = false;
  GroundFieldSummary given;
  EXPECT_EQ(BuildGroundField(times, model, 0.0, o, &given).retro, 0.0);
  EXPECT_EQ(given.retro, 0.0);
}

// Ground in the model's shadow gets light the field does not model (here as much again as the
// sky's, as the walls of a street send it): read in shadow, its albedo comes out twice the
// truth, and that albedo lit by the sun at another time far too bright. A cell the sun reached
// at some time keeps the albedo read in sun, exact here; the shadow moves between the two
// times, so many cells are seen both ways.
TEST_F(GroundFieldPanoramaTest, ACellSeenSunlitKeepsTheAlbedoReadInSun) {
  const double retro = 0.5, sky_e = 20;
  // The tower's shadow falls towards the panorama, south-south-west then south-south-east.
  const std::array<Eigen::Vector3d, 2> suns = {SunAt(20, 35), SunAt(340, 35)};
  GroundFieldOptions o = options;
  o.fit_retro = false;
  // The field's cells and sky visibility, for the renders' sky light.
  Render(suns, retro);
  const GroundField cells = BuildGroundField(times, model, retro, o);
  Render(suns, retro, &cells, sky_e, 1.0);
  const GroundField f = BuildGroundField(times, model, retro, o);
  int both = 0, shade_only = 0, shade_high = 0;
  for (int c = 0; c < f.nx * f.ny; ++c) {
    if (!f.observed[c]) continue;
    const Eigen::Vector3d q = f.CellCentre(c) + Eigen::Vector3d(0, 0, model.surface_offset());
    if (std::abs(q.x()) < 1) continue;
    const bool lit0 = !model.Occluded(q, suns[0], 0.0), lit1 = !model.Occluded(q, suns[1], 0.0);
    if (lit0 != lit1) {
      // Pixels near a cell's shadow edge are read as their own ray's ground is lit: 1%.
      EXPECT_NEAR(f.Albedo(c).x() / TrueAlbedo(q).x(), 1.0, 0.01) << q.transpose();
      ++both;
    } else if (!lit0) {
      ++shade_only;
      shade_high += f.Albedo(c).x() / TrueAlbedo(q).x() > 1.9;
    }
  }
  EXPECT_GT(both, 100);
  // Cells whose centre the shadow covers at both times read it twice too high (some of them
  // hold a sunlit pixel at the shadow's edge and keep that).
  EXPECT_GT(shade_only, 4);
  EXPECT_GE(2 * shade_high, shade_only);
}

// A cell's sky is read at the spots of it outside the model, and between cells bilinearly over
// the cells that see some sky: the ground beside a wall is not dark because a cell's centre
// lies under the wall.
TEST(GroundFieldTest, TheSkyBesideAWallIsReadOutsideTheModel) {
  const GroundField f = [] {
    GroundField g;
    g.cell_m = 2;
    g.nx = g.ny = 3;
    g.x0 = g.y0 = 0;
    g.albedo.assign(9, Eigen::Vector3f::Constant(0.3f));
    g.observed.assign(9, 1);
    g.sky_visibility = {0.2f, 0.4f, 0.6f, 0.8f, 0.f, 1.f, 1.f, 1.f, 1.f};
    return g;
  }();
  // At a cell's centre, its own; midway between two centres, their mean; beyond the cells, 1.
  EXPECT_NEAR(f.SkyVisibility({3, 1, 0}), 0.4, 1e-6);
  EXPECT_NEAR(f.SkyVisibility({2, 1, 0}), 0.3, 1e-6);
  EXPECT_NEAR(f.SkyVisibility({6, 1, 0}), 0.8, 1e-6);  // half the weight beyond the cells
  EXPECT_NEAR(f.SkyVisibility({100, 100, 0}), 1.0, 1e-12);
  // The cell under the model (0) does not count: midway between it and its neighbour, the
  // neighbour's.
  EXPECT_NEAR(f.SkyVisibility({3, 2, 0}), 0.4, 1e-6);

  // Built against a 10 m block whose wall runs through the middle of a column of 2 m cells: those
  // cells see the sky from their spots outside the block (about half of it beside a 30 m wall),
  // the cells wholly inside it next to none.
  Mesh m;
  testing::AddBox(&m, {-5, -5, 0}, {5, 5, 30}, m.AddBlock("tower"));
  const RayCaster model(m);
  const Intrinsics k = [] {
    Intrinsics i;
    i.projection = Projection::kEquirect;
    i.width = 90;
    i.height = 45;
    return i;
  }();
  Image pano(k.width, k.height, 3, PixelUnits::kRadiance);
  for (float& v : pano.data) v = 0.1f;
  GroundFieldTime t;
  t.panoramas.push_back({&pano, k, Pose::Level({0, -30, 1.7}, 0, 0)});
  t.sun_dir = SunAt(180, 40);
  t.sun_e = Eigen::Vector3d::Constant(100);
  t.sky_e = Eigen::Vector3d::Constant(10);
  GroundFieldOptions o;
  o.cell_m = 2;
  o.min_radius_m = 11;  // cells from -16 m: one edge falls on the wall at x = -5 +- 1
  o.radius_factor = 0;
  o.fit_retro = false;
  const GroundField built = BuildGroundField({t}, model, 0, o);
  const int straddling = built.Cell(-5.0 + 0.5, 0), inside = built.Cell(0, 0);
  ASSERT_GE(straddling, 0);
  ASSERT_GE(inside, 0);
  EXPECT_GT(built.sky_visibility[straddling], 0.3) << "the ground beside the wall sees no sky";
  EXPECT_LT(built.sky_visibility[straddling], 0.7);
  // Wholly inside: next to nothing (one ray of a spot's 16 escapes here, between the box's
  // triangles; such a spot then counts as outside).
  EXPECT_LT(built.sky_visibility[inside], 0.1);
}

// A vertical wall sees the level ground below its horizon under half its projected solid angle:
// a uniform Lambertian ground lit by the sun alone gives it rho E_h / 2, E_h the sun's
// irradiance on the ground, by either irradiance method.
TEST(GroundFieldTest, AWallSeesHalfOfAUniformGround) {
  Mesh m;
  const int b = m.AddBlock("wall");
  m.AddPolygon({{0, 0, 0}, {4, 0, 0}, {4, 0, 20}, {0, 0, 20}}, b);  // normal -y
  GridOptions go;
  go.spacing_m = 2;
  const SurfaceGrid g = BuildSurfaceGrid(m, go);
  const RayCaster rc(m);
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
  auto field = std::make_shared<GroundField>();
  field->cell_m = 4;
  field->nx = field->ny = 100;
  field->x0 = field->y0 = -200;
  field->albedo.assign(10000, Eigen::Vector3f(0.3f, 0.3f, 0.3f));
  field->observed.assign(10000, 1);
  field->sky_visibility.assign(10000, 1.f);
  field->far_albedo = Eigen::Vector3d::Constant(0.3);
  Lighting l;
  l.sun_dir = SunAt(180, 30);  // from the south: the wall's shadow falls behind it
  l.sun_radiance = Eigen::Vector3d::Constant(1e5);
  l.sky = testing::UniformSkyModel(0);
  l.env = EnvironmentMap::Constant(EnvOptions{}, Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones());
  l.ground = field;
  const double e_h = 1e5 * l.sun_solid_angle_sr * 0.5;
  IrradianceOptions mc, vf;
  vf.method = IrradianceMethod::kVectorFlux;
  vf.mesh = &m;
  for (const IrradianceOptions& o : {mc, vf}) {
    const SlotIrradiance irr = ComputeIrradiance(g, cache, rc, l, o);
    double mean = 0;
    for (int i = 0; i < g.size(); ++i) mean += irr.direct_se[i].x() / g.size();
    // The cache's 256 stratified directions: half of each azimuth ring below the horizon (up to
    // one of its 16 strata on the boundary).
    EXPECT_NEAR(mean, 0.3 * e_h / 2, 0.3 * e_h / 32);
  }
}

}  // namespace
}  // namespace rouen
