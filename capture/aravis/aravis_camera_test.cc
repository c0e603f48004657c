// Driver tests without a network camera: pixel decoding, frame-id arithmetic, options, bad
// device ids, and the driver against Aravis' in-process Fake camera with test patterns.
#include "capture/aravis/aravis_camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "capture/aravis/aravis_internal.h"
#include "capture/aravis/pixel_decode.h"

namespace rouen {
namespace {

TEST(PixelDecodeTest, MonoAndRgbFormats) {
  const std::vector<uint8_t> mono = {0, 17, 255, 128, 3, 9};
  Image m = DecodeFrame(mono.data(), mono.size(), 3, 2, RawFormat::kMono8);
  EXPECT_EQ(m.units, PixelUnits::kDigital);
  EXPECT_EQ(m.channels, 3);
  for (int i = 0; i < 6; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(m.at(i % 3, i / 3, c), mono[i]);
  // Mono16 little-endian, scaled by 1/257: 65535 -> 255, 257 -> 1, 1000 -> 1000/257.
  const std::vector<uint8_t> m16 = {0xFF, 0xFF, 0x01, 0x01, 0xE8, 0x03, 0, 0};
  Image w = DecodeFrame(m16.data(), m16.size(), 2, 2, RawFormat::kMono16);
  EXPECT_FLOAT_EQ(w.at(0, 0, 1), 255.f);
  EXPECT_FLOAT_EQ(w.at(1, 0, 2), 1.f);
  EXPECT_FLOAT_EQ(w.at(0, 1, 0), static_cast<float>(1000 / 257.0));
  EXPECT_FLOAT_EQ(w.at(1, 1, 0), 0.f);
  const std::vector<uint8_t> rgb = {1, 2, 3, 4, 5, 6};
  Image r = DecodeFrame(rgb.data(), rgb.size(), 2, 1, RawFormat::kRGB8);
  Image b = DecodeFrame(rgb.data(), rgb.size(), 2, 1, RawFormat::kBGR8);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(r.at(1, 0, c), rgb[3 + c]);
    EXPECT_EQ(b.at(1, 0, c), rgb[3 + 2 - c]);
  }
  EXPECT_THROW(DecodeFrame(rgb.data(), rgb.size(), 3, 1, RawFormat::kRGB8), Error);
  EXPECT_THROW(DecodeFrame(rgb.data(), rgb.size(), 0, 1, RawFormat::kMono8), Error);
}

// A mosaic of a field that is linear in x and y (different per colour): bilinear demosaicing
// reproduces every colour exactly away from the border (each missing value is the mean of
// neighbours placed symmetrically around the pixel), and a flat colour exactly everywhere.
TEST(PixelDecodeTest, BayerDemosaicIsExactForLinearFields) {
  const int w = 12, h = 10;
  auto field = [](int c, int x, int y) { return 20 + 40 * c + 3 * x + 2 * y + c * (x - y); };
  for (RawFormat f :
       {RawFormat::kBayerRG8, RawFormat::kBayerGR8, RawFormat::kBayerGB8, RawFormat::kBayerBG8}) {
    std::vector<uint8_t> mosaic(w * h), flat(w * h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const int c = BayerColour(f, x, y);
        mosaic[y * w + x] = static_cast<uint8_t>(field(c, x, y));
        flat[y * w + x] = static_cast<uint8_t>(50 + 70 * c);
      }
    Image im = DecodeFrame(mosaic.data(), mosaic.size(), w, h, f);
    Image fl = DecodeFrame(flat.data(), flat.size(), w, h, f);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) {
          EXPECT_FLOAT_EQ(fl.at(x, y, c), 50 + 70 * c) << RawFormatName(f);
          if (x > 0 && y > 0 && x < w - 1 && y < h - 1) {
            EXPECT_FLOAT_EQ(im.at(x, y, c), field(c, x, y))
                << RawFormatName(f) << " " << x << "," << y << " c" << c;
          }
        }
    // Each colour appears once per 2x2 cell except green twice.
    int count[3] = {0, 0, 0};
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 2; ++x) ++count[BayerColour(f, x, y)];
    EXPECT_EQ(count[0], 1);
    EXPECT_EQ(count[1], 2);
    EXPECT_EQ(count[2], 1);
  }
  EXPECT_EQ(BayerColour(RawFormat::kBayerRG8, 0, 0), 0);
  EXPECT_EQ(BayerColour(RawFormat::kBayerBG8, 0, 0), 2);
  EXPECT_EQ(BayerColour(RawFormat::kBayerGR8, 1, 0), 0);
  EXPECT_EQ(BayerColour(RawFormat::kBayerGB8, 0, 1), 0);
}

// The fast interior path equals the definition (mean of the same-coloured pixels in the
// clipped 3x3 window) on random data, for every pattern; odd sizes exercise the borders.
TEST(PixelDecodeTest, BayerDemosaicMatchesItsDefinition) {
  const int w = 9, h = 7;
  std::vector<uint8_t> raw(w * h);
  uint32_t state = 12345;
  for (uint8_t& v : raw) {
    state = state * 1664525u + 1013904223u;
    v = static_cast<uint8_t>(state >> 24);
  }
  for (RawFormat f :
       {RawFormat::kBayerRG8, RawFormat::kBayerGR8, RawFormat::kBayerGB8, RawFormat::kBayerBG8}) {
    Image im = DecodeFrame(raw.data(), raw.size(), w, h, f);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        double sum[3] = {0, 0, 0};
        int count[3] = {0, 0, 0};
        for (int yy = y - 1; yy <= y + 1; ++yy)
          for (int xx = x - 1; xx <= x + 1; ++xx) {
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            sum[BayerColour(f, xx, yy)] += raw[yy * w + xx];
            ++count[BayerColour(f, xx, yy)];
          }
        for (int c = 0; c < 3; ++c) {
          const double want = c == BayerColour(f, x, y) ? raw[y * w + x] : sum[c] / count[c];
          EXPECT_NEAR(im.at(x, y, c), want, 1e-4) << RawFormatName(f) << " " << x << "," << y;
        }
      }
  }
}

TEST(FrameIdTest, GapsAndSixteenBitWrap) {
  EXPECT_EQ(MissingFrameIds(10, 11), 0u);
  EXPECT_EQ(MissingFrameIds(10, 14), 3u);
  EXPECT_EQ(MissingFrameIds(65535, 1), 0u);  // 65535 -> 1: 0 is skipped, nothing lost
  EXPECT_EQ(MissingFrameIds(65534, 1), 1u);  // 65535 lost
  EXPECT_EQ(MissingFrameIds(65535, 3), 2u);  // 1 and 2 lost
  EXPECT_EQ(MissingFrameIds(65000, 2), 535u + 1u);
  EXPECT_EQ(MissingFrameIds(7, 7), 0u);
  EXPECT_EQ(MissingFrameIds(1ull << 40, 5), 0u);  // 64-bit counter restarted
  // A step back of more than half the 16-bit range: a restarted counter or a late frame, not a
  // wrap (the loopback throughput test once counted 65,443 dropped frames so).
  EXPECT_EQ(MissingFrameIds(93, 1), 0u);
  EXPECT_EQ(MissingFrameIds(30000, 5), 0u);
}

TEST(AravisOptionsTest, ValidateExplainsBadValues) {
  AravisOptions ok;
  EXPECT_NO_THROW(ok.Validate());
  auto bad = [](auto edit, const std::string& word) {
    AravisOptions o;
    edit(o);
    try {
      o.Validate();
      ADD_FAILURE() << "accepted bad " << word;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  bad([](AravisOptions& o) { o.pixel_format = "YUV422"; }, "pixel_format");
  bad([](AravisOptions& o) { o.buffers = 1; }, "buffers");
  bad([](AravisOptions& o) { o.buffers = 1000; }, "buffers");
  bad([](AravisOptions& o) { o.timeout_s = 0; }, "timeout_s");
  bad([](AravisOptions& o) { o.timeout_s = std::nan(""); }, "timeout_s");
  bad([](AravisOptions& o) { o.settle_frames = -1; }, "settle_frames");
  bad([](AravisOptions& o) { o.frame_rate = -5; }, "frame_rate");
  bad([](AravisOptions& o) { o.width = 640; }, "region");
  bad([](AravisOptions& o) { o.raw_gain_db_per_step = 0; }, "raw_gain_db_per_step");
  AravisOptions o;
  o.buffers = 0;
  EXPECT_THROW(OpenAravisCamera(o), Error);  // validated before touching the bus
}

TEST(AravisCameraTest, UnknownDeviceIsAClearError) {
  AravisOptions o;
  o.device_id = "NoSuchVendor-NoSuchCamera-12345";
  o.enable_fake_interface = true;
  try {
    OpenAravisCamera(o);
    FAIL() << "opened a camera that does not exist";
  } catch (const DeviceError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("NoSuchVendor-NoSuchCamera-12345"), std::string::npos) << msg;
    EXPECT_NE(msg.find("Fake_1"), std::string::npos) << "lists the cameras seen: " << msg;
  }
}

TEST(AravisCameraTest, NoCameraIsAClearError) {
  if (!ListAravisDevices(false).empty()) GTEST_SKIP() << "a real camera is connected";
  try {
    OpenAravisCamera(AravisOptions{});  // first camera, Fake excluded
    FAIL() << "opened a camera on an empty bus";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("no camera found"), std::string::npos) << e.what();
  }
}

TEST(AravisCameraTest, ListsTheFakeCameraOnlyWhenAsked) {
  bool found = false;
  for (const AravisDeviceInfo& d : ListAravisDevices(true)) {
    if (d.id != "Fake_1") continue;
    found = true;
    EXPECT_EQ(d.protocol, "Fake");
    EXPECT_EQ(d.vendor, "Aravis");
    EXPECT_EQ(d.model, "Fake");
  }
  EXPECT_TRUE(found);
  for (const AravisDeviceInfo& d : ListAravisDevices(false)) EXPECT_NE(d.protocol, "Fake");
}

// --- The driver against the in-process Fake camera ---

ArvFakeCamera* FakeOf(AravisCamera& cam) {
  return arv_fake_device_get_fake_camera(ARV_FAKE_DEVICE(arv_camera_get_device(cam.impl().camera)));
}

AravisOptions FakeOptions(const std::string& format) {
  AravisOptions o;
  o.device_id = "Fake_1";
  o.enable_fake_interface = true;
  o.pixel_format = format;
  o.trigger = AravisTrigger::kFreeRun;
  o.frame_rate = 200;
  o.settle_frames = 1;
  o.width = 16;
  o.height = 12;
  o.buffers = 4;
  return o;
}

// Writes a pattern that depends on the pixel format and stamps exposure (us) and raw gain
// into the first pixels, so a test can see which settings a delivered frame was made with.
void TestPattern(ArvBuffer* buffer, void*, guint32 exposure_us, guint32 gain,
                 ArvPixelFormat format) {
  const int w = arv_buffer_get_image_width(buffer), h = arv_buffer_get_image_height(buffer);
  auto* d = static_cast<uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (format == ARV_PIXEL_FORMAT_MONO_16) {
        // Pixel 0: exposure in us; pixel 1: gain; others: a ramp.
        const unsigned v = i == 0 ? exposure_us : i == 1 ? gain * 257 : (x * 1000 + y * 10);
        d[2 * i] = v & 0xFF;
        d[2 * i + 1] = (v >> 8) & 0xFF;
      } else if (format == ARV_PIXEL_FORMAT_RGB_8_PACKED) {
        d[3 * i] = x;
        d[3 * i + 1] = y;
        d[3 * i + 2] = x + y;
      } else if (format == ARV_PIXEL_FORMAT_MONO_8) {
        d[i] = (x * 7 + y * 13) & 0xFF;
      } else {  // BayerRG8: a flat colour
        d[i] = BayerColour(RawFormat::kBayerRG8, x, y) * 100 + 20;
      }
    }
}

TEST(AravisFakeTest, DecodesEveryFormatThroughTheStream) {
  for (const char* format : {"Mono8", "RGB8", "BayerRG8", "Mono16"}) {
    AravisCamera cam(FakeOptions(format));
    arv_fake_camera_set_fill_pattern(FakeOf(cam), TestPattern, nullptr);
    cam.DiscardInFlight();
    CapturedFrame f = cam.Grab();
    ASSERT_EQ(f.image.width, 16) << format;
    ASSERT_EQ(f.image.height, 12) << format;
    EXPECT_EQ(f.image.units, PixelUnits::kDigital);
    EXPECT_EQ(cam.PixelFormat(), format);
    EXPECT_FALSE(cam.SoftwareTriggered());
    for (int y = 0; y < 12; ++y)
      for (int x = 0; x < 16; ++x)
        for (int c = 0; c < 3; ++c) {
          const float v = f.image.at(x, y, c);
          const std::string fmt = format;
          float want = v;
          if (fmt == "Mono8") want = (x * 7 + y * 13) & 0xFF;
          if (fmt == "RGB8") want = c == 0 ? x : c == 1 ? y : x + y;
          if (fmt == "BayerRG8") want = c * 100 + 20;
          if (fmt == "Mono16" && x + y * 16 >= 2) want = (x * 1000 + y * 10) / 257.0;
          EXPECT_FLOAT_EQ(v, want) << fmt << " " << x << "," << y << " c" << c;
        }
    arv_fake_camera_set_fill_pattern(FakeOf(cam), nullptr, nullptr);
  }
}

// After each exposure change the delivered frame carries the new exposure (the Fake camera
// reads its register when it fills a buffer), although the camera free-runs at 200 fps with
// buffers queued: the driver discards what was in flight. Also reads back gain (GainRaw, 1 dB
// per step) and exposure quantised to whole microseconds.
TEST(AravisFakeTest, FramesAfterAChangeUseTheNewSettings) {
  AravisCamera cam(FakeOptions("Mono16"));
  arv_fake_camera_set_fill_pattern(FakeOf(cam), TestPattern, nullptr);
  for (int k = 0; k < 7; ++k) {
    const double want = 1e-4 * std::pow(2.0, k) + 0.3e-6;
    const double applied = cam.SetExposure(want);
    EXPECT_NEAR(applied, want, 0.5e-6);
    EXPECT_NEAR(applied * 1e6, std::round(applied * 1e6), 1e-6);      // whole microseconds
    const double gain = cam.SetGain(std::pow(10.0, (k % 4) / 20.0));  // k % 4 dB
    EXPECT_NEAR(gain, std::pow(10.0, (k % 4) / 20.0), 1e-12);
    CapturedFrame f = cam.Grab();
    EXPECT_EQ(f.exposure_s, applied);
    EXPECT_EQ(f.gain, gain);
    // The stamp is an integer number of us; float storage of x/257 keeps it within 1e-3.
    EXPECT_NEAR(f.image.at(0, 0, 0) * 257.0, applied * 1e6, 1e-3) << "frame " << k;
    EXPECT_DOUBLE_EQ(f.image.at(1, 0, 0), (k % 4)) << "frame " << k;
    // Mid-exposure time: host clock at buffer completion minus half the exposure.
    EXPECT_LT(std::abs(f.utc.UnixSeconds() - NowUtc().UnixSeconds()), 5.0);
  }
  // Clamped to the Fake camera's ranges: exposure 10 us .. 10 s, GainRaw 0..10 (x1 .. x3.16).
  EXPECT_DOUBLE_EQ(cam.SetExposure(1e-7), 10e-6);
  EXPECT_DOUBLE_EQ(cam.SetGain(100), std::pow(10.0, 0.5));
  EXPECT_DOUBLE_EQ(cam.SetGain(0.1), 1.0);
  EXPECT_THROW(cam.SetExposure(0), DeviceError);
  EXPECT_THROW(cam.SetExposure(std::nan("")), DeviceError);
  EXPECT_THROW(cam.SetGain(-1), DeviceError);
  EXPECT_THROW(cam.SetNdFilter(-1), DeviceError);
  cam.SetNdFilter(3);
  EXPECT_EQ(cam.Grab().nd_density, 3);
  EXPECT_EQ(cam.ViewCount(Target::kArchitecture), 1);
  EXPECT_NO_THROW(cam.Aim(Target::kSun, 0));
  // The in-process Fake camera fills buffers only when one is free: no id is ever skipped
  // (its ids start near 65400 and wrap 65535 -> 1 within the first few hundred frames).
  EXPECT_EQ(cam.DroppedFrames(), 0u);
  EXPECT_GT(cam.Stats().delivered, 7u);
  EXPECT_GT(cam.Stats().discarded, 0u);
  EXPECT_EQ(cam.Stats().incomplete, 0u);
  arv_fake_camera_set_fill_pattern(FakeOf(cam), nullptr, nullptr);
}

// The Fake camera's 16-bit frame ids start near 65400 and wrap 65535 -> 1: grabbing across
// the wrap counts no dropped frame.
TEST(AravisFakeTest, FrameIdWrapIsNotADrop) {
  AravisOptions o = FakeOptions("Mono8");
  o.frame_rate = 1000;
  AravisCamera cam(o);
  bool wrapped = false;
  uint64_t previous = 0;
  for (int i = 0; i < 2000 && !wrapped; ++i) {
    cam.Grab();
    const uint64_t id = cam.Stats().last_frame_id;
    EXPECT_NE(id, 0u);
    if (i > 0 && id < previous) {
      wrapped = true;
      EXPECT_EQ(previous, 65535u);
      EXPECT_EQ(id, 1u);
    }
    previous = id;
  }
  EXPECT_TRUE(wrapped) << "no wrap within 2000 frames (last id " << previous << ")";
  EXPECT_EQ(cam.DroppedFrames(), 0u);
}

TEST(AravisFakeTest, UnsupportedFormatAndRegionAreDeviceErrors) {
  AravisOptions o = FakeOptions("BGR8");  // decodable, but the Fake camera lacks it
  try {
    AravisCamera cam(o);
    FAIL() << "opened with a format the camera lacks";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("RGB8"), std::string::npos) << "lists offered formats";
    EXPECT_NE(std::string(e.what()).find("Fake_1"), std::string::npos) << e.what();
  }
  AravisCamera cam(FakeOptions("Mono8"));
  EXPECT_THROW(cam.SetRegion(0, 10), DeviceError);
  cam.SetRegion(32, 8);
  CapturedFrame f = cam.Grab();
  EXPECT_EQ(f.image.width, 32);
  EXPECT_EQ(f.image.height, 8);
}

}  // namespace
}  // namespace rouen
