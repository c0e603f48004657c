#include "capture/v4l2/v4l2_io.h"

#include <dirent.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>

namespace rouen {

int SystemV4l2Io::Open(const std::string& path, int flags) {
  return ::open(path.c_str(), flags | O_CLOEXEC);
}

int SystemV4l2Io::Close(int fd) { return ::close(fd); }

int SystemV4l2Io::Ioctl(int fd, unsigned long request, void* arg) {
  return ::ioctl(fd, request, arg);
}

void* SystemV4l2Io::Mmap(size_t length, int prot, int flags, int fd, off_t offset) {
  return ::mmap(nullptr, length, prot, flags, fd, offset);
}

int SystemV4l2Io::Munmap(void* addr, size_t length) { return ::munmap(addr, length); }

int SystemV4l2Io::Poll(int fd, short events, short* revents, int timeout_ms) {
  pollfd p{fd, events, 0};
  const int r = ::poll(&p, 1, timeout_ms);
  *revents = r > 0 ? p.revents : 0;
  return r;
}

std::vector<std::string> SystemV4l2Io::ListDevices() {
  std::vector<std::pair<long, std::string>> found;
  if (DIR* dir = ::opendir("/dev")) {
    while (dirent* e = ::readdir(dir)) {
      const std::string name = e->d_name;
      if (name.size() <= 5 || name.compare(0, 5, "video") != 0) continue;
      const std::string digits = name.substr(5);
      if (!std::all_of(digits.begin(), digits.end(),
                       [](unsigned char c) { return std::isdigit(c) != 0; })) {
        continue;
      }
      found.emplace_back(std::strtol(digits.c_str(), nullptr, 10), "/dev/" + name);
    }
    ::closedir(dir);
  }
  std::sort(found.begin(), found.end());
  std::vector<std::string> paths;
  for (auto& f : found) paths.push_back(f.second);
  return paths;
}

}  // namespace rouen
