#include "pipeline/solve_controller.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "core/cancel.h"
#include "core/error.h"
#include "core/error_of.h"
#include "core/solar.h"
#include "pipeline/demo.h"
#include "pipeline/solve_config.h"
#include "solve/grid.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

// The small scene: the built-in simulated world captured quickly (5 times of day, the demo's
// held-out slot kept out of the albedos) and calibrated once for every test.
class SolveControllerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("rouen_solve_controller_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    DemoOptions demo;
    demo.out = *dir_;
    demo.quick = true;
    heldout_ = CaptureDemo(demo, {}).rig.heldout_slot;
    session_ = new Session(Session::Load(*dir_ / "session"));
    options_ = new PipelineOptions;
    options_->work_dir = *dir_ / "work";
    options_->config =
        SessionSolveConfig(session_->info(), (*dir_ / "session" / "session.json").string(), true);
    options_->exclude_albedo_slots = {heldout_};
    calib_ = new CalibResult(CalibrateSession(*session_, *options_));
  }
  static void TearDownTestSuite() {
    delete calib_;
    delete options_;
    delete session_;
    fs::remove_all(*dir_);
    delete dir_;
  }
  static int Slots() {
    int n = 0;
    for (const auto& [name, g] : calib_->groups) n = std::max(n, g.slot + 1);
    return n;
  }

  static fs::path* dir_;
  static Session* session_;
  static PipelineOptions* options_;
  static CalibResult* calib_;
  static int heldout_;
};
fs::path* SolveControllerTest::dir_ = nullptr;
Session* SolveControllerTest::session_ = nullptr;
PipelineOptions* SolveControllerTest::options_ = nullptr;
CalibResult* SolveControllerTest::calib_ = nullptr;
int SolveControllerTest::heldout_ = -1;

TEST_F(SolveControllerTest, TheStagesRunInThePapersOrderAndNoOtherway) {
  SolveController c(*session_, *calib_, *options_);
  EXPECT_EQ(ErrorOf([&] { c.SolveLighting(); }),
            "solve: stage 'lighting' asked for before stage 'model'");
  c.ReadModel();
  EXPECT_EQ(ErrorOf([&] { c.ReadModel(); }), "solve: stage 'model' asked for again");
  EXPECT_EQ(ErrorOf([&] { c.BuildGrid(); }),
            "solve: stage 'surface grid' asked for before stage 'lighting'");
}

TEST_F(SolveControllerTest, ReadModelGivesTheSessionsModelAndItsCaster) {
  SolveController c(*session_, *calib_, *options_);
  c.ReadModel();
  const Mesh model = ReadSessionModel(*session_);
  EXPECT_EQ(c.result().mesh.block_names, model.block_names);
  EXPECT_EQ(c.result().mesh.triangles.size(), model.triangles.size());
  ASSERT_NE(c.result().caster, nullptr);
  EXPECT_TRUE(c.result().surrounding_blocks.empty());
}

// §3.1-3.3 per slot: the sun where ERFA puts it at the slot's time, its radiance measured, a
// sky fitted and an environment read; a slot without its sky photo named in the error.
TEST_F(SolveControllerTest, SolveLightingLightsEverySlotAtItsTime) {
  SolveController c(*session_, *calib_, *options_);
  c.ReadModel();
  c.SolveLighting();
  const SolveResult& r = c.result();
  ASSERT_EQ(static_cast<int>(r.slots.size()), Slots());
  const Site site = SessionSite(*session_);
  for (const SlotSolve& s : r.slots) {
    const HdrGroup& sky = calib_->groups.at(BracketName(s.slot, Target::kSky, 0));
    EXPECT_EQ(s.utc.Iso8601(), sky.utc.Iso8601()) << s.slot;
    EXPECT_LT((s.lighting.sun_dir - ComputeSunPosition(sky.utc, site).DirectionEnu()).norm(),
              1e-12);
    EXPECT_TRUE(s.lighting.sun_radiance.allFinite());
    EXPECT_GT(s.lighting.sun_radiance.minCoeff(), 0);
    EXPECT_GT(s.sky_summary.samples, 0);
    EXPECT_FALSE(s.lighting.env.radiance.empty()) << s.slot;
    EXPECT_NO_THROW(s.lighting.env.Validate()) << s.slot;
  }
  // Each slot's time as scene.json keeps it.
  ASSERT_EQ(r.stages.size(), r.slots.size());
  EXPECT_EQ(r.stages[1].stage, "slot 1 lighting (sun, sky, environment)");

  CalibResult without_sky = *calib_;
  without_sky.groups.erase(BracketName(2, Target::kSky, 0));
  SolveController d(*session_, without_sky, *options_);
  d.ReadModel();
  EXPECT_EQ(ErrorOf([&] { d.SolveLighting(); }),
            session_->dir().string() + ": slot 2 lacks a sky or landscape bracket (rouen status " +
                session_->dir().string() +
                " lists each slot's brackets and the command that adds a missing one)");
}

// The ground's reflection is fitted from the training slots only, and kept with them; off, the
// ground is Lambert's.
TEST_F(SolveControllerTest, FitGroundReflectionUsesTheTrainingSlotsOnly) {
  SolveController c(*session_, *calib_, *options_);
  c.ReadModel();
  c.SolveLighting();
  c.FitGroundReflection();
  ASSERT_TRUE(c.result().env_stereo.has_value());
  std::vector<int> training;
  for (int s = 0; s < Slots(); ++s)
    if (s != heldout_) training.push_back(s);
  EXPECT_EQ(c.result().env_stereo_slots, training);
  EXPECT_TRUE(std::isfinite(c.result().env_ground_retro));

  PipelineOptions off = *options_;
  off.config.fit_ground_retro = false;
  SolveController d(*session_, *calib_, off);
  d.ReadModel();
  d.SolveLighting();
  d.FitGroundReflection();
  EXPECT_FALSE(d.result().env_stereo.has_value());
  EXPECT_EQ(d.result().env_ground_retro, 0);
}

// The ground field, asked for, is made once and lent to every slot's lighting; by default a
// model without surroundings has none.
TEST_F(SolveControllerTest, BuildGroundFieldLendsOneFieldToEverySlot) {
  SolveController c(*session_, *calib_, *options_);
  c.ReadModel();
  c.SolveLighting();
  c.FitGroundReflection();
  c.BuildGroundField();
  EXPECT_EQ(c.result().ground_field, nullptr);

  PipelineOptions always = *options_;
  always.config.ground_field.use = GroundFieldUse::kAlways;
  SolveController d(*session_, *calib_, always);
  d.ReadModel();
  d.SolveLighting();
  d.FitGroundReflection();
  d.BuildGroundField();
  ASSERT_NE(d.result().ground_field, nullptr);
  EXPECT_FALSE(d.result().ground_field->empty());
  for (const SlotSolve& s : d.result().slots)
    EXPECT_EQ(s.lighting.ground, d.result().ground_field) << s.slot;
}

// The grid, its visibility, the observations and the albedos, each stage on what the one
// before made: no observation from a held-out photo, an albedo per grid point.
TEST_F(SolveControllerTest, GridObservationsAndAlbedosFollowEachOther) {
  SolveController c(*session_, *calib_, *options_);
  c.ReadModel();
  c.SolveLighting();
  c.FitGroundReflection();
  c.BuildGroundField();
  c.BuildGrid();
  const SolveResult& r = c.result();
  EXPECT_EQ(r.grid.size(), CountGridPoints(r.mesh, r.grid_options));
  EXPECT_EQ(r.hemisphere.hit.size(), static_cast<size_t>(r.grid.size()) * r.hemisphere.directions);
  c.CollectObservations();
  ASSERT_FALSE(c.observations().empty());
  for (const ArchitecturePhoto& p : c.photos()) EXPECT_NE(p.slot, heldout_) << p.name;
  c.SolveAlbedos();
  ASSERT_EQ(r.albedo.rho_sun.size(), static_cast<size_t>(r.grid.size()));
  ASSERT_EQ(r.irradiance.size(), r.slots.size());
  EXPECT_GT(r.albedo.summary.points_observed, 0);
  for (int i = 0; i < r.grid.size(); ++i) {
    ASSERT_TRUE(r.albedo.rho_sun[i].allFinite() && r.albedo.rho_se[i].allFinite()) << i;
  }
}

// Run tells each stage's start and end in order, with progress inside the lighting, each end
// with its seconds; a cancellation requested as a stage starts stops the solve there.
TEST_F(SolveControllerTest, RunTellsEveryStageAndStopsWhenCancelled) {
  PipelineOptions o = *options_;
  std::vector<SolveEvent> events;
  o.progress = [&](const SolveEvent& e) { events.push_back(e); };
  const SolveResult r = SolveController(*session_, *calib_, o).Run();
  EXPECT_GT(r.grid.size(), 0);
  const std::vector<std::string>& stages = SolveController::Stages();
  std::vector<std::string> started, ended;
  double last = -1;
  for (const SolveEvent& e : events) {
    EXPECT_EQ(e.count, static_cast<int>(stages.size()));
    EXPECT_EQ(e.stage, stages[e.index - 1]);
    if (e.fraction == 0) {
      started.push_back(e.stage);
      last = 0;
    } else {
      EXPECT_GT(e.fraction, last) << e.stage << " " << e.message;
      last = e.fraction;
    }
    if (e.fraction == 1) {
      ended.push_back(e.stage);
      ASSERT_FALSE(e.figures.empty());
      EXPECT_EQ(e.figures[0].first, "seconds");
      EXPECT_GE(e.figures[0].second, 0);
    }
  }
  EXPECT_EQ(started, stages);
  EXPECT_EQ(ended, stages);
  const auto lighting = std::count_if(events.begin(), events.end(), [](const SolveEvent& e) {
    return e.stage == "lighting" && e.fraction > 0 && e.fraction < 1;
  });
  EXPECT_EQ(lighting, Slots() - 1);  // the last slot's progress is the stage's end

  Cancellation cancel;
  o.cancel = &cancel;
  o.progress = [&](const SolveEvent& e) {
    if (e.stage == "surface grid" && e.fraction == 0) cancel.Request();
  };
  SolveController c(*session_, *calib_, o);
  EXPECT_THROW(c.Run(), Cancelled);
  EXPECT_TRUE(c.result().hemisphere.hit.empty());  // stopped inside the visibility's casting
  EXPECT_TRUE(c.result().albedo.rho_sun.empty());
}

}  // namespace
}  // namespace rouen
