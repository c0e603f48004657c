#include "capture/libcamera/libcamera_camera.h"

#include <gtest/gtest.h>
#include <libcamera/camera.h>
#include <libcamera/camera_manager.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

// The ids a CameraManager of our own reports. Only one manager may exist per process, so this
// runs while no rouen listing or camera holds the shared one.
std::vector<std::string> ManagerCameraIds() {
  libcamera::CameraManager manager;
  EXPECT_EQ(manager.start(), 0);
  std::vector<std::string> ids;
  for (const auto& c : manager.cameras()) ids.push_back(c->id());
  manager.stop();
  return ids;
}

TEST(LibcameraList, ReturnsWhatTheManagerReports) {
  const std::vector<LibcameraCameraInfo> listed = ListLibcameraCameras();
  const std::vector<std::string> expected = ManagerCameraIds();
  ASSERT_EQ(listed.size(), expected.size());
  for (size_t i = 0; i < listed.size(); ++i) {
    EXPECT_EQ(listed[i].id, expected[i]);
    EXPECT_TRUE(std::is_sorted(listed[i].properties.begin(), listed[i].properties.end()));
  }
  // The shared manager is released and restarted cleanly on the next call.
  EXPECT_EQ(ListLibcameraCameras().size(), expected.size());
}

TEST(LibcameraOpen, NoCameraIsAClearDeviceError) {
  if (!ListLibcameraCameras().empty()) GTEST_SKIP() << "this machine has a libcamera camera";
  try {
    LibcameraCamera camera;
    FAIL() << "opened a camera that does not exist";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("no camera"), std::string::npos) << e.what();
  }
  // And the manager is usable again afterwards.
  EXPECT_NO_THROW(ListLibcameraCameras());
}

TEST(LibcameraOpen, UnknownIdIsNamed) {
  LibcameraOptions o;
  o.camera_id = "/base/no/such/camera@0";
  try {
    LibcameraCamera camera(o);
    FAIL() << "opened a camera that does not exist";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("/base/no/such/camera@0"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not found"), std::string::npos) << e.what();
  }
}

TEST(LibcameraOptions, ValidateExplainsItself) {
  LibcameraOptions o;
  EXPECT_NO_THROW(o.Validate());
  auto expect_bad = [](const LibcameraOptions& bad, const std::string& word) {
    try {
      bad.Validate();
      ADD_FAILURE() << "accepted options with bad " << word;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  o.width = 640;
  expect_bad(o, "height");
  o = {};
  o.request_count = 0;
  expect_bad(o, "request_count");
  o = {};
  o.grab_timeout_s = -1;
  expect_bad(o, "grab_timeout_s");
  o = {};
  o.max_frames_per_grab = 0;
  expect_bad(o, "max_frames_per_grab");
  o = {};
  o.gain_rel_tol = std::nan("");
  expect_bad(o, "gain_rel_tol");
  // Bad options are refused before any camera is touched, as a DeviceError.
  o = {};
  o.request_count = 100;
  EXPECT_THROW(LibcameraCamera{o}, DeviceError);
}

TEST(LibcameraSupportedFormats, ListsTheConvertibleFormats) {
  const auto names = LibcameraSupportedFormats();
  for (const char* want : {"YUYV", "NV12", "RGB888", "BGR888", "SRGGB10_CSI2P"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), want), names.end()) << want;
  }
}

TEST(LibcameraCamera, GrabsWithManualExposure) {
  if (ListLibcameraCameras().empty()) GTEST_SKIP() << "no libcamera camera on this machine";
  LibcameraCamera camera;
  EXPECT_FALSE(camera.Id().empty());
  EXPECT_EQ(camera.ViewCount(Target::kArchitecture), 1);
  const double exposure = camera.SetExposure(1.0 / 100);
  const double gain = camera.SetGain(1.0);
  const CapturedFrame frame = camera.Grab();
  EXPECT_FALSE(frame.image.empty());
  EXPECT_EQ(frame.image.channels, 3);
  EXPECT_EQ(frame.image.units, PixelUnits::kDigital);
  for (float v : frame.image.data) {
    ASSERT_TRUE(std::isfinite(v) && v >= 0 && v <= 255);
  }
  EXPECT_GT(frame.exposure_s, 0);
  EXPECT_GT(frame.gain, 0);
  const LibcameraGrabReport& r = camera.LastGrab();
  EXPECT_DOUBLE_EQ(r.wanted_exposure_s, exposure);
  EXPECT_DOUBLE_EQ(r.wanted_gain, gain);
  EXPECT_DOUBLE_EQ(frame.exposure_s, r.applied_exposure_s);
  // The frame's time is within a few seconds of now.
  EXPECT_LT(std::abs(frame.utc.UnixSeconds() - NowUtc().UnixSeconds()), 5.0);
}

}  // namespace
}  // namespace rouen
