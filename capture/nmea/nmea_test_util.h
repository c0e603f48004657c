// Test helper: NMEA sentences with their checksum computed here, independently of the
// decoder's NmeaChecksum, so a checksum bug cannot hide behind itself.
#pragma once

#include <cstdio>
#include <string>

namespace rouen {

// "$" + body + "*HH\r\n".
inline std::string NmeaSentence(const std::string& body) {
  unsigned x = 0;
  for (unsigned char c : body) x ^= c;
  char sum[8];
  std::snprintf(sum, sizeof(sum), "*%02X", x & 0xFF);
  return "$" + body + sum + "\r\n";
}

}  // namespace rouen
