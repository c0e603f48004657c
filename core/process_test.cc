#include "core/process.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <sstream>

#include "core/error.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

fs::path TempLog(const std::string& name) {
  return fs::temp_directory_path() / ("rouen_process_" + name + std::to_string(::getpid()));
}

TEST(RunProcess, ReturnsTheExitCodeAndWritesBothStreamsToTheLog) {
  const fs::path log = TempLog("log");
  std::ofstream(log) << "an earlier run's output\n";
  rusage usage{};
  EXPECT_EQ(RunProcess({"/bin/sh", "-c", "echo out; echo err >&2; exit 3"}, log, &usage), 3);
  std::stringstream text;
  text << std::ifstream(log).rdbuf();
  EXPECT_EQ(text.str(), "out\nerr\n");  // truncated, stdout and stderr in order
  EXPECT_GT(usage.ru_maxrss, 0);
  fs::remove(log);
}

TEST(RunProcess, ASignalIs128PlusItsNumber) {
  EXPECT_EQ(RunProcess({"/bin/sh", "-c", "kill -9 $$"}, "/dev/null"), 128 + 9);
}

TEST(RunProcess, AProgramThatCannotStartIsNamed) {
  try {
    RunProcess({"/nonexistent/rouen-no-such-program"}, "/dev/null");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot start /nonexistent/rouen-no-such-program"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(RunProcess({}, "/dev/null"), Error);
}

}  // namespace
}  // namespace rouen
