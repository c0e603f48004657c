#include "core/outputs.h"

#include <OpenImageIO/imageio.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include "core/error.h"
#include "core/files.h"
#include "core/temporaries.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

void RemoveQuietly(const std::string& path) {
  std::error_code ec;
  fs::remove(path, ec);
}

}  // namespace

bool IsFloatImageFormat(const std::string& path) {
  const std::string e = LowerExtension(path);
  return e == ".exr" || e == ".hdr" || e == ".pfm" || e == ".tif" || e == ".tiff";
}

void CheckWritableFolder(const std::string& what, const std::string& dir) {
  const std::string where = what + " " + dir;
  std::error_code ec;
  fs::path p = dir.empty() ? fs::path(".") : fs::path(dir);
  if (fs::exists(p, ec) && !fs::is_directory(p, ec)) throw Error(where + ": is not a folder");
  while (!fs::exists(p, ec)) {
    p = p.has_parent_path() && p.parent_path() != p ? p.parent_path() : fs::path(".");
  }
  if (!fs::is_directory(p, ec)) throw Error(where + ": " + p.string() + " is not a folder");
  if (::access(p.c_str(), W_OK) != 0)
    throw Error(where + ": cannot write in " + p.string() + ": " + std::strerror(errno));
}

OutputSet::~OutputSet() {
  if (committed_) return;
  for (const Entry& e : entries_) RemoveQuietly(e.temp);
}

bool IsWithin(const fs::path& path, const fs::path& folder) {
  std::error_code ec;
  const fs::path a = fs::weakly_canonical(fs::absolute(path), ec).lexically_normal();
  const fs::path b = fs::weakly_canonical(fs::absolute(folder), ec).lexically_normal();
  auto ai = a.begin();
  for (auto bi = b.begin(); bi != b.end(); ++bi, ++ai) {
    if (bi->empty()) continue;  // a trailing separator
    if (ai == a.end() || *ai != *bi) return false;
  }
  return true;
}

std::string EnclosingSessionOrScene(const fs::path& path, std::string* kind) {
  std::error_code ec;
  for (fs::path d = fs::absolute(path, ec); !d.empty(); d = d.parent_path()) {
    if (fs::is_regular_file(d / "session.json", ec) ||
        fs::is_regular_file(d / "frames.jsonl", ec)) {
      *kind = "session";
      return d.string();
    }
    if (fs::is_regular_file(d / "scene.json", ec)) {
      *kind = "scene";
      return d.string();
    }
    if (d == d.parent_path()) break;
  }
  return "";
}

void CheckNewFolderPlace(const std::string& what, const fs::path& folder) {
  std::error_code ec;
  std::string kind;
  const std::string holder = EnclosingSessionOrScene(fs::absolute(folder, ec).parent_path(), &kind);
  if (!holder.empty())
    throw Error(what + ": lies inside the " + kind + " " + holder +
                ", which only the command that made it writes; give a folder outside it");
}

void CheckReplaceableFolder(const std::string& what, const fs::path& folder,
                            const std::string& marker, const std::string& kind) {
  std::error_code ec;
  if (folder.filename().empty()) throw Error(what + ": a " + kind + " folder needs a name");
  CheckNewFolderPlace(what, folder);
  if (!fs::exists(folder, ec)) {
    const fs::path parent = folder.parent_path().empty() ? fs::path(".") : folder.parent_path();
    if (!fs::is_directory(parent, ec))
      throw Error(what + ": the folder " + parent.string() + " does not exist");
    return;
  }
  if (!fs::is_directory(folder, ec)) throw Error(what + ": exists and is not a folder");
  if (!fs::exists(folder / marker, ec) && !fs::is_empty(folder, ec))
    throw Error(what + ": exists and is not a " + kind + " folder (no " + marker +
                "); give a new folder");
}

namespace {

// Refuses `path` (a file or a folder to write) when it is a protected input or lies inside
// one, or lies inside a session or a scene folder.
void CheckOutputPlace(const std::string& where, const fs::path& canonical,
                      const std::vector<std::pair<std::string, std::string>>& inputs) {
  for (const auto& [what, input] : inputs) {
    if (IsWithin(canonical, input))
      throw Error(where + ": would overwrite " + what + ", an input of this command; write it " +
                  "elsewhere");
  }
  // Sessions and scenes are written only by the commands that make them (capture, import and
  // calib; solve), each file with its hash or provenance: anything else there is refused.
  std::string kind;
  const std::string holder = EnclosingSessionOrScene(canonical, &kind);
  if (!holder.empty())
    throw Error(where + ": lies inside the " + kind + " " + holder + " (it holds " +
                (kind == "scene" ? "scene.json), which only rouen solve writes"
                                 : "session.json), which only capture, import and calib write") +
                "; write it elsewhere");
}

}  // namespace

void OutputSet::Protect(const std::string& what, const std::string& path) {
  if (path.empty()) return;
  std::error_code ec;
  const fs::path canonical = fs::weakly_canonical(path, ec);
  if (ec) return;  // an input that cannot be resolved is reported by its reader
  for (const Entry& e : entries_) {
    if (IsWithin(e.path, canonical))
      throw Error(e.what + " " + e.path + ": would overwrite " + what + " " + path +
                  ", an input of this command; write it elsewhere");
  }
  inputs_.push_back({what, path, canonical.string()});
}

std::string OutputSet::Add(const std::string& what, const std::string& path, OutputKind kind) {
  if (path.empty()) throw Error(what + ": no file name given");
  const std::string where = what + " " + path;
  const fs::path p(path);
  std::error_code ec;
  if (fs::is_directory(p, ec) || !p.has_filename())
    throw Error(where + ": is a folder; give a file name (e.g. " +
                (p / (kind == OutputKind::kFile ? "out.json" : "out.exr")).string() + ")");
  if (fs::exists(fs::symlink_status(p, ec)) && !fs::is_regular_file(p, ec))
    throw Error(where +
                ": is not a regular file (a device or a pipe), which the output would "
                "replace; give a file name");
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  if (!fs::exists(dir, ec)) throw Error(where + ": no such folder " + dir.string());
  if (!fs::is_directory(dir, ec)) throw Error(where + ": " + dir.string() + " is not a folder");
  const std::string ext = LowerExtension(path);
  if (kind == OutputKind::kRadiance && !IsFloatImageFormat(path))
    throw Error(where + ": radiance needs a floating-point image format (.exr, .hdr, .pfm or " +
                ".tif), not '" + (ext.empty() ? std::string("no extension") : ext) + "'");
  if (kind == OutputKind::kImage && !OIIO::ImageOutput::create(path))
    throw Error(where + ": no image format to write for '" +
                (ext.empty() ? std::string("no extension") : ext) + "' (use .png)");
  const fs::path canonical = fs::weakly_canonical(p, ec);
  CheckOutputPlace(where, canonical, InputNames());
  for (const Entry& e : entries_) {
    std::error_code ec2;
    if (fs::weakly_canonical(e.path, ec2) == canonical)
      throw Error(where + ": the same file as " + e.what + " " + e.path);
  }
  WatchForTemporaries(dir);
  const std::string temp = TempPathFor(p, fs::path(path).extension().string()).string();
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0)
    throw Error(where + ": cannot write in " + dir.string() + ": " + std::strerror(errno));
  ::close(fd);
  entries_.push_back({what, path, temp});
  return temp;
}

std::vector<std::pair<std::string, std::string>> OutputSet::InputNames() const {
  std::vector<std::pair<std::string, std::string>> out;
  for (const Input& in : inputs_) out.push_back({in.what + " " + in.path, in.canonical});
  return out;
}

void OutputSet::CreateFolder(const std::string& what, const std::string& dir) {
  const std::string where = what + " " + dir;
  std::error_code ec;
  CheckOutputPlace(where, fs::weakly_canonical(dir, ec), InputNames());
  CheckWritableFolder(what, dir);
  fs::create_directories(dir, ec);
  if (ec) throw Error(where + ": cannot create the folder: " + ec.message());
}

void OutputSet::Commit() {
  for (const Entry& e : entries_) {
    std::error_code ec;
    if (fs::file_size(e.temp, ec) == 0 || ec)
      throw Error(e.what + " " + e.path + ": nothing was written (" +
                  (ec ? ec.message() : std::string("empty")) + ")");
  }
  for (const Entry& e : entries_) CommitFile(e.temp, e.path);
  committed_ = true;
}

}  // namespace rouen
