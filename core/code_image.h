// A frame as the camera's 8-bit codes: what an 8-bit PNG or JPEG frame holds, in a quarter of
// the memory of the same frame as a float Image (core/image.h). The HDR merge and the response
// recovery read such frames several times faster.
#pragma once

#include <cstdint>
#include <vector>

#include "core/image.h"

namespace rouen {

// Digital numbers 0..255, interleaved channels, row 0 at the top.
struct CodeImage {
  int width = 0, height = 0, channels = 3;
  std::vector<uint8_t> data;
};

// The codes of a kDigital image whose values are whole numbers 0..255. Throws rouen::Error for
// another unit, a buffer that does not match the size, or a value that is not such a number
// (16-bit frames have fractional values: keep those as Image), naming the pixel.
CodeImage ToCodes(const Image& frame);

}  // namespace rouen
