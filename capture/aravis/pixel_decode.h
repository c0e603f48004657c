// Decoding of the camera pixel formats the Aravis driver accepts into rouen images
// (3 channels, PixelUnits::kDigital on a 0..255 scale). Independent of Aravis.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"

namespace rouen {

enum class RawFormat { kMono8, kMono16, kBayerRG8, kBayerGR8, kBayerGB8, kBayerBG8, kRGB8, kBGR8 };

// GenICam PixelFormat names ("Mono8", "BayerRG8", ...); nothing for formats not decoded here.
std::optional<RawFormat> RawFormatFromName(const std::string& name);
std::string RawFormatName(RawFormat format);
std::vector<std::string> DecodableFormatNames();
int BytesPerPixel(RawFormat format);  // 1, 2 or 3

// Decodes a tightly packed frame (no line padding; Mono16 little-endian as GigE Vision and
// USB3 Vision send it). Mono is replicated to the 3 channels; Mono16 is scaled by 1/257 (so
// 65535 -> 255); Bayer mosaics are demosaiced bilinearly: each missing colour is the mean of
// the pixels of that colour in the 3x3 neighbourhood (inside the image). 8-bit formats give
// integer values. Throws rouen::Error when `size` is smaller than width x height x bytes.
Image DecodeFrame(const uint8_t* data, size_t size, int width, int height, RawFormat format);

// Colour (0 = R, 1 = G, 2 = B) of the Bayer cell at (x, y) for a Bayer format.
int BayerColour(RawFormat format, int x, int y);

}  // namespace rouen
