#include "core/temporaries.h"

#include <dirent.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

// Everything the handler reads is fixed-size and published through `g_dirs_count` (release
// on write, acquire in the handler), so the handler needs no allocation and no lock.
constexpr int kMaxDirs = 64;
char g_dirs[kMaxDirs][PATH_MAX];
std::atomic<int> g_dirs_count{0};
std::mutex g_dirs_mutex;  // writers only

// Folders inside a temporary folder are removed down to this depth (a session is 2 deep).
constexpr int kMaxDepth = 8;

// ".tmp-<pid>" for this process, written without allocation.
void Marker(char* out, size_t size) {
  const char prefix[] = ".tmp-";
  char digits[24];
  int n = 0;
  for (long pid = ::getpid(); pid > 0 && n < 23; pid /= 10) digits[n++] = '0' + pid % 10;
  size_t k = 0;
  for (size_t i = 0; prefix[i] && k + 1 < size; ++i) out[k++] = prefix[i];
  while (n > 0 && k + 1 < size) out[k++] = digits[--n];
  out[k] = '\0';
}

// True when `name` holds `marker` followed by '-' or its end.
bool IsOwnTemporary(const char* name, const char* marker) {
  const size_t m = std::strlen(marker);
  for (const char* p = name; *p; ++p) {
    if (std::strncmp(p, marker, m) == 0 && (p[m] == '\0' || p[m] == '-')) return true;
  }
  return false;
}

bool IsDotOrDotDot(const char* name) {
  return name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'));
}

// Calls `visit(name, is_dir)` for each entry of the open folder `fd` (getdents64: no
// allocation). Returns how many visits returned true (entries removed).
template <typename Visit>
int ForEachEntry(int fd, Visit visit) {
  alignas(8) char buf[4096];
  int removed = 0;
  while (true) {
    const ssize_t n = ::getdents64(fd, buf, sizeof buf);
    if (n <= 0) return removed;
    for (ssize_t off = 0; off < n;) {
      // struct linux_dirent64: u64 ino, s64 off, u16 reclen, u8 type, char name[].
      uint16_t reclen;
      std::memcpy(&reclen, buf + off + 16, sizeof reclen);
      const unsigned char type = static_cast<unsigned char>(buf[off + 18]);
      const char* name = buf + off + 19;
      off += reclen;
      if (IsDotOrDotDot(name)) continue;
      bool is_dir = type == DT_DIR;
      if (type == DT_UNKNOWN) {
        struct stat st;
        is_dir = ::fstatat(fd, name, &st, AT_SYMLINK_NOFOLLOW) == 0 && S_ISDIR(st.st_mode);
      }
      if (visit(name, is_dir)) ++removed;
    }
  }
}

bool RemoveTree(int parent, const char* name, int depth) {
  if (depth < kMaxDepth) {
    const int fd = ::openat(parent, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd >= 0) {
      // Removing entries while reading the folder may skip some: read it again until a pass
      // removes nothing.
      while (ForEachEntry(fd, [&](const char* child, bool is_dir) {
               return is_dir ? RemoveTree(fd, child, depth + 1) : ::unlinkat(fd, child, 0) == 0;
             }) > 0) {
        ::lseek(fd, 0, SEEK_SET);
      }
      ::close(fd);
    }
  }
  return ::unlinkat(parent, name, AT_REMOVEDIR) == 0;
}

void OnSignal(int sig) {
  const int saved_errno = errno;
  RemoveOwnTemporaries();
  errno = saved_errno;
  // The signal is blocked while its handler runs: re-raised with the default action, it
  // ends the process as soon as the handler returns.
  ::signal(sig, SIG_DFL);
  ::raise(sig);
}

}  // namespace

void WatchForTemporaries(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::path abs = std::filesystem::absolute(dir, ec);
  if (ec) abs = dir;
  const std::string s = abs.lexically_normal().string();
  if (s.size() >= PATH_MAX) throw Error(s + ": path too long");
  std::lock_guard<std::mutex> lock(g_dirs_mutex);
  const int n = g_dirs_count.load(std::memory_order_relaxed);
  for (int i = 0; i < n; ++i)
    if (s == g_dirs[i]) return;
  if (n == kMaxDirs)
    throw Error(s + ": too many folders with temporaries (" + std::to_string(kMaxDirs) + ")");
  std::memcpy(g_dirs[n], s.c_str(), s.size() + 1);
  g_dirs_count.store(n + 1, std::memory_order_release);
}

void RemoveTemporariesOnSignal() {
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction old;
    if (::sigaction(sig, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    struct sigaction sa;
    std::memset(&sa, 0, sizeof sa);
    sa.sa_handler = OnSignal;
    sigemptyset(&sa.sa_mask);
    ::sigaction(sig, &sa, nullptr);
  }
}

void RemoveOwnTemporaries() {
  char marker[32];
  Marker(marker, sizeof marker);
  const int n = g_dirs_count.load(std::memory_order_acquire);
  for (int i = 0; i < n; ++i) {
    const int fd = ::open(g_dirs[i], O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) continue;
    while (ForEachEntry(fd, [&](const char* name, bool is_dir) {
             if (!IsOwnTemporary(name, marker)) return false;
             return is_dir ? RemoveTree(fd, name, 0) : ::unlinkat(fd, name, 0) == 0;
           }) > 0) {
      ::lseek(fd, 0, SEEK_SET);
    }
    ::close(fd);
  }
}

}  // namespace rouen
