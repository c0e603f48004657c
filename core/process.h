// Running another program to its end (ffmpeg for rouen timelapse, rouen itself in benchmarks).
#pragma once

#include <sys/resource.h>

#include <filesystem>
#include <string>
#include <vector>

namespace rouen {

// Runs `args` (args[0] the program's path, e.g. from FindOnPath) with stdin from /dev/null and
// stdout and stderr written to `log` (truncated; "/dev/null" discards them), waits for it and
// returns its exit code, or 128 + the signal that ended it. With `usage`, fills it with the
// child's resource use (wait4: ru_maxrss is its peak resident memory in KiB). Throws
// rouen::Error naming the program when it cannot be started or waited for.
int RunProcess(const std::vector<std::string>& args, const std::filesystem::path& log,
               rusage* usage = nullptr);

}  // namespace rouen
