// The files one command writes, all or nothing. Each output is declared before the work
// starts (Add checks that it can be written and reserves a temporary beside it), written to
// its temporary, and renamed into place with the others by Commit once all are written. An
// OutputSet destroyed before Commit -- an error -- removes its temporaries; signals are
// covered by core/temporaries.h (Add records each output's folder there).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace rouen {

// Whether `path` is `folder` or lies inside it, both made absolute and normal with the symbolic
// links of their existing parts resolved.
bool IsWithin(const std::filesystem::path& path, const std::filesystem::path& folder);

// The session or scene folder `path` lies in (the nearest folder above it, or `path` itself,
// that holds a session's session.json or frames.jsonl, or a scene's scene.json), and `kind`
// "session" or "scene"; none: "". Only the commands that make such a folder write in it.
std::string EnclosingSessionOrScene(const std::filesystem::path& path, std::string* kind);
// Throws rouen::Error "<what>: lies inside the session|scene <folder>; ..." when the new
// folder `folder` (a session, a scene, a viewer) would be made inside a session or a scene.
void CheckNewFolderPlace(const std::string& what, const std::filesystem::path& folder);

// Checks a folder a command writes whole and replaces on each run (`kind`: "scene", "viewer"),
// named `what` in messages: throws rouen::Error when it has no name, would lie inside a session
// or a scene (CheckNewFolderPlace), its parent does not exist, it is a file, or it exists, is
// not empty and holds no `marker` (the file that makes it a `kind` folder the command may
// replace).
void CheckReplaceableFolder(const std::string& what, const std::filesystem::path& folder,
                            const std::string& marker, const std::string& kind);

enum class OutputKind {
  kFile,      // any content (JSON, text)
  kRadiance,  // a floating-point image (IsFloatImageFormat)
  kImage,     // an 8-bit image in a format OpenImageIO writes (.png, .jpg, .tif, ...)
};

// True for the formats that store floating-point radiance: OpenEXR (.exr), Radiance RGBE
// (.hdr), PFM (.pfm) and TIFF (.tif, .tiff). Others (PNG, JPEG) would clip it to 8 or 16 bits.
bool IsFloatImageFormat(const std::string& path);

// Checks that `dir` is a folder this process can write in, or one it can create: throws
// rouen::Error naming `what` (an option) when `dir` or the nearest existing folder above it
// is a file, or when that folder is not writable (permissions, a read-only disk).
void CheckWritableFolder(const std::string& what, const std::string& dir);

class OutputSet {
 public:
  OutputSet() = default;
  ~OutputSet();
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;

  // Declares an input of the command (a file, or a folder such as a scene or a session) that
  // no output may replace or be written into; `what` names it in messages. Empty: nothing.
  // Throws rouen::Error when an output already declared is that file or inside that folder.
  void Protect(const std::string& what, const std::string& path);
  // Declares an output; `what` names it in messages (an option: "--out"). Throws
  // rouen::Error when `path` is empty or a folder, when it exists and is not a regular file
  // (a device, a pipe: renaming over it would replace it), when its folder is missing or not
  // writable, when the format does not suit `kind`, when another output has the same path, or
  // when it is a protected input or lies inside one (Protect), or when it lies inside a session
  // or scene folder (one holding session.json or frames.jsonl, or scene.json), which only the
  // commands that make them write.
  // Returns the temporary to write it to: "<path>.tmp-<pid>-<n><extension>", so writers that
  // choose a format by extension choose the right one.
  std::string Add(const std::string& what, const std::string& path, OutputKind kind);
  // Declares a folder the outputs go into and creates it with its missing parents; refused
  // before anything is created, as Add refuses a path (a protected input or inside one, inside
  // a session or a scene folder, a file where the folder should be, no permission).
  void CreateFolder(const std::string& what, const std::string& dir);
  // Renames every temporary to its path (each rename atomic); after this the destructor
  // removes nothing.
  void Commit();

 private:
  struct Entry {
    std::string what, path, temp;
  };
  std::vector<Entry> entries_;
  struct Input {
    std::string what, path, canonical;
  };
  std::vector<std::pair<std::string, std::string>> InputNames() const;  // ("what path", canonical)
  std::vector<Input> inputs_;
  bool committed_ = false;
};

}  // namespace rouen
