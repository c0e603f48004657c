// Durable file writes and safe relative paths.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

namespace rouen {

// Writes `bytes` to a temporary file beside `path`, fsyncs it, renames it over `path` and
// fsyncs the directory: readers see the old file or the whole new one, never a part.
void WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes);
// Renames a finished temporary file into place and fsyncs it and its directory.
void CommitFile(const std::filesystem::path& tmp, const std::filesystem::path& path);
std::string ReadFileToString(const std::filesystem::path& path);
// A fresh temporary name beside `path`: "<path>.tmp-<pid>-<n><suffix>" (unique within the
// process). Names containing ".tmp-" are leftovers that session resume deletes.
std::filesystem::path TempPathFor(const std::filesystem::path& path,
                                  std::string_view suffix = {});

// Resolves `relative` inside `root`; throws rouen::Error when it is absolute or leaves
// `root` (through "..", or a symlink pointing out).
std::filesystem::path ResolveInside(const std::filesystem::path& root, std::string_view relative);

// Hex SHA-256 (FIPS 180-4) of bytes and of a file.
std::string Sha256Hex(std::string_view bytes);
std::string Sha256File(const std::filesystem::path& path);

}  // namespace rouen
