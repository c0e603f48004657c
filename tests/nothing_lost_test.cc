// Nothing lost, nothing silently wrong, through the real binary: a capture on a disk that
// fills up (a real 2-MB-class tmpfs), two captures on one session at once, and frames changed
// behind the journal's back.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mount.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <set>
#include <string>
#include <thread>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
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

std::set<std::string> GroupsOf(const Session& s) {
  std::set<std::string> g;
  for (const FrameRecord& f : s.frames()) g.insert(f.group);
  return g;
}

// Every journalled frame decodes after its sha256 check, and frames/ holds nothing else.
void ExpectWhole(const fs::path& dir) {
  Session s = Session::Load(dir);
  for (const FrameRecord& f : s.frames()) EXPECT_NO_THROW(s.LoadFrame(f)) << f.file;
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir / "frames")) files += e.is_regular_file();
  EXPECT_EQ(files, s.frames().size()) << dir;
}

uintmax_t BytesUnder(const fs::path& dir) {
  uintmax_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) n += e.file_size();
  return n;
}

class NothingLostTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(cli_test::TempDir("nothing_lost"));
    WriteFileAtomic(*root_ / "rig.toml", cli_test::OneSlotRig());
    const int rc = Wait(Spawn(CaptureArgs(*root_ / "rig.toml", *root_ / "reference", false),
                              *root_ / "reference.log"));
    ASSERT_EQ(rc, 0) << LogOf(*root_ / "reference.log");
    reference_ = new Session(Session::Load(*root_ / "reference"));
  }
  static void TearDownTestSuite() {
    delete reference_;
    reference_ = nullptr;
    if (root_) fs::remove_all(*root_);
    delete root_;
    root_ = nullptr;
  }
  static fs::path Rig() { return *root_ / "rig.toml"; }
  static fs::path* root_;
  static Session* reference_;
};
fs::path* NothingLostTest::root_ = nullptr;
Session* NothingLostTest::reference_ = nullptr;

// A tmpfs of a given size mounted for the test's lifetime.
class Tmpfs {
 public:
  explicit Tmpfs(const fs::path& at, uintmax_t bytes) : at_(at) {
    fs::create_directories(at);
    const std::string opts = "size=" + std::to_string(bytes);
    mounted_ = ::mount("rouen-test", at.c_str(), "tmpfs", 0, opts.c_str()) == 0;
    if (!mounted_) error_ = std::strerror(errno);
  }
  ~Tmpfs() {
    if (mounted_) ::umount2(at_.c_str(), MNT_DETACH);
  }
  bool mounted() const { return mounted_; }
  const std::string& error() const { return error_; }
  bool Resize(uintmax_t bytes) {
    const std::string opts = "size=" + std::to_string(bytes);
    return ::mount("rouen-test", at_.c_str(), "tmpfs", MS_REMOUNT, opts.c_str()) == 0;
  }

 private:
  fs::path at_;
  bool mounted_ = false;
  std::string error_;
};

TEST_F(NothingLostTest, CaptureOnADiskThatFillsUpJournalsOnlyWholeFramesAndResumes) {
  ASSERT_NE(reference_, nullptr);
  // A disk with room for about 40% of the session: it fills in the middle of a bracket.
  const uintmax_t need = BytesUnder(reference_->dir());
  const uintmax_t size = (need * 2 / 5 + 4095) / 4096 * 4096;
  Tmpfs disk(*root_ / "small_disk", size);
  if (!disk.mounted())
    GTEST_SKIP() << "cannot mount a tmpfs here (" << disk.error() << "); needs root";
  const fs::path out = *root_ / "small_disk" / "s";
  const fs::path log = *root_ / "full.log";
  const int rc = Wait(Spawn(CaptureArgs(Rig(), out, false), log));
  const std::string said = LogOf(log);
  EXPECT_NE(rc, 0) << said;
  EXPECT_NE(said.find("the disk is full"), std::string::npos) << said;
  EXPECT_NE(said.find("--resume"), std::string::npos) << said;
  // What is journalled is whole; nothing half-written is left to trip a resume or a render.
  const Session partial = Session::Load(out);
  ASSERT_GT(partial.frames().size(), 0u) << said;
  ASSERT_LT(partial.frames().size(), reference_->frames().size());
  ExpectWhole(out);
  for (const auto& e : fs::recursive_directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  // Space freed: --resume completes the plan and every frame is whole.
  ASSERT_TRUE(disk.Resize(need * 4 + (64 << 20)));
  const int rc2 = Wait(Spawn(CaptureArgs(Rig(), out, true), log));
  ASSERT_EQ(rc2, 0) << LogOf(log);
  const Session done = Session::Load(out);
  EXPECT_EQ(GroupsOf(done), GroupsOf(*reference_));
  ExpectWhole(out);
}

TEST_F(NothingLostTest, ASecondWriterOfASessionIsRefusedNamingTheHolder) {
  ASSERT_NE(reference_, nullptr);
  const fs::path s = *root_ / "locked";
  fs::copy(reference_->dir(), s, fs::copy_options::recursive);
  const std::string journal = ReadFileToString(s / "frames.jsonl");
  {
    // This test process holds the session, as a capture would.
    SessionWriter holder = SessionWriter::Resume(s);
    const Result r = RunRouen("capture --rig " + Q(Rig()) + " --out " + Q(s) + " --quick --resume");
    EXPECT_NE(r.code, 0) << r.out;
    EXPECT_NE(r.out.find(s.string()), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("in use"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("pid " + std::to_string(::getpid())), std::string::npos) << r.out;
  }
  EXPECT_EQ(ReadFileToString(s / "frames.jsonl"), journal);

  // Two rouen processes: the first captures, the second (--resume, or a fresh capture) is
  // refused while it runs, naming its pid; the first finishes a session that loads (no id
  // twice) with every frame whole.
  const fs::path t = *root_ / "twice";
  const fs::path log = *root_ / "twice.log";
  const pid_t first = Spawn(CaptureArgs(Rig(), t, false), log);
  const std::string pid_line = std::to_string(first) + "\n";
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  bool holding = false;
  while (!holding && std::chrono::steady_clock::now() < deadline) {
    std::error_code ec;
    holding = fs::exists(t / "session.lock", ec) &&
              ReadFileToString(t / "session.lock") == pid_line && fs::exists(t / "session.json");
    if (!holding) std::this_thread::sleep_for(std::chrono::milliseconds(2));  // polling
  }
  ASSERT_TRUE(holding) << LogOf(log);
  // Paused while it holds the session, so the second writers meet it whatever the timing.
  ASSERT_EQ(::kill(first, SIGSTOP), 0);
  for (const char* extra : {" --resume", ""}) {
    const Result r = RunRouen("capture --rig " + Q(Rig()) + " --out " + Q(t) + " --quick" + extra);
    EXPECT_NE(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("in use"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("pid " + std::to_string(first)), std::string::npos) << r.out;
  }
  ASSERT_EQ(::kill(first, SIGCONT), 0);
  ASSERT_EQ(Wait(first), 0) << LogOf(log);
  const Session done = Session::Load(t);
  EXPECT_EQ(done.frames().size(), reference_->frames().size());
  EXPECT_EQ(GroupsOf(done), GroupsOf(*reference_));
  ExpectWhole(t);
}

TEST_F(NothingLostTest, SolveRefusesFramesChangedBehindTheJournal) {
  ASSERT_NE(reference_, nullptr);
  const fs::path s = *root_ / "tampered";
  fs::copy(reference_->dir(), s, fs::copy_options::recursive);
  // Every frame gets one pixel changed and is written as a valid image of the same size.
  const Session before = Session::Load(s);
  for (const FrameRecord& f : before.frames()) {
    Image im = ReadImage((s / f.file).string());
    im.data[0] = im.data[0] > 100 ? 0.f : 200.f;
    WriteImage((s / f.file).string(), im, f.hdr ? StoredType::kHalf : StoredType::kUint8);
  }
  const fs::path out = *root_ / "tampered.scene";
  const Result r = RunRouen("solve " + Q(s) + " --out " + Q(out) + " --quick");
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("does not match its journal"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("frames/"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace rouen
