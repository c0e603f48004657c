#include "capture/v4l2/pixel_format.h"

#include <linux/videodev2.h>

#include <algorithm>

namespace rouen::v4l2_internal {

std::string FourccToString(uint32_t fourcc) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((fourcc >> (8 * i)) & 0xff);
    s += (c >= 32 && c < 127) ? c : '?';
  }
  while (!s.empty() && s.back() == ' ') s.pop_back();
  if (fourcc & (1u << 31)) s += "-BE";
  return s;
}

uint32_t FourccFromString(const std::string& name) {
  if (name.empty() || name.size() > 4) return 0;
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) {
    const char c = i < static_cast<int>(name.size()) ? name[i] : ' ';
    if (c < 32 || c >= 127) return 0;
    v |= static_cast<uint32_t>(static_cast<unsigned char>(c)) << (8 * i);
  }
  return v;
}

YcbcrParams YcbcrFromFormat(uint32_t colorspace, uint32_t ycbcr_enc, uint32_t quantization) {
  YcbcrParams p;
  if (ycbcr_enc == V4L2_YCBCR_ENC_DEFAULT) {
    ycbcr_enc = V4L2_MAP_YCBCR_ENC_DEFAULT(colorspace);
  }
  if (ycbcr_enc == V4L2_YCBCR_ENC_709 || ycbcr_enc == V4L2_YCBCR_ENC_XV709) {
    p.kr = 0.2126;
    p.kb = 0.0722;
  }
  if (quantization == V4L2_QUANTIZATION_DEFAULT) {
    quantization = V4L2_MAP_QUANTIZATION_DEFAULT(false, colorspace, ycbcr_enc);
  }
  p.full_range = quantization == V4L2_QUANTIZATION_FULL_RANGE;
  return p;
}

void YcbcrToRgb(double y, double cb, double cr, const YcbcrParams& p, float rgb[3]) {
  // Normalise to Y' in [0, 1], Pb/Pr in [-0.5, 0.5].
  double yn, pb, pr;
  if (p.full_range) {
    yn = y / 255.0;
    pb = (cb - 128.0) / 255.0;
    pr = (cr - 128.0) / 255.0;
  } else {
    yn = (y - 16.0) / 219.0;
    pb = (cb - 128.0) / 224.0;
    pr = (cr - 128.0) / 224.0;
  }
  const double kg = 1.0 - p.kr - p.kb;
  const double r = yn + 2.0 * (1.0 - p.kr) * pr;
  const double b = yn + 2.0 * (1.0 - p.kb) * pb;
  const double g = (yn - p.kr * r - p.kb * b) / kg;
  const double v[3] = {r, g, b};
  for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(std::clamp(v[c] * 255.0, 0.0, 255.0));
}

int FormatPreference(uint32_t fourcc) {
  if (IsBayer(fourcc)) return 4;
  switch (fourcc) {
    case V4L2_PIX_FMT_YUYV:
      return 3;
    case V4L2_PIX_FMT_GREY:
      return 2;
    case V4L2_PIX_FMT_MJPEG:
      return 1;
    default:
      return -1;
  }
}

bool IsBayer(uint32_t fourcc) {
  return fourcc == V4L2_PIX_FMT_SBGGR8 || fourcc == V4L2_PIX_FMT_SGBRG8 ||
         fourcc == V4L2_PIX_FMT_SGRBG8 || fourcc == V4L2_PIX_FMT_SRGGB8;
}

int BytesPerPixel(uint32_t fourcc) {
  if (fourcc == V4L2_PIX_FMT_YUYV) return 2;
  if (fourcc == V4L2_PIX_FMT_GREY || IsBayer(fourcc)) return 1;
  return 0;
}

void YuyvToRgb(const uint8_t* data, int width, int height, size_t bytes_per_line,
               const YcbcrParams& p, Image* out) {
  *out = Image(width, height, 3, PixelUnits::kDigital);
  for (int y = 0; y < height; ++y) {
    const uint8_t* row = data + y * bytes_per_line;
    for (int x = 0; x + 1 < width; x += 2) {
      const uint8_t* q = row + 2 * x;
      YcbcrToRgb(q[0], q[1], q[3], p, &out->at(x, y, 0));
      YcbcrToRgb(q[2], q[1], q[3], p, &out->at(x + 1, y, 0));
    }
  }
}

void GreyToRgb(const uint8_t* data, int width, int height, size_t bytes_per_line, Image* out) {
  *out = Image(width, height, 3, PixelUnits::kDigital);
  for (int y = 0; y < height; ++y) {
    const uint8_t* row = data + y * bytes_per_line;
    for (int x = 0; x < width; ++x) {
      for (int c = 0; c < 3; ++c) out->at(x, y, c) = row[x];
    }
  }
}

int BayerColour(uint32_t fourcc, int x, int y) {
  // Colours of the 2x2 tile in reading order: (0,0) (1,0) (0,1) (1,1).
  static constexpr int kBggr[4] = {2, 1, 1, 0}, kGbrg[4] = {1, 2, 0, 1}, kGrbg[4] = {1, 0, 2, 1},
                       kRggb[4] = {0, 1, 1, 2};
  const int* t = kRggb;
  if (fourcc == V4L2_PIX_FMT_SBGGR8) t = kBggr;
  if (fourcc == V4L2_PIX_FMT_SGBRG8) t = kGbrg;
  if (fourcc == V4L2_PIX_FMT_SGRBG8) t = kGrbg;
  return t[(y & 1) * 2 + (x & 1)];
}

void BayerToRgb(const uint8_t* data, int width, int height, size_t bytes_per_line, uint32_t fourcc,
                Image* out) {
  *out = Image(width, height, 3, PixelUnits::kDigital);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      float sum[3] = {0, 0, 0};
      int n[3] = {0, 0, 0};
      const int own = BayerColour(fourcc, x, y);
      for (int dy = -1; dy <= 1; ++dy) {
        const int yy = y + dy;
        if (yy < 0 || yy >= height) continue;
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx;
          if (xx < 0 || xx >= width) continue;
          const int c = BayerColour(fourcc, xx, yy);
          if (c == own) continue;
          sum[c] += data[yy * bytes_per_line + xx];
          ++n[c];
        }
      }
      for (int c = 0; c < 3; ++c) {
        out->at(x, y, c) = c == own ? static_cast<float>(data[y * bytes_per_line + x])
                                    : (n[c] > 0 ? sum[c] / n[c] : 0.f);
      }
    }
  }
}

}  // namespace rouen::v4l2_internal
