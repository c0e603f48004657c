// The Snakemake workflow (workflow/Snakefile) over a folder of three quick simulated sessions: a
// dry run plans solve, validate and report for each; the run writes them all; a second run does
// nothing; a forced solve finds every scene up to date; and only what changed is planned again.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/files.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;
using cli_test::RunShell;

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// Jobs per rule from the "Job stats" tables snakemake prints (a dry run prints the same twice).
std::map<std::string, int> JobCounts(const std::string& out) {
  std::map<std::string, int> counts;
  const std::regex row(R"(^(\w+)\s+(\d+)\s+\d+\s+\d+\s*$)");
  std::istringstream lines(out);
  std::string line;
  std::smatch m;
  while (std::getline(lines, line))
    if (std::regex_match(line, m, row)) counts[m[1]] = std::stoi(m[2]);
  return counts;
}

std::map<fs::path, fs::file_time_type> Times(const std::vector<fs::path>& files) {
  std::map<fs::path, fs::file_time_type> times;
  for (const fs::path& f : files) times[f] = fs::last_write_time(f);
  return times;
}

void ExpectFinite(const nlohmann::json& figures, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_TRUE(figures.is_object());
  const double rmse = figures.at("rel_rmse").get<double>();
  const double psnr = figures.at("psnr_db").get<double>();
  EXPECT_TRUE(std::isfinite(rmse) && rmse > 0.0 && rmse < 0.2) << rmse;
  EXPECT_TRUE(std::isfinite(psnr) && psnr > 25.0 && psnr < 80.0) << psnr;
  EXPECT_GT(figures.at("pixels").get<int>(), 1000);
}

class WorkflowTest : public testing::Test {
 protected:
  void SetUp() override {
    if (FindOnPath("snakemake").empty())
      GTEST_SKIP() << "snakemake is not installed (Debian: snakemake; ./dev installs it): "
                      "workflow/Snakefile is not run";
    dir_ = cli_test::TempDir("workflow");
  }
  void TearDown() override {
    if (!dir_.empty() && !HasFailure()) fs::remove_all(dir_);
  }

  // snakemake on the workflow in dir_ (its .snakemake folder there), sessions in dir_/sessions,
  // outputs in dir_/out, the solve quick; `extra` goes before the config.
  Result Snakemake(const std::string& extra) const {
    return RunShell("cd " + Q(dir_) + " && snakemake -s " +
                    Q(fs::path(ROUEN_SOURCE_DIR) / "workflow/Snakefile") + " --cores 2 --nocolor " +
                    extra + " --config sessions=" + Q(dir_ / "sessions") + " out=" + Q(Out()) +
                    " rouen=" + Q(ROUEN_BINARY) + " quick=true exclude_blocks=plaza");
  }
  fs::path Out() const { return dir_ / "out"; }

  fs::path dir_;
};

TEST_F(WorkflowTest, ThreeSessionsOnceThenNothingToDo) {
  // One quick simulated capture (the demo's session, five slots, slot 3 held out), three copies;
  // session b holds out slot 2 by its own workflow.toml.
  auto start = std::chrono::steady_clock::now();
  const Result capture =
      RunRouen("capture --rig " + Q(fs::path(ROUEN_SOURCE_DIR) / "rigs/sim.toml") + " --out " +
               Q(dir_ / "capture") + " --quick --no-prompt");
  ASSERT_EQ(capture.code, 0) << capture.out;
  std::printf("capture: %.1f s\n", Seconds(start));
  const nlohmann::json info =
      nlohmann::json::parse(ReadFileToString(dir_ / "capture/session.json"));
  ASSERT_EQ(info.at("extra").at("heldout_slot"), 3) << "rigs/sim.toml's heldout time moved";
  ASSERT_EQ(info.at("extra").at("plan").at("slots").size(), 5u);
  const std::vector<std::string> names = {"a", "b", "c"};
  const std::map<std::string, int> slot = {{"a", 3}, {"b", 2}, {"c", 3}};
  fs::create_directories(dir_ / "sessions");
  for (const std::string& name : names)
    fs::copy(dir_ / "capture", dir_ / "sessions" / name, fs::copy_options::recursive);
  WriteFileAtomic(dir_ / "sessions/b/workflow.toml",
                  "holdout_slot = 2\nexclude_blocks = [\"plaza\"]\n");

  // A dry run on the fresh folder plans every job and writes nothing.
  const Result plan = Snakemake("-n");
  ASSERT_EQ(plan.code, 0) << plan.out;
  const std::map<std::string, int> planned = {{"all", 1},     {"report", 3},   {"solve", 3},
                                              {"summary", 1}, {"validate", 3}, {"total", 11}};
  EXPECT_EQ(JobCounts(plan.out), planned) << plan.out;
  EXPECT_FALSE(fs::exists(Out()));

  start = std::chrono::steady_clock::now();
  const Result first = Snakemake("");
  ASSERT_EQ(first.code, 0) << first.out;
  std::printf("first run: %.1f s\n", Seconds(start));
  EXPECT_NE(first.out.find("11 of 11 steps (100%) done"), std::string::npos) << first.out;

  std::vector<fs::path> outputs = {Out() / "summary.tsv"};
  for (const std::string& name : names) {
    SCOPED_TRACE("session " + name);
    const fs::path out = Out() / name;
    outputs.insert(outputs.end(), {out / "scene/scene.json", out / "scene/solved.json",
                                   out / "validate.json", out / "report.html"});
    // The scene, its stamp (the inputs hash rouen recorded), the held-out slot kept out.
    const nlohmann::json scene = nlohmann::json::parse(ReadFileToString(out / "scene/scene.json"));
    const std::string hash = scene.at("provenance").at("inputs_sha256");
    EXPECT_TRUE(std::regex_match(hash, std::regex("[0-9a-f]{64}"))) << hash;
    EXPECT_EQ(scene.at("holdout_slots"), nlohmann::json::array({slot.at(name)}));
    EXPECT_EQ(scene.at("slots").size(), 5u);
    const nlohmann::json stamp = nlohmann::json::parse(ReadFileToString(out / "scene/solved.json"));
    EXPECT_EQ(stamp.at("inputs_sha256"), hash);

    // The held-out slot against renders, measured and predicted lighting.
    const nlohmann::json v = nlohmann::json::parse(ReadFileToString(out / "validate.json"));
    EXPECT_EQ(v.at("slot"), slot.at(name));
    EXPECT_EQ(v.at("held_out"), true);
    EXPECT_EQ(v.at("exclude_blocks"), nlohmann::json::array({"plaza"}));
    EXPECT_EQ(v.at("photos").size(), 4u);
    ExpectFinite(v.at("measured"), "measured");
    ExpectFinite(v.at("predicted"), "predicted");

    // The report: its sections, the held-out photos beside their renders, no network.
    const std::string html = ReadFileToString(out / "report.html");
    EXPECT_GT(html.size(), 100000u);
    for (const char* section :
         {"Scene", "Capture timeline", "Sun path and capture times", "Camera response", "Sky fits",
          "Environment", "Albedos", "Validation", "Timings"})
      EXPECT_NE(html.find(std::string("<h2>") + section + "</h2>"), std::string::npos) << section;
    EXPECT_NE(html.find("Slot " + std::to_string(slot.at(name)) + ", held out"), std::string::npos);
    EXPECT_EQ(html.find("src=\"http"), std::string::npos);
  }
  // One line per session: its slot and finite figures.
  std::istringstream tsv(ReadFileToString(Out() / "summary.tsv"));
  std::string line;
  std::getline(tsv, line);
  EXPECT_EQ(line.rfind("session\tslot\theld_out\t", 0), 0u) << line;
  for (const std::string& name : names) {
    ASSERT_TRUE(std::getline(tsv, line));
    std::vector<std::string> cells;
    std::istringstream row(line);
    for (std::string cell; std::getline(row, cell, '\t');) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 10u) << line;
    EXPECT_EQ(cells[0], name);
    EXPECT_EQ(cells[1], std::to_string(slot.at(name)));
    for (size_t i = 5; i < 9; ++i) EXPECT_TRUE(std::isfinite(std::stod(cells[i]))) << line;
    EXPECT_EQ(cells[9], "ok");
  }
  EXPECT_FALSE(std::getline(tsv, line)) << line;

  // Again with nothing changed: nothing to do, nothing written.
  const auto times = Times(outputs);
  start = std::chrono::steady_clock::now();
  const Result second = Snakemake("");
  ASSERT_EQ(second.code, 0) << second.out;
  std::printf("second run: %.1f s\n", Seconds(start));
  EXPECT_NE(second.out.find("Nothing to be done"), std::string::npos) << second.out;
  EXPECT_EQ(Times(outputs), times);

  // Every solve forced: the scenes stay in place, rouen finds each up to date, the stamps are
  // the same, so validate and report have nothing to do afterwards.
  const Result forced = Snakemake("--forcerun solve --until solve");
  ASSERT_EQ(forced.code, 0) << forced.out;
  for (const std::string& name : names) {
    const std::string log = ReadFileToString(Out() / "logs" / name / "solve.log");
    EXPECT_NE(log.find(": up to date ("), std::string::npos) << name << ": " << log;
    EXPECT_EQ(fs::last_write_time(Out() / name / "scene/scene.json"),
              times.at(Out() / name / "scene/scene.json"))
        << name;
  }
  const Result after = Snakemake("-n");
  EXPECT_NE(after.out.find("Nothing to be done"), std::string::npos) << after.out;

  // A scene folder gone is solved again (with what depends on it), not left missing.
  const std::map<std::string, int> one_session = {{"all", 1},     {"report", 1},   {"solve", 1},
                                                  {"summary", 1}, {"validate", 1}, {"total", 5}};
  fs::rename(Out() / "c/scene", dir_ / "scene_c");
  const Result gone = Snakemake("-n");
  EXPECT_EQ(JobCounts(gone.out), one_session) << gone.out;
  EXPECT_NE(gone.out.find("wildcards: name=c"), std::string::npos) << gone.out;
  fs::rename(dir_ / "scene_c", Out() / "c/scene");

  // A session setting rewritten unchanged is not a change; another held-out slot is, for that
  // session only (its solve, validate, report, and the summary).
  const fs::path settings = dir_ / "sessions/b/workflow.toml";
  const std::string text = ReadFileToString(settings);
  fs::remove(settings);
  WriteFileAtomic(settings, text);
  const Result same = Snakemake("-n");
  EXPECT_NE(same.out.find("Nothing to be done"), std::string::npos) << same.out;
  WriteFileAtomic(settings, "holdout_slot = 1\n");
  const Result changed = Snakemake("-n");
  EXPECT_EQ(JobCounts(changed.out), one_session) << changed.out;
  EXPECT_NE(changed.out.find("wildcards: name=b"), std::string::npos) << changed.out;
  EXPECT_EQ(changed.out.find("wildcards: name=a"), std::string::npos) << changed.out;
  fs::remove(settings);
  WriteFileAtomic(settings, text);

  // Session d's session.json is broken, session e's solve fails (its options are refused): the
  // run stops before any job, naming d; with --keep-going every good session is processed and
  // the summary marks d broken and e failed.
  fs::copy(dir_ / "capture", dir_ / "sessions/d", fs::copy_options::recursive);
  WriteFileAtomic(dir_ / "sessions/d/session.json", "{\"site\": ");
  fs::copy(dir_ / "capture", dir_ / "sessions/e", fs::copy_options::recursive);
  nlohmann::json e_info = info;
  e_info["extra"]["solve_config"] = {{"grid", {{"spacing_m", -3}}}};
  fs::remove(dir_ / "sessions/e/session.json");
  WriteFileAtomic(dir_ / "sessions/e/session.json", e_info.dump(2));
  const Result stopped = Snakemake("");
  EXPECT_NE(stopped.code, 0) << stopped.out;
  EXPECT_NE(stopped.out.find((dir_ / "sessions/d/session.json").string()), std::string::npos)
      << stopped.out;
  EXPECT_NE(stopped.out.find("--keep-going"), std::string::npos) << stopped.out;
  EXPECT_FALSE(fs::exists(Out() / "e")) << stopped.out;
  const Result kept = Snakemake("--keep-going");
  EXPECT_NE(kept.code, 0) << kept.out;
  std::map<std::string, std::string> status;
  std::istringstream rows(ReadFileToString(Out() / "summary.tsv"));
  std::getline(rows, line);
  while (std::getline(rows, line))
    status[line.substr(0, line.find('\t'))] = line.substr(line.rfind('\t') + 1);
  EXPECT_EQ(status.size(), 5u) << kept.out;
  for (const std::string& name : names) EXPECT_EQ(status[name], "ok") << name;
  EXPECT_EQ(status["d"].rfind("broken: " + (dir_ / "sessions/d/session.json").string(), 0), 0u)
      << status["d"];
  EXPECT_EQ(status["e"], "failed: solve (see " + (Out() / "logs/e").string() + "/)") << kept.out;
  EXPECT_NE(ReadFileToString(Out() / "logs/e/solve.log").find("grid.spacing_m"), std::string::npos);
}

}  // namespace
}  // namespace rouen
