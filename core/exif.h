// Photo metadata (EXIF) read through OpenImageIO's ImageSpec attributes, and the linear RAW
// reader (DNG and camera RAW through OpenImageIO's libraw plugin). Every field is optional:
// a value the file does not carry is empty, never NaN or zero.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "core/image.h"
#include "core/time.h"

namespace rouen {

// Where a photo was taken, as its camera's GPS wrote it in EXIF's GPS directory.
struct GpsPosition {
  double lat_deg = 0, lon_deg = 0;   // north- and east-positive degrees
  std::optional<double> altitude_m;  // GPSAltitude, negative below its datum (sea level)
};

struct PhotoMetadata {
  std::optional<double> exposure_s;  // ExposureTime, seconds
  std::optional<double> f_number;    // FNumber
  std::optional<double> iso;         // Exif:PhotographicSensitivity (ISOSpeedRatings)
  // Capture time as written by the camera (DateTimeOriginal, else DateTimeDigitized; for RAW
  // files also libraw's DateTime; never a JPEG/PNG/TIFF file-change DateTime), without
  // interpretation: "YYYY:MM:DD HH:MM:SS" or an ISO 8601 form (XMP).
  std::optional<std::string> datetime;
  std::string datetime_source;             // attribute the time came from
  std::optional<std::string> subsec;       // SubSecTimeOriginal digits, when present
  std::optional<std::string> offset;       // OffsetTimeOriginal ("+HH:MM"), when present
  std::optional<std::string> make, model;  // camera
  int width = 0, height = 0, channels = 0;
  int bits = 0;           // bits per stored sample (8, 16, 32 ...)
  bool is_float = false;  // half/float/double samples (EXR, HDR)
  bool is_raw = false;    // read through the libraw plugin (DNG, camera RAW)
  // GPSLatitude/GPSLongitude with their N/S and E/W references, and GPSAltitude: empty when
  // the photo has none. A GPS position present but unusable (a reference other than N/S or
  // E/W, minutes or seconds out of range, a latitude beyond 90 deg) is left empty and
  // `gps_problem` says why.
  std::optional<GpsPosition> gps;
  std::string gps_problem;
};

// Reads the metadata of an image file (no pixels). Throws rouen::Error naming the file when
// it cannot be opened as an image.
PhotoMetadata ReadPhotoMetadata(const std::string& path);

// True for file names OpenImageIO reads through libraw (.dng .cr2 .cr3 .nef .arw .raf .orf
// .rw2 .pef .srw ...), case-insensitive.
bool IsRawFileName(const std::string& path);

// Parses a UTC offset "+HH:MM", "-HHMM", "+HH" or "Z" into minutes east of UTC; throws
// rouen::Error naming the text.
int ParseUtcOffsetMinutes(std::string_view text);

// The capture instant of a photo: the camera's civil time (with sub-seconds when present)
// interpreted in the offset it carries (an ISO time with an offset, or OffsetTimeOriginal),
// else in `fallback_offset_min`. Empty when the photo has no time, or has one without an
// offset and no fallback is given. Throws rouen::Error (without the file name) when the
// stored time is malformed.
std::optional<UtcTime> CaptureUtc(const PhotoMetadata& m, std::optional<int> fallback_offset_min);
// True when the photo's time carries its own UTC offset.
bool HasOwnOffset(const PhotoMetadata& m);

// Reads a DNG or camera RAW file through libraw as linear data: demosaiced, camera white
// balance, sRGB primaries with a linear transfer ("raw:ColorSpace" = "linear"), black level
// subtracted and the white level mapped to 1.0 by libraw; no response curve applies.
// Returns kRadiance units (relative, not yet divided by exposure). Throws rouen::Error.
Image ReadRawLinear(const std::string& path);

}  // namespace rouen
