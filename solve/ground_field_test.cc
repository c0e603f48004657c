#include "solve/ground_field.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

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
// the ground in shadow also gets `unmodelled` x the sky's light (the walls around it), and
// every spot of ground the irradiance `walls` gives its cell of `field` (none: nothing).
Image RenderPanorama(const RayCaster& model, const Eigen::Vector3d& eye, const Intrinsics& k,
                     const Pose& pose, const Eigen::Vector3d& sun, double sun_e, double retro,
                     const GroundField* field = nullptr, double sky_e = 0, double unmodelled = 0,
                     const std::vector<Eigen::Vector3f>* walls = nullptr) {
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
          const int c = field->Cell(q.x(), q.y());
          if (walls && c >= 0) e += (*walls)[c].x() * AmbientRetroFactor(retro, {0, 0, 1}, -d);
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
              const GroundField* field = nullptr, double sky_e = 0, double unmodelled = 0,
              const std::vector<Eigen::Vector3f>* walls = nullptr) {
    images.clear();
    images.reserve(2);  // the times point into it
    times.assign(2, GroundFieldTime{});
    for (int t = 0; t < 2; ++t) {
      images.push_back(RenderPanorama(model, pose.position, k, pose, suns[t], kSunE, retro, field,
                                      sky_e, unmodelled, walls));
      times[t].panoramas.push_back({&images[t], k, pose});
      times[t].sun_dir = suns[t];
      times[t].sun_e = Eigen::Vector3d::Constant(kSunE);
      times[t].sky_e = Eigen::Vector3d::Constant(sky_e);
    }
  }
  // The field's cells and sky visibility, read from panoramas under `suns` without sky light,
  // the retro given.
  GroundField Cells(const std::array<Eigen::Vector3d, 2>& suns, double retro) {
    Render(suns, retro);
    return BuildGroundField(times, model, retro, FixedRetro());
  }
  GroundFieldOptions FixedRetro() const {
    GroundFieldOptions o = options;
    o.fit_retro = false;
    return o;
  }
  // Suns whose tower shadow falls towards the panorama, south-south-west then south-south-east.
  const std::array<Eigen::Vector3d, 2> towards_panorama = {SunAt(20, 35), SunAt(340, 35)};
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
  const std::array<Eigen::Vector3d, 2>& suns = towards_panorama;
  const GroundFieldOptions o = FixedRetro();
  const GroundField cells = Cells(suns, retro);  // for the renders' sky light
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

// The walls' light on the ground given (GroundFieldTime::walls_e, here 40 x the part of the sky
// the tower hides from the cell, on every spot of it, sunlit or not): the field reads the
// ground's own albedo beside the tower, where without it the albedo holds that light, and says
// so (GroundField::walls). Given for some times only, or for another layout, it is refused.
TEST_F(GroundFieldPanoramaTest, TheWallsLightGivenTheFieldReadsTheGroundsOwnAlbedo) {
  const double retro = 0.5, sky_e = 20;
  const std::array<Eigen::Vector3d, 2>& suns = towards_panorama;
  const GroundFieldOptions o = FixedRetro();
  const GroundField cells = Cells(suns, retro);
  EXPECT_FALSE(cells.walls);
  std::vector<Eigen::Vector3f> walls(cells.sky_visibility.size());
  for (size_t c = 0; c < walls.size(); ++c)
    walls[c] = Eigen::Vector3f::Constant(40 * (1 - cells.sky_visibility[c]));
  Render(suns, retro, &cells, sky_e, 0.0, &walls);
  const GroundField without = BuildGroundField(times, model, retro, o);
  for (GroundFieldTime& t : times) t.walls_e = walls;
  const GroundField with = BuildGroundField(times, model, retro, o);
  EXPECT_TRUE(with.walls);
  EXPECT_EQ(with.sky_visibility, cells.sky_visibility);
  int near = 0, high = 0;
  for (int c = 0; c < with.nx * with.ny; ++c) {
    if (!with.observed[c] || !(with.sky_visibility[c] < 0.9)) continue;
    const Eigen::Vector3d q = with.CellCentre(c);
    if (std::abs(q.x()) < 1) continue;
    ++near;
    // Exact up to float rounding: the model and the renderer agree.
    EXPECT_LT((with.Albedo(c) - TrueAlbedo(q)).cwiseAbs().maxCoeff(), 1e-4) << q.transpose();
    high += without.Albedo(c).x() > 1.05 * TrueAlbedo(q).x();
  }
  EXPECT_GT(near, 20);
  EXPECT_GE(2 * high, near) << "the walls' light is not in the albedo read without it";

  times[1].walls_e.clear();
  EXPECT_THROW(BuildGroundField(times, model, retro, o), Error);
  times[1].walls_e.assign(7, Eigen::Vector3f::Zero());
  EXPECT_THROW(BuildGroundField(times, model, retro, o), Error);
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

// A wall 4 m wide and 20 m high facing -y at y = 0, its 2 m grid and hemisphere cache.
struct Wall {
  static Mesh Make() {
    Mesh m;
    m.AddPolygon({{0, 0, 0}, {4, 0, 0}, {4, 0, 20}, {0, 0, 20}}, m.AddBlock("wall"));
    return m;
  }
  static SurfaceGrid Grid(const Mesh& m) {
    GridOptions go;
    go.spacing_m = 2;
    return BuildSurfaceGrid(m, go);
  }
  const Mesh m = Make();
  const SurfaceGrid g = Grid(m);
  const RayCaster rc{m};
  const HemisphereCache cache = BuildHemisphereCache(g, rc);
};

// A field of nx x nx cells of cell_m from (x0, x0), albedo 0.3 everywhere, every cell seeing the
// whole sky.
std::shared_ptr<GroundField> UniformField(double cell_m, int nx, double x0) {
  auto field = std::make_shared<GroundField>();
  field->cell_m = cell_m;
  field->nx = field->ny = nx;
  field->x0 = field->y0 = x0;
  field->albedo.assign(nx * nx, Eigen::Vector3f::Constant(0.3f));
  field->observed.assign(nx * nx, 1);
  field->sky_visibility.assign(nx * nx, 1.f);
  field->far_albedo = Eigen::Vector3d::Constant(0.3);
  return field;
}

// A vertical wall sees the level ground below its horizon under half its projected solid angle:
// a uniform Lambertian ground lit by the sun alone gives it rho E_h / 2, E_h the sun's
// irradiance on the ground, by either irradiance method.
TEST(GroundFieldTest, AWallSeesHalfOfAUniformGround) {
  const Wall w;
  const Mesh& m = w.m;
  const SurfaceGrid& g = w.g;
  const RayCaster& rc = w.rc;
  const HemisphereCache& cache = w.cache;
  const std::shared_ptr<GroundField> field = UniformField(4, 100, -200);
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

// A wall of uniform radiosity B lights the ground in front of it (GroundWallsIrradiance): a cell
// gets B times the part of its sky the wall hides, 1 - V, exactly (the same rays); a cell behind
// it sees its back and gets nothing. That ground lights the wall back (AddInterreflection with
// the bounce): rho_g (1 / K) sum over the point's directions to the ground of its cell's light,
// against an estimate made here from other rays (per point 2,048 cosine directions, per spot of
// ground 256 rays): the per-point estimates scatter by a few percent (about 100 directions meet
// the ground, each cell's wall fraction from 64 rays), their mean over the wall's points by about
// 1%, hence 4%. A field read without the walls' light gets no bounce (it holds that light).
TEST(GroundFieldTest, AWallLightsTheGroundAndTheGroundTheWall) {
  const Wall w;
  const SurfaceGrid& g = w.g;
  const RayCaster& rc = w.rc;
  const HemisphereCache& cache = w.cache;
  const std::shared_ptr<GroundField> field = UniformField(0.5, 160, -40);
  const int n = field->nx * field->ny;
  const GroundWalls walls = CastGroundWalls(*field, rc, false);
  for (int c = 0; c < n; ++c) field->sky_visibility[c] = walls.SkyVisibility(c);
  field->walls = true;

  const GroundBounce bounce = BuildGroundBounce(*field, rc, g, cache);
  ASSERT_FALSE(bounce.empty());
  const double kB = 50;  // rho_sun 0.5 x E_sun 100, no sky light
  const std::vector<Eigen::Vector3d> rho_sun(g.size(), Eigen::Vector3d::Constant(0.5)),
      rho_se(g.size(), Eigen::Vector3d::Zero());
  SlotIrradiance irr;
  irr.sun.assign(g.size(), Eigen::Vector3d::Constant(100));
  irr.direct_se.assign(g.size(), Eigen::Vector3d::Zero());
  irr.se = irr.direct_se;
  irr.sun_visibility.assign(g.size(), 1.f);
  const std::vector<Eigen::Vector3f> e = GroundWallsIrradiance(bounce, g, rho_sun, rho_se, irr);
  ASSERT_EQ(static_cast<int>(e.size()), n);
  const int front = field->Cell(2, -1), behind = field->Cell(2, 1);
  ASSERT_LT(field->sky_visibility[front], 0.7);
  ASSERT_LT(field->sky_visibility[behind], 0.7);
  EXPECT_NEAR(e[front].x(), kB * (1 - field->sky_visibility[front]), 1e-4 * kB);
  EXPECT_EQ(e[behind].x(), 0.f);

  SlotIrradiance with = irr, plain = irr;
  AddInterreflection(g, cache, rho_sun, rho_se, &plain, 1);
  AddInterreflection(g, cache, rho_sun, rho_se, &with, 1, {}, Eigen::Vector3d::UnitZ(), nullptr,
                     nullptr, &bounce);
  // Here: 2,048 cosine directions about the normal (-y), each that meets the ground at q adding
  // the part of 256 rays from q that meet the wall's front.
  const int kDirs = 2048, kRays = 256;
  double got = 0, want = 0;
  for (int i = 0; i < g.size(); ++i) {
    const GridPoint& p = g.points[i];
    const Eigen::Vector3d o = p.position + rc.surface_offset() * p.normal;
    double sum = 0;
    for (int k = 0; k < kDirs; ++k) {
      const double u = (k % 64 + 0.5) / 64, v = (k / 64 + 0.5) / 32;
      const double r = std::sqrt(u), phi = 2 * kPi * v;
      // About n = -y: tangent x, bitangent z.
      const Eigen::Vector3d d(r * std::cos(phi), -std::sqrt(1 - u), r * std::sin(phi));
      if (!(d.z() < 0)) continue;
      const Eigen::Vector3d q = o + (o.z() / -d.z()) * d;
      int hit = 0;
      for (int j = 0; j < kRays; ++j) {
        const double a = (j % 16 + 0.5) / 16, c = (j / 16 + 0.5) / 16;
        const double s = std::sqrt(a), psi = 2 * kPi * c;
        const Eigen::Vector3d up(s * std::cos(psi), s * std::sin(psi), std::sqrt(1 - a));
        const RayHit h = rc.Intersect(q + Eigen::Vector3d(0, 0, rc.surface_offset()), up);
        hit += h.hit && up.y() > 0;  // the front (normal -y) faces rays going +y
      }
      sum += 0.3 * kB * hit / kRays;
    }
    want += sum / kDirs;
    got += with.se[i].x() - plain.se[i].x();
  }
  EXPECT_GT(want, 0);
  EXPECT_NEAR(got / want, 1.0, 0.04);

  field->walls = false;
  Lighting l;
  l.ground = field;
  EXPECT_EQ(GroundBouncesOf({l}, rc, g, cache)[0], nullptr);
  field->walls = true;
  EXPECT_NE(GroundBouncesOf({l}, rc, g, cache)[0], nullptr);
}

// A wall's sun lobe sends its glint to the ground and by the ground back to the wall as its
// diffuse light does (GroundWallsIrradiance, AddInterreflection with the bounce, sun_lobes):
// eq. 13's lobe of exponent 0 under a sun along the wall's normal has f_s = rho_s towards every
// direction in front, a Lambertian reflector of albedo pi rho_s. So the black wall with that
// lobe lights the ground, and the wall, as the Lambertian wall of that albedo does, to rounding.
TEST(GroundFieldTest, AWallsGlintReachesTheGroundAsItsDiffuseLightDoes) {
  const Wall w;
  const SurfaceGrid& g = w.g;
  const std::shared_ptr<GroundField> field = UniformField(0.5, 160, -40);
  const GroundWalls walls = CastGroundWalls(*field, w.rc, false);
  for (int c = 0; c < field->nx * field->ny; ++c) field->sky_visibility[c] = walls.SkyVisibility(c);
  field->walls = true;
  const GroundBounce bounce = BuildGroundBounce(*field, w.rc, g, w.cache);
  ASSERT_FALSE(bounce.empty());
  const Eigen::Vector3d normal = g.points[0].normal;  // -y
  const double rho_s = 0.1;
  std::vector<SpecularLobe> lobes(1);
  lobes[0].rho_s.setConstant(rho_s);
  lobes[0].n = 0;
  const std::vector<Eigen::Vector3d> black(g.size(), Eigen::Vector3d::Zero()),
      lambert(g.size(), Eigen::Vector3d::Constant(kPi * rho_s));
  SlotIrradiance irr;
  irr.sun.assign(g.size(), Eigen::Vector3d::Constant(100));
  irr.direct_se.assign(g.size(), Eigen::Vector3d::Zero());
  irr.se = irr.direct_se;
  const std::vector<Eigen::Vector3f> diffuse =
      GroundWallsIrradiance(bounce, g, lambert, black, irr, {}, normal);
  const std::vector<Eigen::Vector3f> glint =
      GroundWallsIrradiance(bounce, g, black, black, irr, {}, normal, lobes);
  double lit = 0;
  for (size_t c = 0; c < diffuse.size(); ++c) {
    EXPECT_NEAR(glint[c].x(), diffuse[c].x(), 1e-5 * (1 + diffuse[c].x())) << c;
    lit += diffuse[c].x();
  }
  EXPECT_GT(lit, 0);
  SlotIrradiance a = irr, b = irr;
  AddInterreflection(g, w.cache, lambert, black, &a, 2, {}, normal, nullptr, nullptr, &bounce);
  AddInterreflection(g, w.cache, black, black, &b, 2, {}, normal, nullptr, nullptr, &bounce, lobes);
  for (int i = 0; i < g.size(); ++i) {
    EXPECT_GT(a.se[i].x(), 0) << i;
    EXPECT_NEAR(b.se[i].x(), a.se[i].x(), 1e-9 * a.se[i].x()) << i;
  }
}

// Beside a long 20 m wall north of it, a spot of ground loses the sky the wall hides as that sky
// is (HiddenSkyExcess), not as the sky's mean: under a sky ten times brighter in the north (a low
// sun's side) it keeps the southern half and the sliver of northern sky above the wall,
// pi L_s / 2 + pi L_n (1/2 - h) with h the share of its rays the wall stops (every one of them
// northwards); the mean would give it (1 - h) of the whole sky's irradiance, three times as much
// here. Under a uniform sky both are the same.
TEST(GroundFieldTest, TheSkyAWallHidesIsTheSkyInItsDirections) {
  Mesh m;
  m.AddPolygon({{-100, 0, 0}, {-100, 0, 20}, {100, 0, 20}, {100, 0, 0}}, m.AddBlock("wall"));
  const RayCaster model(m);
  const std::shared_ptr<GroundField> field = UniformField(2, 20, -20);
  field->sky_rays = 1024;
  const GroundWalls all = CastGroundWalls(*field, model, false);
  for (int c = 0; c < field->nx * field->ny; ++c) field->sky_visibility[c] = all.SkyVisibility(c);
  const Eigen::Vector3d q(1, -1, 0);  // the centre of the cell at the wall's foot
  const int cell = field->Cell(q.x(), q.y());
  ASSERT_GE(cell, 0);
  const double h = 1 - field->sky_visibility[cell];
  ASSERT_GT(h, 0.3) << "the wall hides little of the cell's sky";
  const double ln = 10, ls = 1;
  const auto north_bright = [&](const Eigen::Vector3d& d) {
    return Eigen::Vector3d::Constant(d.y() > 0 ? ln : ls);
  };
  const Eigen::Vector3d sky_e = Eigen::Vector3d::Constant(kPi * (ln + ls) / 2);
  const Eigen::Vector3d no_sun = Eigen::Vector3d::Zero(), sun = SunAt(180, -10);
  const Eigen::Vector3d up(0, 0, 1);
  const double rho = 0.3;
  const double want = rho / kPi * (kPi * ls / 2 + kPi * ln * (0.5 - h));
  const GroundWalls shaded = CastGroundWalls(*field, model, true);
  const GroundLight directional(*field, model, sun, no_sun, sky_e,
                                HiddenSkyExcess(shaded, north_bright, sky_e));
  const GroundLight mean(*field, model, sun, no_sun, sky_e);
  EXPECT_NEAR(directional.Radiance(q, up).x(), want, 1e-6 * want);
  EXPECT_GT(mean.Radiance(q, up).x(), 2 * want);
  EXPECT_NEAR(mean.Radiance(q, up).x(), rho / kPi * sky_e.x() * (1 - h), 1e-6);
  // A uniform sky of the same irradiance: the same light either way.
  const GroundLight uniform(
      *field, model, sun, no_sun, sky_e,
      HiddenSkyExcess(
          shaded, [&](const Eigen::Vector3d&) { return Eigen::Vector3d(sky_e / kPi); }, sky_e));
  EXPECT_NEAR(uniform.Radiance(q, up).x(), mean.Radiance(q, up).x(), 1e-9);
}

}  // namespace
}  // namespace rouen
