// Running the `rouen` binary from the integration tests.
#pragma once

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/files.h"

extern char** environ;

namespace rouen::cli_test {

struct Result {
  int code = -1;
  std::string out;  // stdout and stderr together
};

// Runs `command` through the shell, stderr with stdout.
inline Result RunShell(const std::string& command) {
  const std::string cmd = command + " 2>&1";
  Result r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Runs `rouen ARGS` (the binary under test, ROUEN_BINARY) through the shell.
inline Result RunRouen(const std::string& args) {
  return RunShell(std::string(ROUEN_BINARY) + " " + args);
}

// A path quoted for the shell (the tests' paths hold no quote). Built by appending: GCC 12
// warns falsely (-Wrestrict) on "'" + std::string in Release builds.
inline std::string Q(const std::filesystem::path& p) {
  std::string q(1, '\'');
  q.append(p.string());
  q.push_back('\'');
  return q;
}

// An empty folder of its own for this test process.
inline std::filesystem::path TempDir(const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path p =
      fs::temp_directory_path() / ("rouen_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

// Starts `args` (argv[0] a path) in the background, stdout and stderr appended to `log`,
// stdin from /dev/null.
inline pid_t Spawn(const std::vector<std::string>& args, const std::filesystem::path& log) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw Error(std::string("cannot start ") + argv[0] + ": " + std::strerror(rc));
  return pid;
}

// The exit code of `pid`, or minus the signal that ended it.
inline int Wait(pid_t pid) {
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

inline std::string LogOf(const std::filesystem::path& log) {
  std::ifstream in(log);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The shipped simulated rig cut down to one time of day, so one capture takes a few seconds.
inline std::string OneSlotRig() {
  std::string text = ReadFileToString(std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs/sim.toml");
  text = std::regex_replace(text, std::regex("\ntimes = \\[[^\\]]*\\]"), "\ntimes = [\"16:00\"]");
  text = std::regex_replace(text, std::regex("\nheldout = [^\n]*"), "");
  return text;
}

// `rouen capture` of `rig` into `out` (quick, no prompts), as argv for Spawn.
inline std::vector<std::string> CaptureArgs(const std::filesystem::path& rig,
                                            const std::filesystem::path& out, bool resume) {
  std::vector<std::string> a = {ROUEN_BINARY, "capture",    "--rig",  rig.string(),
                                "--out",      out.string(), "--quick"};
  if (resume) a.push_back("--resume");
  return a;
}

}  // namespace rouen::cli_test
