#include "capture/v4l2/pixel_format.h"

#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <sys/resource.h>

#include <algorithm>
#include <vector>

#include "capture/v4l2/jpeg_codec.h"

namespace rouen::v4l2_internal {
namespace {

TEST(V4l2Fourcc, RoundTripsAndRejectsBadNames) {
  EXPECT_EQ(FourccFromString("YUYV"), V4L2_PIX_FMT_YUYV);
  EXPECT_EQ(FourccFromString("MJPG"), V4L2_PIX_FMT_MJPEG);
  EXPECT_EQ(FourccFromString("GREY"), V4L2_PIX_FMT_GREY);
  EXPECT_EQ(FourccFromString("GRBG"), V4L2_PIX_FMT_SGRBG8);
  EXPECT_EQ(FourccToString(V4L2_PIX_FMT_SGRBG8), "GRBG");
  EXPECT_EQ(FourccToString(V4L2_PIX_FMT_YUYV), "YUYV");
  EXPECT_EQ(FourccFromString(""), 0u);
  EXPECT_EQ(FourccFromString("TOOLONG"), 0u);
}

TEST(V4l2Ycbcr, DefaultsFollowV4l2Rules) {
  YcbcrParams p =
      YcbcrFromFormat(V4L2_COLORSPACE_SRGB, V4L2_YCBCR_ENC_DEFAULT, V4L2_QUANTIZATION_DEFAULT);
  EXPECT_DOUBLE_EQ(p.kr, 0.299);
  EXPECT_FALSE(p.full_range);
  p = YcbcrFromFormat(V4L2_COLORSPACE_JPEG, V4L2_YCBCR_ENC_DEFAULT, V4L2_QUANTIZATION_DEFAULT);
  EXPECT_TRUE(p.full_range);
  p = YcbcrFromFormat(V4L2_COLORSPACE_REC709, V4L2_YCBCR_ENC_DEFAULT, V4L2_QUANTIZATION_FULL_RANGE);
  EXPECT_DOUBLE_EQ(p.kr, 0.2126);
  EXPECT_TRUE(p.full_range);
}

// BT.601 limited-range code values of the primaries, from the standard's equations:
// Y' = 16 + 219 (0.299 R + 0.587 G + 0.114 B), Cb = 128 + 224 (B - Y)/1.772,
// Cr = 128 + 224 (R - Y)/1.402 (R, G, B in 0..1).
TEST(V4l2Ycbcr, Bt601LimitedReferenceColours) {
  YcbcrParams p;  // BT.601 limited
  float rgb[3];
  YcbcrToRgb(235, 128, 128, p, rgb);  // white
  for (float v : rgb) EXPECT_NEAR(v, 255.f, 1e-3);
  YcbcrToRgb(16, 128, 128, p, rgb);  // black
  for (float v : rgb) EXPECT_NEAR(v, 0.f, 1e-3);
  YcbcrToRgb(16 + 219 * 0.299, 128 - 224 * 0.299 / 1.772, 240, p, rgb);  // red
  EXPECT_NEAR(rgb[0], 255, 1e-3);
  EXPECT_NEAR(rgb[1], 0, 1e-3);
  EXPECT_NEAR(rgb[2], 0, 1e-3);
  YcbcrToRgb(16 + 219 * 0.114, 240, 128 - 224 * 0.114 / 1.402, p, rgb);  // blue
  EXPECT_NEAR(rgb[0], 0, 1e-3);
  EXPECT_NEAR(rgb[1], 0, 1e-3);
  EXPECT_NEAR(rgb[2], 255, 1e-3);
  YcbcrToRgb(0, 0, 255, p, rgb);  // out of gamut: clamped
  for (float v : rgb) EXPECT_TRUE(v >= 0 && v <= 255);
}

TEST(V4l2Ycbcr, FullRangeGreyIsIdentity) {
  YcbcrParams p;
  p.full_range = true;
  float rgb[3];
  for (int y : {0, 37, 128, 255}) {
    YcbcrToRgb(y, 128, 128, p, rgb);
    for (float v : rgb) EXPECT_NEAR(v, y, 1e-3);
  }
}

TEST(V4l2Bayer, CfaLayouts) {
  // SGRBG8: G R / B G.
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SGRBG8, 0, 0), 1);
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SGRBG8, 1, 0), 0);
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SGRBG8, 0, 1), 2);
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SGRBG8, 1, 1), 1);
  // SRGGB8: R G / G B; SBGGR8: B G / G R.
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SRGGB8, 0, 0), 0);
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SRGGB8, 1, 1), 2);
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SBGGR8, 0, 0), 2);
  EXPECT_EQ(BayerColour(V4L2_PIX_FMT_SGBRG8, 1, 0), 2);
}

TEST(V4l2Bayer, FlatColourIsReproducedEverywhereIncludingBorders) {
  const int w = 9, h = 7;  // odd sizes exercise the clipped borders
  const uint8_t colour[3] = {200, 100, 30};
  for (uint32_t f :
       {V4L2_PIX_FMT_SBGGR8, V4L2_PIX_FMT_SGBRG8, V4L2_PIX_FMT_SGRBG8, V4L2_PIX_FMT_SRGGB8}) {
    const size_t bpl = w + 3;  // padded rows
    std::vector<uint8_t> raw(bpl * h, 0xEE);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) raw[y * bpl + x] = colour[BayerColour(f, x, y)];
    Image out;
    BayerToRgb(raw.data(), w, h, bpl, f, &out);
    ASSERT_EQ(out.width, w);
    EXPECT_EQ(out.units, PixelUnits::kDigital);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) EXPECT_EQ(out.at(x, y, c), colour[c]) << x << "," << y;
  }
}

TEST(V4l2Bayer, LinearRampInterpolatesExactly) {
  // Bilinear interpolation reproduces a horizontal linear ramp at interior pixels.
  const int w = 12, h = 6;
  std::vector<uint8_t> raw(w * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) raw[y * w + x] = static_cast<uint8_t>(10 * x);
  Image out;
  BayerToRgb(raw.data(), w, h, w, V4L2_PIX_FMT_SGRBG8, &out);
  for (int y = 1; y < h - 1; ++y)
    for (int x = 1; x < w - 1; ++x)
      for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(out.at(x, y, c), 10.f * x);
}

TEST(V4l2Yuyv, PaddedRowsAndPairs) {
  const int w = 4, h = 2;
  const size_t bpl = 2 * w + 6;
  std::vector<uint8_t> raw(bpl * h, 0x55);
  for (int y = 0; y < h; ++y) {
    uint8_t* r = &raw[y * bpl];
    // pair 0: Y 16 / 235, grey; pair 1: Y 126 / 126, grey.
    const uint8_t row[8] = {16, 128, 235, 128, 126, 128, 126, 128};
    std::copy(row, row + 8, r);
  }
  Image out;
  YuyvToRgb(raw.data(), w, h, bpl, YcbcrParams{}, &out);
  for (int y = 0; y < h; ++y) {
    EXPECT_NEAR(out.at(0, y, 1), 0, 1e-3);
    EXPECT_NEAR(out.at(1, y, 1), 255, 1e-3);
    EXPECT_NEAR(out.at(2, y, 0), (126 - 16) * 255.0 / 219, 1e-3);
  }
}

TEST(V4l2Jpeg, RoundTripWithoutHuffmanTables) {
  if (!JpegAvailable()) GTEST_SKIP() << "built without libjpeg";
  const int w = 32, h = 16;
  std::vector<uint8_t> rgb(w * h * 3);
  for (int i = 0; i < w * h; ++i) {
    rgb[3 * i] = 180;
    rgb[3 * i + 1] = 90;
    rgb[3 * i + 2] = 40;
  }
  for (bool omit : {false, true}) {
    const std::vector<uint8_t> jpeg = EncodeJpeg(rgb.data(), w, h, 95, omit);
    ASSERT_GT(jpeg.size(), 100u);
    bool has_dht = false;
    for (size_t i = 0; i + 1 < jpeg.size(); ++i) has_dht |= jpeg[i] == 0xFF && jpeg[i + 1] == 0xC4;
    EXPECT_EQ(has_dht, !omit);
    Image out;
    std::string error;
    ASSERT_TRUE(DecodeJpeg(jpeg.data(), jpeg.size(), w, h, &out, &error)) << error;
    // A flat image: only DC terms; colour conversion and rounding stay within 4 DN.
    for (int i = 0; i < w * h; ++i) {
      EXPECT_NEAR(out.data[3 * i], 180, 4);
      EXPECT_NEAR(out.data[3 * i + 1], 90, 4);
      EXPECT_NEAR(out.data[3 * i + 2], 40, 4);
    }
    // Junk bytes between markers (some webcams) are tolerated: insert them before the
    // second marker (after SOI).
    std::vector<uint8_t> junk = jpeg;
    const uint8_t extra[3] = {0x12, 0x34, 0x56};
    junk.insert(junk.begin() + 2, extra, extra + 3);
    ASSERT_TRUE(DecodeJpeg(junk.data(), junk.size(), w, h, &out, &error)) << error;
    EXPECT_NEAR(out.data[0], 180, 4);
    // Wrong expected size, truncated data and garbage are refused, never crash.
    EXPECT_FALSE(DecodeJpeg(jpeg.data(), jpeg.size(), w + 2, h, &out, &error));
    EXPECT_NE(error.find("expected"), std::string::npos);
    EXPECT_FALSE(DecodeJpeg(jpeg.data(), jpeg.size() - 20, w, h, &out, &error));
    EXPECT_NE(error.find("corrupt JPEG"), std::string::npos) << error;
    std::vector<uint8_t> garbage(jpeg.size(), 0x42);
    EXPECT_FALSE(DecodeJpeg(garbage.data(), garbage.size(), w, h, &out, &error));
    garbage[0] = 0xFF;
    garbage[1] = 0xD8;
    EXPECT_FALSE(DecodeJpeg(garbage.data(), garbage.size(), w, h, &out, &error));
    EXPECT_FALSE(error.empty());
  }
}

TEST(V4l2Jpeg, HeaderClaimingAHugeFrameIsRefusedBeforeDecoding) {
  if (!JpegAvailable()) GTEST_SKIP() << "built without libjpeg";
  const int w = 32, h = 16;
  const std::vector<uint8_t> rgb(w * h * 3, 128);
  std::vector<uint8_t> jpeg = EncodeJpeg(rgb.data(), w, h, 90, true);
  // SOF0: FF C0, length (2), precision (1), height (2), width (2): claim 16000 x 16000.
  size_t sof = 0;
  while (sof + 8 < jpeg.size() && !(jpeg[sof] == 0xFF && jpeg[sof + 1] == 0xC0)) ++sof;
  ASSERT_LT(sof + 8, jpeg.size());
  for (size_t i : {sof + 5, sof + 7}) {
    jpeg[i] = 16000 >> 8;
    jpeg[i + 1] = 16000 & 0xFF;
  }
  rusage before{}, after{};
  ::getrusage(RUSAGE_SELF, &before);
  Image out;
  std::string error;
  EXPECT_FALSE(DecodeJpeg(jpeg.data(), jpeg.size(), w, h, &out, &error));
  EXPECT_NE(error.find("JPEG is 16000x16000, expected 32x16"), std::string::npos) << error;
  ::getrusage(RUSAGE_SELF, &after);
  // Before, the frame was decoded into 768 MB before its size was compared.
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 64 * 1024) << "KiB of peak memory";
}

}  // namespace
}  // namespace rouen::v4l2_internal
