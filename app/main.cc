// rouen: capture and relight architecture (Yu & Malik 1998).
//
// Start-up in two weights. `rouen --help` and `rouen sun` run here, in a binary that links
// only core, ERFA and CLI11, and answer in milliseconds. Every other command loads the
// librouen_cli module (app/cli.cc), which links the camera drivers, OpenCV, OpenImageIO,
// Ceres and Embree (~290 shared libraries, 0.3 s of dynamic linking), and runs the whole CLI.
#include <dlfcn.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "app/command_list.h"
#include "app/commands.h"

namespace {

namespace fs = std::filesystem;

// True when the light path answers argv: no command at all (top-level help or the "a
// command is required" error), or `rouen sun ...`.
bool LightCommand(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help-all") == 0) return false;  // every command's options
    if (argv[i][0] != '-') return std::strcmp(argv[i], "sun") == 0;
  }
  return true;
}

// Where the module may be: beside this binary (the build tree), or in ../lib/rouen (installed).
std::vector<fs::path> ModuleCandidates() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return {"librouen_cli.so"};  // the loader's own search path
  return {exe.parent_path() / "librouen_cli.so",
          exe.parent_path().parent_path() / "lib" / "rouen" / "librouen_cli.so"};
}

int RunFullCli(int argc, char** argv) {
  std::string errors;
  for (const fs::path& path : ModuleCandidates()) {
    std::error_code ec;
    if (path.has_parent_path() && !fs::exists(path, ec)) {
      errors += "\n  " + path.string() + ": not found";
      continue;
    }
    void* module = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (module == nullptr) {
      errors += "\n  " + std::string(dlerror());
      continue;
    }
    auto* entry = reinterpret_cast<int (*)(int, char**)>(dlsym(module, "rouen_cli_main"));
    if (entry == nullptr) {
      errors += "\n  " + path.string() + ": no rouen_cli_main (" + dlerror() + ")";
      continue;
    }
    return entry(argc, argv);  // the module stays loaded until exit runs its destructors
  }
  std::fprintf(stderr,
               "rouen: error: cannot load rouen's command module librouen_cli.so, built beside "
               "the rouen binary (cmake --build build --target rouen):%s\n",
               errors.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (!LightCommand(argc, argv)) return RunFullCli(argc, argv);
  CLI::App app;
  rouen::DescribeRouen(app);
  for (const rouen::CommandInfo& c : rouen::kCommands) {
    // The others only list their summary here; naming one loads the module instead.
    if (std::strcmp(c.name, "sun") == 0) {
      rouen::RegisterSun(app);
    } else {
      app.add_subcommand(c.name, c.summary);
    }
  }
  return rouen::ParseAndRun(app, argc, argv);
}
