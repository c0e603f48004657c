// Durable file writes and safe relative paths.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>

namespace rouen {

// The system calls every durable write goes through (WriteFileAtomic, WriteAll, and so every
// image, JSON file and journal line rouen writes). Tests install another one with ScopedFileIo
// to inject a full disk, a read-only folder or an I/O error at any single call.
class FileIo {
 public:
  virtual ~FileIo() = default;
  virtual int Open(const char* path, int flags, mode_t mode);
  virtual ssize_t Write(int fd, const void* data, size_t n);
  virtual int Fsync(int fd);
  virtual int Rename(const char* from, const char* to);
};
// The FileIo in force: the system's, unless a ScopedFileIo is alive.
FileIo& CurrentFileIo();
class ScopedFileIo {
 public:
  explicit ScopedFileIo(FileIo& io);
  ~ScopedFileIo();
  ScopedFileIo(const ScopedFileIo&) = delete;
  ScopedFileIo& operator=(const ScopedFileIo&) = delete;

 private:
  FileIo* previous_;
};

// "<path>: <what>: <strerror(err)>", saying so in words when the disk is full or read-only.
std::string IoErrorMessage(const std::filesystem::path& path, std::string_view what, int err);

// Writes all of `bytes` to `fd` (retrying short writes and EINTR); throws rouen::Error naming
// `path` on failure (errno is kept).
void WriteAll(int fd, std::string_view bytes, const std::filesystem::path& path);

// Writes `bytes` to a temporary file beside `path`, checks every write, fsyncs it, checks
// that the file on disk has exactly `bytes.size()` bytes, renames it over `path` and fsyncs
// the directory: readers see the old file or the whole new one, never a part. On failure
// the temporary is removed and `path` is untouched.
void WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes);
// Renames a finished temporary file into place and fsyncs it and its directory.
void CommitFile(const std::filesystem::path& tmp, const std::filesystem::path& path);
// The whole file; throws rouen::Error naming it when it is missing, a folder or a device (a
// device such as /dev/zero never ends; a pipe does and is read).
std::string ReadFileToString(const std::filesystem::path& path);
// Throws rouen::Error "<path>: is a folder, not <what>" or "...: is a device, not <what>".
void CheckReadableKind(const std::filesystem::path& path, const std::string& what);
// Makes a folder's entries (files created, renamed or removed in it) durable: fsync of the
// folder. Throws rouen::Error naming it.
void FsyncDirectory(const std::filesystem::path& dir);
// A fresh temporary name beside `path`: "<path>.tmp-<pid>-<n><suffix>" (unique within the
// process). Names containing ".tmp-" are leftovers that session resume deletes.
std::filesystem::path TempPathFor(const std::filesystem::path& path, std::string_view suffix = {});

// Resolves `relative` inside `root`; throws rouen::Error when it is absolute or leaves
// `root` (through "..", or a symlink pointing out).
std::filesystem::path ResolveInside(const std::filesystem::path& root, std::string_view relative);

// Hex SHA-256 (FIPS 180-4) of bytes and of a file.
std::string Sha256Hex(std::string_view bytes);
std::string Sha256File(const std::filesystem::path& path);

// The extension of the file `path` names, lower case, with its dot (".dng"); empty for none.
std::string LowerExtension(const std::filesystem::path& path);

// The path of `program` as the shell would find it: itself when it holds a '/' and is
// executable, else the first executable file of that name in a PATH folder; empty when none.
std::string FindOnPath(const std::string& program);

}  // namespace rouen
