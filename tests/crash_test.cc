// Crash safety of `rouen capture`: the process is killed with SIGKILL at random moments of a
// simulated capture (50 runs in 5 shards). After every kill the session must load, hold every
// frame written before the kill except at most the one in flight, have no journal line that
// points at a missing or partial file, and `--resume` must complete it.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/error.h"
#include "core/files.h"
#include "core/session.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

constexpr int kShards = 5;
constexpr int kRunsPerShard = 10;

using cli_test::OneSlotRig;
using cli_test::Spawn;
using cli_test::Wait;

size_t JournalLines(const fs::path& session) {
  std::ifstream in(session / "frames.jsonl");
  size_t n = 0;
  std::string line;
  while (std::getline(in, line)) ++n;
  return n;
}

std::vector<std::string> CaptureArgs(const fs::path& rig, const fs::path& out, bool resume) {
  std::vector<std::string> a = {ROUEN_BINARY, "capture",    "--rig",  rig.string(),
                                "--out",      out.string(), "--quick"};
  if (resume) a.push_back("--resume");
  return a;
}

std::string LogOf(const fs::path& log) {
  std::ifstream in(log);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The journalled sequence (group, exposure) of a session.
std::vector<std::pair<std::string, double>> Sequence(const Session& s) {
  std::vector<std::pair<std::string, double>> out;
  for (const FrameRecord& f : s.frames()) out.push_back({f.group, f.exposure_s});
  return out;
}

// Every journalled file exists and has the journalled checksum.
void ExpectFilesIntact(const Session& s, const std::string& when) {
  for (const FrameRecord& f : s.frames()) {
    fs::path p = s.dir() / f.file;
    ASSERT_TRUE(fs::is_regular_file(p)) << when << ": journal points at missing " << f.file;
    EXPECT_EQ(Sha256File(p), f.sha256) << when << ": partial or altered " << f.file;
  }
}

class CrashTest : public ::testing::TestWithParam<int> {
 protected:
  static void SetUpTestSuite() {
    dir_ =
        new fs::path(fs::temp_directory_path() / ("rouen_crash_test_" + std::to_string(getpid())));
    fs::remove_all(*dir_);
    fs::create_directories(*dir_);
    WriteFileAtomic(*dir_ / "rig.toml", OneSlotRig());
    // The uninterrupted reference capture (the simulation is deterministic for a seed).
    const fs::path ref = *dir_ / "reference";
    int rc = Wait(Spawn(CaptureArgs(*dir_ / "rig.toml", ref, false), *dir_ / "reference.log"));
    ASSERT_EQ(rc, 0) << LogOf(*dir_ / "reference.log");
    reference_ = new Session(Session::Load(ref));
  }
  static void TearDownTestSuite() {
    if (dir_) fs::remove_all(*dir_);
    delete dir_;
    delete reference_;
    dir_ = nullptr;
    reference_ = nullptr;
  }
  static fs::path* dir_;
  static Session* reference_;
};
fs::path* CrashTest::dir_ = nullptr;
Session* CrashTest::reference_ = nullptr;

TEST_P(CrashTest, SigkillAtRandomMomentsThenResume) {
  ASSERT_NE(reference_, nullptr);
  const auto ref_seq = Sequence(*reference_);
  std::set<std::string> ref_groups;
  for (const auto& [g, e] : ref_seq) ref_groups.insert(g);
  const size_t n_ref = ref_seq.size();
  ASSERT_GT(n_ref, 5u);

  std::mt19937 rng(1234 + GetParam());
  for (int run = 0; run < kRunsPerShard; ++run) {
    SCOPED_TRACE("shard " + std::to_string(GetParam()) + " run " + std::to_string(run));
    std::string name = "s";
    name.append(std::to_string(GetParam())).append("_").append(std::to_string(run));
    const fs::path out = *dir_ / name;
    const fs::path log = out.string() + ".log";
    // Kill once the journal holds `after` frames, plus a random delay that lands anywhere in
    // the next frame's rendering, encoding, fsync, rename or journalling. after == 0 with a
    // short delay also hits the session's creation.
    const size_t after = std::uniform_int_distribution<size_t>(0, n_ref - 1)(rng);
    const int delay_ms = std::uniform_int_distribution<int>(0, after == 0 ? 2500 : 250)(rng);
    pid_t pid = Spawn(CaptureArgs(*dir_ / "rig.toml", out, false), log);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    int status = 0;
    bool exited = false;
    while (JournalLines(out) < after && std::chrono::steady_clock::now() < deadline) {
      if (waitpid(pid, &status, WNOHANG) == pid) {
        exited = true;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));  // polling the journal
    }
    ASSERT_FALSE(exited) << "capture ended before the kill: " << LogOf(log);
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
    kill(pid, SIGKILL);
    Wait(pid);

    if (fs::exists(out / "session.json")) {
      Session s = Session::Load(out);
      ExpectFilesIntact(s, "after SIGKILL");
      // Nothing written before the kill is lost: the journal is a prefix of the reference.
      const auto seq = Sequence(s);
      ASSERT_LE(seq.size(), n_ref);
      for (size_t i = 0; i < seq.size(); ++i) {
        EXPECT_EQ(seq[i].first, ref_seq[i].first) << "frame " << i;
        EXPECT_DOUBLE_EQ(seq[i].second, ref_seq[i].second) << "frame " << i;
      }
      // At most the frame in flight is not journalled: one renamed frame file, one temporary.
      std::set<std::string> journalled;
      for (const FrameRecord& f : s.frames()) journalled.insert(fs::path(f.file).filename());
      int unjournalled = 0, temporaries = 0;
      for (const auto& e : fs::directory_iterator(out / "frames")) {
        const std::string name = e.path().filename();
        if (name.find(".tmp-") != std::string::npos) {
          ++temporaries;
        } else if (!journalled.count(name)) {
          ++unjournalled;
        }
      }
      EXPECT_LE(unjournalled, 1);
      EXPECT_LE(temporaries, 1);
      EXPECT_LE(unjournalled + temporaries, 1);
    } else if (fs::exists(out)) {
      // Killed before session.json: the folder holds no data, and a new capture may use it.
      for (const auto& e : fs::recursive_directory_iterator(out))
        EXPECT_TRUE(e.is_directory() ||
                    e.path().filename().string().find(".tmp-") != std::string::npos)
            << e.path();
    }

    // --resume completes the plan.
    int rc = Wait(Spawn(CaptureArgs(*dir_ / "rig.toml", out, true), log));
    ASSERT_EQ(rc, 0) << LogOf(log);
    Session done = Session::Load(out);
    ExpectFilesIntact(done, "after --resume");
    std::set<std::string> groups;
    for (const FrameRecord& f : done.frames()) groups.insert(f.group);
    EXPECT_EQ(groups, ref_groups);
    EXPECT_GE(done.frames().size(), n_ref);
    EXPECT_FALSE(done.info().model.empty());
    EXPECT_TRUE(fs::is_regular_file(out / done.info().model));
    for (const auto& e : fs::recursive_directory_iterator(out))
      EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
    fs::remove_all(out);
    fs::remove(log);
  }
}

INSTANTIATE_TEST_SUITE_P(Shards, CrashTest, ::testing::Range(0, kShards));

}  // namespace
}  // namespace rouen
