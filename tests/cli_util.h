// Running the `rouen` binary from the integration tests.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>

namespace rouen::cli_test {

struct Result {
  int code = -1;
  std::string out;  // stdout and stderr together
};

// Runs `rouen ARGS` (the binary under test, ROUEN_BINARY) through the shell.
inline Result RunRouen(const std::string& args) {
  const std::string cmd = std::string(ROUEN_BINARY) + " " + args + " 2>&1";
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

}  // namespace rouen::cli_test
