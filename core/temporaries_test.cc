#include "core/temporaries.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "core/files.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

fs::path TempDir(const std::string& name) {
  const fs::path d =
      fs::temp_directory_path() / ("rouen_tmps_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void Touch(const fs::path& p) { std::ofstream(p) << "x"; }

TEST(TemporariesTest, RemovesThisProcesssTemporariesOnly) {
  const fs::path d = TempDir("own");
  const std::string pid = std::to_string(::getpid());
  Touch(TempPathFor(d / "a.exr", ".exr"));  // a.exr.tmp-<pid>-<n>.exr
  Touch(d / ("b.json.tmp-" + pid + "-7"));
  fs::create_directories(d / ("session.tmp-" + pid) / "frames");  // a folder being built
  Touch(d / ("session.tmp-" + pid) / "frames" / "000001.png");
  Touch(d / ("session.tmp-" + pid) / "session.json");
  // Not this process's: another pid, a longer pid with ours as its prefix, ordinary files.
  Touch(d / "c.exr.tmp-1-0.exr");
  Touch(d / ("c.exr.tmp-" + pid + "9-0.exr"));
  Touch(d / "result.exr");
  WatchForTemporaries(d);
  WatchForTemporaries(d / "." / "");  // the same folder again: harmless
  RemoveOwnTemporaries();
  std::set<std::string> left;
  for (const auto& e : fs::directory_iterator(d)) left.insert(e.path().filename().string());
  EXPECT_EQ(left, (std::set<std::string>{"c.exr.tmp-1-0.exr", "c.exr.tmp-" + pid + "9-0.exr",
                                         "result.exr"}));
  fs::remove_all(d);
}

TEST(TemporariesTest, ASignalRemovesThemAndStillEndsTheProcess) {
  const fs::path d = TempDir("signal");
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    WatchForTemporaries(d);
    RemoveTemporariesOnSignal();
    Touch(TempPathFor(d / "big.exr", ".exr"));
    ::raise(SIGTERM);
    ::_exit(0);  // not reached: SIGTERM ends the process
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status)) << "exit status " << status;
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  EXPECT_TRUE(fs::is_empty(d));
  fs::remove_all(d);
}

}  // namespace
}  // namespace rouen
