#include "capture/aravis/pixel_decode.h"

#include <algorithm>
#include <array>

#include "core/error.h"

namespace rouen {
namespace {

struct FormatName {
  RawFormat format;
  const char* name;
};
constexpr std::array<FormatName, 8> kNames = {{{RawFormat::kMono8, "Mono8"},
                                               {RawFormat::kMono16, "Mono16"},
                                               {RawFormat::kBayerRG8, "BayerRG8"},
                                               {RawFormat::kBayerGR8, "BayerGR8"},
                                               {RawFormat::kBayerGB8, "BayerGB8"},
                                               {RawFormat::kBayerBG8, "BayerBG8"},
                                               {RawFormat::kRGB8, "RGB8"},
                                               {RawFormat::kBGR8, "BGR8"}}};

}  // namespace

std::optional<RawFormat> RawFormatFromName(const std::string& name) {
  for (const FormatName& n : kNames)
    if (name == n.name) return n.format;
  return std::nullopt;
}

std::string RawFormatName(RawFormat format) {
  for (const FormatName& n : kNames)
    if (n.format == format) return n.name;
  return "?";
}

std::vector<std::string> DecodableFormatNames() {
  std::vector<std::string> out;
  for (const FormatName& n : kNames) out.push_back(n.name);
  return out;
}

int BytesPerPixel(RawFormat format) {
  switch (format) {
    case RawFormat::kMono16:
      return 2;
    case RawFormat::kRGB8:
    case RawFormat::kBGR8:
      return 3;
    default:
      return 1;
  }
}

int BayerColour(RawFormat format, int x, int y) {
  // Colours of the 2x2 cell, row-major: (0,0) (1,0) (0,1) (1,1).
  static constexpr int kRG[4] = {0, 1, 1, 2}, kGR[4] = {1, 0, 2, 1}, kGB[4] = {1, 2, 0, 1},
                       kBG[4] = {2, 1, 1, 0};
  const int i = (y & 1) * 2 + (x & 1);
  switch (format) {
    case RawFormat::kBayerRG8:
      return kRG[i];
    case RawFormat::kBayerGR8:
      return kGR[i];
    case RawFormat::kBayerGB8:
      return kGB[i];
    default:
      return kBG[i];
  }
}

Image DecodeFrame(const uint8_t* data, size_t size, int width, int height, RawFormat format) {
  if (width <= 0 || height <= 0) {
    throw Error("pixel decode: bad frame size " + std::to_string(width) + "x" +
                std::to_string(height));
  }
  const size_t pixels = static_cast<size_t>(width) * height;
  const size_t needed = pixels * BytesPerPixel(format);
  if (data == nullptr || size < needed) {
    throw Error("pixel decode: " + RawFormatName(format) + " frame " + std::to_string(width) + "x" +
                std::to_string(height) + " needs " + std::to_string(needed) + " bytes, got " +
                std::to_string(data ? size : 0));
  }
  Image im(width, height, 3, PixelUnits::kDigital);
  float* out = im.data.data();
  switch (format) {
    case RawFormat::kMono8:
      for (size_t i = 0; i < pixels; ++i) out[3 * i] = out[3 * i + 1] = out[3 * i + 2] = data[i];
      break;
    case RawFormat::kMono16:
      for (size_t i = 0; i < pixels; ++i) {
        const unsigned v = data[2 * i] | (static_cast<unsigned>(data[2 * i + 1]) << 8);
        out[3 * i] = out[3 * i + 1] = out[3 * i + 2] = static_cast<float>(v / 257.0);
      }
      break;
    case RawFormat::kRGB8:
      for (size_t i = 0; i < 3 * pixels; ++i) out[i] = data[i];
      break;
    case RawFormat::kBGR8:
      for (size_t i = 0; i < pixels; ++i)
        for (int c = 0; c < 3; ++c) out[3 * i + c] = data[3 * i + 2 - c];
      break;
    default: {
      // Bilinear demosaic: each missing colour is the mean of the same-coloured pixels of the
      // 3x3 window. Inside the image that window has a fixed layout (below); on the border
      // the window is clipped and the generic loop takes the mean of what is left.
      auto px = [&](int x, int y) -> int { return data[static_cast<size_t>(y) * width + x]; };
      auto generic = [&](int x, int y) {
        int sum[3] = {0, 0, 0}, count[3] = {0, 0, 0};
        for (int yy = std::max(0, y - 1); yy <= std::min(height - 1, y + 1); ++yy)
          for (int xx = std::max(0, x - 1); xx <= std::min(width - 1, x + 1); ++xx) {
            const int c = BayerColour(format, xx, yy);
            sum[c] += px(xx, yy);
            ++count[c];
          }
        const int own = BayerColour(format, x, y);
        for (int c = 0; c < 3; ++c) {
          im.at(x, y, c) = c == own   ? static_cast<float>(px(x, y))
                           : count[c] ? static_cast<float>(double(sum[c]) / count[c])
                                      : 0.f;  // only in a 1-pixel-wide or -high image
        }
      };
      for (int y = 0; y < height; ++y) {
        const bool inner_row = y > 0 && y < height - 1;
        for (int x = 0; x < width; ++x) {
          if (!inner_row || x == 0 || x == width - 1) {
            generic(x, y);
            continue;
          }
          float* o = &out[(static_cast<size_t>(y) * width + x) * 3];
          const int own = BayerColour(format, x, y);
          const int centre = px(x, y);
          const float cross = (px(x - 1, y) + px(x + 1, y) + px(x, y - 1) + px(x, y + 1)) / 4.f;
          const float diag =
              (px(x - 1, y - 1) + px(x + 1, y - 1) + px(x - 1, y + 1) + px(x + 1, y + 1)) / 4.f;
          if (own != 1) {  // red or blue site: green on the cross, the other on the diagonals
            o[own] = static_cast<float>(centre);
            o[1] = cross;
            o[2 - own] = diag;
          } else {  // green site: one colour left/right, the other above/below
            const int horizontal = BayerColour(format, x + 1, y);
            o[1] = static_cast<float>(centre);
            o[horizontal] = (px(x - 1, y) + px(x + 1, y)) / 2.f;
            o[2 - horizontal] = (px(x, y - 1) + px(x, y + 1)) / 2.f;
          }
        }
      }
    }
  }
  return im;
}

}  // namespace rouen
