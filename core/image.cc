#include "core/image.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string_view>

#include "core/error.h"
#include "core/exif.h"
#include "core/files.h"
#include "core/internal/image_input.h"
#include "core/outputs.h"

namespace rouen {
namespace {

constexpr float kHalfMax = 65504.0f;

// A little-endian int32 (OpenEXR headers).
int32_t Le32(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return static_cast<int32_t>(b[0] | b[1] << 8 | b[2] << 16 | uint32_t{b[3]} << 24);
}

}  // namespace

float Image::Sample(double x, double y, int c) const {
  if (width <= 0 || height <= 0) return 0.f;
  const double fx = std::clamp(x - 0.5, 0.0, static_cast<double>(width - 1));
  const double fy = std::clamp(y - 0.5, 0.0, static_cast<double>(height - 1));
  const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  const int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
  const double ax = fx - x0, ay = fy - y0;
  const double top = (1 - ax) * at(x0, y0, c) + ax * at(x1, y0, c);
  const double bottom = (1 - ax) * at(x0, y1, c) + ax * at(x1, y1, c);
  return static_cast<float>((1 - ay) * top + ay * bottom);
}

void CheckImageSize(const std::string& path, int width, int height, int channels) {
  const std::string claimed = std::to_string(width) + "x" + std::to_string(height) + ", " +
                              std::to_string(channels) + " channels";
  if (width <= 0 || height <= 0 || channels <= 0) {
    throw Error(path + ": unsupported image layout (" + claimed + ")");
  }
  if (width > kMaxImageSide || height > kMaxImageSide ||
      static_cast<int64_t>(width) * height > kMaxImagePixels || channels > kMaxImageChannels) {
    throw Error(path + ": image of " + claimed + " is beyond the limit of " +
                std::to_string(kMaxImageSide) + " pixels a side, " +
                std::to_string(kMaxImagePixels) + " pixels and " +
                std::to_string(kMaxImageChannels) + " channels (a corrupt header?)");
  }
}

namespace internal {

namespace {

// OpenEXR headers (several when multi-part, then an empty one): attributes "name\0type\0" +
// int32 size + value, ended by an empty name. Only what is parsed is checked; OpenEXR reports
// other damage itself.
void CheckExrHeader(std::ifstream& in, int64_t size, int32_t version, const std::string& path) {
  auto read_int = [&](int32_t* v) {
    char b[4];
    if (!in.read(b, 4)) return false;
    *v = Le32(b);
    return true;
  };
  const bool multipart = version & 0x1000;
  auto read_name = [&](std::string* s) {
    s->clear();
    for (char c; in.get(c);) {
      if (c == '\0') return true;
      if (s->size() == 255) return false;
      s->push_back(c);
    }
    return false;
  };
  std::string name, type;
  while (true) {
    int attributes = 0;
    while (read_name(&name) && !name.empty()) {
      int32_t claimed = 0;
      if (!read_name(&type) || !read_int(&claimed)) return;
      const int64_t left = size - in.tellg();
      if (claimed < 0 || claimed > left) {
        throw Error(path + ": OpenEXR header attribute \"" + name + "\" claims " +
                    std::to_string(claimed) + " bytes; the file has " + std::to_string(left) +
                    " left (a corrupt header)");
      }
      if (type == "chlist") {
        // Channels: "name\0", int32 pixel type (0 uint, 1 half, 2 float), 12 more bytes; an
        // empty name ends the list. OpenImageIO 2.4 aborts the process on another pixel type,
        // and OpenEXR reads an entry the attribute's size cuts short on past that size.
        std::string list(claimed, '\0');
        if (!in.read(list.data(), claimed)) return;
        for (size_t pos = 0; pos >= list.size() || list[pos] != '\0';) {
          const size_t end = pos < list.size() ? list.find('\0', pos) : std::string::npos;
          if (end == std::string::npos || end + 17 > list.size()) {
            throw Error(path + ": OpenEXR channel list \"" + name + "\" ends inside an entry (" +
                        std::to_string(claimed) + " bytes; a corrupt header)");
          }
          const int32_t pixel_type = Le32(list.data() + end + 1);
          if (pixel_type < 0 || pixel_type > 2) {
            throw Error(path + ": OpenEXR channel \"" + list.substr(pos, end - pos) +
                        "\" has unknown pixel type " + std::to_string(pixel_type) +
                        " (a corrupt header)");
          }
          pos = end + 17;
        }
      } else {
        in.seekg(claimed, std::ios::cur);
      }
      ++attributes;
    }
    if (!in || !multipart || attributes == 0) return;
  }
}

// A BMP's info header: RLE compression is refused. OpenImageIO 2.4's RLE decoder reads out of
// bounds on a file whose compression and bit depth disagree (found by tests/fuzz/image_fuzz), and
// no camera or tool rouen works with writes RLE bitmaps.
void CheckBmpHeader(std::ifstream& in, const std::string& path) {
  char h[34] = {};
  in.seekg(0);
  if (!in.read(h, sizeof h)) return;  // too short for an info header: the reader refuses it
  const int32_t info_size = Le32(h + 14);
  if (info_size < 40) return;  // OS/2 headers have no compression field
  const int32_t compression = Le32(h + 30);
  if (compression == 1 || compression == 2) {
    throw Error(path + ": cannot read image: run-length encoded BMP (RLE" +
                std::string(compression == 1 ? "8" : "4") +
                ") is not supported; save it as PNG or TIFF");
  }
}

// PNG chunks after the signature: big-endian uint32 length, 4-byte type, data, CRC, up to
// IEND. libpng allocates a chunk's claimed length before reading it.
void CheckPngChunks(std::ifstream& in, int64_t size, const std::string& path) {
  in.seekg(8);
  unsigned char head[8];
  while (in.read(reinterpret_cast<char*>(head), 8)) {
    const uint32_t length =
        uint32_t{head[0]} << 24 | uint32_t{head[1]} << 16 | uint32_t{head[2]} << 8 | head[3];
    const std::string type(reinterpret_cast<const char*>(head + 4), 4);
    const int64_t left = size - in.tellg();
    if (int64_t{length} + 4 > left) {
      std::string shown;
      for (char c : type) shown += std::isalpha(static_cast<unsigned char>(c)) ? c : '?';
      throw Error(path + ": PNG chunk \"" + shown + "\" claims " + std::to_string(length) +
                  " bytes; the file has " + std::to_string(std::max<int64_t>(0, left - 4)) +
                  " left (a truncated or corrupt file)");
    }
    if (type == "IEND") return;
    in.seekg(int64_t{length} + 4, std::ios::cur);
  }
}

// A JPEG's segments from its start to its end-of-image marker: a file cut short (its scan data
// running into the end of the file) is refused, which libjpeg would fill with grey and only
// warn about. Data after the end-of-image marker (a phone's motion clip) is left alone.
void CheckJpegSegments(std::ifstream& in, int64_t size, const std::string& path) {
  std::string data(static_cast<size_t>(size), '\0');
  in.clear();
  in.seekg(0);
  in.read(data.data(), size);
  const size_t n = static_cast<size_t>(in.gcount());
  auto byte = [&](size_t i) { return static_cast<unsigned char>(data[i]); };
  auto cut = [&](const std::string& what) {
    throw Error(path + ": JPEG " + what + " (a truncated or corrupt file)");
  };
  const std::string ends = "ends before its end-of-image marker";
  size_t i = 2;  // after the start-of-image marker
  while (true) {
    if (i >= n) cut(ends);
    if (byte(i) != 0xFF) cut("has no marker at byte " + std::to_string(i));
    while (i < n && byte(i) == 0xFF) ++i;  // fill bytes
    if (i >= n) cut(ends);
    const unsigned char marker = byte(i++);
    if (marker == 0xD9) return;                                          // end of image
    if ((marker >= 0xD0 && marker <= 0xD7) || marker == 0x01) continue;  // no length
    if (i + 2 > n) cut(ends);
    const size_t length = size_t{byte(i)} << 8 | byte(i + 1);
    if (length < 2 || i + length > n)
      cut("segment at byte " + std::to_string(i - 2) + " claims " + std::to_string(length) +
          " bytes; the file has " + std::to_string(n - i) + " left");
    i += length;
    if (marker != 0xDA) continue;
    // Start of scan: its entropy-coded data runs to the next marker that is neither a stuffed
    // 0xFF00 nor a restart marker.
    while (true) {
      if (i + 1 >= n) cut(ends);
      if (byte(i) != 0xFF) {
        ++i;
        continue;
      }
      const unsigned char next = byte(i + 1);
      if (next == 0x00 || (next >= 0xD0 && next <= 0xD7)) {
        i += 2;
        continue;
      }
      if (next == 0xFF) {
        ++i;
        continue;
      }
      break;
    }
  }
}

// The OpenImageIO reader for a file, from its name (RAW formats, Targa: no magic number) or its
// first bytes; empty when rouen does not read that format.
std::string ReaderFor(const std::string& path, std::string_view head) {
  auto starts = [&](std::string_view magic) { return head.substr(0, magic.size()) == magic; };
  if (IsRawFileName(path)) return "raw";
  if (head.size() >= 4 && Le32(head.data()) == 20000630) return "openexr";
  if (starts("\x89PNG\r\n\x1a\n")) return "png";
  if (starts("II*") || starts(std::string_view("MM\0*", 4))) return "tiff";
  if (starts("\xff\xd8\xff")) return "jpeg";
  if (starts("#?")) return "hdr";
  if (starts("BM")) return "bmp";
  if (head.size() >= 2 && head[0] == 'P' &&
      (head[1] == 'f' || head[1] == 'F' || (head[1] >= '1' && head[1] <= '6')))
    return "pnm";
  if (LowerExtension(path) == ".tga") return "targa";
  return "";
}

}  // namespace

std::unique_ptr<OIIO::ImageInput> OpenImageFile(const std::string& path, const char* what,
                                                const OIIO::ImageSpec* config) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(IoErrorMessage(path, std::string("cannot read ") + what, errno));
  char magic[8] = {};
  in.read(magic, 8);
  const std::string_view head(magic, static_cast<size_t>(in.gcount()));
  in.clear();
  in.seekg(0, std::ios::end);
  const int64_t size = in.tellg();
  const std::string reader = ReaderFor(path, head);
  if (reader.empty()) {
    throw Error(path + ": cannot read " + what +
                ": not a format rouen reads (OpenEXR, TIFF, JPEG, PNG, Radiance HDR, BMP, "
                "PNM/PFM, Targa (.tga) or a camera RAW file)");
  }
  if (reader == "openexr") {
    in.seekg(8);
    CheckExrHeader(in, size, Le32(magic + 4), path);
  } else if (reader == "png") {
    CheckPngChunks(in, size, path);
  } else if (reader == "bmp") {
    CheckBmpHeader(in, path);
  } else if (reader == "jpeg") {
    CheckJpegSegments(in, size, path);
  }
  // Only that reader: OpenImageIO would otherwise hand a file its reader refuses to every
  // other one it has (movies, DICOM, SGI, ...), far more code than rouen's formats need.
  std::unique_ptr<OIIO::ImageInput> input = OIIO::ImageInput::create(reader);
  if (!input) throw Error(path + ": cannot read " + what + ": " + OIIO::geterror());
  OIIO::ImageSpec spec;
  const OIIO::ImageSpec none;
  if (!input->open(path, spec, config ? *config : none)) {
    std::string msg = input->geterror();
    throw Error(path + ": cannot read " + what + ": " +
                (msg.empty() ? "not a valid " + reader + " file" : msg));
  }
  return input;
}

bool ReadRowBands(OIIO::ImageInput& in, OIIO::TypeDesc type,
                  const std::function<void(int first_row, int rows, const void* data)>& band) {
  const OIIO::ImageSpec& spec = in.spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  const size_t row_samples = static_cast<size_t>(w) * nch;
  int rows = static_cast<int>(std::clamp<size_t>(kBandSamples / row_samples, 1, h));
  const bool tiled = spec.tile_width > 0;
  if (tiled) {
    // read_tiles wants whole rows of tiles (the last one may end at the image's bottom).
    const int th = std::max(1, spec.tile_height);
    rows = static_cast<int>(std::min<int64_t>((rows + int64_t{th} - 1) / th * th, h));
  }
  std::vector<unsigned char> buf;
  for (int y = 0; y < h; y += rows) {
    const int n = std::min(rows, h - y);
    buf.resize(static_cast<size_t>(n) * row_samples * type.size());
    const int y0 = spec.y + y;
    const bool ok = tiled
                        ? in.read_tiles(0, 0, spec.x, spec.x + w, y0, y0 + n, spec.z,
                                        spec.z + std::max(1, spec.depth), 0, nch, type, buf.data())
                        : in.read_scanlines(0, 0, y0, y0 + n, spec.z, 0, nch, type, buf.data());
    if (!ok) return false;
    band(y, n, buf.data());
  }
  return true;
}

}  // namespace internal

ImageSize ReadImageSize(const std::string& path) {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = internal::OpenImageFile(path, "image", &config);
  const OIIO::ImageSpec spec = in->spec();
  CheckImageSize(path, spec.width, spec.height, spec.nchannels);
  in->close();
  return {spec.width, spec.height, spec.nchannels};
}

Image ReadImage(const std::string& path, bool keep_alpha) {
  // Colour values as stored: no premultiplication by an alpha channel (dropped unless kept).
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = internal::OpenImageFile(path, "image", &config);
  const OIIO::ImageSpec spec = in->spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  if (spec.depth > 1) {
    throw Error(path + ": unsupported image layout (a volume of depth " +
                std::to_string(spec.depth) + ")");
  }
  // Before any pixel memory: the header may claim far more than the file holds.
  CheckImageSize(path, w, h, nch);
  const auto base = static_cast<OIIO::TypeDesc::BASETYPE>(spec.format.basetype);
  const bool is_float = base == OIIO::TypeDesc::HALF || base == OIIO::TypeDesc::FLOAT ||
                        base == OIIO::TypeDesc::DOUBLE;
  // Drop alpha: RGBA -> RGB, gray+alpha -> gray; other layouts are kept as stored.
  int out_ch = nch;
  if (nch == 4 && !keep_alpha) out_ch = 3;
  if (nch == 2 && spec.alpha_channel == 1 && !keep_alpha) out_ch = 1;
  Image img;
  img.width = w;
  img.height = h;
  img.channels = out_ch;
  img.units = is_float ? PixelUnits::kRadiance : PixelUnits::kDigital;
  // 8- and 16-bit data are read as stored and mapped exactly (16-bit: /257) onto 0..255;
  // other integer types come through OIIO's 0..1 normalisation.
  const OIIO::TypeDesc type = base == OIIO::TypeDesc::UINT8    ? OIIO::TypeDesc::UINT8
                              : base == OIIO::TypeDesc::UINT16 ? OIIO::TypeDesc::UINT16
                                                               : OIIO::TypeDesc::FLOAT;
  const size_t total = static_cast<size_t>(w) * h * out_ch;
  const bool ok = internal::ReadRowBands(*in, type, [&](int y0, int rows, const void* data) {
    const size_t first = static_cast<size_t>(y0) * w, count = static_cast<size_t>(rows) * w;
    internal::GrowTo(&img.data, (first + count) * out_ch, total);
    for (size_t i = 0; i < count; ++i) {
      for (int c = 0; c < out_ch; ++c) {
        const size_t s = i * nch + c;
        float v;
        if (type == OIIO::TypeDesc::UINT8) {
          v = static_cast<const uint8_t*>(data)[s];
        } else if (type == OIIO::TypeDesc::UINT16) {
          v = static_cast<float>(static_cast<const uint16_t*>(data)[s] / 257.0);
        } else {
          v = static_cast<const float*>(data)[s];
          if (!is_float) v *= 255.f;
        }
        if (!std::isfinite(v)) {
          const size_t p = first + i;
          throw Error(path + ": pixel (" + std::to_string(p % w) + ", " + std::to_string(p / w) +
                      ") is not finite");
        }
        img.data[(first + i) * out_ch + c] = v;
      }
    }
  });
  if (!ok) {
    std::string msg = in->geterror();
    throw Error(path + ": cannot read image: " + (msg.empty() ? "read failed" : msg));
  }
  in->close();
  return img;
}

std::vector<uint8_t> ReadMask(const std::string& path, int width, int height,
                              const std::string& for_what) {
  const Image m = ReadImage(path);
  if (m.width != width || m.height != height) {
    throw Error(path + ": mask is " + std::to_string(m.width) + "x" + std::to_string(m.height) +
                " but " + for_what + " is " + std::to_string(width) + "x" + std::to_string(height));
  }
  std::vector<uint8_t> mask(static_cast<size_t>(width) * height, 0);
  for (size_t p = 0; p < mask.size(); ++p)
    for (int c = 0; c < m.channels; ++c)
      if (m.data[p * m.channels + c] != 0) mask[p] = 1;
  return mask;
}

std::string EncodeImage(const std::string& path, const Image& image, StoredType type,
                        const std::vector<ImageAttribute>& attributes) {
  if ((type == StoredType::kHalf || type == StoredType::kFloat) && !IsFloatImageFormat(path)) {
    throw Error(path +
                ": cannot store floating-point values in this format (it would clip "
                "them); use .exr, .hdr, .pfm or .tif");
  }
  if (image.width <= 0 || image.height <= 0 || image.channels <= 0 ||
      image.data.size() != static_cast<size_t>(image.width) * image.height * image.channels) {
    throw Error(path + ": cannot write an empty or inconsistent image (" +
                std::to_string(image.width) + "x" + std::to_string(image.height) + "x" +
                std::to_string(image.channels) + ", " + std::to_string(image.data.size()) +
                " values)");
  }
  for (size_t i = 0; i < image.data.size(); ++i) {
    const float v = image.data[i];
    if (!std::isfinite(v)) {
      const size_t p = i / image.channels;
      throw Error(path + ": refusing to write a non-finite value at pixel (" +
                  std::to_string(p % image.width) + ", " + std::to_string(p / image.width) +
                  "): a value computed from the inputs overflowed or is undefined; check them");
    }
    if (type == StoredType::kHalf && std::abs(v) > kHalfMax) {
      throw Error(path + ": value " + std::to_string(v) +
                  " exceeds the half-float range (65504); store as float");
    }
  }
  OIIO::TypeDesc format = OIIO::TypeDesc::FLOAT;
  std::vector<uint8_t> u8;
  std::vector<uint16_t> u16;
  const void* pixels = image.data.data();
  OIIO::TypeDesc pixel_type = OIIO::TypeDesc::FLOAT;
  switch (type) {
    case StoredType::kUint8:
      format = OIIO::TypeDesc::UINT8;
      u8.resize(image.data.size());
      for (size_t i = 0; i < u8.size(); ++i) {
        u8[i] = static_cast<uint8_t>(std::lround(std::clamp(image.data[i], 0.f, 255.f)));
      }
      pixels = u8.data();
      pixel_type = OIIO::TypeDesc::UINT8;
      break;
    case StoredType::kUint16:
      // Values on the 0..255 digital scale are stored x257 so ReadImage returns them.
      format = OIIO::TypeDesc::UINT16;
      u16.resize(image.data.size());
      for (size_t i = 0; i < u16.size(); ++i) {
        u16[i] =
            static_cast<uint16_t>(std::lround(std::clamp(image.data[i] * 257.0, 0.0, 65535.0)));
      }
      pixels = u16.data();
      pixel_type = OIIO::TypeDesc::UINT16;
      break;
    case StoredType::kHalf:
      format = OIIO::TypeDesc::HALF;
      break;
    case StoredType::kFloat:
      format = OIIO::TypeDesc::FLOAT;
      break;
  }
  // Encoded in memory, so every byte reaches the disk through WriteFileAtomic's checked writes
  // (an encoder writing its own file may not report a full disk).
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput sink(bytes);
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw Error(path + ": cannot write image: " + OIIO::geterror());
  if (!out->supports("ioproxy")) {
    throw Error(path + ": cannot write image: the " + out->format_name() +
                " writer cannot encode to memory");
  }
  OIIO::ImageSpec spec(image.width, image.height, image.channels, format);
  if (image.channels == 4) {
    spec.alpha_channel = 3;
    spec.attribute("oiio:UnassociatedAlpha", 1);  // store colours as given
  }
  for (const ImageAttribute& a : attributes) {
    if (a.name.empty()) throw Error(path + ": an image attribute needs a name");
    if (const auto* text = std::get_if<std::string>(&a.value)) {
      spec.attribute(a.name, *text);
    } else if (const auto* f = std::get_if<float>(&a.value)) {
      if (!std::isfinite(*f))
        throw Error(path + ": refusing to write the non-finite attribute " + a.name);
      spec.attribute(a.name, *f);
    } else {
      spec.attribute(a.name, std::get<int>(a.value));
    }
  }
  void* proxy = &sink;
  spec.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
  auto fail = [&](const std::string& what) {
    const std::string msg = out->geterror();
    throw Error(path + ": " + what + (msg.empty() ? "" : ": " + msg));
  };
  if (!out->open(path, spec)) fail("cannot start encoding");
  if (!out->write_image(pixel_type, pixels)) fail("cannot encode the pixels");
  if (!out->close()) fail("cannot finish encoding");
  out.reset();
  // What was encoded decodes to the same layout (the file is written only if it does).
  OIIO::Filesystem::IOMemReader source(bytes.data(), bytes.size());
  OIIO::ImageSpec config;
  void* in_proxy = &source;
  config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &in_proxy);
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) throw Error(path + ": the encoded image does not decode: " + OIIO::geterror());
  const OIIO::ImageSpec& back = in->spec();
  if (back.width != image.width || back.height != image.height ||
      back.nchannels != image.channels) {
    throw Error(path + ": the encoded image decodes as " + std::to_string(back.width) + "x" +
                std::to_string(back.height) + "x" + std::to_string(back.nchannels));
  }
  std::vector<float> check(image.data.size());
  if (!in->read_image(0, 0, 0, image.channels, OIIO::TypeDesc::FLOAT, check.data())) {
    throw Error(path + ": the encoded image does not decode: " + in->geterror());
  }
  return std::string(bytes.begin(), bytes.end());
}

void WriteImage(const std::string& path, const Image& image, StoredType type,
                const std::vector<ImageAttribute>& attributes) {
  WriteFileAtomic(path, EncodeImage(path, image, type, attributes));
}

std::vector<ImageAttribute> ReadImageAttributes(const std::string& path) {
  auto in = internal::OpenImageFile(path, "the image header");
  std::vector<ImageAttribute> out;
  for (const OIIO::ParamValue& p : in->spec().extra_attribs) {
    const OIIO::TypeDesc t = p.type();
    if (t == OIIO::TypeDesc::STRING) {
      out.push_back({p.name().string(), std::string(p.get_ustring().string())});
    } else if (t == OIIO::TypeDesc::INT) {
      out.push_back({p.name().string(), p.get_int()});
    } else if (t.basetype == OIIO::TypeDesc::FLOAT || t.basetype == OIIO::TypeDesc::DOUBLE ||
               t.basetype == OIIO::TypeDesc::HALF) {
      out.push_back({p.name().string(), p.get_float()});
    }
  }
  in->close();
  return out;
}

}  // namespace rouen
