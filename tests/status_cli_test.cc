// `rouen status` on a simulated session captured once: whole, it can be solved (exit 0);
// without its model, without a slot's sun frames, or without a frame file it names the
// problem and the command that adds what is missing (exit 2), and that command works.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/files.h"
#include "core/session.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::CaptureArgs;
using cli_test::LogOf;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;
using cli_test::Spawn;
using cli_test::Wait;

class StatusCliTest : public ::testing::Test {
 protected:
  // One quick one-slot capture for every test; each test works on its own copy.
  static void SetUpTestSuite() {
    root_ = new fs::path(cli_test::TempDir("status_cli"));
    WriteFileAtomic(Rig(), cli_test::OneSlotRig());
    const fs::path log = *root_ / "reference.log";
    ASSERT_EQ(Wait(Spawn(CaptureArgs(Rig(), Reference(), false), log)), 0) << LogOf(log);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    root_ = nullptr;
  }
  static fs::path Rig() { return *root_ / "rig.toml"; }
  static fs::path Reference() { return *root_ / "reference"; }
  static fs::path Copy(const std::string& name) {
    const fs::path to = *root_ / name;
    fs::copy(Reference(), to, fs::copy_options::recursive);
    fs::remove(to / "session.lock");
    return to;
  }
  static fs::path* root_;
};
fs::path* StatusCliTest::root_ = nullptr;

TEST_F(StatusCliTest, AWholeSessionCanBeSolved) {
  const fs::path json = *root_ / "whole.json";
  const Result r = RunRouen("status " + Q(Reference()) + " --json " + Q(json));
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("solvable: yes"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("frame contents verified"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("capture: complete"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("slot0/sun/view0"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ND 4.5"), std::string::npos) << r.out;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(json));
  EXPECT_EQ(j["solvable"], true);
  EXPECT_EQ(j["frames"], Session::Load(Reference()).frames().size());
  ASSERT_EQ(j["slots"].size(), 1u);
  EXPECT_GE(j["slots"][0]["brackets"].size(), 4u);
  EXPECT_TRUE(j["problems"].empty());
}

TEST_F(StatusCliTest, WithoutAModelItSaysWhereToNameOne) {
  const fs::path s = Copy("no_model");
  SessionInfo info = ParseSessionInfo(ReadFileToString(s / "session.json"), "session.json");
  info.model.clear();
  WriteFileAtomic(s / "session.json", nlohmann::json(info).dump(2));
  const fs::path json = *root_ / "no_model.json";
  const Result r = RunRouen("status " + Q(s) + " --json " + Q(json));
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("solvable: no"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("no_model: " + (s / "session.json").string()), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"model\": \"model.obj\""), std::string::npos) << r.out;
  const nlohmann::json j = nlohmann::json::parse(ReadFileToString(json));
  EXPECT_EQ(j["solvable"], false);
  ASSERT_EQ(j["problems"].size(), 1u);
  EXPECT_EQ(j["problems"][0]["kind"], "no_model");
}

TEST_F(StatusCliTest, WithoutASlotsSunFramesItNamesTheSlotAndTheCaptureThatAddsThem) {
  const fs::path s = Copy("no_sun");
  const std::string text = ReadFileToString(s / "frames.jsonl");
  std::string kept;
  int dropped = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    const size_t end = text.find('\n', pos);
    const std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    if (ParseJournalLine(line).group == "slot0/sun/view0") {
      ++dropped;
    } else {
      kept += line + "\n";
    }
  }
  ASSERT_GT(dropped, 0);
  WriteFileAtomic(s / "frames.jsonl", kept);
  const Result r = RunRouen("status " + Q(s));
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("slot 0 lacks a sun bracket"), std::string::npos) << r.out;
  const std::string fix = "rouen capture --rig RIG --out " + s.string() + " --resume --target sun";
  EXPECT_NE(r.out.find(fix), std::string::npos) << r.out;
  // The command does what it says (with this rig, and --quick as the session was captured).
  const fs::path log = *root_ / "no_sun.log";
  std::vector<std::string> args = CaptureArgs(Rig(), s, true);
  args.insert(args.end(), {"--target", "sun"});
  ASSERT_EQ(Wait(Spawn(args, log)), 0) << LogOf(log);
  const Result again = RunRouen("status " + Q(s));
  EXPECT_EQ(again.code, 0) << again.out;
}

TEST_F(StatusCliTest, AMissingFrameFileIsNamed) {
  const fs::path s = Copy("missing_frame");
  const Session session = Session::Load(s);
  const FrameRecord& f = session.frames().at(session.frames().size() / 2);
  fs::remove(s / f.file);
  const Result r = RunRouen("status " + Q(s));
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("missing_file"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find((s / f.file).string() + " is missing"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("restore the frame files"), std::string::npos) << r.out;
}

TEST_F(StatusCliTest, NotASessionIsAnErrorNamingTheFolder) {
  const Result r = RunRouen("status " + Q(*root_ / "nothing"));
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find((*root_ / "nothing").string()), std::string::npos) << r.out;
  const Result h = RunRouen("status --help");
  EXPECT_EQ(h.code, 0);
  EXPECT_NE(h.out.find("sha256"), std::string::npos) << h.out;
}

}  // namespace
}  // namespace rouen
