#include "capture/libcamera/frame_convert.h"

#include <libcamera/formats.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include "core/error.h"

namespace rouen::libcamera_internal {
namespace {

namespace fmt = libcamera::formats;

enum class Kind { kRgb24, kRgb32, kPacked422, kSemiPlanar420, kPlanar420, kBayer };

struct FormatInfo {
  const char* name;
  PixelCode code;
  Kind kind;
  // kRgb24/kRgb32: byte offsets of R, G, B within a pixel. kPacked422: offsets of Y0, U, Y1,
  // V within 4 bytes. kSemiPlanar420: U offset within the UV pair (0 NV12, 1 NV21).
  int r_or_y0, g_or_u, b_or_y1, v;
  // kBayer: colour-filter order of the top-left 2x2 cell, bits, packing.
  const char* cfa;
  int bits;
  bool csi2_packed;
};

// The libcamera name and code of a format.
#define FMT(name) \
#name, PixelCode { fmt::name.fourcc(), fmt::name.modifier() }
// clang-format off
constexpr FormatInfo kFormats[] = {
  {FMT(RGB888), Kind::kRgb24, 2, 1, 0, 0, "", 8, false},  // memory B,G,R
  {FMT(BGR888), Kind::kRgb24, 0, 1, 2, 0, "", 8, false},  // memory R,G,B
  {FMT(XRGB8888), Kind::kRgb32, 2, 1, 0, 0, "", 8, false},  // memory B,G,R,X
  {FMT(XBGR8888), Kind::kRgb32, 0, 1, 2, 0, "", 8, false},  // memory R,G,B,X
  {FMT(YUYV), Kind::kPacked422, 0, 1, 2, 3, "", 8, false},
  {FMT(UYVY), Kind::kPacked422, 1, 0, 3, 2, "", 8, false},
  {FMT(NV12), Kind::kSemiPlanar420, 0, 0, 0, 0, "", 8, false},
  {FMT(NV21), Kind::kSemiPlanar420, 0, 1, 0, 0, "", 8, false},
  {FMT(YUV420), Kind::kPlanar420, 0, 0, 0, 0, "", 8, false},
  {FMT(SRGGB8), Kind::kBayer, 0, 0, 0, 0, "RGGB", 8, false},
  {FMT(SGRBG8), Kind::kBayer, 0, 0, 0, 0, "GRBG", 8, false},
  {FMT(SGBRG8), Kind::kBayer, 0, 0, 0, 0, "GBRG", 8, false},
  {FMT(SBGGR8), Kind::kBayer, 0, 0, 0, 0, "BGGR", 8, false},
  {FMT(SRGGB10), Kind::kBayer, 0, 0, 0, 0, "RGGB", 10, false},
  {FMT(SGRBG10), Kind::kBayer, 0, 0, 0, 0, "GRBG", 10, false},
  {FMT(SGBRG10), Kind::kBayer, 0, 0, 0, 0, "GBRG", 10, false},
  {FMT(SBGGR10), Kind::kBayer, 0, 0, 0, 0, "BGGR", 10, false},
  {FMT(SRGGB12), Kind::kBayer, 0, 0, 0, 0, "RGGB", 12, false},
  {FMT(SGRBG12), Kind::kBayer, 0, 0, 0, 0, "GRBG", 12, false},
  {FMT(SGBRG12), Kind::kBayer, 0, 0, 0, 0, "GBRG", 12, false},
  {FMT(SBGGR12), Kind::kBayer, 0, 0, 0, 0, "BGGR", 12, false},
  {FMT(SRGGB16), Kind::kBayer, 0, 0, 0, 0, "RGGB", 16, false},
  {FMT(SGRBG16), Kind::kBayer, 0, 0, 0, 0, "GRBG", 16, false},
  {FMT(SGBRG16), Kind::kBayer, 0, 0, 0, 0, "GBRG", 16, false},
  {FMT(SBGGR16), Kind::kBayer, 0, 0, 0, 0, "BGGR", 16, false},
  {FMT(SRGGB10_CSI2P), Kind::kBayer, 0, 0, 0, 0, "RGGB", 10, true},
  {FMT(SGRBG10_CSI2P), Kind::kBayer, 0, 0, 0, 0, "GRBG", 10, true},
  {FMT(SGBRG10_CSI2P), Kind::kBayer, 0, 0, 0, 0, "GBRG", 10, true},
  {FMT(SBGGR10_CSI2P), Kind::kBayer, 0, 0, 0, 0, "BGGR", 10, true},
  {FMT(SRGGB12_CSI2P), Kind::kBayer, 0, 0, 0, 0, "RGGB", 12, true},
  {FMT(SGRBG12_CSI2P), Kind::kBayer, 0, 0, 0, 0, "GRBG", 12, true},
  {FMT(SGBRG12_CSI2P), Kind::kBayer, 0, 0, 0, 0, "GBRG", 12, true},
  {FMT(SBGGR12_CSI2P), Kind::kBayer, 0, 0, 0, 0, "BGGR", 12, true},
};
// clang-format on
#undef FMT

const FormatInfo* Find(PixelCode code) {
  for (const FormatInfo& f : kFormats) {
    if (f.code == code) return &f;
  }
  return nullptr;
}

[[noreturn]] void Fail(const FrameLayout& layout, const std::string& what) {
  throw Error("libcamera frame " + FormatName(layout.format) + " " + std::to_string(layout.width) +
              "x" + std::to_string(layout.height) + ": " + what);
}

// Bytes a row of `width` pixels occupies at least.
size_t MinRowBytes(const FormatInfo& f, int width) {
  switch (f.kind) {
    case Kind::kRgb24:
      return static_cast<size_t>(width) * 3;
    case Kind::kRgb32:
      return static_cast<size_t>(width) * 4;
    case Kind::kPacked422:
      return static_cast<size_t>(width) * 2;
    case Kind::kSemiPlanar420:
    case Kind::kPlanar420:
      return static_cast<size_t>(width);
    case Kind::kBayer:
      if (f.bits == 8) return static_cast<size_t>(width);
      if (!f.csi2_packed) return static_cast<size_t>(width) * 2;
      if (f.bits == 10) return (static_cast<size_t>(width) * 5 + 3) / 4;
      return (static_cast<size_t>(width) * 3 + 1) / 2;
  }
  return 0;
}

struct YuvToRgb {
  double kr = 0.299, kb = 0.114, y_off = 16, y_scale = 1, c_scale = 1;
  explicit YuvToRgb(const FrameLayout& l) {
    switch (l.matrix) {
      case YcbcrMatrix::kRec601:
        kr = 0.299;
        kb = 0.114;
        break;
      case YcbcrMatrix::kRec709:
        kr = 0.2126;
        kb = 0.0722;
        break;
      case YcbcrMatrix::kRec2020:
        kr = 0.2627;
        kb = 0.0593;
        break;
    }
    if (l.full_range) {
      y_off = 0;
      y_scale = 1;
      c_scale = 1;
    } else {
      y_off = 16;
      y_scale = 255.0 / 219.0;
      c_scale = 255.0 / 224.0;
    }
  }
  void Put(uint8_t y, uint8_t u, uint8_t v, float* rgb) const {
    const double yy = (y - y_off) * y_scale;
    const double cb = (u - 128.0) * c_scale, cr = (v - 128.0) * c_scale;
    const double kg = 1.0 - kr - kb;
    const double r = yy + 2.0 * (1.0 - kr) * cr;
    const double b = yy + 2.0 * (1.0 - kb) * cb;
    const double g = (yy - kr * r - kb * b) / kg;
    rgb[0] = static_cast<float>(std::clamp(r, 0.0, 255.0));
    rgb[1] = static_cast<float>(std::clamp(g, 0.0, 255.0));
    rgb[2] = static_cast<float>(std::clamp(b, 0.0, 255.0));
  }
};

// The planes of a multi-planar layout: either given separately, or one contiguous buffer
// split at the standard offsets.
std::vector<PlaneBytes> SplitPlanes(const FrameLayout& l, const std::vector<PlaneBytes>& planes,
                                    const std::vector<size_t>& sizes) {
  if (planes.size() >= sizes.size()) {
    for (size_t i = 0; i < sizes.size(); ++i) {
      if (planes[i].data == nullptr || planes[i].size < sizes[i]) {
        Fail(l, "plane " + std::to_string(i) + " holds " + std::to_string(planes[i].size) +
                    " bytes, the layout needs " + std::to_string(sizes[i]));
      }
    }
    return {planes.begin(), planes.begin() + sizes.size()};
  }
  if (planes.size() != 1) Fail(l, "expected 1 or " + std::to_string(sizes.size()) + " planes");
  size_t total = 0;
  for (size_t s : sizes) total += s;
  if (planes[0].data == nullptr || planes[0].size < total) {
    Fail(l, "buffer holds " + std::to_string(planes[0].size) + " bytes, the layout needs " +
                std::to_string(total));
  }
  std::vector<PlaneBytes> out;
  size_t offset = 0;
  for (size_t s : sizes) {
    out.push_back({planes[0].data + offset, s});
    offset += s;
  }
  return out;
}

}  // namespace

bool IsSupportedFormat(PixelCode format) { return Find(format) != nullptr; }

std::string FormatName(PixelCode format) {
  if (const FormatInfo* f = Find(format)) return f->name;
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((format.fourcc >> (8 * i)) & 0xff);
    s += (c >= 32 && c < 127) ? c : '?';
  }
  if (format.modifier != 0) {
    char hex[24];
    std::snprintf(hex, sizeof hex, "/0x%llx", static_cast<unsigned long long>(format.modifier));
    s += hex;
  }
  return s;
}

std::vector<std::string> SupportedFormatNames() {
  std::vector<std::string> names;
  for (const FormatInfo& f : kFormats) names.push_back(f.name);
  return names;
}

PixelCode ChooseFormat(PixelCode wanted, PixelCode stream_default,
                       const std::vector<PixelCode>& offered) {
  auto is_offered = [&](PixelCode f) {
    return std::find(offered.begin(), offered.end(), f) != offered.end();
  };
  if (wanted.fourcc != 0) return wanted;  // validate() adjusts it if the camera cannot
  if (IsSupportedFormat(stream_default)) return stream_default;
  // kFormats lists the non-Bayer formats in preference order; among Bayer, more bits first.
  const FormatInfo* best = nullptr;
  for (const FormatInfo& f : kFormats) {
    if (!is_offered(f.code)) continue;
    if (f.kind != Kind::kBayer) return f.code;
    if (best == nullptr || f.bits > best->bits) best = &f;
  }
  return best != nullptr ? best->code : PixelCode{};
}

Image ConvertFrame(const FrameLayout& l, const std::vector<PlaneBytes>& planes) {
  const FormatInfo* f = Find(l.format);
  if (f == nullptr) Fail(l, "unsupported pixel format");
  if (l.width <= 0 || l.height <= 0) Fail(l, "empty frame size");
  if (planes.empty()) Fail(l, "no planes");
  const size_t min_row = MinRowBytes(*f, l.width);
  if (l.stride < 0 || static_cast<size_t>(l.stride) < min_row) {
    Fail(l, "stride " + std::to_string(l.stride) + " is below the row size " +
                std::to_string(min_row));
  }
  const size_t stride = static_cast<size_t>(l.stride);
  const int w = l.width, h = l.height;
  Image img(w, h, 3, PixelUnits::kDigital);

  auto need_one_plane = [&](size_t bytes) {
    if (planes[0].data == nullptr || planes[0].size < bytes) {
      Fail(l, "plane 0 holds " + std::to_string(planes[0].size) + " bytes, the layout needs " +
                  std::to_string(bytes));
    }
  };
  const size_t luma_bytes = stride * (h - 1) + min_row;

  switch (f->kind) {
    case Kind::kRgb24:
    case Kind::kRgb32: {
      need_one_plane(luma_bytes);
      const int bpp = f->kind == Kind::kRgb24 ? 3 : 4;
      for (int y = 0; y < h; ++y) {
        const uint8_t* row = planes[0].data + stride * y;
        for (int x = 0; x < w; ++x) {
          const uint8_t* p = row + static_cast<size_t>(x) * bpp;
          img.at(x, y, 0) = p[f->r_or_y0];
          img.at(x, y, 1) = p[f->g_or_u];
          img.at(x, y, 2) = p[f->b_or_y1];
        }
      }
      break;
    }
    case Kind::kPacked422: {
      if (w % 2 != 0) Fail(l, "width must be even for 4:2:2");
      need_one_plane(luma_bytes);
      const YuvToRgb cvt(l);
      for (int y = 0; y < h; ++y) {
        const uint8_t* row = planes[0].data + stride * y;
        for (int x = 0; x < w; x += 2) {
          const uint8_t* p = row + static_cast<size_t>(x) * 2;
          cvt.Put(p[f->r_or_y0], p[f->g_or_u], p[f->v], &img.at(x, y, 0));
          cvt.Put(p[f->b_or_y1], p[f->g_or_u], p[f->v], &img.at(x + 1, y, 0));
        }
      }
      break;
    }
    case Kind::kSemiPlanar420:
    case Kind::kPlanar420: {
      if (w % 2 != 0 || h % 2 != 0) Fail(l, "width and height must be even for 4:2:0");
      const YuvToRgb cvt(l);
      const size_t y_size = stride * h;
      std::vector<PlaneBytes> p;
      size_t c_stride;
      if (f->kind == Kind::kSemiPlanar420) {
        c_stride = stride;
        p = SplitPlanes(l, planes, {y_size, c_stride * (h / 2)});
      } else {
        c_stride = stride / 2;
        if (c_stride < static_cast<size_t>(w / 2)) Fail(l, "chroma stride too small");
        p = SplitPlanes(l, planes, {y_size, c_stride * (h / 2), c_stride * (h / 2)});
      }
      for (int y = 0; y < h; ++y) {
        const uint8_t* yrow = p[0].data + stride * y;
        for (int x = 0; x < w; ++x) {
          uint8_t u, v;
          if (f->kind == Kind::kSemiPlanar420) {
            const uint8_t* c = p[1].data + c_stride * (y / 2) + static_cast<size_t>(x / 2) * 2;
            u = c[f->g_or_u];
            v = c[1 - f->g_or_u];
          } else {
            u = p[1].data[c_stride * (y / 2) + x / 2];
            v = p[2].data[c_stride * (y / 2) + x / 2];
          }
          cvt.Put(yrow[x], u, v, &img.at(x, y, 0));
        }
      }
      break;
    }
    case Kind::kBayer: {
      if (w < 2 || h < 2 || w % 2 != 0 || h % 2 != 0) {
        Fail(l, "raw Bayer frames need an even width and height of at least 2");
      }
      need_one_plane(luma_bytes);
      const float scale = 255.0f / static_cast<float>((1u << f->bits) - 1u);
      const uint8_t* base = planes[0].data;
      std::function<unsigned(int, int)> raw;
      if (f->bits == 8) {
        raw = [&](int x, int y) -> unsigned { return base[stride * y + x]; };
      } else if (!f->csi2_packed) {
        const unsigned mask = (1u << f->bits) - 1u;
        raw = [&, mask](int x, int y) -> unsigned {
          const uint8_t* p = base + stride * y + static_cast<size_t>(x) * 2;
          return (static_cast<unsigned>(p[0]) | (static_cast<unsigned>(p[1]) << 8)) & mask;
        };
      } else if (f->bits == 10) {
        // 4 pixels in 5 bytes: 4 high bytes (bits 9..2), then the four 2-bit low parts.
        raw = [&](int x, int y) -> unsigned {
          const uint8_t* g = base + stride * y + static_cast<size_t>(x / 4) * 5;
          const int i = x % 4;
          return (static_cast<unsigned>(g[i]) << 2) | ((g[4] >> (2 * i)) & 0x3u);
        };
      } else {
        // 2 pixels in 3 bytes: 2 high bytes (bits 11..4), then both 4-bit low parts.
        raw = [&](int x, int y) -> unsigned {
          const uint8_t* g = base + stride * y + static_cast<size_t>(x / 2) * 3;
          const int i = x % 2;
          return (static_cast<unsigned>(g[i]) << 4) | ((g[2] >> (4 * i)) & 0xfu);
        };
      }
      for (int cy = 0; cy < h; cy += 2) {
        for (int cx = 0; cx < w; cx += 2) {
          float r = 0, g = 0, b = 0;
          for (int k = 0; k < 4; ++k) {
            const int dx = k % 2, dy = k / 2;
            const float v = static_cast<float>(raw(cx + dx, cy + dy)) * scale;
            switch (f->cfa[k]) {
              case 'R':
                r = v;
                break;
              case 'B':
                b = v;
                break;
              default:
                g += 0.5f * v;
                break;
            }
          }
          for (int k = 0; k < 4; ++k) {
            float* px = &img.at(cx + k % 2, cy + k / 2, 0);
            px[0] = r;
            px[1] = g;
            px[2] = b;
          }
        }
      }
      break;
    }
  }
  return img;
}

}  // namespace rouen::libcamera_internal
