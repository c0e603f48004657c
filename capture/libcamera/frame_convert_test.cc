#include "capture/libcamera/frame_convert.h"

#include <gtest/gtest.h>
#include <libcamera/formats.h>

#include <cmath>
#include <cstring>

#include "core/error.h"

namespace rouen::libcamera_internal {
namespace {

namespace fmt = libcamera::formats;

FrameLayout Layout(const libcamera::PixelFormat& pf, int w, int h, int stride) {
  FrameLayout l;
  l.format = {pf.fourcc(), pf.modifier()};
  l.width = w;
  l.height = h;
  l.stride = stride;
  return l;
}

void ExpectPixel(const Image& img, int x, int y, float r, float g, float b, float tol = 0) {
  EXPECT_NEAR(img.at(x, y, 0), r, tol) << "R at " << x << "," << y;
  EXPECT_NEAR(img.at(x, y, 1), g, tol) << "G at " << x << "," << y;
  EXPECT_NEAR(img.at(x, y, 2), b, tol) << "B at " << x << "," << y;
}

TEST(FrameConvert, Rgb888IsStoredBgrAndPaddingIsSkipped) {
  // 2x2, stride 8 (2 bytes of padding per row, filled with junk).
  std::vector<uint8_t> buf = {10, 20, 30, 40,  50,  60,  0xEE, 0xEE,
                              70, 80, 90, 100, 110, 120, 0xEE, 0xEE};
  const Image img = ConvertFrame(Layout(fmt::RGB888, 2, 2, 8), {{buf.data(), buf.size()}});
  ASSERT_EQ(img.width, 2);
  ASSERT_EQ(img.height, 2);
  ASSERT_EQ(img.channels, 3);
  EXPECT_EQ(img.units, PixelUnits::kDigital);
  ExpectPixel(img, 0, 0, 30, 20, 10);  // memory B,G,R
  ExpectPixel(img, 1, 0, 60, 50, 40);
  ExpectPixel(img, 0, 1, 90, 80, 70);
  ExpectPixel(img, 1, 1, 120, 110, 100);
  const Image swapped = ConvertFrame(Layout(fmt::BGR888, 2, 2, 8), {{buf.data(), buf.size()}});
  ExpectPixel(swapped, 0, 0, 10, 20, 30);  // memory R,G,B
}

TEST(FrameConvert, Xrgb8888) {
  std::vector<uint8_t> buf = {1, 2, 3, 255, 4, 5, 6, 255};
  const Image img = ConvertFrame(Layout(fmt::XRGB8888, 2, 1, 8), {{buf.data(), buf.size()}});
  ExpectPixel(img, 0, 0, 3, 2, 1);
  ExpectPixel(img, 1, 0, 6, 5, 4);
  const Image x = ConvertFrame(Layout(fmt::XBGR8888, 2, 1, 8), {{buf.data(), buf.size()}});
  ExpectPixel(x, 1, 0, 4, 5, 6);
}

// BT.601 forward transform, limited range, for building test pixels.
void ToYuv601Limited(double r, double g, double b, uint8_t* y, uint8_t* u, uint8_t* v) {
  const double yy = 0.299 * r + 0.587 * g + 0.114 * b;
  const double cb = (b - yy) / 1.772, cr = (r - yy) / 1.402;
  *y = static_cast<uint8_t>(std::lround(16 + yy * 219.0 / 255.0));
  *u = static_cast<uint8_t>(std::lround(128 + cb * 224.0 / 255.0));
  *v = static_cast<uint8_t>(std::lround(128 + cr * 224.0 / 255.0));
}

TEST(FrameConvert, YuyvGreyAndColoursRoundTrip) {
  // Quantising Y'CbCr to 8 bits moves RGB by at most ~1.6 DN (half a code step times the
  // largest inverse-matrix coefficient 1.772 * 255/224 ~ 2.0, halved); allow 2.
  const double colours[][3] = {{255, 0, 0},    {0, 255, 0}, {0, 0, 255},    {128, 128, 128},
                               {200, 150, 30}, {0, 0, 0},   {255, 255, 255}};
  for (const auto& c : colours) {
    uint8_t y, u, v;
    ToYuv601Limited(c[0], c[1], c[2], &y, &u, &v);
    std::vector<uint8_t> yuyv = {y, u, y, v};
    const Image img = ConvertFrame(Layout(fmt::YUYV, 2, 1, 4), {{yuyv.data(), yuyv.size()}});
    ExpectPixel(img, 0, 0, c[0], c[1], c[2], 2.0);
    ExpectPixel(img, 1, 0, c[0], c[1], c[2], 2.0);
    std::vector<uint8_t> uyvy = {u, y, v, y};
    const Image img2 = ConvertFrame(Layout(fmt::UYVY, 2, 1, 4), {{uyvy.data(), uyvy.size()}});
    ExpectPixel(img2, 1, 0, c[0], c[1], c[2], 2.0);
  }
}

TEST(FrameConvert, YuvRangeAndMatrix) {
  std::vector<uint8_t> grey = {128, 128, 128, 128};
  FrameLayout l = Layout(fmt::YUYV, 2, 1, 4);
  l.full_range = true;
  ExpectPixel(ConvertFrame(l, {{grey.data(), grey.size()}}), 0, 0, 128, 128, 128, 1e-4);
  l.full_range = false;
  const float limited = (128 - 16) * 255.0f / 219.0f;
  ExpectPixel(ConvertFrame(l, {{grey.data(), grey.size()}}), 0, 0, limited, limited, limited, 1e-3);
  // Full-range black and white clamp to exactly 0 and 255.
  std::vector<uint8_t> bw = {0, 128, 255, 128};
  ExpectPixel(ConvertFrame(l, {{bw.data(), bw.size()}}), 0, 0, 0, 0, 0);
  ExpectPixel(ConvertFrame(l, {{bw.data(), bw.size()}}), 1, 0, 255, 255, 255);
  // Rec.709 red differs from Rec.601 red decoding of the same bytes.
  std::vector<uint8_t> red = {63, 102, 63, 240};  // Rec.709 limited red
  l.matrix = YcbcrMatrix::kRec709;
  ExpectPixel(ConvertFrame(l, {{red.data(), red.size()}}), 0, 0, 255, 0, 0, 2.0);
  l.matrix = YcbcrMatrix::kRec601;  // Kr = 0.299 instead of 0.2126: R comes out near 233
  EXPECT_LT(ConvertFrame(l, {{red.data(), red.size()}}).at(0, 0, 0), 245.0f);
}

TEST(FrameConvert, Nv12AsTwoPlanesOrOneAndNv21Swaps) {
  const int w = 4, h = 2, stride = 6;
  std::vector<uint8_t> y(stride * h, 0xEE), uv(stride * h / 2, 0xEE);
  for (int r = 0; r < h; ++r) {
    for (int x = 0; x < w; ++x) y[r * stride + x] = static_cast<uint8_t>(60 + 20 * x + 5 * r);
  }
  uv[0] = 90, uv[1] = 200, uv[2] = 160, uv[3] = 100;  // two chroma pairs
  const Image two =
      ConvertFrame(Layout(fmt::NV12, w, h, stride), {{y.data(), y.size()}, {uv.data(), uv.size()}});
  std::vector<uint8_t> one = y;
  one.insert(one.end(), uv.begin(), uv.end());
  const Image single = ConvertFrame(Layout(fmt::NV12, w, h, stride), {{one.data(), one.size()}});
  EXPECT_EQ(two.data, single.data);
  // Pixel (2,1) uses chroma pair 1 and its own luma; compare with YUYV decoding.
  std::vector<uint8_t> yuyv = {y[1 * stride + 2], uv[2], y[1 * stride + 2], uv[3]};
  const Image ref = ConvertFrame(Layout(fmt::YUYV, 2, 1, 4), {{yuyv.data(), yuyv.size()}});
  ExpectPixel(two, 2, 1, ref.at(0, 0, 0), ref.at(0, 0, 1), ref.at(0, 0, 2), 1e-4);
  // NV21 stores V first: swapping the bytes gives the same image.
  std::vector<uint8_t> vu = uv;
  std::swap(vu[0], vu[1]);
  std::swap(vu[2], vu[3]);
  const Image nv21 =
      ConvertFrame(Layout(fmt::NV21, w, h, stride), {{y.data(), y.size()}, {vu.data(), vu.size()}});
  EXPECT_EQ(nv21.data, two.data);
  // YUV420 planar with the same samples.
  std::vector<uint8_t> u = {uv[0], uv[2], 0xEE}, v = {uv[1], uv[3], 0xEE};
  const Image planar =
      ConvertFrame(Layout(fmt::YUV420, w, h, stride),
                   {{y.data(), y.size()}, {u.data(), u.size()}, {v.data(), v.size()}});
  EXPECT_EQ(planar.data, two.data);
}

TEST(FrameConvert, Bayer8CellsGiveTheirColours) {
  // 4x2 RGGB: cell 0 R=200 G=100,120 B=50; cell 1 R=10 G=20,40 B=30.
  std::vector<uint8_t> buf = {200, 100, 10, 20, 120, 50, 40, 30};
  const Image img = ConvertFrame(Layout(fmt::SRGGB8, 4, 2, 4), {{buf.data(), buf.size()}});
  for (int y = 0; y < 2; ++y) {
    ExpectPixel(img, 0, y, 200, 110, 50);
    ExpectPixel(img, 1, y, 200, 110, 50);
    ExpectPixel(img, 2, y, 10, 30, 30);
    ExpectPixel(img, 3, y, 10, 30, 30);
  }
  // Same bytes read as BGGR: red and blue swap.
  const Image bggr = ConvertFrame(Layout(fmt::SBGGR8, 4, 2, 4), {{buf.data(), buf.size()}});
  ExpectPixel(bggr, 0, 0, 50, 110, 200);
  // GRBG: greens on the diagonal 200 and 50, R=100, B=120.
  const Image grbg = ConvertFrame(Layout(fmt::SGRBG8, 4, 2, 4), {{buf.data(), buf.size()}});
  ExpectPixel(grbg, 1, 1, 100, 125, 120);
  const Image gbrg = ConvertFrame(Layout(fmt::SGBRG8, 4, 2, 4), {{buf.data(), buf.size()}});
  ExpectPixel(gbrg, 0, 1, 120, 125, 100);
}

TEST(FrameConvert, Bayer10And12UnpackedScaleLinearly) {
  // Little-endian 16-bit words; high bits beyond the depth are ignored.
  auto le = [](uint16_t v) { return std::vector<uint8_t>{uint8_t(v & 0xff), uint8_t(v >> 8)}; };
  std::vector<uint8_t> buf;
  for (uint16_t v : {uint16_t(1023), uint16_t(0), uint16_t(0xFC00 | 512), uint16_t(341)}) {
    const auto b = le(v);
    buf.insert(buf.end(), b.begin(), b.end());
  }
  const Image img = ConvertFrame(Layout(fmt::SRGGB10, 2, 2, 4), {{buf.data(), buf.size()}});
  ExpectPixel(img, 0, 0, 255.0f, 512 * 255.0f / 1023 / 2, 341 * 255.0f / 1023, 1e-3);
  const Image img12 = ConvertFrame(Layout(fmt::SRGGB12, 2, 2, 4), {{buf.data(), buf.size()}});
  ExpectPixel(img12, 0, 0, 1023 * 255.0f / 4095, (0xC00 | 512) * 255.0f / 4095 / 2,
              341 * 255.0f / 4095, 1e-3);
}

TEST(FrameConvert, Bayer10And12Csi2Packed) {
  // RGGB 4x2, 10-bit values per row: row 0: R0 G0 R1 G1; row 1: G2 B0 G3 B1.
  const uint16_t row0[4] = {1023, 0, 514, 3}, row1[4] = {1, 1022, 256, 700};
  auto pack10 = [](const uint16_t* v) {
    std::vector<uint8_t> g(5);
    for (int i = 0; i < 4; ++i) {
      g[i] = uint8_t(v[i] >> 2);
      g[4] |= uint8_t((v[i] & 3) << (2 * i));
    }
    return g;
  };
  std::vector<uint8_t> buf = pack10(row0);
  buf.push_back(0xEE);  // stride 6
  const auto r1 = pack10(row1);
  buf.insert(buf.end(), r1.begin(), r1.end());
  buf.push_back(0xEE);
  const Image img = ConvertFrame(Layout(fmt::SRGGB10_CSI2P, 4, 2, 6), {{buf.data(), buf.size()}});
  const float s = 255.0f / 1023;
  ExpectPixel(img, 0, 1, 1023 * s, (0 + 1) * s / 2, 1022 * s, 1e-3);
  ExpectPixel(img, 3, 0, 514 * s, (3 + 256) * s / 2, 700 * s, 1e-3);

  // 12-bit: 2 pixels in 3 bytes. RGGB 2x2: R=4095 G=2049 / G=7 B=1234.
  auto pack12 = [](uint16_t a, uint16_t b) {
    return std::vector<uint8_t>{uint8_t(a >> 4), uint8_t(b >> 4),
                                uint8_t((a & 0xf) | ((b & 0xf) << 4))};
  };
  std::vector<uint8_t> b12 = pack12(4095, 2049);
  const auto b12r1 = pack12(7, 1234);
  b12.insert(b12.end(), b12r1.begin(), b12r1.end());
  const Image img12 = ConvertFrame(Layout(fmt::SRGGB12_CSI2P, 2, 2, 3), {{b12.data(), b12.size()}});
  const float s12 = 255.0f / 4095;
  ExpectPixel(img12, 1, 1, 4095 * s12, (2049 + 7) * s12 / 2, 1234 * s12, 1e-3);
}

TEST(FrameConvert, BadInputIsAnErrorNamingTheFormat) {
  std::vector<uint8_t> buf(64, 0);
  const std::vector<PlaneBytes> planes = {{buf.data(), buf.size()}};
  try {
    ConvertFrame(Layout(fmt::MJPEG, 4, 4, 4), planes);
    FAIL() << "MJPEG accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("MJPG"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("unsupported"), std::string::npos);
  }
  EXPECT_THROW(ConvertFrame(Layout(fmt::RGB888, 8, 8, 24), planes), Error);  // too small
  EXPECT_THROW(ConvertFrame(Layout(fmt::RGB888, 4, 2, 11), planes), Error);  // stride < row
  EXPECT_THROW(ConvertFrame(Layout(fmt::SRGGB8, 3, 2, 4), planes), Error);   // odd Bayer
  EXPECT_THROW(ConvertFrame(Layout(fmt::YUYV, 3, 2, 8), planes), Error);     // odd 4:2:2
  EXPECT_THROW(ConvertFrame(Layout(fmt::NV12, 4, 4, 4), {{buf.data(), 20}}), Error);
  EXPECT_THROW(ConvertFrame(Layout(fmt::NV12, 4, 4, 4), {{buf.data(), 16}, {buf.data(), 4}}),
               Error);
  EXPECT_THROW(ConvertFrame(Layout(fmt::RGB888, 0, 2, 0), planes), Error);
  EXPECT_THROW(ConvertFrame(Layout(fmt::RGB888, 1, 1, 3), {}), Error);
  EXPECT_THROW(ConvertFrame(Layout(fmt::RGB888, 1, 1, 3), {{nullptr, 3}}), Error);
  EXPECT_THROW(ConvertFrame(Layout(fmt::SRGGB10_CSI2P, 4, 2, 4), planes), Error);  // needs 5
}

TEST(FrameConvert, FormatNamesAndChoice) {
  auto code = [](const libcamera::PixelFormat& pf) {
    return PixelCode{pf.fourcc(), pf.modifier()};
  };
  EXPECT_EQ(FormatName(code(fmt::YUYV)), "YUYV");
  EXPECT_EQ(FormatName(code(fmt::SRGGB10)), "SRGGB10");
  // The packed format shares the fourcc and differs by the modifier.
  EXPECT_EQ(fmt::SRGGB10_CSI2P.fourcc(), fmt::SRGGB10.fourcc());
  EXPECT_EQ(FormatName(code(fmt::SRGGB10_CSI2P)), "SRGGB10_CSI2P");
  EXPECT_EQ(FormatName(code(fmt::MJPEG)), "MJPG");
  EXPECT_EQ(FormatName(code(fmt::SRGGB10_IPU3)).substr(0, 7), "RG10/0x");  // unsupported
  EXPECT_TRUE(IsSupportedFormat(code(fmt::NV12)));
  EXPECT_FALSE(IsSupportedFormat(code(fmt::MJPEG)));
  EXPECT_FALSE(IsSupportedFormat(code(fmt::SRGGB10_IPU3)));
  EXPECT_FALSE(IsSupportedFormat(PixelCode{}));
  EXPECT_GE(SupportedFormatNames().size(), 20u);
  const PixelCode mjpeg = code(fmt::MJPEG), nv12 = code(fmt::NV12), yuyv = code(fmt::YUYV),
                  r10 = code(fmt::SRGGB10_CSI2P), r12 = code(fmt::SRGGB12), r8 = code(fmt::SRGGB8);
  EXPECT_EQ(ChooseFormat(yuyv, nv12, {nv12, yuyv}), yuyv);         // the caller's wish
  EXPECT_EQ(ChooseFormat({}, nv12, {nv12, yuyv}), nv12);           // supported default
  EXPECT_EQ(ChooseFormat({}, mjpeg, {mjpeg, nv12, yuyv}), yuyv);   // preference order
  EXPECT_EQ(ChooseFormat({}, mjpeg, {mjpeg, r8, r10, r12}), r12);  // deepest raw
  EXPECT_EQ(ChooseFormat({}, mjpeg, {mjpeg}), PixelCode{});
}

}  // namespace
}  // namespace rouen::libcamera_internal
