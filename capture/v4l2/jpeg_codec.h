// Internal to rouen_v4l2: JPEG (MJPEG frame) decoding for the driver and encoding for the
// fake device, through libjpeg-turbo (Debian libjpeg62-turbo-dev). Built without it,
// JpegAvailable() is false and both calls fail.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace rouen::v4l2_internal {

bool JpegAvailable();

// Decodes a baseline JPEG (Huffman tables may be missing, as in UVC MJPEG: the standard
// tables are used) to a 3-channel kDigital image. On failure (corrupt data, truncated or
// damaged entropy-coded data, or a size other than `width` x `height`) returns false with
// `error` set. Extraneous bytes between markers are tolerated.
bool DecodeJpeg(const uint8_t* data, size_t size, int width, int height, Image* out,
                std::string* error);

// Encodes 8-bit interleaved RGB as YCbCr 4:2:2 (like UVC cameras). `omit_huffman_tables`
// leaves out the DHT segment as UVC MJPEG does.
std::vector<uint8_t> EncodeJpeg(const uint8_t* rgb, int width, int height, int quality,
                                bool omit_huffman_tables);

}  // namespace rouen::v4l2_internal
