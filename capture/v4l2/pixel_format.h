// Internal to rouen_v4l2: fourcc names and the conversions of V4L2 pixel formats to the
// 3-channel kDigital images the driver returns (values on the 0..255 scale, not rounded).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "core/image.h"

namespace rouen::v4l2_internal {

// "YUYV" <-> V4L2_PIX_FMT_YUYV. FourccFromString returns 0 unless the name has 1..4
// printable characters (shorter names are padded with spaces, as V4L2 does).
std::string FourccToString(uint32_t fourcc);
uint32_t FourccFromString(const std::string& name);

// The Y'CbCr -> R'G'B' decoding of a YUV format. Limited range: Y' 16..235, Cb/Cr 16..240
// around 128; full range: all three 0..255 (Cb/Cr around 128).
struct YcbcrParams {
  double kr = 0.299, kb = 0.114;  // BT.601; BT.709 is kr 0.2126, kb 0.0722
  bool full_range = false;
};
// From the fields of a v4l2_pix_format (colorspace, ycbcr_enc, quantization), resolving the
// V4L2 defaults (V4L2_MAP_*_DEFAULT): BT.709 only when asked or for Rec.709/DCI colorspaces.
YcbcrParams YcbcrFromFormat(uint32_t colorspace, uint32_t ycbcr_enc, uint32_t quantization);
// One Y'CbCr triple (8-bit code values) to R'G'B' on 0..255, clamped.
void YcbcrToRgb(double y, double cb, double cr, const YcbcrParams& p, float rgb[3]);

// The formats the driver can decode, and the preference order for "best available":
// raw Bayer first (no processing by the camera), then YUYV, GREY, MJPEG. -1: unsupported.
int FormatPreference(uint32_t fourcc);
bool IsBayer(uint32_t fourcc);
// Bytes per pixel row of the uncompressed formats (0 for MJPEG).
int BytesPerPixel(uint32_t fourcc);

// YUYV 4:2:2 (Y0 Cb Y1 Cr per pixel pair). Width must be even.
void YuyvToRgb(const uint8_t* data, int width, int height, size_t bytes_per_line,
               const YcbcrParams& p, Image* out);
// 8-bit grey replicated to the three channels.
void GreyToRgb(const uint8_t* data, int width, int height, size_t bytes_per_line, Image* out);
// 8-bit Bayer (SBGGR8, SGBRG8, SGRBG8, SRGGB8), bilinear: each missing colour is the mean of
// the pixels of that colour in the 3x3 neighbourhood (clipped at the image border).
void BayerToRgb(const uint8_t* data, int width, int height, size_t bytes_per_line, uint32_t fourcc,
                Image* out);
// The CFA colour (0 R, 1 G, 2 B) at pixel (x, y) of a Bayer format.
int BayerColour(uint32_t fourcc, int x, int y);

}  // namespace rouen::v4l2_internal
