#include "core/code_image.h"

#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {

CodeImage ToCodes(const Image& frame) {
  if (frame.units != PixelUnits::kDigital) {
    throw Error("ToCodes: the image is not in digital numbers (kDigital)");
  }
  if (frame.data.size() != static_cast<size_t>(frame.width) * frame.height * frame.channels) {
    throw Error("ToCodes: pixel buffer size does not match the image's dimensions");
  }
  CodeImage codes;
  codes.width = frame.width;
  codes.height = frame.height;
  codes.channels = frame.channels;
  codes.data.resize(frame.data.size());
  for (size_t i = 0; i < frame.data.size(); ++i) {
    const float v = frame.data[i];
    if (!(v >= 0.f && v <= 255.f && v == std::floor(v))) {
      const size_t p = i / frame.channels;
      throw Error("ToCodes: pixel (" + std::to_string(p % frame.width) + ", " +
                  std::to_string(p / frame.width) + ") channel " +
                  std::to_string(i % frame.channels) + " holds " + std::to_string(v) +
                  ", not a whole number 0..255");
    }
    codes.data[i] = static_cast<uint8_t>(v);
  }
  return codes;
}

}  // namespace rouen
