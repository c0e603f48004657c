#include "core/memory.h"

#include <cstdio>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace rouen {

int64_t AvailableMemoryBytes() {
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("MemAvailable:", 0) != 0) continue;
    std::istringstream s(line.substr(13));
    int64_t kb = -1;
    std::string unit;
    if (s >> kb >> unit && unit == "kB" && kb >= 0) return kb * 1024;
    return -1;
  }
  return -1;
}

void CheckMemory(int64_t bytes, const std::string& what, const std::string& advice) {
  const int64_t available = AvailableMemoryBytes();
  if (available < 0 || bytes <= available) return;
  char figures[96];
  std::snprintf(figures, sizeof figures, " needs about %.1f GB of memory; %.1f GB are available",
                bytes / 1e9, available / 1e9);
  throw Error(what + figures + " (" + advice + ")");
}

}  // namespace rouen
