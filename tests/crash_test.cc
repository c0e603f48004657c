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
using cli_test::CaptureArgs;
using cli_test::LogOf;
using cli_test::OneSlotRig;
using cli_test::Spawn;
using cli_test::Wait;

constexpr int kShards = 5;
constexpr int kRunsPerShard = 10;

size_t JournalLines(const fs::path& session) {
  std::ifstream in(session / "frames.jsonl");
  size_t n = 0;
  std::string line;
  while (std::getline(in, line)) ++n;
  return n;
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

// Starts `args`, waits until `out`'s journal holds `after` lines (polling), lets `delay_ms`
// more pass and kills the process. Returns false if it ended by itself first.
bool KillAfter(const std::vector<std::string>& args, const fs::path& out, const fs::path& log,
               size_t after, int delay_ms) {
  const pid_t pid = Spawn(args, log);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (JournalLines(out) < after && std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == pid) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));  // polling the journal
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  kill(pid, SIGKILL);
  Wait(pid);
  return true;
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
    ASSERT_TRUE(KillAfter(CaptureArgs(*dir_ / "rig.toml", out, false), out, log, after, delay_ms))
        << "capture ended before the kill: " << LogOf(log);

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
        EXPECT_TRUE(e.is_directory() || e.path().filename() == "session.lock" ||
                    (e.path().filename() == "frames.jsonl" && fs::file_size(e.path()) == 0) ||
                    e.path().filename().string().find(".tmp-") != std::string::npos)
            << e.path();
    }

    // --resume completes the plan (a kill before the folder was made left nothing to resume:
    // --resume refuses a folder that does not exist, and a new capture is started instead).
    int rc = Wait(Spawn(CaptureArgs(*dir_ / "rig.toml", out, fs::exists(out)), log));
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

// A kill during --resume is as harmless as one during the first run: the journal stays a
// prefix of the reference, and the next --resume completes it.
TEST_P(CrashTest, SigkillDuringResumeThenResumeAgain) {
  ASSERT_NE(reference_, nullptr);
  const auto ref_seq = Sequence(*reference_);
  std::set<std::string> ref_groups;
  for (const auto& [g, e] : ref_seq) ref_groups.insert(g);
  const size_t n_ref = ref_seq.size();
  std::mt19937 rng(777 + GetParam());
  for (int run = 0; run < 2; ++run) {
    SCOPED_TRACE("shard " + std::to_string(GetParam()) + " run " + std::to_string(run));
    std::string name = "r";  // appended: GCC 12 warns falsely (-Wrestrict) on "r" + string
    name.append(std::to_string(GetParam())).append("_").append(std::to_string(run));
    const fs::path out = *dir_ / name;
    const fs::path log = out.string() + ".log";
    const size_t first = std::uniform_int_distribution<size_t>(1, n_ref / 2)(rng);
    const size_t second = std::uniform_int_distribution<size_t>(first + 1, n_ref - 1)(rng);
    const int delay_ms = std::uniform_int_distribution<int>(0, 250)(rng);
    ASSERT_TRUE(KillAfter(CaptureArgs(*dir_ / "rig.toml", out, false), out, log, first, delay_ms))
        << LogOf(log);
    ASSERT_TRUE(KillAfter(CaptureArgs(*dir_ / "rig.toml", out, true), out, log, second, delay_ms))
        << "resume ended before the kill: " << LogOf(log);
    Session s = Session::Load(out);
    ExpectFilesIntact(s, "after SIGKILL during --resume");
    const auto seq = Sequence(s);
    EXPECT_GE(seq.size(), first);
    ASSERT_EQ(Wait(Spawn(CaptureArgs(*dir_ / "rig.toml", out, true), log)), 0) << LogOf(log);
    Session done = Session::Load(out);
    ExpectFilesIntact(done, "after the last --resume");
    std::set<std::string> groups;
    for (const FrameRecord& f : done.frames()) groups.insert(f.group);
    EXPECT_EQ(groups, ref_groups);
    for (const auto& e : fs::recursive_directory_iterator(out))
      EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
    fs::remove_all(out);
    fs::remove(log);
  }
}

// A kill during `rouen import` leaves no session or a whole one (the import is built under a
// temporary name and renamed), and importing again works and clears what the kill left.
TEST_P(CrashTest, SigkillDuringImportLeavesNothingOrAWholeSession) {
  ASSERT_NE(reference_, nullptr);
  // The photos: one bracket of the reference capture (a list without groups is one bracket);
  // the list gives exposure and time.
  const fs::path photos = *dir_ / ("photos" + std::to_string(GetParam()));
  fs::create_directories(photos);
  std::string list;
  const std::string group = reference_->frames().back().group;
  for (const FrameRecord& f : reference_->frames()) {
    if (f.hdr || f.group != group) continue;
    fs::copy_file(reference_->dir() / f.file, photos / fs::path(f.file).filename());
    list += fs::path(f.file).filename().string() + " " + std::to_string(f.exposure_s) + " " +
            f.utc.Iso8601(3) + "\n";
  }
  const fs::path list_file = *dir_ / ("list" + std::to_string(GetParam()) + ".txt");
  WriteFileAtomic(list_file, list);
  const fs::path parent = *dir_ / ("import" + std::to_string(GetParam()));
  fs::create_directories(parent);
  const fs::path out = parent / "s";
  const fs::path log = parent.string() + ".log";
  const std::vector<std::string> args = {
      ROUEN_BINARY, "import",           "--photos", photos.string(),
      "--list",     list_file.string(), "--site",   "37.8722,-122.2578,60",
      "--out",      out.string()};
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(Wait(Spawn(args, log)), 0) << LogOf(log);
  const size_t n = Session::Load(out).frames().size();
  const int full_ms = static_cast<int>(
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0)
          .count());
  std::mt19937 rng(99 + GetParam());
  for (int run = 0; run < 3; ++run) {
    SCOPED_TRACE("run " + std::to_string(run));
    fs::remove_all(out);
    const pid_t pid = Spawn(args, log);
    std::this_thread::sleep_for(
        std::chrono::milliseconds(std::uniform_int_distribution<int>(0, full_ms)(rng)));
    kill(pid, SIGKILL);
    Wait(pid);
    if (fs::exists(out)) {
      Session s = Session::Load(out);
      EXPECT_EQ(s.frames().size(), n);
      ExpectFilesIntact(s, "import after SIGKILL");
      fs::remove_all(out);
    }
    ASSERT_EQ(Wait(Spawn(args, log)), 0) << LogOf(log);
    EXPECT_EQ(Session::Load(out).frames().size(), n);
    for (const auto& e : fs::directory_iterator(parent))
      EXPECT_EQ(e.path().filename(), "s") << "left behind: " << e.path();
  }
  fs::remove_all(parent);
}

INSTANTIATE_TEST_SUITE_P(Shards, CrashTest, ::testing::Range(0, kShards));

}  // namespace
}  // namespace rouen
