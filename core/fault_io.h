// A FileIo for fault-injection tests: counts the open, write, fsync and rename calls of
// durable writes and fails them from a chosen call on, as a disk that fills up (ENOSPC),
// turns read-only (EROFS) or breaks (EIO) would. The first failing write may be short (some
// bytes written), as a real disk filling up mid-write gives.
#pragma once

#include <cerrno>
#include <cstddef>

#include "core/files.h"

namespace rouen {

class FaultyFileIo : public FileIo {
 public:
  // Calls numbered 0, 1, ... fail from `fail_from` on with `err` (-1: never fail).
  explicit FaultyFileIo(long fail_from = -1, int err = ENOSPC, bool short_first_write = true)
      : fail_from_(fail_from), err_(err), short_first_(short_first_write) {}

  long calls() const { return calls_; }
  bool failed() const { return failed_; }

  int Open(const char* path, int flags, mode_t mode) override {
    if (Fails()) return -1;
    return FileIo::Open(path, flags, mode);
  }
  ssize_t Write(int fd, const void* data, size_t n) override {
    if (Fails()) {
      if (short_first_ && !short_done_ && n > 1) {
        short_done_ = true;  // half of it lands, then the disk is full
        return FileIo::Write(fd, data, n / 2);
      }
      return -1;
    }
    return FileIo::Write(fd, data, n);
  }
  int Fsync(int fd) override { return Fails() ? -1 : FileIo::Fsync(fd); }
  int Rename(const char* from, const char* to) override {
    return Fails() ? -1 : FileIo::Rename(from, to);
  }

 private:
  bool Fails() {
    const long k = calls_++;
    if (fail_from_ < 0 || k < fail_from_) return false;
    failed_ = true;
    errno = err_;
    return true;
  }
  long fail_from_;
  int err_;
  bool short_first_;
  bool short_done_ = false;
  long calls_ = 0;
  bool failed_ = false;
};

}  // namespace rouen
