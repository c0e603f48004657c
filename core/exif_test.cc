#include "core/exif.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "core/image.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

fs::path TempDir(const std::string& name) {
  fs::path p =
      fs::temp_directory_path() / ("rouen_exif_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

// Writes a small 8-bit image with the given attributes through OpenImageIO.
void WriteWithAttributes(const fs::path& path, const OIIO::ImageSpec& attrs) {
  OIIO::ImageSpec spec = attrs;
  spec.width = spec.full_width = 16;
  spec.height = spec.full_height = 8;
  spec.nchannels = 3;
  spec.set_format(OIIO::TypeDesc::UINT8);
  spec.default_channel_names();
  std::vector<unsigned char> pixels(16 * 8 * 3, 100);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out) << OIIO::geterror();
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data())) << out->geterror();
  ASSERT_TRUE(out->close());
}

// GPS as a phone writes it in a JPEG: degrees, minutes, seconds and a hemisphere per axis,
// altitude with its above/below flag. South and west are negative; a bad reference or minutes
// beyond 60 leave no position and say why; a photo without GPS has neither.
TEST(ExifTest, GpsPositionFromItsDegreesMinutesSecondsAndHemispheres) {
  const fs::path dir = TempDir("gps");
  const auto write = [&](const std::string& name, const char* lat_ref, float lat_min,
                         const char* lon_ref, int altitude_ref) {
    OIIO::ImageSpec a;
    const float lat[3] = {33, lat_min, 51.5f}, lon[3] = {151, 12, 36};
    a.attribute("GPS:Latitude", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 3), lat);
    a.attribute("GPS:LatitudeRef", lat_ref);
    a.attribute("GPS:Longitude", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 3), lon);
    a.attribute("GPS:LongitudeRef", lon_ref);
    a.attribute("GPS:Altitude", 12.5f);
    a.attribute("GPS:AltitudeRef", altitude_ref);
    WriteWithAttributes(dir / name, a);
    return (dir / name).string();
  };
  const PhotoMetadata sydney = ReadPhotoMetadata(write("s.jpg", "S", 51, "E", 1));
  ASSERT_TRUE(sydney.gps) << sydney.gps_problem;
  // float32 seconds: 1e-6 deg is 0.1 m.
  EXPECT_NEAR(sydney.gps->lat_deg, -(33 + 51 / 60.0 + 51.5 / 3600), 1e-6);
  EXPECT_NEAR(sydney.gps->lon_deg, 151 + 12 / 60.0 + 36 / 3600.0, 1e-6);
  ASSERT_TRUE(sydney.gps->altitude_m);
  EXPECT_NEAR(*sydney.gps->altitude_m, -12.5, 1e-6);  // below sea level
  const PhotoMetadata north = ReadPhotoMetadata(write("n.jpg", "N", 51, "W", 0));
  ASSERT_TRUE(north.gps) << north.gps_problem;
  EXPECT_GT(north.gps->lat_deg, 33);
  EXPECT_LT(north.gps->lon_deg, -151);
  EXPECT_NEAR(*north.gps->altitude_m, 12.5, 1e-6);

  const PhotoMetadata bad_ref = ReadPhotoMetadata(write("r.jpg", "X", 51, "E", 0));
  EXPECT_FALSE(bad_ref.gps);
  EXPECT_EQ(bad_ref.gps_problem, "GPS:LatitudeRef \"X\" is not N or S");
  const PhotoMetadata bad_minutes = ReadPhotoMetadata(write("m.jpg", "N", 75, "E", 0));
  EXPECT_FALSE(bad_minutes.gps);
  EXPECT_NE(bad_minutes.gps_problem.find("GPS:Latitude 33, 75, 51.5"), std::string::npos)
      << bad_minutes.gps_problem;

  OIIO::ImageSpec none;
  none.attribute("Make", "Acme");
  WriteWithAttributes(dir / "none.jpg", none);
  const PhotoMetadata without = ReadPhotoMetadata((dir / "none.jpg").string());
  EXPECT_FALSE(without.gps);
  EXPECT_TRUE(without.gps_problem.empty());
  fs::remove_all(dir);
}

TEST(ExifTest, ReadsAttributesWrittenToJpeg) {
  const fs::path dir = TempDir("jpeg");
  OIIO::ImageSpec a;
  a.attribute("ExposureTime", 1.0f / 250);
  a.attribute("FNumber", 5.6f);
  a.attribute("Exif:PhotographicSensitivity", 400);
  a.attribute("Exif:DateTimeOriginal", "2024:06:21 14:30:05");
  a.attribute("Exif:OffsetTimeOriginal", "+02:00");
  a.attribute("Make", "Acme");
  a.attribute("Model", "Box 1");
  const fs::path path = dir / "a.jpg";
  WriteWithAttributes(path, a);

  const PhotoMetadata m = ReadPhotoMetadata(path.string());
  ASSERT_TRUE(m.exposure_s);
  // EXIF stores a rational; 1/n times and short decimals come back exactly.
  EXPECT_EQ(*m.exposure_s, 1.0 / 250);
  ASSERT_TRUE(m.f_number);
  EXPECT_EQ(*m.f_number, 5.6);
  ASSERT_TRUE(m.iso);
  EXPECT_EQ(*m.iso, 400);
  ASSERT_TRUE(m.datetime);
  EXPECT_EQ(*m.datetime, "2024:06:21 14:30:05");
  ASSERT_TRUE(m.offset);
  EXPECT_EQ(*m.offset, "+02:00");
  ASSERT_TRUE(m.make);
  EXPECT_EQ(*m.make, "Acme");
  ASSERT_TRUE(m.model);
  EXPECT_EQ(*m.model, "Box 1");
  EXPECT_EQ(m.width, 16);
  EXPECT_EQ(m.height, 8);
  EXPECT_EQ(m.bits, 8);
  EXPECT_FALSE(m.is_float);
  EXPECT_FALSE(m.is_raw);

  // 14:30:05 at +02:00 is 12:30:05Z; the photo's own offset wins over a fallback.
  EXPECT_TRUE(HasOwnOffset(m));
  const auto utc = CaptureUtc(m, -300);
  ASSERT_TRUE(utc);
  EXPECT_EQ(*utc, ParseIso8601("2024-06-21T12:30:05Z"));
  fs::remove_all(dir);
}

TEST(ExifTest, MissingExifGivesEmptyOptionals) {
  const fs::path dir = TempDir("none");
  Image im(8, 4, 3, PixelUnits::kDigital, 10.f);
  const fs::path path = dir / "plain.png";
  WriteImage(path.string(), im, StoredType::kUint8);
  const PhotoMetadata m = ReadPhotoMetadata(path.string());
  EXPECT_FALSE(m.exposure_s);
  EXPECT_FALSE(m.f_number);
  EXPECT_FALSE(m.iso);
  EXPECT_FALSE(m.datetime);
  EXPECT_FALSE(m.offset);
  EXPECT_FALSE(m.make);
  EXPECT_FALSE(m.model);
  EXPECT_FALSE(HasOwnOffset(m));
  EXPECT_FALSE(CaptureUtc(m, 60));
  EXPECT_EQ(m.width, 8);
  EXPECT_EQ(m.height, 4);

  // Zero or negative exposure values are treated as absent, not passed on.
  OIIO::ImageSpec a;
  a.attribute("ExposureTime", 0.0f);
  a.attribute("FNumber", -2.0f);
  const fs::path zero = dir / "zero.jpg";
  WriteWithAttributes(zero, a);
  const PhotoMetadata z = ReadPhotoMetadata(zero.string());
  EXPECT_FALSE(z.exposure_s);
  EXPECT_FALSE(z.f_number);
  fs::remove_all(dir);
}

TEST(ExifTest, TimeWithoutOffsetNeedsFallback) {
  PhotoMetadata m;
  m.datetime = "2008:05:31 22:44:54";
  EXPECT_FALSE(HasOwnOffset(m));
  EXPECT_FALSE(CaptureUtc(m, std::nullopt));
  // 22:44:54 at -05:00 is 03:44:54Z the next day.
  const auto utc = CaptureUtc(m, -300);
  ASSERT_TRUE(utc);
  EXPECT_EQ(*utc, ParseIso8601("2008-06-01T03:44:54Z"));
  // Sub-seconds are appended when the stored time has none.
  m.subsec = "25";
  EXPECT_EQ(*CaptureUtc(m, 0), ParseIso8601("2008-05-31T22:44:54.25Z"));
  // An XMP-style ISO time carries its own offset.
  PhotoMetadata x;
  x.datetime = "2008-05-31T22:44:54-05:00";
  EXPECT_TRUE(HasOwnOffset(x));
  EXPECT_EQ(*CaptureUtc(x, std::nullopt), ParseIso8601("2008-06-01T03:44:54Z"));
  PhotoMetadata bad;
  bad.datetime = "2008:13:31 22:44:54";
  EXPECT_THROW(CaptureUtc(bad, 0), Error);
}

TEST(ExifTest, ParsesUtcOffsets) {
  EXPECT_EQ(ParseUtcOffsetMinutes("+02:00"), 120);
  EXPECT_EQ(ParseUtcOffsetMinutes("-05:30"), -330);
  EXPECT_EQ(ParseUtcOffsetMinutes("+0545"), 345);
  EXPECT_EQ(ParseUtcOffsetMinutes("-08"), -480);
  EXPECT_EQ(ParseUtcOffsetMinutes("Z"), 0);
  for (const char* bad : {"", "02:00", "+2:00", "+25:00", "+02:60", "+02:0x", "-"}) {
    EXPECT_THROW(ParseUtcOffsetMinutes(bad), Error) << bad;
  }
}

TEST(ExifTest, RecognisesRawFileNames) {
  EXPECT_TRUE(IsRawFileName("a/IMG_1.CR2"));
  EXPECT_TRUE(IsRawFileName("x.dng"));
  EXPECT_TRUE(IsRawFileName("x.NEF"));
  EXPECT_TRUE(IsRawFileName("x.arw"));
  EXPECT_FALSE(IsRawFileName("x.jpg"));
  EXPECT_FALSE(IsRawFileName("x.exr"));
  EXPECT_FALSE(IsRawFileName("dir.dng/file"));
  EXPECT_FALSE(IsRawFileName("noext"));
}

TEST(ExifTest, UnreadableFileNamesItself) {
  const fs::path dir = TempDir("bad");
  const fs::path p = dir / "broken.jpg";
  { std::ofstream(p) << "not a jpeg"; }
  try {
    ReadPhotoMetadata(p.string());
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("broken.jpg"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadRawLinear((dir / "missing.dng").string()), Error);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
