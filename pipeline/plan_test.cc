#include "pipeline/plan.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

// A 10 m cube on a 60 x 60 m ground at Berkeley.
Mesh BoxOnGround() {
  Mesh m;
  const int box = m.AddBlock("box");
  const int ground = m.AddBlock("ground");
  testing::AddBox(&m, {-5, -5, 0}, {5, 5, 10}, box);
  testing::AddHorizontalRect(&m, -30, 30, -30, 30, 0, true, ground);
  return m;
}

PlanOptions Options(LocalDate date) {
  PlanOptions o;
  o.site = Site{37.8722, -122.2578, 60};
  o.schedule.date = date;
  o.schedule.utc_offset_minutes = -480;
  o.spacing_m = 2;
  return o;
}

const PlanFace& Face(const PlanResult& plan, const std::string& block, const std::string& facing) {
  for (const PlanFace& f : plan.faces)
    if (f.block_name == block && f.facing == facing) return f;
  throw Error("no face " + block + " " + facing);
}

void ExpectScheduleIsSortedWithinDaylight(const PlanResult& plan, int max_times) {
  ASSERT_FALSE(plan.chosen.empty());
  EXPECT_LE(static_cast<int>(plan.chosen.size()), max_times);
  for (size_t i = 0; i < plan.chosen.size(); ++i) {
    EXPECT_GE(plan.chosen[i].time, plan.daylight.sunrise);
    EXPECT_LE(plan.chosen[i].time, plan.daylight.sunset);
    if (i > 0) {
      EXPECT_LT(plan.chosen[i - 1].time, plan.chosen[i].time);
    }
  }
}

// The faces are the box's six sides (less its bottom: five) and the ground.
TEST(Plan, GroupsTrianglesIntoFacesByBlockAndPlane) {
  const PlanResult plan = PlanCapture(BoxOnGround(), Options({2026, 12, 21}));
  ASSERT_EQ(plan.faces.size(), 6u);
  for (const char* facing : {"up", "N", "E", "S", "W"}) {
    const PlanFace& f = Face(plan, "box", facing);
    EXPECT_NEAR(f.area_m2, 100, 1e-9) << facing;
    EXPECT_GT(f.points, 0) << facing;
  }
  EXPECT_NEAR(Face(plan, "ground", "up").area_m2, 3600, 1e-9);
}

// Winter at 38 N: the sun stays south of east-west all day, so the north wall is never sunlit
// and the south wall never in shadow; nothing stands above the roof, so it is never in shadow.
// The east and west walls are each sunlit half the day: five times cover them.
TEST(Plan, WinterNorthWallIsNeverSunlitAndTheRestIsCovered) {
  PlanOptions o = Options({2026, 12, 21});
  const PlanResult plan = PlanCapture(BoxOnGround(), o);
  const PlanFace& north = Face(plan, "box", "N");
  EXPECT_EQ(north.never_sunlit, north.points);
  EXPECT_EQ(north.covered, 0);
  for (const char* facing : {"up", "S"}) {
    const PlanFace& f = Face(plan, "box", facing);
    EXPECT_EQ(f.never_shadowed, f.points) << facing;
    EXPECT_EQ(f.covered, 0) << facing;
  }
  for (const char* facing : {"E", "W"}) {
    const PlanFace& f = Face(plan, "box", facing);
    EXPECT_EQ(f.coverable, f.points) << facing;
    EXPECT_EQ(f.covered, f.points) << facing;
  }
  // The ground near the box falls in its shadow at some time; far from it it never does.
  const PlanFace& ground = Face(plan, "ground", "up");
  EXPECT_GT(ground.coverable, 0);
  EXPECT_GT(ground.never_shadowed, 0);
  ExpectScheduleIsSortedWithinDaylight(plan, o.max_times);
  EXPECT_EQ(plan.chosen.size(), 5u);  // the ground's sweeping shadow asks for more
  // With enough times the greedy cover covers every coverable point and stops there.
  o.max_times = 60;
  const PlanResult full = PlanCapture(BoxOnGround(), o);
  EXPECT_EQ(full.covered, full.coverable);
  EXPECT_EQ(Face(full, "ground", "up").covered, Face(full, "ground", "up").coverable);
  EXPECT_LT(full.chosen.size(), full.candidates.size());
  ExpectScheduleIsSortedWithinDaylight(full, o.max_times);
  // Each chosen time added pairs no earlier one had: two per covered point in all.
  int gains = 0;
  for (const PlanTime& t : full.chosen) {
    EXPECT_GT(t.gain, 0);
    gains += t.gain;
  }
  EXPECT_EQ(gains, 2 * full.covered);
}

// Around noon in summer the north wall is in shadow too; over the whole summer day the early
// and late sun (rising in the north-east, setting in the north-west) lights it.
TEST(Plan, SummerNorthWallIsLitOnlyEarlyAndLate) {
  PlanOptions o = Options({2026, 6, 21});
  o.schedule.from = "10:00";
  o.schedule.to = "14:00";
  const PlanResult noon = PlanCapture(BoxOnGround(), o);
  EXPECT_EQ(Face(noon, "box", "N").never_sunlit, Face(noon, "box", "N").points);
  o.schedule.from = "sunrise";
  o.schedule.to = "sunset";
  const PlanResult day = PlanCapture(BoxOnGround(), o);
  const PlanFace& north = Face(day, "box", "N");
  EXPECT_EQ(north.never_sunlit, 0);
  EXPECT_EQ(north.covered, north.points);
  ExpectScheduleIsSortedWithinDaylight(day, o.max_times);
}

// A single capture time cannot show a point both sunlit and in shadow.
TEST(Plan, OneTimeCoversNothing) {
  PlanOptions o = Options({2026, 12, 21});
  o.max_times = 1;
  const PlanResult plan = PlanCapture(BoxOnGround(), o);
  ASSERT_EQ(plan.chosen.size(), 1u);
  EXPECT_EQ(plan.covered, 0);
  EXPECT_GT(plan.coverable, 0);
}

// With views, only what they see counts: a camera south of the box sees no north wall.
TEST(Plan, ViewsLimitWhatCounts) {
  PlanOptions o = Options({2026, 6, 21});
  o.views.push_back(
      {"south", Intrinsics::PinholeFov(640, 480, 70), Pose::LookAt({0, -25, 5}, {0, 0, 5})});
  const PlanResult plan = PlanCapture(BoxOnGround(), o);
  const PlanFace& north = Face(plan, "box", "N");
  EXPECT_EQ(north.unseen, north.points);
  EXPECT_EQ(north.coverable, 0);
  const PlanFace& south = Face(plan, "box", "S");
  EXPECT_EQ(south.unseen, 0);
  EXPECT_EQ(south.covered, south.points);
}

TEST(Plan, RefusesDegenerateModelsAndBadOptions) {
  Mesh flat;
  const int b = flat.AddBlock("line");
  flat.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  flat.AddTriangle(0, 1, 2, b);
  try {
    PlanCapture(flat, Options({2026, 6, 21}));
    ADD_FAILURE() << "a model of degenerate triangles was planned";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no surface"), std::string::npos) << e.what();
  }
  PlanOptions o = Options({2026, 6, 21});
  o.max_times = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = Options({2026, 6, 21});
  o.site.lat_deg = 95;
  EXPECT_THROW(o.Validate(), Error);
}

TEST(Plan, ReadsViewsFilesAndNamesTheirProblems) {
  const fs::path dir = fs::temp_directory_path() / ("rouen_plan_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const nlohmann::json k = Intrinsics::PinholeFov(64, 48, 60);
  const nlohmann::json p = Pose::LookAt({0, -25, 5}, {0, 0, 5});
  std::ofstream(dir / "views.json")
      << nlohmann::json{{"views", {{{"name", "a"}, {"intrinsics", k}, {"pose", p}}}}}.dump();
  const std::vector<PlanView> views = ReadPlanViews(dir / "views.json");
  ASSERT_EQ(views.size(), 1u);
  EXPECT_EQ(views[0].name, "a");
  EXPECT_EQ(views[0].intrinsics.width, 64);
  auto message = [](const fs::path& f) {
    try {
      ReadPlanViews(f);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(message(dir / "none.json").find("no such views file"), std::string::npos);
  std::ofstream(dir / "bad.json") << "{";
  EXPECT_NE(message(dir / "bad.json").find("not valid JSON"), std::string::npos);
  std::ofstream(dir / "nopose.json") << nlohmann::json::array({{{"intrinsics", k}}}).dump();
  EXPECT_NE(message(dir / "nopose.json").find("view 0: needs"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen

namespace rouen {
namespace {

// A session with a box model and one architecture frame in each of two winter slots, morning
// and afternoon: after the morning nothing is both sunlit and in shadow; after the afternoon the
// east and west walls are (each lit at one time and in shadow at the other).
TEST(Plan, SessionCoverageGrowsWithItsSlots) {
  const fs::path dir =
      fs::temp_directory_path() / ("rouen_plan_session_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  SessionInfo info;
  info.site = Site{37.8722, -122.2578, 60};
  info.model = "model.obj";
  {
    SessionWriter w = SessionWriter::Create(dir, info);
    for (int slot = 0; slot < 2; ++slot) {
      FrameRecord f;
      f.device = "sim";
      f.target = Target::kArchitecture;
      f.slot = slot;
      f.group = BracketName(slot, Target::kArchitecture, 0);
      f.utc = ParseIso8601(slot == 0 ? "2026-12-21T09:00:00-08:00" : "2026-12-21T15:00:00-08:00");
      f.exposure_s = 0.01;
      w.Append(f, Image(4, 4, 3, PixelUnits::kOther, 0.5f));
    }
  }
  Mesh m;
  testing::AddBox(&m, {-5, -5, 0}, {5, 5, 10}, m.AddBlock("box"));
  WriteObj((dir / "model.obj").string(), m);
  const std::vector<SlotCoverage> c = SessionCoverage(Session::Load(dir), 2.0);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0].slot, 0);
  EXPECT_EQ(c[0].covered, 0);
  EXPECT_GT(c[0].sunlit, 0);
  // The box's east and west walls: 2 x 72 points at 2 m (PlanCapture's faces above).
  EXPECT_EQ(c[1].covered, 144);
  EXPECT_NEAR(c[1].CoveredPercent(), 100.0 * 144 / c[1].points, 1e-9);
  EXPECT_EQ(c[1].seen, c[1].points);  // no cameras in the journal: every point counts
  fs::remove(dir / "model.obj");
  try {
    SessionCoverage(Session::Load(dir), 2.0);
    ADD_FAILURE() << "a missing model was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("model.obj"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

// With cameras in the journal only what they see counts: one east of the box sees its east wall
// (and its roof at a grazing angle from 5 m up: not at all), so the coverage is the east wall's.
TEST(Plan, SessionCoverageCountsWhatTheCamerasSee) {
  const fs::path dir =
      fs::temp_directory_path() / ("rouen_plan_posed_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  SessionInfo info;
  info.site = Site{37.8722, -122.2578, 60};
  info.model = "model.obj";
  {
    SessionWriter w = SessionWriter::Create(dir, info);
    for (int slot = 0; slot < 2; ++slot) {
      FrameRecord f;
      f.device = "sim";
      f.target = Target::kArchitecture;
      f.slot = slot;
      f.group = BracketName(slot, Target::kArchitecture, 0);
      f.utc = ParseIso8601(slot == 0 ? "2026-12-21T09:00:00-08:00" : "2026-12-21T15:00:00-08:00");
      f.exposure_s = 0.01;
      f.intrinsics = Intrinsics::PinholeFov(640, 480, 90);
      f.pose = Pose::LookAt({25, 0, 5}, {0, 0, 5});
      w.Append(f, Image(4, 4, 3, PixelUnits::kOther, 0.5f));
    }
  }
  Mesh m;
  testing::AddBox(&m, {-5, -5, 0}, {5, 5, 10}, m.AddBlock("box"));
  WriteObj((dir / "model.obj").string(), m);
  const std::vector<SlotCoverage> c = SessionCoverage(Session::Load(dir), 2.0);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[1].seen, 72);
  EXPECT_EQ(c[1].covered, 72);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
