// rouen plan on a box on the ground: the schedule, the faces that cannot be covered, the JSON,
// and the inputs it refuses.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>

#include "core/files.h"
#include "core/mesh.h"
#include "solve/test_scenes.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;

class PlanCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = cli_test::TempDir("plan_cli");
    Mesh m;
    const int box = m.AddBlock("box");
    const int ground = m.AddBlock("ground");
    testing::AddBox(&m, {-5, -5, 0}, {5, 5, 10}, box);
    testing::AddHorizontalRect(&m, -30, 30, -30, 30, 0, true, ground);
    WriteObj((dir_ / "box.obj").string(), m);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(PlanCli, PrintsTheScheduleAndWhatCannotBeCovered) {
  const fs::path json = dir_ / "plan.json";
  const Result r = RunRouen("plan --model " + Q(dir_ / "box.obj") +
                            " --site 37.8722,-122.2578,60 --date 2026-12-21 --tz -08:00 "
                            "--spacing 2 --json " +
                            Q(json));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("Schedule (5 capture times, every point assumed seen"), std::string::npos)
      << r.out;
  // The north wall (72 points at 2 m) is never sunlit in December at 38 N.
  EXPECT_TRUE(std::regex_search(r.out, std::regex(" box +N +100.0 +72 +0.0%  72 never sunlit\n")))
      << r.out;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(json));
  EXPECT_EQ(j["utc_offset"], "-08:00");
  ASSERT_EQ(j["schedule"].size(), 5u);
  std::string previous;
  for (const nlohmann::json& t : j["schedule"]) {
    const std::string utc = t["utc"];
    EXPECT_GE(utc, j["sunrise"].get<std::string>());
    EXPECT_LE(utc, j["sunset"].get<std::string>());
    EXPECT_GT(utc, previous);
    previous = utc;
  }
  int never_sunlit_faces = 0;
  for (const nlohmann::json& f : j["faces"])
    if (f["block"] == "box" && f["facing"] == "N") {
      EXPECT_EQ(f["never_sunlit"], f["points"]);
      EXPECT_EQ(f["lacks"], nlohmann::json::array({"never sunlit"}));
      ++never_sunlit_faces;
    }
  EXPECT_EQ(never_sunlit_faces, 1);
}

TEST_F(PlanCli, RefusesBadInputsWithClearErrors) {
  std::ofstream(dir_ / "flat.obj") << "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n";
  struct Case {
    std::string args, message;
  };
  const std::string model = " --model " + Q(dir_ / "box.obj");
  for (const Case& c : std::vector<Case>{
           {" --model " + Q(dir_ / "none.obj") + " --site 37.8,-122.2,60 --date 2026-06-21",
            "none.obj"},
           {model + " --site 37.8,-122.2 --date 2026-06-21", "--site '37.8,-122.2': expected"},
           {model + " --site 97.8,-122.2,60 --date 2026-06-21", "--site"},
           {model + " --site 37.8,-122.2,60 --date 2026-06-31", "--date '2026-06-31'"},
           {model + " --site 37.8,-122.2,60 --date 2026-06-21 --views " + Q(dir_ / "v.json"),
            "no such views file"},
           {model + " --site 37.8,-122.2,60 --date 2026-06-21 --json " +
                Q(dir_ / "no" / "plan.json"),
            "no such folder"},
           {model + " --site 37.8,-122.2,60 --date 2026-06-21 --from 02:00",
            "--from 02:00 is before sunrise"},
           {" --model " + Q(dir_ / "flat.obj") + " --site 37.8,-122.2,60 --date 2026-06-21",
            "flat.obj"},
       }) {
    const Result r = RunRouen("plan" + c.args);
    EXPECT_EQ(r.code, 1) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find(c.message), std::string::npos) << c.args << "\n" << r.out;
  }
}

}  // namespace
}  // namespace rouen

namespace rouen {
namespace {

// rouen capture on the simulated rig prints the coverage after each slot, never decreasing.
TEST(CaptureCoverage, GrowsSlotBySlot) {
  const fs::path dir = cli_test::TempDir("capture_coverage");
  const Result r = RunRouen("capture --rig " + Q(fs::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml") +
                            " --out " + Q(dir / "session") + " --quick");
  ASSERT_EQ(r.code, 0) << r.out;
  const std::regex line("coverage: after slot (\\d+) \\([^)]*\\): ([0-9.]+)% of the model");
  double previous = -1;
  int slots = 0;
  for (auto it = std::sregex_iterator(r.out.begin(), r.out.end(), line);
       it != std::sregex_iterator(); ++it) {
    EXPECT_EQ(std::stoi((*it)[1]), slots);
    const double percent = std::stod((*it)[2]);
    EXPECT_GE(percent, previous);
    previous = percent;
    ++slots;
  }
  EXPECT_EQ(slots, 5) << r.out;
  EXPECT_GT(previous, 0) << r.out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
