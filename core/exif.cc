#include "core/exif.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

#include "core/error.h"
#include "core/files.h"
#include "core/internal/image_input.h"

namespace rouen {
namespace {

const OIIO::ParamValue* Find(const OIIO::ImageSpec& spec, const char* name) {
  return spec.find_attribute(name);  // case-insensitive: "Exif:" and XMP's "exif:" alike
}

// A positive finite number from a numeric (int, float, rational) or numeric-string attribute.
std::optional<double> PositiveNumber(const OIIO::ImageSpec& spec, const char* name) {
  const OIIO::ParamValue* p = Find(spec, name);
  if (!p) return std::nullopt;
  double v = std::nan("");
  const OIIO::TypeDesc t = p->type();
  if (t == OIIO::TypeRational) {
    const int* r = static_cast<const int*>(p->data());
    if (r[1] != 0) v = static_cast<double>(r[0]) / r[1];
  } else if (t.basetype == OIIO::TypeDesc::STRING) {
    const std::string s = p->get_string();
    try {
      size_t used = 0;
      v = std::stod(s, &used);
      if (used < s.size() && s[used] == '/') {
        const double den = std::stod(s.substr(used + 1));
        v = den != 0 ? v / den : std::nan("");
      }
    } catch (const std::exception&) {
      v = std::nan("");
    }
  } else if (t.basetype == OIIO::TypeDesc::FLOAT) {
    // A float attribute: take its shortest decimal form (2.7, not 2.700000047683716).
    const float f = p->get_float(std::nanf(""));
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.7g", f);
    v = std::strtod(buf, nullptr);
  } else {
    v = p->get_float(std::nanf(""));
  }
  if (!std::isfinite(v) || !(v > 0)) return std::nullopt;
  return v;
}

// EXIF stores exposure times as rationals, usually 1/n; OIIO hands them over as floats.
// Restores 1/n when the float is within float precision of it (1/30 s, not 0.033333335).
double SnapExposure(double t) {
  if (t >= 1) return t;
  const double n = std::round(1.0 / t);
  return std::abs(1.0 / t - n) <= 1e-6 * n ? 1.0 / n : t;
}

std::optional<std::string> NonEmptyString(const OIIO::ImageSpec& spec, const char* name) {
  const OIIO::ParamValue* p = Find(spec, name);
  if (!p || p->type().basetype != OIIO::TypeDesc::STRING) return std::nullopt;
  std::string s = p->get_string();
  while (!s.empty() && (std::isspace(static_cast<unsigned char>(s.back())) || s.back() == '\0'))
    s.pop_back();
  size_t b = 0;
  while (b < s.size() && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  s = s.substr(b);
  if (s.empty()) return std::nullopt;
  return s;
}

// "YYYY:MM:DD HH:MM:SS" (EXIF) or "YYYY-MM-DDTHH:MM:SS..." (XMP) -> ISO form with 'T'.
std::string NormaliseDateTime(std::string s) {
  if (s.size() >= 19 && s[4] == ':' && s[7] == ':') {
    s[4] = '-';
    s[7] = '-';
  }
  if (s.size() >= 11 && s[10] == ' ') s[10] = 'T';
  return s;
}

// Whether text after "YYYY-MM-DDTHH:MM:SS[.fff]" carries an offset.
bool TextHasOffset(const std::string& iso) {
  if (iso.size() <= 19) return false;
  size_t i = 19;
  if (iso[i] == '.' || iso[i] == ',') {
    ++i;
    while (i < iso.size() && std::isdigit(static_cast<unsigned char>(iso[i]))) ++i;
  }
  return i < iso.size() && (iso[i] == 'Z' || iso[i] == 'z' || iso[i] == '+' || iso[i] == '-');
}

}  // namespace

bool IsRawFileName(const std::string& path) {
  static const char* kExt[] = {".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw",
                               ".srf", ".sr2", ".raf", ".orf", ".rw2", ".rwl", ".pef",
                               ".ptx", ".srw", ".raw", ".3fr", ".erf", ".kdc", ".dcr",
                               ".mrw", ".mos", ".mef", ".iiq", ".x3f"};
  const std::string ext = LowerExtension(path);
  return std::find(std::begin(kExt), std::end(kExt), ext) != std::end(kExt);
}

namespace {

// The `n` numbers of a numeric attribute (float, double, int or rational values), or none
// when it is absent, not numeric or of another length.
std::optional<std::vector<double>> Numbers(const OIIO::ImageSpec& spec, const char* name, int n) {
  const OIIO::ParamValue* p = Find(spec, name);
  if (!p) return std::nullopt;
  const OIIO::TypeDesc t = p->type();
  std::vector<double> out;
  if (t.vecsemantics == OIIO::TypeDesc::RATIONAL) {
    if (p->nvalues() * static_cast<int>(t.numelements()) != n) return std::nullopt;
    const auto* r = static_cast<const int32_t*>(p->data());
    for (int i = 0; i < n; ++i)
      out.push_back(r[2 * i + 1] != 0 ? static_cast<double>(r[2 * i]) / r[2 * i + 1]
                                      : std::nan(""));
  } else if (t.basetype >= OIIO::TypeDesc::UINT8 && t.basetype <= OIIO::TypeDesc::DOUBLE) {
    // Any integer or floating type (EXIF's BYTE, SHORT, LONG; OIIO's float for RATIONAL).
    // Integers by get_int: get_float would scale a BYTE to [0, 1].
    const bool integer = t.basetype < OIIO::TypeDesc::HALF;
    const int values = p->nvalues() * static_cast<int>(t.numelements()) * t.aggregate;
    if (values != n) return std::nullopt;
    for (int i = 0; i < n; ++i)
      out.push_back(integer ? p->get_int_indexed(i) : p->get_float_indexed(i, std::nanf("")));
  } else {
    return std::nullopt;
  }
  return out;
}

// EXIF's GPS position: degrees, minutes and seconds with a hemisphere letter per axis.
void ReadGps(const OIIO::ImageSpec& spec, PhotoMetadata* m) {
  const auto lat = Numbers(spec, "GPS:Latitude", 3), lon = Numbers(spec, "GPS:Longitude", 3);
  const auto lat_ref = NonEmptyString(spec, "GPS:LatitudeRef");
  const auto lon_ref = NonEmptyString(spec, "GPS:LongitudeRef");
  if (!lat && !lon) return;
  if (!lat || !lon || !lat_ref || !lon_ref) {
    m->gps_problem = "GPS:Latitude, GPS:Longitude or their N/S, E/W references missing";
    return;
  }
  const auto angle = [&](const std::vector<double>& dms, const char* axis,
                         double limit) -> std::optional<double> {
    const bool ok = std::isfinite(dms[0]) && std::isfinite(dms[1]) && std::isfinite(dms[2]) &&
                    dms[0] >= 0 && dms[1] >= 0 && dms[1] < 60 && dms[2] >= 0 && dms[2] < 60;
    const double deg = dms[0] + dms[1] / 60 + dms[2] / 3600;
    if (!ok || deg > limit) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "GPS:%s %g, %g, %g is not degrees, minutes, seconds", axis,
                    dms[0], dms[1], dms[2]);
      m->gps_problem = buf;
      return std::nullopt;
    }
    return deg;
  };
  const auto la = angle(*lat, "Latitude", 90), lo = angle(*lon, "Longitude", 180);
  if (!la || !lo) return;
  if (*lat_ref != "N" && *lat_ref != "S") {
    m->gps_problem = "GPS:LatitudeRef \"" + *lat_ref + "\" is not N or S";
    return;
  }
  if (*lon_ref != "E" && *lon_ref != "W") {
    m->gps_problem = "GPS:LongitudeRef \"" + *lon_ref + "\" is not E or W";
    return;
  }
  GpsPosition g;
  g.lat_deg = *lat_ref == "S" ? -*la : *la;
  g.lon_deg = *lon_ref == "W" ? -*lo : *lo;
  if (const auto alt = Numbers(spec, "GPS:Altitude", 1); alt && std::isfinite((*alt)[0])) {
    const auto below = Numbers(spec, "GPS:AltitudeRef", 1);
    g.altitude_m = below && (*below)[0] == 1 ? -(*alt)[0] : (*alt)[0];
  }
  m->gps = g;
}

}  // namespace

PhotoMetadata ReadPhotoMetadata(const std::string& path) {
  auto in = internal::OpenImageFile(path, "image");
  const OIIO::ImageSpec spec = in->spec();
  PhotoMetadata m;
  m.width = spec.width;
  m.height = spec.height;
  m.channels = spec.nchannels;
  m.bits = static_cast<int>(spec.format.size() * 8);
  const auto base = static_cast<OIIO::TypeDesc::BASETYPE>(spec.format.basetype);
  m.is_float = base == OIIO::TypeDesc::HALF || base == OIIO::TypeDesc::FLOAT ||
               base == OIIO::TypeDesc::DOUBLE;
  m.is_raw = std::string(in->format_name()) == "raw";
  in->close();

  m.exposure_s = PositiveNumber(spec, "ExposureTime");
  if (!m.exposure_s) m.exposure_s = PositiveNumber(spec, "Exif:ExposureTime");
  if (m.exposure_s) m.exposure_s = SnapExposure(*m.exposure_s);
  m.f_number = PositiveNumber(spec, "FNumber");
  if (!m.f_number) m.f_number = PositiveNumber(spec, "Exif:FNumber");
  for (const char* name : {"Exif:PhotographicSensitivity", "Exif:ISOSpeedRatings", "Exif:ISOSpeed",
                           "ISOSpeedRatings"}) {
    if (!m.iso) m.iso = PositiveNumber(spec, name);
  }
  // EXIF DateTime (0x0132) and PNG's tIME are when the file was last changed, not taken;
  // only libraw reports the capture time under "DateTime".
  for (const char* name : {"Exif:DateTimeOriginal", "Exif:DateTimeDigitized", "DateTime"}) {
    if (m.datetime) break;
    if (std::string(name) == "DateTime" && !m.is_raw) break;
    m.datetime = NonEmptyString(spec, name);
    // "0000:00:00 00:00:00" means unknown in EXIF; libraw reports an unknown time as the
    // Unix epoch.
    if (m.datetime &&
        (m.datetime->rfind("0000", 0) == 0 ||
         (m.is_raw && m.datetime->rfind("1970", 0) == 0 && m.datetime->find("00:00:00") == 11)))
      m.datetime.reset();
    if (m.datetime) m.datetime_source = name;
  }
  m.subsec = NonEmptyString(spec, "Exif:SubsecTimeOriginal");
  if (m.subsec && !std::all_of(m.subsec->begin(), m.subsec->end(),
                               [](unsigned char c) { return std::isdigit(c); }))
    m.subsec.reset();
  m.offset = NonEmptyString(spec, "Exif:OffsetTimeOriginal");
  if (!m.offset) m.offset = NonEmptyString(spec, "Exif:OffsetTime");
  m.make = NonEmptyString(spec, "Make");
  m.model = NonEmptyString(spec, "Model");
  ReadGps(spec, &m);
  return m;
}

int ParseUtcOffsetMinutes(std::string_view text) {
  const std::string t(text);
  auto fail = [&] {
    throw Error("UTC offset \"" + t + "\" is not of the form +HH:MM, -HH:MM or Z");
  };
  if (t == "Z" || t == "z") return 0;
  if (t.size() < 3 || (t[0] != '+' && t[0] != '-')) fail();
  const int sign = t[0] == '-' ? -1 : 1;
  std::string digits;
  for (size_t i = 1; i < t.size(); ++i) {
    if (t[i] == ':' && i == 3) continue;
    if (!std::isdigit(static_cast<unsigned char>(t[i]))) fail();
    digits += t[i];
  }
  if (digits.size() != 2 && digits.size() != 4) fail();
  const int hh = std::stoi(digits.substr(0, 2));
  const int mm = digits.size() == 4 ? std::stoi(digits.substr(2, 2)) : 0;
  if (hh > 14 || mm > 59) fail();
  return sign * (hh * 60 + mm);
}

bool HasOwnOffset(const PhotoMetadata& m) {
  if (!m.datetime) return false;
  return TextHasOffset(NormaliseDateTime(*m.datetime)) || m.offset.has_value();
}

std::optional<UtcTime> CaptureUtc(const PhotoMetadata& m, std::optional<int> fallback_offset_min) {
  if (!m.datetime) return std::nullopt;
  std::string iso = NormaliseDateTime(*m.datetime);
  if (TextHasOffset(iso)) return ParseIso8601(iso);
  // Sub-seconds from SubSecTimeOriginal when the stored time has none.
  if (m.subsec && iso.size() == 19) {
    iso.push_back('.');
    iso.append(m.subsec->substr(0, 9));
  }
  int offset_min = 0;
  if (m.offset) {
    offset_min = ParseUtcOffsetMinutes(*m.offset);
  } else if (fallback_offset_min) {
    offset_min = *fallback_offset_min;
  } else {
    return std::nullopt;
  }
  // Read the civil time as if it were UTC, then remove the offset.
  const UtcTime as_utc = ParseIso8601(iso + "Z");
  return as_utc.PlusSeconds(-60.0 * offset_min);
}

Image ReadRawLinear(const std::string& path) {
  OIIO::ImageSpec config;
  config.attribute("raw:ColorSpace", "linear");  // sRGB primaries, linear transfer
  config.attribute("raw:use_camera_wb", 1);
  config.attribute("raw:auto_bright", 0);    // no automatic brightening
  config.attribute("raw:HighlightMode", 0);  // clip
  auto in = internal::OpenImageFile(path, "RAW image", &config);
  const OIIO::ImageSpec spec = in->spec();
  const int w = spec.width, h = spec.height, nch = spec.nchannels;
  if (w <= 0 || h <= 0 || nch <= 0) throw Error(path + ": RAW image has no pixels");
  if (spec.depth > 1) throw Error(path + ": RAW image is a volume");
  // Before any pixel memory: the header may claim far more than the file holds.
  CheckImageSize(path, w, h, nch);
  const int out_ch = nch >= 3 ? 3 : nch;
  Image img;
  img.width = w;
  img.height = h;
  img.channels = out_ch;
  img.units = PixelUnits::kRadiance;
  const size_t total = static_cast<size_t>(w) * h * out_ch;
  // Integer data come through OIIO's 0..1 normalisation: the white level maps to 1.
  const bool ok =
      internal::ReadRowBands(*in, OIIO::TypeDesc::FLOAT, [&](int y0, int rows, const void* data) {
        const float* raw = static_cast<const float*>(data);
        const size_t first = static_cast<size_t>(y0) * w, count = static_cast<size_t>(rows) * w;
        internal::GrowTo(&img.data, (first + count) * out_ch, total);
        for (size_t i = 0; i < count; ++i) {
          for (int c = 0; c < out_ch; ++c) {
            const float v = raw[i * nch + c];
            if (!std::isfinite(v)) throw Error(path + ": RAW pixel value is not finite");
            img.data[(first + i) * out_ch + c] = std::max(v, 0.f);
          }
        }
      });
  if (!ok) {
    std::string msg = in->geterror();
    throw Error(path + ": cannot read RAW pixels: " + (msg.empty() ? "read failed" : msg));
  }
  in->close();
  return img;
}

}  // namespace rouen
