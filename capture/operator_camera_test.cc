#include "capture/operator_camera.h"

#include <gtest/gtest.h>

#include "core/error.h"

namespace rouen {
namespace {

// A driver camera with fixed-size grey frames that records what was set.
class FixedCamera : public Camera {
 public:
  int width = 40, height = 30;
  double exposure = 0.01, gain = 1, nd = 0;
  int aims = 0;
  std::string Id() const override { return "fixed"; }
  std::vector<ControlInfo> Controls() const override { return {}; }
  double SetExposure(double s) override { return exposure = s; }
  double SetGain(double g) override { return gain = g; }
  void SetNdFilter(double d) override { nd = d; }
  double NdFilter() const override { return nd; }
  int ViewCount(Target) const override { return 1; }
  void Aim(Target, int) override { ++aims; }
  CapturedFrame Grab() override {
    CapturedFrame f;
    f.image = Image(width, height, 3, PixelUnits::kDigital, 100.f);
    f.exposure_s = exposure;
    f.gain = gain;
    return f;
  }
};

TEST(OperatorCameraTest, AsksOncePerViewAndForEachFilterChange) {
  auto dev = std::make_unique<FixedCamera>();
  FixedCamera* raw = dev.get();
  std::vector<OperatorRequest> asked;
  OperatorCamera cam(std::move(dev), {{Target::kArchitecture, 3}}, {},
                     [&](const OperatorRequest& r) { asked.push_back(r); });
  EXPECT_EQ(cam.ViewCount(Target::kArchitecture), 3);
  EXPECT_EQ(cam.ViewCount(Target::kSky), 1);
  cam.Aim(Target::kSun, 0);
  cam.SetNdFilter(4.5);
  cam.SetNdFilter(4.5);      // unchanged: no question
  cam.Aim(Target::kSun, 0);  // same aim: no question
  CapturedFrame f = cam.Grab();
  EXPECT_DOUBLE_EQ(f.nd_density, 4.5);
  cam.SetNdFilter(0);
  cam.Aim(Target::kArchitecture, 1);
  ASSERT_EQ(asked.size(), 4u);
  EXPECT_EQ(asked[0].kind, OperatorRequest::Kind::kAim);
  EXPECT_EQ(asked[1].kind, OperatorRequest::Kind::kFitNd);
  EXPECT_NE(asked[1].text.find("4.5"), std::string::npos) << asked[1].text;
  EXPECT_EQ(asked[2].kind, OperatorRequest::Kind::kRemoveNd);
  EXPECT_EQ(asked[3].view, 1);
  EXPECT_EQ(asked[3].views, 3);
  EXPECT_NE(asked[3].text.find("view 2 of 3"), std::string::npos) << asked[3].text;
  EXPECT_EQ(raw->aims, 2);
  EXPECT_DOUBLE_EQ(raw->nd, 0);
}

TEST(OperatorCameraTest, AttachesTheTargetsLensAndRefusesAWrongSize) {
  auto dev = std::make_unique<FixedCamera>();
  FixedCamera* raw = dev.get();
  Intrinsics fisheye = Intrinsics::FisheyeFov(40, 30, 180);
  OperatorCamera cam(std::move(dev), {}, {{Target::kSky, fisheye}}, nullptr);
  cam.Aim(Target::kArchitecture, 0);
  EXPECT_FALSE(cam.Grab().intrinsics);  // no lens for this target
  cam.Aim(Target::kSky, 0);
  CapturedFrame f = cam.Grab();
  ASSERT_TRUE(f.intrinsics);
  EXPECT_EQ(f.intrinsics->projection, Projection::kFisheye);
  raw->width = 64;
  try {
    cam.Grab();
    FAIL() << "no error for a lens of the wrong size";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("40x30"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("64x30"), std::string::npos) << e.what();
  }
}

TEST(OperatorCameraTest, AReplacedDeviceGetsTheSameSettings) {
  OperatorCamera cam(std::make_unique<FixedCamera>(), {}, {}, nullptr);
  cam.SetNdFilter(3);
  cam.SetExposure(0.002);
  cam.SetGain(4);
  cam.Aim(Target::kSky, 0);
  auto fresh = std::make_unique<FixedCamera>();
  FixedCamera* raw = fresh.get();
  cam.ReplaceDevice(std::move(fresh));
  EXPECT_DOUBLE_EQ(raw->nd, 3);
  EXPECT_DOUBLE_EQ(raw->exposure, 0.002);
  EXPECT_DOUBLE_EQ(raw->gain, 4);
  EXPECT_EQ(raw->aims, 1);
  EXPECT_THROW(cam.ReplaceDevice(nullptr), Error);
  EXPECT_THROW(cam.SetNdFilter(-1), Error);
}

}  // namespace
}  // namespace rouen
