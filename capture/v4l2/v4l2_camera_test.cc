#include "capture/v4l2/v4l2_camera.h"

#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <memory>
#include <string>

#include "capture/v4l2/fake_v4l2.h"
#include "capture/v4l2/jpeg_codec.h"
#include "capture/v4l2/pixel_format.h"

namespace rouen {
namespace {

using Fill = FakeV4l2Options::Fill;

struct Rig {
  std::shared_ptr<FakeV4l2Device> fake;
  std::unique_ptr<V4l2Camera> cam;
};

}  // namespace

// Names for parameterised test output (ADL finds it in the enum's namespace).
void PrintTo(FakeV4l2Options::Fill f, std::ostream* os) {
  *os << (f == FakeV4l2Options::Fill::kOnQueue ? "kOnQueue" : "kOnPoll");
}

namespace {

Rig Open(FakeV4l2Options fo = {}, V4l2Options o = {}) {
  Rig r;
  r.fake = std::make_shared<FakeV4l2Device>(fo);
  r.cam = OpenV4l2Camera(o, r.fake);
  return r;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const DeviceError& e) {
    return std::string("DeviceError: ") + e.what();
  } catch (const Error& e) {
    return std::string("Error: ") + e.what();
  }
  return "no error";
}

// A pixel at least `r` pixels inside its 16x16 patch of the fake's scene (and the image).
bool Interior(int x, int y, int w, int h, int r) {
  return x % 16 >= r && x % 16 <= 15 - r && y % 16 >= r && y % 16 <= 15 - r && x + r < w &&
         y + r < h;
}

// Largest |decoded - truth| per channel over the pixels `Interior(.., r)`.
std::array<double, 3> MaxError(const Image& img, const FakeV4l2Frame& truth, int r) {
  std::array<double, 3> worst = {0, 0, 0};
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      if (!Interior(x, y, img.width, img.height, r)) continue;
      for (int c = 0; c < 3; ++c) {
        const double t = truth.rgb[(static_cast<size_t>(y) * truth.width + x) * 3 + c];
        worst[c] = std::max(worst[c], std::abs(img.at(x, y, c) - t));
      }
    }
  return worst;
}

bool IsBayerCase(uint32_t f) { return f == V4L2_PIX_FMT_SGRBG8 || f == V4L2_PIX_FMT_SRGGB8; }

struct FormatCase {
  std::string name;
  uint32_t fourcc;
};
void PrintTo(const FormatCase& f, std::ostream* os) { *os << f.name; }

class V4l2Formats : public ::testing::TestWithParam<std::tuple<FormatCase, Fill>> {};

// The whole protocol (open, format, controls, mmap streaming, grab, close) in each format,
// and the decoded pixels against what the fake encoded.
TEST_P(V4l2Formats, DecodesWhatTheFakeEncoded) {
  const auto& [fc, fill] = GetParam();
  if (fc.fourcc == V4L2_PIX_FMT_MJPEG && !v4l2_internal::JpegAvailable()) {
    GTEST_SKIP() << "built without libjpeg: MJPEG not supported";
  }
  FakeV4l2Options fo;
  fo.fill = fill;
  fo.bytesperline_padding = 24;  // the driver must honour bytesperline
  fo.control_latency_frames = 2;
  V4l2Options o;
  o.pixel_format = fc.name;
  o.control_latency_frames = 2;
  Rig r = Open(fo, o);
  EXPECT_EQ(r.cam->pixel_format(), v4l2_internal::FourccToString(fc.fourcc));
  EXPECT_EQ(r.cam->width(), 160);  // the largest offered
  EXPECT_EQ(r.cam->height(), 120);
  const double applied = r.cam->SetExposure(0.008);
  for (int i = 0; i < 3; ++i) {
    const CapturedFrame f = r.cam->Grab();
    ASSERT_EQ(f.image.width, 160);
    ASSERT_EQ(f.image.height, 120);
    ASSERT_EQ(f.image.channels, 3);
    EXPECT_EQ(f.image.units, PixelUnits::kDigital);
    EXPECT_DOUBLE_EQ(f.exposure_s, applied);
    const auto truth = r.fake->Frame(r.cam->last_sequence());
    ASSERT_TRUE(truth.has_value());
    EXPECT_FALSE(truth->auto_exposure);
    EXPECT_FALSE(truth->auto_white_balance);
    EXPECT_DOUBLE_EQ(truth->exposure_s, applied);  // the latency was honoured
    for (float v : f.image.data) ASSERT_TRUE(v >= 0 && v <= 255);
    std::array<double, 3> tol{}, err{};
    if (fc.fourcc == V4L2_PIX_FMT_GREY) {
      err = MaxError(f.image, *truth, 0);  // replicated: exact
      tol = {0, 0, 0};
    } else if (IsBayerCase(fc.fourcc)) {
      // Bilinear demosaicing is exact inside a flat patch (one pixel away from its edge).
      err = MaxError(f.image, *truth, 1);
      tol = {0, 0, 0};
    } else if (fc.fourcc == V4L2_PIX_FMT_YUYV) {
      // Limited range: Y' and Cb/Cr rounded to integers (+-0.5 each), so
      // R +- 0.5*255/219 + 0.5*1.402*255/224, G +- 0.5*255/219 + 0.5*(0.344+0.714)*255/224,
      // B +- 0.5*255/219 + 0.5*1.772*255/224 (pixel pairs never straddle a patch edge).
      err = MaxError(f.image, *truth, 0);
      const double ys = 0.5 * 255 / 219, cs = 0.5 * 255 / 224;
      tol = {ys + 1.402 * cs, ys + (0.344136 + 0.714136) * cs, ys + 1.772 * cs};
      for (double& t : tol) t += 1e-4;
    } else {
      // JPEG: Y'CbCr each off by <= 0.5 (colour conversion) + 0.125 (DC quantisation at
      // quality 95: step 2 on 8x the level) + 0.5 (IDCT rounding); then the matrix and a
      // final rounding of 0.5. Two pixels from patch edges (chroma upsampling blends across).
      err = MaxError(f.image, *truth, 2);
      const double e = 1.125;
      tol = {e + 1.402 * e + 0.5, e + (0.344136 + 0.714136) * e + 0.5, e + 1.772 * e + 0.5};
    }
    for (int c = 0; c < 3; ++c) EXPECT_LE(err[c], tol[c]) << fc.name << " channel " << c;
  }
  r.cam.reset();
  EXPECT_EQ(r.fake->OpenFds(), 0);
  EXPECT_EQ(r.fake->Mappings(), 0);
  EXPECT_EQ(r.fake->AllocatedBuffers(), 0);
  EXPECT_FALSE(r.fake->Streaming());
  EXPECT_TRUE(r.fake->Misuse().empty()) << r.fake->Misuse().front();
}

INSTANTIATE_TEST_SUITE_P(
    AllFormats, V4l2Formats,
    ::testing::Combine(::testing::Values(FormatCase{"YUYV", V4L2_PIX_FMT_YUYV},
                                         FormatCase{"MJPG", V4L2_PIX_FMT_MJPEG},
                                         FormatCase{"GREY", V4L2_PIX_FMT_GREY},
                                         FormatCase{"SGRBG8", V4L2_PIX_FMT_SGRBG8}),
                       ::testing::Values(Fill::kOnQueue, Fill::kOnPoll)),
    [](const auto& info) {
      return std::get<0>(info.param).name +
             (std::get<1>(info.param) == Fill::kOnQueue ? "_OnQueue" : "_OnPoll");
    });

TEST(V4l2Camera, YuyvFullRangeAndBayerBordersStayInTheirNeighbourhood) {
  FakeV4l2Options fo;
  fo.yuyv_quantization = V4L2_QUANTIZATION_FULL_RANGE;
  V4l2Options o;
  o.pixel_format = "YUYV";
  {
    Rig r = Open(fo, o);
    const CapturedFrame f = r.cam->Grab();
    const auto truth = r.fake->Frame(r.cam->last_sequence());
    const auto err = MaxError(f.image, *truth, 0);
    // Full range: Y' +-0.5, Pb/Pr +-0.5 code values, all on the 255 scale.
    EXPECT_LE(err[0], 0.5 + 1.402 * 0.5 + 1e-4);
    EXPECT_LE(err[1], 0.5 + (0.344136 + 0.714136) * 0.5 + 1e-4);
    EXPECT_LE(err[2], 0.5 + 1.772 * 0.5 + 1e-4);
  }
  o.pixel_format = "SGRBG8";
  Rig r = Open(fo, o);
  const CapturedFrame f = r.cam->Grab();
  const auto truth = r.fake->Frame(r.cam->last_sequence());
  // Every output value is a mean of same-colour samples in the 3x3 neighbourhood.
  for (int y = 0; y < f.image.height; ++y)
    for (int x = 0; x < f.image.width; ++x)
      for (int c = 0; c < 3; ++c) {
        double lo = 255, hi = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= f.image.width || yy >= f.image.height) continue;
            const double t = truth->rgb[(static_cast<size_t>(yy) * truth->width + xx) * 3 + c];
            lo = std::min(lo, t);
            hi = std::max(hi, t);
          }
        ASSERT_GE(f.image.at(x, y, c), lo - 1e-4);
        ASSERT_LE(f.image.at(x, y, c), hi + 1e-4);
      }
}

TEST(V4l2Camera, ChoosesTheBestFormatAndLargestSize) {
  const std::vector<std::pair<std::vector<uint32_t>, std::string>> cases = {
      {{V4L2_PIX_FMT_MJPEG, V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_SGRBG8}, "GRBG"},
      {{V4L2_PIX_FMT_MJPEG, V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV}, "YUYV"},
      {{V4L2_PIX_FMT_MJPEG, V4L2_PIX_FMT_GREY}, "GREY"},
  };
  for (const auto& [formats, expected] : cases) {
    FakeV4l2Options fo;
    fo.pixel_formats = formats;
    fo.frame_sizes = {{64, 48}, {160, 120}, {96, 64}};
    Rig r = Open(fo);
    EXPECT_EQ(r.cam->pixel_format(), expected);
    EXPECT_EQ(r.cam->width(), 160);
    EXPECT_EQ(r.cam->height(), 120);
  }
  if (v4l2_internal::JpegAvailable()) {
    FakeV4l2Options fo;
    fo.pixel_formats = {V4L2_PIX_FMT_MJPEG};
    EXPECT_EQ(Open(fo).cam->pixel_format(), "MJPG");
  }
  V4l2Options o;
  o.width = 64;
  o.height = 48;
  Rig r = Open({}, o);
  EXPECT_EQ(r.cam->width(), 64);
  EXPECT_EQ(r.cam->Grab().image.width, 64);
}

TEST(V4l2Camera, StepwiseFrameSizes) {
  FakeV4l2Options fo;
  fo.stepwise_sizes = true;  // 32x24 .. 192x144 in steps of 16x8
  Rig r = Open(fo);
  EXPECT_EQ(r.cam->width(), 192);
  EXPECT_EQ(r.cam->height(), 144);
  EXPECT_EQ(r.cam->Grab().image.height, 144);
  V4l2Options o;
  o.width = 96;
  o.height = 64;
  EXPECT_EQ(Open(fo, o).cam->width(), 96);
  o.width = 100;  // off the 16-pixel grid: the driver would get 96
  std::string e = ErrorOf([&] { Open(fo, o); });
  EXPECT_NE(e.find("asked for GRBG 100x64, the driver set GRBG 96x64"), std::string::npos) << e;
  o.width = 400;
  e = ErrorOf([&] { Open(fo, o); });
  EXPECT_NE(e.find("outside the camera's range 32x24 .. 192x144"), std::string::npos) << e;
  const auto list = ListV4l2Devices(*r.fake);
  EXPECT_EQ(list[0].formats[0].sizes, (std::vector<std::pair<int, int>>{{32, 24}, {192, 144}}));
}

TEST(V4l2Camera, UsesTheBufferCountTheDriverGrants) {
  FakeV4l2Options fo;
  fo.max_buffers = 2;
  V4l2Options o;
  o.buffers = 6;
  Rig r = Open(fo, o);
  EXPECT_EQ(r.cam->buffer_count(), 2);
  for (int i = 0; i < 4; ++i) r.cam->Grab();
  EXPECT_TRUE(r.fake->Misuse().empty());
  fo.max_buffers = 1;
  const std::string e = ErrorOf([&] { Open(fo, o); });
  EXPECT_NE(e.find("/dev/video0: the driver granted 1 streaming buffers"), std::string::npos) << e;
}

TEST(V4l2Camera, RefusesFormatsAndSizesTheCameraLacks) {
  FakeV4l2Options fo;
  fo.pixel_formats = {V4L2_PIX_FMT_YUYV};
  V4l2Options o;
  o.pixel_format = "GREY";
  std::string e = ErrorOf([&] { Open(fo, o); });
  EXPECT_NE(e.find("DeviceError: /dev/video0: pixel format GREY not offered"), std::string::npos)
      << e;
  EXPECT_NE(e.find("YUYV"), std::string::npos) << e;
  o.pixel_format = "";
  o.width = 640;
  o.height = 480;
  e = ErrorOf([&] { Open(fo, o); });
  EXPECT_NE(e.find("640x480 not offered"), std::string::npos) << e;
  EXPECT_NE(e.find("160x120"), std::string::npos) << e;
  fo.pixel_formats = {V4L2_PIX_FMT_RGB565};
  e = ErrorOf([&] { Open(fo); });
  EXPECT_NE(e.find("no pixel format this driver can decode"), std::string::npos) << e;
}

TEST(V4l2Camera, OpensWithManualControls) {
  Rig r = Open();
  EXPECT_EQ(r.fake->Control(V4L2_CID_EXPOSURE_AUTO), V4L2_EXPOSURE_MANUAL);
  EXPECT_EQ(r.fake->Control(V4L2_CID_EXPOSURE_AUTO_PRIORITY), 0);
  EXPECT_EQ(r.fake->Control(V4L2_CID_AUTO_WHITE_BALANCE), 0);
  EXPECT_EQ(r.cam->ViewCount(Target::kSky), 1);
  r.cam->Aim(Target::kSky, 0);  // nothing to do
  // A camera without the optional controls opens too.
  FakeV4l2Options fo;
  fo.has_exposure_auto_priority = false;
  fo.has_auto_white_balance = false;
  fo.has_gain = false;
  Rig bare = Open(fo);
  EXPECT_DOUBLE_EQ(bare.cam->SetGain(4), 1.0);
  EXPECT_DOUBLE_EQ(bare.cam->Controls()[1].max, 1.0);
  EXPECT_TRUE(bare.fake->Misuse().empty());
}

TEST(V4l2Camera, ExposureIsClampedAndQuantised) {
  FakeV4l2Options fo;
  fo.exposure_min = 3;
  fo.exposure_max = 2047;
  fo.exposure_step = 5;  // grid 3, 8, 13, ... 2043
  fo.control_latency_frames = V4l2Options{}.control_latency_frames;
  Rig r = Open(fo);
  const auto controls = r.cam->Controls();
  EXPECT_EQ(controls[0].name, "exposure_s");
  EXPECT_NEAR(controls[0].min, 3e-4, 1e-12);
  EXPECT_NEAR(controls[0].max, 0.2043, 1e-12);
  EXPECT_NEAR(r.cam->SetExposure(1e-6), 3e-4, 1e-12);      // below the range
  EXPECT_NEAR(r.cam->SetExposure(100), 0.2043, 1e-12);     // above: the last grid value
  EXPECT_NEAR(r.cam->SetExposure(0.0101), 0.0103, 1e-12);  // 101 -> grid 103
  EXPECT_NEAR(r.cam->SetExposure(0.0100), 0.0098, 1e-12);  // 100 -> grid 98
  EXPECT_EQ(r.fake->Control(V4L2_CID_EXPOSURE_ABSOLUTE), 98);
  EXPECT_NEAR(r.cam->Controls()[0].value, 0.0098, 1e-12);
  EXPECT_NE(ErrorOf([&] { r.cam->SetExposure(-1); }).find("not a positive time"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { r.cam->SetExposure(NAN); }).find("DeviceError"), std::string::npos);
  // A camera that silently caps exposure (frame interval): the driver reports the cap.
  fo.exposure_step = 1;
  fo.exposure_cap = 333;
  Rig capped = Open(fo);
  EXPECT_NEAR(capped.cam->SetExposure(0.1), 0.0333, 1e-12);
  EXPECT_NEAR(capped.cam->Grab().exposure_s, 0.0333, 1e-12);
  EXPECT_NEAR(capped.fake->Frame(capped.cam->last_sequence())->exposure_s, 0.0333, 1e-12);
}

TEST(V4l2Camera, GainMapsLinearlyOntoTheControlRange) {
  FakeV4l2Options fo;
  fo.gain_min = 0;
  fo.gain_max = 255;
  fo.gain_at_max = 16;
  fo.control_latency_frames = 1;
  V4l2Options o;
  o.gain_at_max = 16;
  o.control_latency_frames = 1;
  Rig r = Open(fo, o);
  // gain = 1 + raw / 255 * 15: gain 2 -> raw 17 exactly; 3 -> raw 34.
  EXPECT_NEAR(r.cam->SetGain(2), 2.0, 1e-12);
  EXPECT_EQ(r.fake->Control(V4L2_CID_GAIN), 17);
  // 2.03 -> raw 1.03 / 15 * 255 = 17.51 -> 18 -> gain 1 + 18 * 15 / 255.
  EXPECT_NEAR(r.cam->SetGain(2.03), 1 + 18.0 * 15 / 255, 1e-12);
  EXPECT_NEAR(r.cam->SetGain(100), 16, 1e-12);
  EXPECT_NEAR(r.cam->SetGain(0.1), 1, 1e-12);
  EXPECT_NEAR(r.cam->SetGain(3), 3, 1e-12);
  const CapturedFrame f = r.cam->Grab();
  EXPECT_NEAR(f.gain, 3, 1e-12);
  EXPECT_NEAR(r.fake->Frame(r.cam->last_sequence())->gain, 3, 1e-12);
}

TEST(V4l2Camera, FrameMetadata) {
  Rig r = Open();
  r.cam->SetNdFilter(2.5);
  EXPECT_DOUBLE_EQ(r.cam->NdFilter(), 2.5);
  EXPECT_NE(ErrorOf([&] { r.cam->SetNdFilter(-1); }).find("ND density"), std::string::npos);
  const double e = r.cam->SetExposure(0.02);
  const UtcTime before = NowUtc();
  const CapturedFrame f = r.cam->Grab();
  const UtcTime after = NowUtc();
  EXPECT_DOUBLE_EQ(f.nd_density, 2.5);
  EXPECT_DOUBLE_EQ(f.exposure_s, e);
  EXPECT_FALSE(f.hdr);
  // Mid-exposure: the fake's start-of-frame stamp (taken during Grab) plus half the
  // exposure, so between `before` and `after` + e/2 (give 5 ms for the clock offset).
  EXPECT_GE(f.utc.ns, before.ns + static_cast<int64_t>(e / 2 * 1e9) - 5000000);
  EXPECT_LE(f.utc.ns, after.ns + static_cast<int64_t>(e / 2 * 1e9) + 5000000);
  // Precisely: the fake's start-of-frame stamp + e/2, moved by realtime - monotonic.
  timespec m, rt;
  clock_gettime(CLOCK_MONOTONIC, &m);
  clock_gettime(CLOCK_REALTIME, &rt);
  const int64_t offset =
      (static_cast<int64_t>(rt.tv_sec) - m.tv_sec) * 1000000000 + (rt.tv_nsec - m.tv_nsec);
  const int64_t expected = r.fake->Frame(r.cam->last_sequence())->timestamp_ns +
                           static_cast<int64_t>(e / 2 * 1e9) + offset;
  EXPECT_NEAR(static_cast<double>(f.utc.ns - expected), 0.0, 1e6);  // 1 ms
}

// Brightness follows exposure x gain end to end (fake sensor, driver mapping, decoding).
TEST(V4l2Camera, BrightnessFollowsExposureTimesGain) {
  FakeV4l2Options fo;
  fo.control_latency_frames = 2;
  V4l2Options o;
  o.pixel_format = "GREY";
  Rig r = Open(fo, o);
  const auto mean = [](const Image& im) {
    double s = 0;
    for (float v : im.data) s += v;
    return s / im.data.size();
  };
  // Reference: 2 ms at gain 1 (means ~17 DN, nothing saturates even at 8x).
  const double e1 = r.cam->SetExposure(0.002), g1 = r.cam->SetGain(1);
  const double m1 = mean(r.cam->Grab().image);
  const double e2 = r.cam->SetExposure(0.004), g2 = r.cam->SetGain(1 + 17 * 15.0 / 255);
  const double m2 = mean(r.cam->Grab().image);
  // Rounding each pixel to an integer moves a mean of ~17 DN by well under 0.5 DN.
  EXPECT_NEAR(m2 / m1, (e2 * g2) / (e1 * g1), 0.5 / m1 * 2);
  EXPECT_NEAR(g2, 2.0, 1e-12);
}

// The frame Grab() returns reflects the exposure just set, in both fill modes and for
// several latencies; a driver discarding too few frames would return the old exposure.
TEST(V4l2Camera, ControlLatencyIsHonoured) {
  for (Fill fill : {Fill::kOnQueue, Fill::kOnPoll}) {
    for (int latency : {0, 1, 4}) {
      FakeV4l2Options fo;
      fo.fill = fill;
      fo.control_latency_frames = latency;
      V4l2Options o;
      o.control_latency_frames = latency;
      o.buffers = 3;
      Rig r = Open(fo, o);
      for (double e : {0.002, 0.009, 0.004}) {
        const double applied = r.cam->SetExposure(e);
        const CapturedFrame f = r.cam->Grab();
        const auto truth = r.fake->Frame(r.cam->last_sequence());
        EXPECT_DOUBLE_EQ(truth->exposure_s, applied) << "latency " << latency;
        EXPECT_DOUBLE_EQ(f.exposure_s, applied);
      }
      EXPECT_TRUE(r.fake->Misuse().empty());
    }
  }
  // The check bites: a driver told a shorter latency than the camera's returns stale frames.
  FakeV4l2Options fo;
  fo.control_latency_frames = 4;
  V4l2Options o;
  o.control_latency_frames = 1;
  Rig r = Open(fo, o);
  r.cam->Grab();
  const double applied = r.cam->SetExposure(0.002);
  r.cam->Grab();
  EXPECT_NE(r.fake->Frame(r.cam->last_sequence())->exposure_s, applied);
}

// Dropped frames (sequence gaps) still count as frames the control change has aged by; the
// driver never returns a stale frame, and the measured latency is exact or, when a drop hits
// the very frame the change shows in, one frame conservative.
TEST(V4l2Camera, DroppedFramesAreCountedConservatively) {
  for (Fill fill : {Fill::kOnQueue, Fill::kOnPoll}) {
    FakeV4l2Options fo;
    fo.fill = fill;
    fo.control_latency_frames = 3;
    for (int k = 4; k < 400; k += 6) fo.dropped_frames.push_back(k);
    V4l2Options o;
    o.control_latency_frames = 3;
    Rig r = Open(fo, o);
    for (double e : {0.002, 0.009, 0.004, 0.011, 0.003, 0.007}) {
      const double applied = r.cam->SetExposure(e);
      r.cam->Grab();
      EXPECT_DOUBLE_EQ(r.fake->Frame(r.cam->last_sequence())->exposure_s, applied);
    }
    EXPECT_GT(r.fake->FramesProduced(), 10);  // so the drops at 4 and 10 happened
    const int measured = MeasureControlLatency(*r.cam);
    EXPECT_TRUE(measured == 3 || measured == 4) << measured;
    EXPECT_TRUE(r.fake->Misuse().empty());
  }
}

// A camera that ramps a new exposure in over 3 frames after a 2-frame latency: the last
// ramp frame (index 2 + 3 - 1 = 4 after the change) is the first at the new level.
TEST(V4l2Camera, RampedExposureChangesAreMeasuredToTheirEnd) {
  FakeV4l2Options fo;
  fo.control_latency_frames = 2;
  fo.exposure_ramp_frames = 3;
  Rig r = Open(fo);
  EXPECT_EQ(MeasureControlLatency(*r.cam), 4);
  r.cam->set_control_latency_frames(4);
  const double applied = r.cam->SetExposure(0.005);
  r.cam->Grab();
  EXPECT_DOUBLE_EQ(r.fake->Frame(r.cam->last_sequence())->exposure_s, applied);
  // Discarding only the latency returns a frame still on its way (between old and new).
  r.cam->set_control_latency_frames(2);
  const double next = r.cam->SetExposure(0.015);
  r.cam->Grab();
  const double seen = r.fake->Frame(r.cam->last_sequence())->exposure_s;
  EXPECT_GT(seen, applied);
  EXPECT_LT(seen, next);
}

// Signals interrupt ioctl and poll (EINTR); the driver retries and nothing leaks.
TEST(V4l2Camera, SurvivesInterruptedSystemCalls) {
  for (Fill fill : {Fill::kOnQueue, Fill::kOnPoll}) {
    for (int every : {2, 3, 7}) {
      FakeV4l2Options fo;
      fo.fill = fill;
      fo.eintr_every = every;
      fo.control_latency_frames = 2;
      Rig r = Open(fo);
      for (double e : {0.004, 0.008}) {
        const double applied = r.cam->SetExposure(e);
        r.cam->Grab();
        EXPECT_DOUBLE_EQ(r.fake->Frame(r.cam->last_sequence())->exposure_s, applied);
      }
      EXPECT_EQ(MeasureControlLatency(*r.cam), 2);
      EXPECT_EQ(ListV4l2Devices(*r.fake).at(0).formats.size(), 4u);
      r.cam.reset();
      EXPECT_EQ(r.fake->OpenFds(), 0);
      EXPECT_EQ(r.fake->Mappings(), 0);
      EXPECT_EQ(r.fake->AllocatedBuffers(), 0);
      EXPECT_TRUE(r.fake->Misuse().empty()) << r.fake->Misuse().front();
    }
  }
}

TEST(V4l2Camera, GrabReturnsAFrameThatStartedAfterTheCall) {
  FakeV4l2Options fo;
  fo.fill = Fill::kOnQueue;  // buffers wait with old frames
  Rig r = Open(fo);
  r.cam->Grab();
  for (int i = 0; i < 3; ++i) {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    const int64_t call = (static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec) / 1000 * 1000;
    r.cam->Grab();
    EXPECT_GE(r.fake->Frame(r.cam->last_sequence())->timestamp_ns, call);
  }
}

TEST(V4l2Camera, MeasureControlLatencyRecoversTheCamerasLatency) {
  for (Fill fill : {Fill::kOnQueue, Fill::kOnPoll}) {
    for (int latency : {0, 1, 3, 6}) {
      FakeV4l2Options fo;
      fo.fill = fill;
      fo.control_latency_frames = latency;
      V4l2Options o;
      o.control_latency_frames = 2;
      Rig r = Open(fo, o);
      const double before = r.cam->Controls()[0].value;
      EXPECT_EQ(MeasureControlLatency(*r.cam, 12), latency) << "fill " << static_cast<int>(fill);
      EXPECT_EQ(r.cam->control_latency_frames(), 2);  // restored
      EXPECT_DOUBLE_EQ(r.cam->Controls()[0].value, before);
      EXPECT_TRUE(r.fake->Misuse().empty());
    }
  }
  // Starting from a bright setting it first finds a low exposure.
  FakeV4l2Options fo;
  fo.control_latency_frames = 2;
  fo.exposure_default = 2000;
  Rig r = Open(fo);
  EXPECT_EQ(MeasureControlLatency(*r.cam), 2);
  // Latency beyond what max_frames can see is an error, not a wrong answer.
  fo.control_latency_frames = 10;
  Rig slow = Open(fo);
  const std::string e = ErrorOf([&] { MeasureControlLatency(*slow.cam, 8); });
  EXPECT_NE(e.find("DeviceError: /dev/video0"), std::string::npos) << e;
}

TEST(V4l2Camera, VanishingDeviceGivesDeviceErrorAndStaysDestructible) {
  for (Fill fill : {Fill::kOnQueue, Fill::kOnPoll}) {
    FakeV4l2Options fo;
    fo.fill = fill;
    fo.vanish_after_frames = 12;
    Rig r = Open(fo);
    std::string e;
    int grabs = 0;
    for (; grabs < 50 && e.empty(); ++grabs) {
      try {
        r.cam->Grab();
      } catch (const DeviceError& err) {
        e = err.what();
      }
    }
    EXPECT_EQ(e, "/dev/video0: device vanished during streaming (ENODEV)");
    EXPECT_LT(grabs, 12);
    // Everything afterwards fails cleanly too.
    EXPECT_NE(ErrorOf([&] { r.cam->Grab(); }).find("vanished"), std::string::npos);
    EXPECT_NE(ErrorOf([&] { r.cam->SetExposure(0.01); }).find("vanished"), std::string::npos);
    EXPECT_NE(ErrorOf([&] { r.cam->SetGain(2); }).find("vanished"), std::string::npos);
    r.cam.reset();
    EXPECT_EQ(r.fake->OpenFds(), 0);
    EXPECT_EQ(r.fake->Mappings(), 0);
    EXPECT_TRUE(r.fake->Misuse().empty()) << r.fake->Misuse().front();
  }
  // Unplugged between grabs (poll reports POLLERR | POLLHUP, ioctls ENODEV).
  Rig r = Open();
  r.cam->Grab();
  r.fake->Unplug("/dev/video0");
  EXPECT_NE(ErrorOf([&] { r.cam->Grab(); }).find("/dev/video0: device vanished"),
            std::string::npos);
}

TEST(V4l2Camera, StalledStreamTimesOut) {
  FakeV4l2Options fo;
  fo.fill = Fill::kOnPoll;
  fo.stall_after_frames = 5;
  V4l2Options o;
  o.timeout_s = 0.5;
  Rig r = Open(fo, o);
  std::string e;
  for (int i = 0; i < 10 && e.empty(); ++i) {
    try {
      r.cam->Grab();
    } catch (const DeviceError& err) {
      e = err.what();
    }
  }
  EXPECT_NE(e.find("/dev/video0: timed out after"), std::string::npos) << e;
  r.cam.reset();
  EXPECT_EQ(r.fake->OpenFds(), 0);
}

TEST(V4l2Camera, CorruptAndErrorFramesAreSkipped) {
  for (const char* format : {"YUYV", "MJPG"}) {
    if (std::string(format) == "MJPG" && !v4l2_internal::JpegAvailable()) continue;
    FakeV4l2Options fo;
    fo.fill = Fill::kOnPoll;
    fo.control_latency_frames = 0;
    fo.error_frames = {3, 4};
    fo.corrupt_frames = {5, 6};
    V4l2Options o;
    o.pixel_format = format;
    o.control_latency_frames = 0;
    Rig r = Open(fo, o);
    for (int i = 0; i < 6; ++i) {
      r.cam->Grab();
      const uint32_t s = r.cam->last_sequence();
      EXPECT_TRUE(s < 3 || s > 6) << format << " returned frame " << s;
    }
    // Nothing but corrupt frames: a DeviceError, not an endless loop.
    fo.corrupt_frames.clear();
    for (int k = 0; k < 200; ++k) fo.corrupt_frames.push_back(k);
    Rig bad = Open(fo, o);
    const std::string e = ErrorOf([&] { bad.cam->Grab(); });
    EXPECT_NE(e.find("/dev/video0: no usable frame"), std::string::npos) << e;
  }
}

TEST(V4l2Camera, ClearErrorsForMissingBusyAndWrongDevices) {
  FakeV4l2Options meta;
  meta.path = "/dev/video1";
  meta.video_capture = false;
  auto fake = std::make_shared<FakeV4l2Device>(std::vector<FakeV4l2Options>{{}, meta});
  V4l2Options o;
  o.device = "/dev/video1";
  std::string e = ErrorOf([&] { V4l2Camera cam(o, fake); });
  EXPECT_NE(e.find("DeviceError: /dev/video1 (Fake UVC Camera, uvcvideo) is not a video "
                   "capture device"),
            std::string::npos)
      << e;
  o.device = "/dev/video7";
  e = ErrorOf([&] { V4l2Camera cam(o, fake); });
  EXPECT_NE(e.find("DeviceError: /dev/video7: cannot open: No such file or directory"),
            std::string::npos)
      << e;
  // Busy: another camera object streams from the node.
  o.device = "/dev/video0";
  V4l2Camera first(o, fake);
  e = ErrorOf([&] { V4l2Camera second(o, fake); });
  EXPECT_NE(e.find("/dev/video0: device busy (EBUSY)"), std::string::npos) << e;
  EXPECT_EQ(fake->OpenFds(), 1);  // the failed open closed its descriptor
  first.Grab();
  // A device without streaming I/O.
  FakeV4l2Options nostream;
  nostream.streaming = false;
  e = ErrorOf([&] { Open(nostream); });
  EXPECT_NE(e.find("is not a video capture device with streaming I/O"), std::string::npos) << e;
}

TEST(V4l2Options, ValidateExplains) {
  V4l2Options o;
  EXPECT_NO_THROW(o.Validate());
  const auto bad = [](auto change) {
    V4l2Options o;
    change(o);
    return ErrorOf([&] { o.Validate(); });
  };
  EXPECT_NE(bad([](V4l2Options& o) { o.device = ""; }).find("device path"), std::string::npos);
  EXPECT_NE(bad([](V4l2Options& o) { o.width = 640; }).find("width and height"), std::string::npos);
  EXPECT_NE(bad([](V4l2Options& o) { o.pixel_format = "TOOLONG"; }).find("not a fourcc"),
            std::string::npos);
  EXPECT_NE(bad([](V4l2Options& o) { o.buffers = 1; }).find("buffers"), std::string::npos);
  EXPECT_NE(bad([](V4l2Options& o) { o.control_latency_frames = -1; }).find("latency"),
            std::string::npos);
  EXPECT_NE(bad([](V4l2Options& o) { o.timeout_s = 0; }).find("timeout_s"), std::string::npos);
  EXPECT_NE(bad([](V4l2Options& o) { o.gain_at_max = 0.5; }).find("gain_at_max"),
            std::string::npos);
  // Invalid options never reach the device.
  auto fake = std::make_shared<FakeV4l2Device>();
  V4l2Options o2;
  o2.buffers = 100;
  EXPECT_THROW(OpenV4l2Camera(o2, fake), Error);
  EXPECT_EQ(fake->OpenFds(), 0);
}

TEST(ListV4l2Devices, DescribesEveryNode) {
  FakeV4l2Options meta;
  meta.path = "/dev/video1";
  meta.video_capture = false;
  FakeV4l2Device fake(std::vector<FakeV4l2Options>{{}, meta});
  const auto list = ListV4l2Devices(fake);
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].path, "/dev/video0");
  EXPECT_EQ(list[0].driver, "uvcvideo");
  EXPECT_EQ(list[0].card, "Fake UVC Camera");
  EXPECT_EQ(list[0].bus_info, "usb-fake-1");
  EXPECT_TRUE(list[0].can_capture);
  ASSERT_EQ(list[0].formats.size(), 4u);
  EXPECT_EQ(list[0].formats[0].fourcc, "GRBG");
  EXPECT_EQ(list[0].formats[3].fourcc, "MJPG");
  EXPECT_TRUE(list[0].formats[3].compressed);
  EXPECT_EQ(list[0].formats[1].sizes, (std::vector<std::pair<int, int>>{{160, 120}, {64, 48}}));
  EXPECT_FALSE(list[1].can_capture);
  EXPECT_TRUE(list[1].formats.empty());
  EXPECT_TRUE(list[1].error.empty());
  EXPECT_EQ(fake.OpenFds(), 0);
}

// The real system calls, on what this machine has (no /dev/video*).
TEST(SystemV4l2Io, MissingPathAndNonV4l2FilesGiveClearErrors) {
  auto io = std::make_shared<SystemV4l2Io>();
  V4l2Options o;
  o.device = "/nonexistent/video0";
  std::string e = ErrorOf([&] { OpenV4l2Camera(o, io); });
  EXPECT_EQ(e,
            "DeviceError: /nonexistent/video0: cannot open: No such file or directory "
            "(ENOENT) (is the camera plugged in? `rouen devices` lists cameras)");
  o.device = "/dev/null";
  e = ErrorOf([&] { OpenV4l2Camera(o, io); });
  EXPECT_NE(e.find("DeviceError: /dev/null: not a V4L2 device"), std::string::npos) << e;
  for (const std::string& p : io->ListDevices()) EXPECT_EQ(p.rfind("/dev/video", 0), 0u);
  for (const auto& info : ListV4l2Devices(*io)) EXPECT_FALSE(info.path.empty());
}

TEST(SystemV4l2Io, RealCamera) {
  SystemV4l2Io io;
  const auto devices = ListV4l2Devices(io);
  const auto it = std::find_if(devices.begin(), devices.end(),
                               [](const V4l2DeviceInfo& d) { return d.can_capture; });
  if (it == devices.end()) GTEST_SKIP() << "no V4L2 capture device on this machine";
  V4l2Options o;
  o.device = it->path;
  auto cam = OpenV4l2Camera(o);
  const CapturedFrame f = cam->Grab();
  EXPECT_EQ(f.image.channels, 3);
  EXPECT_GT(f.image.width, 0);
}

}  // namespace
}  // namespace rouen
