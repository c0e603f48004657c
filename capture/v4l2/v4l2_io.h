// The system-call seam of the V4L2 driver: everything the driver does to a /dev/videoN node
// goes through a V4l2Io, so tests can put a FakeV4l2Device (fake_v4l2.h) where the kernel is.
// Calls follow the syscall convention: on failure they return -1 (MAP_FAILED for Mmap) and
// set errno.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <string>
#include <vector>

namespace rouen {

class V4l2Io {
 public:
  virtual ~V4l2Io() = default;
  // open(2)/close(2)/ioctl(2)/mmap(2)/munmap(2) with the same meaning.
  virtual int Open(const std::string& path, int flags) = 0;
  virtual int Close(int fd) = 0;
  virtual int Ioctl(int fd, unsigned long request, void* arg) = 0;
  virtual void* Mmap(size_t length, int prot, int flags, int fd, off_t offset) = 0;
  virtual int Munmap(void* addr, size_t length) = 0;
  // poll(2) on one descriptor: returns 1 with *revents set, 0 after `timeout_ms`
  // milliseconds with nothing to report, -1 with errno on failure.
  virtual int Poll(int fd, short events, short* revents, int timeout_ms) = 0;
  // The V4L2 device nodes present (/dev/video0, /dev/video1, ... in numeric order).
  virtual std::vector<std::string> ListDevices() = 0;
};

// The real system calls.
class SystemV4l2Io : public V4l2Io {
 public:
  int Open(const std::string& path, int flags) override;
  int Close(int fd) override;
  int Ioctl(int fd, unsigned long request, void* arg) override;
  void* Mmap(size_t length, int prot, int flags, int fd, off_t offset) override;
  int Munmap(void* addr, size_t length) override;
  int Poll(int fd, short events, short* revents, int timeout_ms) override;
  // Lists /dev/video<digits> (nothing when /dev cannot be read).
  std::vector<std::string> ListDevices() override;
};

}  // namespace rouen
