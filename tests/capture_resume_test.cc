// What `rouen capture` says and returns when it is stopped and resumed: Ctrl-C and SIGTERM
// exit 130 and 143 naming what of the plan is left and the command that continues; that
// command completes the session; --resume of a complete session changes nothing and exits 0;
// --resume of a folder that does not exist is an error that creates nothing.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <string>
#include <thread>

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
using cli_test::TempDir;
using cli_test::Wait;

size_t JournalLines(const fs::path& session) {
  std::ifstream in(session / "frames.jsonl");
  size_t n = 0;
  std::string line;
  while (std::getline(in, line)) ++n;
  return n;
}

std::set<std::string> GroupsOf(const fs::path& session) {
  std::set<std::string> out;
  const Session s = Session::Load(session);
  for (const FrameRecord& f : s.frames()) out.insert(f.group);
  return out;
}

// Starts the capture `args`, waits (polling the journal) until `out` holds `lines` frames,
// sends `sig` and returns the exit code; -1000 when the capture ended before the signal.
int SignalAfter(const std::vector<std::string>& args, const fs::path& out, const fs::path& log,
                size_t lines, int sig) {
  const pid_t pid = Spawn(args, log);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (JournalLines(out) < lines && std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == pid) return -1000;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));  // polling the journal
  }
  ::kill(pid, sig);
  return Wait(pid);
}

class CaptureResumeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = TempDir("capture_resume");
    rig_ = dir_ / "rig.toml";
    WriteFileAtomic(rig_, cli_test::OneSlotRig());
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_, rig_;
};

TEST_F(CaptureResumeTest, ASignalExitsNonZeroSayingWhatIsLeftAndHowToContinue) {
  for (const int sig : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(sig == SIGINT ? "SIGINT" : "SIGTERM");
    const fs::path out = dir_ / (sig == SIGINT ? "int" : "term");
    const fs::path log = out.string() + ".log";
    const int rc = SignalAfter(CaptureArgs(rig_, out, false), out, log, 8, sig);
    const std::string said = LogOf(log);
    ASSERT_NE(rc, -1000) << "the capture ended before the signal: " << said;
    EXPECT_EQ(rc, 128 + sig) << said;
    EXPECT_NE(said.find(sig == SIGINT ? "stopped by Ctrl-C (SIGINT)" : "stopped by SIGTERM"),
              std::string::npos)
        << said;
    // What is left: the plan's brackets not journalled, and the one journalled last (a resume
    // captures it again: it may have been cut short).
    std::smatch m;
    const std::string text = said;
    ASSERT_TRUE(std::regex_search(
        text, m, std::regex("left of the plan: ([0-9]+) of ([0-9]+) brackets in 1 slot")))
        << said;
    const int journalled = static_cast<int>(GroupsOf(out).size());
    EXPECT_GE(journalled, 2);
    EXPECT_EQ(std::stoi(m[1]), std::stoi(m[2]) - (journalled - 1));
    // The exact command that continues, and it does.
    const std::string resume =
        "rouen capture --rig " + rig_.string() + " --out " + out.string() + " --quick --resume";
    EXPECT_NE(said.find("continue with:\n  " + resume + "\n"), std::string::npos) << said;
    ASSERT_EQ(Wait(Spawn(CaptureArgs(rig_, out, true), log)), 0) << LogOf(log);
    EXPECT_EQ(Session::Load(out).info().capture_complete, true);
  }
  // Both sessions, stopped at different moments, end with the same brackets.
  EXPECT_EQ(GroupsOf(dir_ / "int"), GroupsOf(dir_ / "term"));
  EXPECT_GT(GroupsOf(dir_ / "int").size(), 3u);
}

TEST_F(CaptureResumeTest, ResumeOfACompleteSessionChangesNothing) {
  const fs::path out = dir_ / "done";
  const fs::path log = dir_ / "done.log";
  ASSERT_EQ(Wait(Spawn(CaptureArgs(rig_, out, false), log)), 0) << LogOf(log);
  const std::string journal = ReadFileToString(out / "frames.jsonl");
  const std::string info = ReadFileToString(out / "session.json");
  const Result r = RunRouen("capture --rig " + Q(rig_) + " --out " + Q(out) + " --quick --resume");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("the session is complete"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("nothing to capture"), std::string::npos) << r.out;
  EXPECT_EQ(ReadFileToString(out / "frames.jsonl"), journal);
  EXPECT_EQ(ReadFileToString(out / "session.json"), info);
}

TEST_F(CaptureResumeTest, ResumeOfAFolderThatDoesNotExistIsAnError) {
  const fs::path out = dir_ / "never_captured";
  const Result r = RunRouen("capture --rig " + Q(rig_) + " --out " + Q(out) + " --quick --resume");
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find(out.string() + ": no session to resume"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("drop --resume"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace rouen
