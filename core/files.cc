#include "core/files.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "core/error.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

std::string Errno() { return std::strerror(errno); }

void FsyncPath(const fs::path& p, bool directory) {
  const int fd = ::open(p.c_str(), (directory ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) throw Error(p.string() + ": cannot open for fsync: " + Errno());
  if (CurrentFileIo().Fsync(fd) != 0) {
    const int err = errno;
    ::close(fd);
    throw Error(IoErrorMessage(p, "fsync failed", err));
  }
  ::close(fd);
}

fs::path ParentOrDot(const fs::path& p) {
  fs::path parent = p.parent_path();
  return parent.empty() ? fs::path(".") : parent;
}

// SHA-256 (FIPS 180-4, section 6.2).
class Sha256 {
 public:
  Sha256() { Reset(); }
  void Reset() {
    h_ = {0x6a09e667u, 0xbb67ae85u, 0x3c6ef372u, 0xa54ff53au,
          0x510e527fu, 0x9b05688cu, 0x1f83d9abu, 0x5be0cd19u};
    length_ = 0;
    buffered_ = 0;
  }
  void Update(const unsigned char* data, size_t n) {
    length_ += n;
    if (buffered_ > 0) {
      const size_t take = std::min(n, size_t{64} - buffered_);
      std::memcpy(buffer_.data() + buffered_, data, take);
      buffered_ += take;
      data += take;
      n -= take;
      if (buffered_ == 64) {
        Block(buffer_.data());
        buffered_ = 0;
      }
    }
    while (n >= 64) {
      Block(data);
      data += 64;
      n -= 64;
    }
    if (n > 0) {
      std::memcpy(buffer_.data(), data, n);
      buffered_ = n;
    }
  }
  std::string HexDigest() {
    const uint64_t bits = length_ * 8;
    unsigned char pad[72] = {0x80};
    const size_t pad_len = (buffered_ < 56 ? 56 - buffered_ : 120 - buffered_);
    Update(pad, pad_len);
    unsigned char len[8];
    for (int i = 0; i < 8; ++i) len[i] = static_cast<unsigned char>(bits >> (56 - 8 * i));
    Update(len, 8);
    static const char* kHex = "0123456789abcdef";
    std::string out;
    for (uint32_t w : h_) {
      for (int s = 28; s >= 0; s -= 4) out += kHex[(w >> s) & 0xf];
    }
    return out;
  }

 private:
  static uint32_t Rotr(uint32_t x, int n) { return (x >> n) | (x << (32 - n)); }
  void Block(const unsigned char* p) {
    static const uint32_t kK[64] = {
        0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4,
        0xab1c5ed5, 0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe,
        0x9bdc06a7, 0xc19bf174, 0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f,
        0x4a7484aa, 0x5cb0a9dc, 0x76f988da, 0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7,
        0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967, 0x27b70a85, 0x2e1b2138, 0x4d2c6dfc,
        0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85, 0xa2bfe8a1, 0xa81a664b,
        0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070, 0x19a4c116,
        0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
        0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7,
        0xc67178f2};
    uint32_t w[64];
    for (int t = 0; t < 16; ++t) {
      w[t] = (uint32_t{p[4 * t]} << 24) | (uint32_t{p[4 * t + 1]} << 16) |
             (uint32_t{p[4 * t + 2]} << 8) | uint32_t{p[4 * t + 3]};
    }
    for (int t = 16; t < 64; ++t) {
      const uint32_t s0 = Rotr(w[t - 15], 7) ^ Rotr(w[t - 15], 18) ^ (w[t - 15] >> 3);
      const uint32_t s1 = Rotr(w[t - 2], 17) ^ Rotr(w[t - 2], 19) ^ (w[t - 2] >> 10);
      w[t] = w[t - 16] + s0 + w[t - 7] + s1;
    }
    uint32_t a = h_[0], b = h_[1], c = h_[2], d = h_[3], e = h_[4], f = h_[5], g = h_[6], h = h_[7];
    for (int t = 0; t < 64; ++t) {
      const uint32_t big_s1 = Rotr(e, 6) ^ Rotr(e, 11) ^ Rotr(e, 25);
      const uint32_t ch = (e & f) ^ (~e & g);
      const uint32_t t1 = h + big_s1 + ch + kK[t] + w[t];
      const uint32_t big_s0 = Rotr(a, 2) ^ Rotr(a, 13) ^ Rotr(a, 22);
      const uint32_t maj = (a & b) ^ (a & c) ^ (b & c);
      const uint32_t t2 = big_s0 + maj;
      h = g;
      g = f;
      f = e;
      e = d + t1;
      d = c;
      c = b;
      b = a;
      a = t1 + t2;
    }
    h_[0] += a;
    h_[1] += b;
    h_[2] += c;
    h_[3] += d;
    h_[4] += e;
    h_[5] += f;
    h_[6] += g;
    h_[7] += h;
  }

  std::array<uint32_t, 8> h_;
  std::array<unsigned char, 64> buffer_;
  uint64_t length_ = 0;
  size_t buffered_ = 0;
};

}  // namespace

fs::path TempPathFor(const fs::path& path, std::string_view suffix) {
  static std::atomic<uint64_t> counter{0};
  return path.string() + ".tmp-" + std::to_string(::getpid()) + "-" +
         std::to_string(counter.fetch_add(1)) + std::string(suffix);
}

int FileIo::Open(const char* path, int flags, mode_t mode) { return ::open(path, flags, mode); }
ssize_t FileIo::Write(int fd, const void* data, size_t n) { return ::write(fd, data, n); }
int FileIo::Fsync(int fd) { return ::fsync(fd); }
int FileIo::Rename(const char* from, const char* to) { return ::rename(from, to); }

namespace {
FileIo g_system_io;
std::atomic<FileIo*> g_io{&g_system_io};
}  // namespace

FileIo& CurrentFileIo() { return *g_io.load(); }
ScopedFileIo::ScopedFileIo(FileIo& io) : previous_(g_io.exchange(&io)) {}
ScopedFileIo::~ScopedFileIo() { g_io.store(previous_); }

std::string LowerExtension(const fs::path& path) {
  std::string e = path.extension().string();
  std::transform(e.begin(), e.end(), e.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return e;
}

std::string IoErrorMessage(const fs::path& path, std::string_view what, int err) {
  std::string m = path.string() + ": " + std::string(what) + ": " + std::strerror(err);
  if (err == ENOSPC || err == EDQUOT) m += " (the disk is full)";
  if (err == EROFS) m += " (the disk is mounted read-only)";
  return m;
}

void WriteAll(int fd, std::string_view bytes, const fs::path& path) {
  FileIo& io = CurrentFileIo();
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = io.Write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      // write() returning 0 for a non-empty request means no progress: treat it as full.
      const int err = n == 0 ? ENOSPC : errno;
      const std::string m = IoErrorMessage(path,
                                           "write failed after " + std::to_string(done) + " of " +
                                               std::to_string(bytes.size()) + " bytes",
                                           err);
      errno = err;
      throw Error(m);
    }
    done += static_cast<size_t>(n);
  }
}

void WriteFileAtomic(const fs::path& path, std::string_view bytes) {
  FileIo& io = CurrentFileIo();
  const fs::path tmp = TempPathFor(path);
  const int fd = io.Open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(IoErrorMessage(path, "cannot create a temporary file", errno));
  auto fail = [&](const std::string& message) {
    if (fd >= 0) ::close(fd);
    ::unlink(tmp.c_str());
    throw Error(message);
  };
  try {
    WriteAll(fd, bytes, path);
  } catch (const Error& e) {
    fail(e.what());
  }
  if (io.Fsync(fd) != 0) fail(IoErrorMessage(path, "fsync failed", errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0) fail(IoErrorMessage(path, "cannot stat the written file", errno));
  if (static_cast<uint64_t>(st.st_size) != bytes.size()) {
    fail(path.string() + ": the file on disk has " + std::to_string(st.st_size) +
         " bytes after writing " + std::to_string(bytes.size()));
  }
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    throw Error(IoErrorMessage(path, "close failed", err));
  }
  if (io.Rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    throw Error(IoErrorMessage(path, "rename failed", err));
  }
  try {
    FsyncPath(ParentOrDot(path), true);
  } catch (const Error& e) {
    throw Error(path.string() + ": written, but its folder could not be made durable: " + e.what());
  }
}

void CommitFile(const fs::path& tmp, const fs::path& path) {
  FsyncPath(tmp, false);
  if (CurrentFileIo().Rename(tmp.c_str(), path.c_str()) != 0) {
    throw Error(IoErrorMessage(path, "rename from " + tmp.string() + " failed", errno));
  }
  FsyncPath(ParentOrDot(path), true);
}

void FsyncDirectory(const fs::path& dir) { FsyncPath(dir, true); }

void CheckReadableKind(const fs::path& path, const std::string& what) {
  // A folder opens, and then its first read throws std::ios_base::failure ("Is a directory").
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (fs::is_directory(st)) throw Error(path.string() + ": is a folder, not " + what);
  if (fs::is_character_file(st) || fs::is_block_file(st))
    throw Error(path.string() + ": is a device, not " + what);
}

std::string ReadFileToString(const fs::path& path) {
  CheckReadableKind(path, "a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open: " + Errno());
  std::string out((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw Error(path.string() + ": read failed");
  return out;
}

fs::path ResolveInside(const fs::path& root, std::string_view relative) {
  const std::string rel(relative);
  if (rel.empty()) throw Error("path is empty (expected a path inside " + root.string() + ")");
  if (rel.find('\0') != std::string::npos) throw Error("path \"" + rel + "\" contains NUL");
  const fs::path r(rel);
  if (r.is_absolute() || rel.front() == '/') {
    throw Error("path \"" + rel + "\" is absolute (expected a path inside " + root.string() + ")");
  }
  for (const auto& part : r) {
    if (part == "..") throw Error("path \"" + rel + "\" leaves " + root.string() + " (\"..\")");
  }
  const fs::path joined = (root / r).lexically_normal();
  std::error_code ec;
  const fs::path canon_root = fs::weakly_canonical(root, ec);
  if (ec) throw Error(root.string() + ": cannot resolve: " + ec.message());
  const fs::path canon = fs::weakly_canonical(joined, ec);
  if (ec) throw Error(joined.string() + ": cannot resolve: " + ec.message());
  auto it = canon.begin();
  for (auto rt = canon_root.begin(); rt != canon_root.end(); ++rt, ++it) {
    if (rt->empty()) continue;  // trailing separator
    if (it == canon.end() || *it != *rt) {
      throw Error("path \"" + rel + "\" leaves " + root.string() + " (through a symlink to " +
                  canon.string() + ")");
    }
  }
  return joined;
}

std::string Sha256Hex(std::string_view bytes) {
  Sha256 s;
  s.Update(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size());
  return s.HexDigest();
}

std::string Sha256File(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw Error(path.string() + ": cannot open: " + Errno());
  Sha256 s;
  std::vector<unsigned char> buf(1 << 16);
  while (true) {
    const ssize_t n = ::read(fd, buf.data(), buf.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string e = Errno();
      ::close(fd);
      throw Error(path.string() + ": read failed: " + e);
    }
    if (n == 0) break;
    s.Update(buf.data(), static_cast<size_t>(n));
  }
  ::close(fd);
  return s.HexDigest();
}

std::string FindOnPath(const std::string& program) {
  if (program.empty()) return {};
  if (program.find('/') != std::string::npos)
    return ::access(program.c_str(), X_OK) == 0 ? program : std::string();
  const char* path = std::getenv("PATH");
  const std::string dirs = path ? path : "/usr/bin:/bin";
  for (size_t start = 0; start <= dirs.size();) {
    const size_t end = std::min(dirs.find(':', start), dirs.size());
    const std::string dir = dirs.substr(start, end - start);
    const std::filesystem::path candidate =
        std::filesystem::path(dir.empty() ? "." : dir) / program;
    std::error_code ec;
    if (std::filesystem::is_regular_file(candidate, ec) && ::access(candidate.c_str(), X_OK) == 0)
      return candidate.string();
    start = end + 1;
  }
  return {};
}

}  // namespace rouen
