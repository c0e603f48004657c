// Internal to rouen_libcamera: converts a mapped libcamera frame into a 3-channel rouen Image
// of digital numbers on the 0..255 scale (PixelUnits::kDigital). Pure: works on plain bytes,
// so tests build synthetic frames.
//
// Supported (libcamera / DRM fourcc names; DRM names give the little-endian word order, so
// RGB888 is stored B,G,R in memory and BGR888 is R,G,B):
//   RGB888, BGR888, XRGB8888, XBGR8888, YUYV, UYVY, NV12, NV21, YUV420,
//   raw Bayer RGGB/GRBG/GBRG/BGGR at 8 bits, 10/12/16 bits unpacked (little-endian 16-bit
//   words) and 10/12 bits MIPI CSI-2 packed.
// Raw Bayer is scaled linearly to 0..255 (v * 255 / (2^bits - 1)) and demosaiced by giving
// every pixel the colours of the 2x2 Bayer cell it lies in (two greens averaged): linear, no
// interpolation across edges, full resolution.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace rouen::libcamera_internal {

enum class YcbcrMatrix { kRec601, kRec709, kRec2020 };

// A libcamera pixel format as plain numbers: the DRM fourcc and modifier (the MIPI CSI-2
// packed raw formats share the fourcc of the unpacked ones and differ by the modifier).
struct PixelCode {
  uint32_t fourcc = 0;
  uint64_t modifier = 0;
  friend bool operator==(const PixelCode&, const PixelCode&) = default;
};

struct FrameLayout {
  PixelCode format;
  int width = 0, height = 0;
  int stride = 0;  // bytes per row of the first plane (StreamConfiguration::stride)
  YcbcrMatrix matrix = YcbcrMatrix::kRec601;
  bool full_range = false;  // YCbCr: full (0..255) or limited (16..235 / 16..240) range
};

struct PlaneBytes {
  const uint8_t* data = nullptr;
  size_t size = 0;
};

bool IsSupportedFormat(PixelCode format);
// libcamera's name for a supported format ("NV12", "SRGGB10_CSI2P"); for others the four
// fourcc characters, with the modifier in hex when there is one.
std::string FormatName(PixelCode format);
// The supported formats' libcamera names, for error messages and `rouen devices`.
std::vector<std::string> SupportedFormatNames();

// Picks the format to ask for: `wanted` when given (fourcc 0 = no wish; validate() may adjust
// it),
// else the stream's default when supported, else the first supported offer by preference
// (RGB888, BGR888, XRGB8888, XBGR8888, YUYV, UYVY, NV12, NV21, YUV420, then raw Bayer with
// the most bits). Returns fourcc 0 when nothing offered is supported.
PixelCode ChooseFormat(PixelCode wanted, PixelCode stream_default,
                       const std::vector<PixelCode>& offered);

// Converts one frame. `planes` are the frame buffer's planes in order; formats with several
// planes may also arrive as one contiguous plane. Throws rouen::Error (naming the format)
// when the format is unsupported or the planes are too small for the layout.
Image ConvertFrame(const FrameLayout& layout, const std::vector<PlaneBytes>& planes);

}  // namespace rouen::libcamera_internal
