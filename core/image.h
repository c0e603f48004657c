// Float images, interleaved channels, row 0 at the top. Every image states its units.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <variant>
#include <vector>

namespace rouen {

enum class PixelUnits {
  kDigital,   // camera output, digital numbers 0..255 (8-bit LDR)
  kRadiance,  // scene-linear relative radiance, per colour band (W m^-2 sr^-1 up to a scale)
  kOther,
};

struct Image {
  int width = 0, height = 0, channels = 3;
  PixelUnits units = PixelUnits::kOther;
  std::vector<float> data;

  Image() = default;
  Image(int w, int h, int c = 3, PixelUnits u = PixelUnits::kOther, float fill = 0.f)
      : width(w), height(h), channels(c), units(u), data(static_cast<size_t>(w) * h * c, fill) {}
  bool empty() const { return data.empty(); }
  size_t index(int x, int y, int c = 0) const {
    return (static_cast<size_t>(y) * width + x) * channels + c;
  }
  float& at(int x, int y, int c = 0) { return data[index(x, y, c)]; }
  float at(int x, int y, int c = 0) const { return data[index(x, y, c)]; }
  // Bilinear sample at continuous pixel coordinates (pixel centres at integer + 0.5),
  // clamped to the border.
  float Sample(double x, double y, int c) const;
};

enum class StoredType { kUint8, kUint16, kHalf, kFloat };

// The largest image a file may claim: ReadImage and ReadRawLinear check the header against
// these before allocating any pixel memory (a 167-byte file can claim 100000 x 100000), and
// then allocate as decoded rows arrive, so a truncated file fails before it costs memory.
constexpr int kMaxImageSide = 65536;                   // pixels, width and height each
constexpr int64_t kMaxImagePixels = int64_t{1} << 28;  // 268 megapixels (16384 x 16384)
constexpr int kMaxImageChannels = 64;
// Throws rouen::Error naming `path`, the claimed size and the limit when width x height x
// channels is empty or beyond the limits above.
void CheckImageSize(const std::string& path, int width, int height, int channels);

// Reads any format OpenImageIO knows. 8/16-bit files come back as digital numbers on a
// 0..255 scale (kDigital), float/half files as kRadiance. Throws rouen::Error naming the file
// (also for a file claiming more than kMaxImageSide / kMaxImagePixels / kMaxImageChannels).
// An alpha channel (RGBA, gray + alpha) is dropped unless `keep_alpha`; colours come as stored.
Image ReadImage(const std::string& path, bool keep_alpha = false);
// The size ReadImage would give `path`, from its header alone (checked as ReadImage checks it).
// Throws rouen::Error naming the file.
struct ImageSize {
  int width = 0, height = 0, channels = 0;
};
ImageSize ReadImageSize(const std::string& path);
// A mask image (any format ReadImage reads): width x height entries, 1 where some channel is
// nonzero. Throws rouen::Error naming the file when it is unreadable or not width x height
// (`for_what` names the image it must match).
std::vector<uint8_t> ReadMask(const std::string& path, int width, int height,
                              const std::string& for_what);
// One header attribute of an image file (OpenEXR keeps any name; rouen's are "rouen:<name>"):
// a string, a float or an integer.
struct ImageAttribute {
  using Value = std::variant<std::string, float, int>;
  std::string name;
  Value value;
};

// Encodes through OpenImageIO in memory, choosing the format from `path`'s extension, and
// checks that the bytes decode to the same width, height and channels. Same value rules as
// WriteImage; throws rouen::Error naming `path`.
// `attributes` go into the file's header (formats that cannot hold them drop them). A 4-channel
// image is written RGBA, its fourth channel the alpha, colours stored as given.
std::string EncodeImage(const std::string& path, const Image& image, StoredType type,
                        const std::vector<ImageAttribute>& attributes = {});
// Writes through OpenImageIO, choosing the format from the extension. Integer types clamp
// and round the values (0..255 scale for kUint8; for kUint16 values on the same 0..255 scale
// are stored x257 as 0..65535, so ReadImage gives them back). The encoded bytes are written by
// WriteFileAtomic (every write checked, fsynced, size checked, renamed), so a crash or a full
// disk never leaves a partial file. Non-finite values, values beyond 65504 for kHalf, and
// kHalf/kFloat to a format that cannot store them (IsFloatImageFormat in core/outputs.h: PNG,
// JPEG, ...) are refused with rouen::Error.
void WriteImage(const std::string& path, const Image& image, StoredType type,
                const std::vector<ImageAttribute>& attributes = {});
// The header attributes of an image file as OpenImageIO reads them (the format's own names,
// e.g. "rouen:time"): strings, integers and floats (of an array, its first value). Throws
// rouen::Error naming the file when it cannot be opened.
std::vector<ImageAttribute> ReadImageAttributes(const std::string& path);

}  // namespace rouen
