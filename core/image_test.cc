#include "core/image.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/exif.h"
#include "core/files.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

class ImageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rouen_core_image_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string P(const std::string& name) const { return (dir_ / name).string(); }
  int CountFiles() const {
    int n = 0;
    for (const auto& e : fs::directory_iterator(dir_)) {
      (void)e;
      ++n;
    }
    return n;
  }
  fs::path dir_;
};

Image Ramp(int w, int h, int c, PixelUnits u, float scale) {
  Image img(w, h, c, u);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int k = 0; k < c; ++k) {
        img.at(x, y, k) = scale * (x + 3 * y + 7 * k) / (w + 3 * h + 7 * c);
      }
    }
  }
  return img;
}

TEST_F(ImageTest, Png8RoundTrip) {
  const Image img = Ramp(17, 9, 3, PixelUnits::kDigital, 255.f);
  WriteImage(P("a.png"), img, StoredType::kUint8);
  EXPECT_EQ(CountFiles(), 1);  // no temporary left behind
  const Image back = ReadImage(P("a.png"));
  EXPECT_EQ(back.width, 17);
  EXPECT_EQ(back.height, 9);
  EXPECT_EQ(back.channels, 3);
  EXPECT_EQ(back.units, PixelUnits::kDigital);
  for (size_t i = 0; i < img.data.size(); ++i) {
    EXPECT_EQ(back.data[i], std::round(img.data[i])) << i;
  }
}

TEST_F(ImageTest, IntegerWritesClampAndRound) {
  Image img(3, 1, 1, PixelUnits::kDigital);
  img.data = {-20.f, 127.4f, 300.f};
  WriteImage(P("c.png"), img, StoredType::kUint8);
  const Image back = ReadImage(P("c.png"));
  EXPECT_EQ(back.channels, 1);  // one channel stays one channel
  EXPECT_EQ(back.data, (std::vector<float>{0.f, 127.f, 255.f}));
}

TEST_F(ImageTest, Png16RoundTripOnTheDigitalScale) {
  const Image img = Ramp(11, 5, 3, PixelUnits::kDigital, 255.f);
  WriteImage(P("b.png"), img, StoredType::kUint16);
  const Image back = ReadImage(P("b.png"));
  EXPECT_EQ(back.units, PixelUnits::kDigital);
  for (size_t i = 0; i < img.data.size(); ++i) {
    EXPECT_NEAR(back.data[i], img.data[i], 0.5 / 257 + 1e-4) << i;  // 16-bit quantisation
  }
}

TEST_F(ImageTest, ExrHalfAndFloat) {
  Image img = Ramp(8, 6, 3, PixelUnits::kRadiance, 1000.f);
  img.at(0, 0, 0) = 1e-3f;
  WriteImage(P("h.exr"), img, StoredType::kHalf);
  const Image half = ReadImage(P("h.exr"));
  EXPECT_EQ(half.units, PixelUnits::kRadiance);
  for (size_t i = 0; i < img.data.size(); ++i) {
    EXPECT_NEAR(half.data[i], img.data[i], std::abs(img.data[i]) * 1.0 / 2048 + 1e-7) << i;
  }
  img.at(1, 1, 1) = 1e6f;  // beyond half
  EXPECT_THROW(WriteImage(P("h2.exr"), img, StoredType::kHalf), Error);
  WriteImage(P("f.exr"), img, StoredType::kFloat);
  EXPECT_EQ(ReadImage(P("f.exr")).data, img.data);
}

TEST_F(ImageTest, RefusesNonFiniteValues) {
  Image img = Ramp(4, 4, 3, PixelUnits::kRadiance, 1.f);
  img.at(2, 3, 1) = NAN;
  try {
    WriteImage(P("n.exr"), img, StoredType::kFloat);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("n.exr"), std::string::npos);
  }
  img.at(2, 3, 1) = INFINITY;
  EXPECT_THROW(WriteImage(P("n.exr"), img, StoredType::kHalf), Error);
  EXPECT_THROW(WriteImage(P("n.png"), img, StoredType::kUint8), Error);
  EXPECT_EQ(CountFiles(), 0);
  EXPECT_THROW(WriteImage(P("e.png"), Image(), StoredType::kUint8), Error);
}

TEST_F(ImageTest, RgbaLosesAlpha) {
  Image img = Ramp(5, 4, 4, PixelUnits::kDigital, 255.f);
  WriteImage(P("rgba.png"), img, StoredType::kUint8);
  const Image back = ReadImage(P("rgba.png"));
  EXPECT_EQ(back.channels, 3);
  for (int y = 0; y < 4; ++y) {
    for (int x = 0; x < 5; ++x) {
      for (int c = 0; c < 3; ++c) EXPECT_EQ(back.at(x, y, c), std::round(img.at(x, y, c)));
    }
  }
}

TEST_F(ImageTest, CorruptFilesGiveErrorsNamingTheFile) {
  const Image img = Ramp(64, 64, 3, PixelUnits::kDigital, 255.f);
  WriteImage(P("full.png"), img, StoredType::kUint8);
  const std::string bytes = ReadFileToString(P("full.png"));
  WriteFileAtomic(P("cut.png"), std::string_view(bytes).substr(0, bytes.size() / 2));
  WriteFileAtomic(P("text.exr"), "this is not an OpenEXR file\n");
  WriteFileAtomic(P("empty.png"), "");
  for (const char* name : {"cut.png", "text.exr", "empty.png", "missing.png"}) {
    try {
      ReadImage(P(name));
      ADD_FAILURE() << name;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

// OpenImageIO hands a file its named reader refuses to every reader it has; rouen opens only
// the formats it reads, each with its own reader: a valid SGI image (which OpenImageIO reads)
// is refused under its own name and under a Targa name, and so is a GIF.
TEST_F(ImageTest, OnlyTheFormatsRouenReadsAreOpened) {
  const Image img = Ramp(8, 8, 3, PixelUnits::kDigital, 255.f);
  std::vector<unsigned char> pixels(img.data.size());
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<unsigned char>(img.data[i]);
  auto out = OIIO::ImageOutput::create("sgi");
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(P("ramp.sgi"), OIIO::ImageSpec(8, 8, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  ASSERT_TRUE(out->close());
  ASSERT_TRUE(OIIO::ImageInput::open(P("ramp.sgi"))) << "OpenImageIO reads the SGI file";
  fs::copy_file(P("ramp.sgi"), P("ramp.tga"));
  WriteFileAtomic(P("tiny.gif"), std::string("GIF89a\x01\x00\x01\x00\x00\x00\x00;", 14));
  for (const char* name : {"ramp.sgi", "ramp.tga", "tiny.gif"}) {
    for (int call = 0; call < 3; ++call) {
      try {
        if (call == 0) ReadImage(P(name));
        if (call == 1) ReadPhotoMetadata(P(name));
        if (call == 2) ReadImageAttributes(P(name));
        ADD_FAILURE() << name << " call " << call;
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
      }
    }
  }
  // The formats it reads still open through their readers.
  WriteImage(P("ramp.png"), img, StoredType::kUint8);
  WriteImage(P("ramp.exr"), img, StoredType::kHalf);
  EXPECT_EQ(ReadImage(P("ramp.png")).width, 8);
  EXPECT_EQ(ReadPhotoMetadata(P("ramp.exr")).width, 8);
}

// A binary PPM header claiming width x height pixels, followed by 100 bytes of pixels.
std::string ClaimedPpm(int64_t width, int64_t height) {
  return "P6\n" + std::to_string(width) + " " + std::to_string(height) + "\n255\n" +
         std::string(100, '\x80');
}

TEST_F(ImageTest, HeaderClaimingAHugeImageIsRefusedNamingFileAndLimit) {
  // Before the limit, 100000x100000 ended in std::bad_alloc (3e10 floats) naming no file.
  for (const auto& [w, h] : {std::pair{100000, 100000}, std::pair{20000, 20000}}) {
    WriteFileAtomic(P("huge.ppm"), ClaimedPpm(w, h));
    try {
      ReadImage(P("huge.ppm"));
      ADD_FAILURE() << w << "x" << h;
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(P("huge.ppm")), std::string::npos) << msg;
      EXPECT_NE(msg.find(std::to_string(w) + "x" + std::to_string(h)), std::string::npos) << msg;
      EXPECT_NE(msg.find(std::to_string(kMaxImageSide) + " pixels a side"), std::string::npos)
          << msg;
      EXPECT_NE(msg.find(std::to_string(kMaxImagePixels) + " pixels"), std::string::npos) << msg;
    }
  }
  EXPECT_NO_THROW(CheckImageSize("a.dng", kMaxImageSide, kMaxImagePixels / kMaxImageSide, 3));
  EXPECT_THROW(CheckImageSize("a.dng", kMaxImageSide + 1, 1, 3), Error);
  EXPECT_THROW(CheckImageSize("a.dng", 1, kMaxImageSide + 1, 3), Error);
  EXPECT_THROW(CheckImageSize("a.dng", 16, 16, kMaxImageChannels + 1), Error);
  EXPECT_THROW(CheckImageSize("a.dng", 0, 16, 3), Error);
}

TEST_F(ImageTest, TruncatedLargeImageFailsWithoutAllocatingItsClaimedSize) {
  // 15000x15000 is within the limits, but the file holds 100 bytes of it: memory follows the
  // rows decoded (before, 3.4 GB were allocated and zero-filled up front for 167 bytes).
  WriteFileAtomic(P("big.ppm"), ClaimedPpm(15000, 15000));
  rusage before{}, after{};
  ::getrusage(RUSAGE_SELF, &before);
  try {
    ReadImage(P("big.ppm"));
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(P("big.ppm")), std::string::npos) << e.what();
  }
  ::getrusage(RUSAGE_SELF, &after);
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 256 * 1024) << "KiB of peak memory";
}

TEST_F(ImageTest, ExrAttributeClaimingMoreThanTheFileIsRefused) {
  // Found by tests/fuzz/image_fuzz: OpenEXR 3.1 allocates and clears an attribute's claimed
  // size before reading it (a 700-byte file cost 1.9 GB and 10 s, then "cannot read image").
  std::string exr("\x76\x2f\x31\x01\x02\x00\x00\x00", 8);
  exr += std::string("comments\0string\0", 16) + std::string("\x00\x00\x00\x70", 4) + "abc";
  WriteFileAtomic(P("claims.exr"), exr);
  WriteFileAtomic(P("claims.png"), exr);  // the content decides, not the name
  rusage before{}, after{};
  ::getrusage(RUSAGE_SELF, &before);
  for (const char* name : {"claims.exr", "claims.png"}) {
    try {
      ReadImage(P(name));
      ADD_FAILURE() << name;
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(P(name)), std::string::npos) << msg;
      EXPECT_NE(msg.find("attribute \"comments\" claims 1879048192 bytes"), std::string::npos)
          << msg;
    }
  }
  // Valid files pass the check: a two-part EXR with a 100 kB attribute.
  {
    const Image img = Ramp(8, 4, 3, PixelUnits::kRadiance, 2.f);
    OIIO::ImageSpec specs[2] = {OIIO::ImageSpec(8, 4, 3, OIIO::TypeDesc::HALF),
                                OIIO::ImageSpec(8, 4, 3, OIIO::TypeDesc::HALF)};
    specs[0].attribute("ImageDescription", std::string(100000, 'x'));
    specs[1].attribute("oiio:subimagename", "second");
    auto out = OIIO::ImageOutput::create(P("two.exr"));
    ASSERT_TRUE(out && out->open(P("two.exr"), 2, specs));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data()));
    ASSERT_TRUE(out->open(P("two.exr"), specs[1], OIIO::ImageOutput::AppendSubimage));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data()));
    ASSERT_TRUE(out->close());
    EXPECT_EQ(ReadImage(P("two.exr")).width, 8);
  }
  EXPECT_THROW(ReadPhotoMetadata(P("claims.exr")), Error);
  EXPECT_THROW(ReadRawLinear(P("claims.exr")), Error);
  ::getrusage(RUSAGE_SELF, &after);
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 256 * 1024) << "KiB of peak memory";
}

TEST_F(ImageTest, ExrChannelOfUnknownPixelTypeIsRefused) {
  // Found by tests/fuzz/image_fuzz: OpenImageIO 2.4 aborts the process ("Unknown
  // Imf::PixelType 3") on such a channel.
  WriteImage(P("ok.exr"), Ramp(4, 2, 3, PixelUnits::kRadiance, 1.f), StoredType::kHalf);
  std::string bytes = ReadFileToString(P("ok.exr"));
  const size_t chlist = bytes.find(std::string("chlist\0", 7));
  ASSERT_NE(chlist, std::string::npos);
  // After "chlist\0": int32 size, then the first channel "B\0" and its int32 pixel type.
  ASSERT_EQ(bytes.substr(chlist + 11, 2), std::string("B\0", 2));
  bytes[chlist + 13] = 3;
  WriteFileAtomic(P("bad.exr"), bytes);
  try {
    ReadImage(P("bad.exr"));
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()),
              P("bad.exr") + ": OpenEXR channel \"B\" has unknown pixel type 3 (a corrupt header)");
  }
  EXPECT_THROW(ReadPhotoMetadata(P("bad.exr")), Error);
}

TEST_F(ImageTest, ExrChannelListEndingInsideAnEntryIsRefused) {
  // Found by tests/fuzz/image_fuzz: a channel list whose declared size ends inside its last
  // entry; OpenEXR reads that entry's pixel type from the bytes after it and OpenImageIO 2.4
  // aborts on what it finds there.
  WriteImage(P("ok.exr"), Ramp(4, 2, 3, PixelUnits::kRadiance, 1.f), StoredType::kHalf);
  std::string bytes = ReadFileToString(P("ok.exr"));
  const size_t chlist = bytes.find(std::string("chlist\0", 7));
  ASSERT_NE(chlist, std::string::npos);
  // Three entries of "X\0" + 16 bytes and the list's terminating '\0': 55 bytes; claim 52.
  int32_t claimed = 0;
  std::memcpy(&claimed, bytes.data() + chlist + 7, 4);  // little-endian, as x86 and ARM
  ASSERT_EQ(claimed, 55);
  bytes[chlist + 7] = 52;
  WriteFileAtomic(P("cut.exr"), bytes);
  try {
    ReadImage(P("cut.exr"));
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), P("cut.exr") +
                                         ": OpenEXR channel list \"channels\" ends inside an "
                                         "entry (52 bytes; a corrupt header)");
  }
  EXPECT_THROW(ReadPhotoMetadata(P("cut.exr")), Error);
}

TEST_F(ImageTest, PngChunkClaimingMoreThanTheFileIsRefused) {
  // Found by tests/fuzz/image_fuzz: libpng allocates a chunk's claimed length before reading
  // it (a 558-byte file whose tEXt chunk claimed 1711276190 bytes asked for 1.7 GB).
  WriteImage(P("ok.png"), Ramp(4, 2, 3, PixelUnits::kDigital, 100.f), StoredType::kUint8);
  const std::string good = ReadFileToString(P("ok.png"));
  // After the 8-byte signature and the 25-byte IHDR chunk: a tEXt chunk claiming 0x66000000.
  std::string bad =
      good.substr(0, 33) + std::string("\x66\x00\x00\x00tEXtkey\0value", 18) + good.substr(33);
  WriteFileAtomic(P("claims.png"), bad);
  WriteFileAtomic(P("cut.png"), good.substr(0, good.size() - 20));  // into the last chunks
  rusage before{}, after{};
  ::getrusage(RUSAGE_SELF, &before);
  for (const auto& [name, chunk] : {std::pair{"claims.png", "tEXt"}, std::pair{"cut.png", ""}}) {
    try {
      ReadImage(P(name));
      ADD_FAILURE() << name;
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind(P(name) + ": PNG chunk \"" + chunk, 0), 0u) << msg;
      EXPECT_NE(msg.find("(a truncated or corrupt file)"), std::string::npos) << msg;
    }
    EXPECT_THROW(ReadPhotoMetadata(P(name)), Error);
  }
  ::getrusage(RUSAGE_SELF, &after);
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 256 * 1024) << "KiB of peak memory";
  EXPECT_EQ(ReadImage(P("ok.png")).width, 4);  // a whole PNG passes
}

// A JPEG cut short decoded without a word before (libjpeg fills the rest with grey and warns):
// a response fit on such a bracket came out 8x worse. It is refused, naming the file; a whole
// JPEG, and one with data after its end (a phone's motion clip), read.
TEST_F(ImageTest, ATruncatedJpegIsRefused) {
  Image im(64, 48, 3, PixelUnits::kDigital, 0.f);
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(x, y, c) = static_cast<float>((x * 7 + y * 13 + c * 50) % 256);
  WriteImage(P("ok.jpg"), im, StoredType::kUint8);
  const std::string good = ReadFileToString(P("ok.jpg"));
  ASSERT_EQ(good.substr(good.size() - 2), "\xff\xd9");
  WriteFileAtomic(P("trailer.jpg"), good + std::string(100, '\x42'));
  EXPECT_EQ(ReadImage(P("ok.jpg")).width, 64);
  EXPECT_EQ(ReadImage(P("trailer.jpg")).height, 48);
  for (const size_t keep : {good.size() * 6 / 10, good.size() - 2, size_t{300}}) {
    WriteFileAtomic(P("cut.jpg"), good.substr(0, keep));
    try {
      ReadImage(P("cut.jpg"));
      ADD_FAILURE() << keep;
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind(P("cut.jpg") + ": JPEG ", 0), 0u) << msg;
      EXPECT_NE(msg.find("(a truncated or corrupt file)"), std::string::npos) << msg;
    }
  }
}

TEST_F(ImageTest, RunLengthEncodedBmpIsRefusedNamingTheFile) {
  // Found by tests/fuzz/image_fuzz: a 76-byte 24-bit BMP whose header says RLE8 made
  // OpenImageIO's decoder read out of bounds (a crash). RLE bitmaps are refused before it runs;
  // an uncompressed BMP still reads.
  const std::string crash(
      "BM\x86\0\0\0\0\x84\0\0\x36\0\0\0\x28\0\0\0\x06\0\0\0\x04\0\0\0\x01\0\x18\0"
      "\x01\0\0\0\0\0\0\xa4\x77\x6f\x80\x77\x6f\x80\x77\x6f\0\0\x66\x4d\x36\x66\x4d\x33"
      "\x66\x4d\x33\x66\x4d\0\0\x01\x33\0\0\0\0\xa4\x66\x4d\x33\x66\x4d\x33\0\0",
      76);
  WriteFileAtomic(P("rle.bmp"), crash);
  try {
    ReadImage(P("rle.bmp"));
    ADD_FAILURE() << "read";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).rfind(P("rle.bmp") + ": cannot read image: run-length", 0), 0u)
        << e.what();
  }
  WriteImage(P("plain.bmp"), Ramp(6, 4, 3, PixelUnits::kDigital, 100.f), StoredType::kUint8);
  EXPECT_EQ(ReadImage(P("plain.bmp")).width, 6);
}

TEST_F(ImageTest, ReadsTiledAndScanlineFilesInBands) {
  // More samples than one band (internal::kBandSamples): the bands join seamlessly.
  const Image img = Ramp(1500, 1000, 3, PixelUnits::kRadiance, 4.f);
  WriteImage(P("lines.exr"), img, StoredType::kFloat);
  {
    auto out = OIIO::ImageOutput::create(P("tiles.exr"));
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(img.width, img.height, 3, OIIO::TypeDesc::FLOAT);
    spec.tile_width = spec.tile_height = 64;
    ASSERT_TRUE(out->open(P("tiles.exr"), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data()));
    ASSERT_TRUE(out->close());
  }
  for (const char* name : {"lines.exr", "tiles.exr"}) {
    const Image back = ReadImage(P(name));
    EXPECT_EQ(back.width, img.width);
    EXPECT_EQ(back.height, img.height);
    EXPECT_EQ(back.data.capacity(), back.data.size()) << name;
    EXPECT_TRUE(back.data == img.data) << name;
  }
}

TEST_F(ImageTest, WritingToAMissingFolderFails) {
  EXPECT_THROW(
      WriteImage(P("nope/a.png"), Ramp(2, 2, 3, PixelUnits::kDigital, 1.f), StoredType::kUint8),
      Error);
}

TEST(ImageSampleTest, Bilinear) {
  Image img(2, 2, 1);
  img.data = {0.f, 10.f, 20.f, 30.f};
  EXPECT_FLOAT_EQ(img.Sample(0.5, 0.5, 0), 0.f);  // pixel centre
  EXPECT_FLOAT_EQ(img.Sample(1.5, 1.5, 0), 30.f);
  EXPECT_FLOAT_EQ(img.Sample(1.0, 0.5, 0), 5.f);   // between two centres
  EXPECT_FLOAT_EQ(img.Sample(1.0, 1.0, 0), 15.f);  // middle of four
  EXPECT_FLOAT_EQ(img.Sample(0.75, 1.25, 0), 0.25f * 10 + 0.75f * 20);
  EXPECT_FLOAT_EQ(img.Sample(-5.0, 0.5, 0), 0.f);  // clamped at the border
  EXPECT_FLOAT_EQ(img.Sample(9.0, 9.0, 0), 30.f);
}

}  // namespace
}  // namespace rouen
