// Image files through OpenImageIO (core/image.h ReadImage, core/exif.h ReadPhotoMetadata and
// CaptureUtc; for TIFF-like input also ReadRawLinear, which DNG goes through). The bytes are
// written to a file in a per-process folder under /dev/shm, named by their magic number as a
// user's file would be (unknown magic: ".tga", which has none); rouen opens each with the one
// reader of its format (core/internal/image_input.h OpenImageFile). A decoded image is within
// the size limits, holds width x height x channels finite values.
#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/exif.h"
#include "core/image.h"
#include "tests/fuzz/fuzz_util.h"

namespace rouen {
namespace {

// The per-process folder, removed when the process exits normally.
struct Folder {
  Folder() {
    std::filesystem::path d = "/dev/shm";
    if (!std::filesystem::is_directory(d)) d = std::filesystem::temp_directory_path();
    path = d / ("rouen-image-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(path);
  }
  ~Folder() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  std::filesystem::path path;
};

bool StartsWith(std::string_view s, std::string_view magic) {
  return s.substr(0, magic.size()) == magic;
}

const char* Extension(std::string_view s) {
  if (StartsWith(s, "\x89PNG")) return ".png";
  if (StartsWith(s, "\x76\x2f\x31\x01")) return ".exr";
  if (StartsWith(s, "II*") || StartsWith(s, std::string_view("MM\0*", 4))) return ".tif";
  if (StartsWith(s, "\xff\xd8")) return ".jpg";
  if (StartsWith(s, "#?")) return ".hdr";
  if (StartsWith(s, "BM")) return ".bmp";
  if (s.size() >= 2 && s[0] == 'P' && s[1] >= '1' && s[1] <= '7') return ".ppm";
  return ".tga";
}

std::string Write(std::string_view bytes, const char* ext) {
  static const Folder folder;
  const std::string path = (folder.path / (std::string("input") + ext)).string();
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), bytes.size());
  return path;
}

void CheckImage(const Image& im) {
  FUZZ_CHECK(im.width > 0 && im.height > 0 && im.channels > 0, "empty image returned");
  FUZZ_CHECK(im.width <= kMaxImageSide && im.height <= kMaxImageSide &&
                 int64_t{im.width} * im.height <= kMaxImagePixels &&
                 im.channels <= kMaxImageChannels,
             "image beyond the limits");
  FUZZ_CHECK(im.data.size() == size_t(im.width) * im.height * im.channels, "data size");
  for (float v : im.data) FUZZ_CHECK(std::isfinite(v), "non-finite pixel");
}

}  // namespace
}  // namespace rouen

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  OIIO::attribute("threads", 1);  // deterministic runs, one core
  OIIO::attribute("exr_threads", 0);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  const std::string_view bytes = fuzz::Text(data, size);
  const char* ext = Extension(bytes);
  const std::string path = Write(bytes, ext);
  Image im;
  if (fuzz::Accepts([&] { im = ReadImage(path); }, path)) CheckImage(im);
  PhotoMetadata m;
  if (fuzz::Accepts([&] { m = ReadPhotoMetadata(path); }, path)) {
    fuzz::Accepts([&] { CaptureUtc(m, 0); });
    fuzz::Accepts([&] { CaptureUtc(m, std::nullopt); });
  }
  if (std::strcmp(ext, ".tif") == 0) {
    const std::string dng = Write(bytes, ".dng");
    if (fuzz::Accepts([&] { im = ReadRawLinear(dng); }, dng)) CheckImage(im);
  }
  return 0;
}
