#include "core/image.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>

#include <OpenImageIO/imageio.h>

#include "core/error.h"
#include "core/files.h"
#include "core/outputs.h"

namespace rouen {
namespace {

constexpr float kHalfMax = 65504.0f;

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

Image ReadImage(const std::string& path) {
  // Colour values as stored: no premultiplication by an alpha channel (alpha is dropped).
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) {
    std::string msg = OIIO::geterror();
    throw Error(path + ": cannot read image: " + (msg.empty() ? "unknown format" : msg));
  }
  const OIIO::ImageSpec spec = in->spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  if (w <= 0 || h <= 0 || nch <= 0 || spec.depth > 1) {
    throw Error(path + ": unsupported image layout (" + std::to_string(w) + "x" +
                std::to_string(h) + ", " + std::to_string(nch) + " channels)");
  }
  const auto base = static_cast<OIIO::TypeDesc::BASETYPE>(spec.format.basetype);
  const bool is_float = base == OIIO::TypeDesc::HALF || base == OIIO::TypeDesc::FLOAT ||
                        base == OIIO::TypeDesc::DOUBLE;
  // 8- and 16-bit data are read as stored and mapped exactly (16-bit: /257) onto 0..255;
  // other integer types come through OIIO's 0..1 normalisation.
  const size_t n = static_cast<size_t>(w) * h * nch;
  std::vector<float> raw(n);
  bool ok;
  if (base == OIIO::TypeDesc::UINT8) {
    std::vector<uint8_t> buf(n);
    ok = in->read_image(0, 0, 0, nch, OIIO::TypeDesc::UINT8, buf.data());
    for (size_t i = 0; i < n; ++i) raw[i] = buf[i];
  } else if (base == OIIO::TypeDesc::UINT16) {
    std::vector<uint16_t> buf(n);
    ok = in->read_image(0, 0, 0, nch, OIIO::TypeDesc::UINT16, buf.data());
    for (size_t i = 0; i < n; ++i) raw[i] = static_cast<float>(buf[i] / 257.0);
  } else {
    ok = in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, raw.data());
    if (!is_float) {
      for (float& v : raw) v *= 255.f;
    }
  }
  if (!ok) {
    std::string msg = in->geterror();
    throw Error(path + ": cannot read image: " + (msg.empty() ? "read failed" : msg));
  }
  in->close();
  // Drop alpha: RGBA -> RGB, gray+alpha -> gray; other layouts are kept as stored.
  int out_ch = nch;
  if (nch == 4) out_ch = 3;
  if (nch == 2 && spec.alpha_channel == 1) out_ch = 1;
  Image img(w, h, out_ch, is_float ? PixelUnits::kRadiance : PixelUnits::kDigital);
  for (size_t p = 0; p < static_cast<size_t>(w) * h; ++p) {
    for (int c = 0; c < out_ch; ++c) {
      const float v = raw[p * nch + c];
      if (!std::isfinite(v)) {
        throw Error(path + ": pixel (" + std::to_string(p % w) + ", " + std::to_string(p / w) +
                    ") is not finite");
      }
      img.data[p * out_ch + c] = v;
    }
  }
  return img;
}

std::vector<uint8_t> ReadMask(const std::string& path, int width, int height,
                              const std::string& for_what) {
  const Image m = ReadImage(path);
  if (m.width != width || m.height != height) {
    throw Error(path + ": mask is " + std::to_string(m.width) + "x" + std::to_string(m.height) +
                " but " + for_what + " is " + std::to_string(width) + "x" +
                std::to_string(height));
  }
  std::vector<uint8_t> mask(static_cast<size_t>(width) * height, 0);
  for (size_t p = 0; p < mask.size(); ++p)
    for (int c = 0; c < m.channels; ++c)
      if (m.data[p * m.channels + c] != 0) mask[p] = 1;
  return mask;
}

void WriteImage(const std::string& path, const Image& image, StoredType type) {
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
                  std::to_string(p % image.width) + ", " + std::to_string(p / image.width) + ")");
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
        u16[i] = static_cast<uint16_t>(
            std::lround(std::clamp(image.data[i] * 257.0, 0.0, 65535.0)));
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
  const std::filesystem::path target(path);
  const std::string ext = target.extension().string();
  const std::filesystem::path tmp = TempPathFor(target, ext);
  auto out = OIIO::ImageOutput::create(tmp.string());
  if (!out) {
    throw Error(path + ": cannot write image: " + OIIO::geterror());
  }
  OIIO::ImageSpec spec(image.width, image.height, image.channels, format);
  if (image.channels == 4) {
    spec.alpha_channel = 3;
    spec.attribute("oiio:UnassociatedAlpha", 1);  // store colours as given
  }
  auto fail = [&](const std::string& what) {
    std::string msg = out->geterror();
    out.reset();
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": " + what + ": " + msg);
  };
  if (!out->open(tmp.string(), spec)) fail("cannot open for writing");
  if (!out->write_image(pixel_type, pixels)) fail("cannot write pixels");
  if (!out->close()) fail("cannot finish the file");
  out.reset();
  try {
    CommitFile(tmp, target);
  } catch (...) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw;
  }
}

}  // namespace rouen
