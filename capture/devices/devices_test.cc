#include "capture/devices/devices.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <set>

#include "capture/v4l2/fake_v4l2.h"
#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

fs::path Rigs() { return fs::path(ROUEN_SOURCE_DIR) / "rigs"; }

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(DevicesTest, BuildHasEveryDriverThisMachineCanBuild) {
  std::vector<std::string> d = BuiltDrivers();
  std::set<std::string> built(d.begin(), d.end());
  // v4l2 and nmea need only the kernel headers and libc; the rest were found by CMake.
  EXPECT_TRUE(built.count("v4l2"));
  EXPECT_TRUE(built.count("nmea"));
#ifdef ROUEN_HAVE_ARAVIS
  EXPECT_TRUE(built.count("aravis"));
#endif
}

TEST(DevicesTest, ListingNeverThrowsAndHasEverySection) {
  nlohmann::json j = ListDevices();
  for (const char* key : {"drivers", "cameras", "gps", "usb", "errors"})
    EXPECT_TRUE(j.contains(key) && j[key].is_array()) << key;
  for (const auto& c : j["cameras"]) {
    EXPECT_TRUE(c.contains("rig_kind")) << c.dump();
    EXPECT_FALSE(c["id"].get<std::string>().empty()) << c.dump();
  }
}

TEST(DevicesTest, FieldRigsWithoutTheirDeviceFailClearly) {
  // No camera is connected here: each field rig says which device it could not open.
  RigConfig uvc = LoadRig(Rigs() / "uvc-webcam.toml");
  std::string e = ErrorOf([&] { OpenRig(uvc); });
  EXPECT_NE(e.find("/dev/video0"), std::string::npos) << e;
#ifdef ROUEN_HAVE_LIBCAMERA
  RigConfig rpi = LoadRig(Rigs() / "rpi-libcamera.toml");
  e = ErrorOf([&] { OpenRig(rpi); });
  EXPECT_NE(e.find("camera"), std::string::npos) << e;
#endif
  RigConfig replay = LoadRig(Rigs() / "replay.toml");
  e = ErrorOf([&] { OpenRig(replay); });
  EXPECT_NE(e.find("--from"), std::string::npos) << e;
}

TEST(DevicesTest, SimulatedRigsOpen) {
  RigConfig sim = LoadRig(Rigs() / "sim.toml");
  sim.quick = true;
  RigDevices d = OpenRig(sim);
  ASSERT_TRUE(d.camera && d.gps && d.clock);
  EXPECT_TRUE(d.model.has_value());
  EXPECT_FALSE(d.clock->IsLaptopClock());
  EXPECT_EQ(d.plan.slots.size(), sim.plan.slots.size());
#ifdef ROUEN_HAVE_ARAVIS
  RigConfig fake = LoadRig(Rigs() / "aravis-fake.toml");
  fake.quick = true;
  RigDevices f = OpenRig(fake);
  ASSERT_TRUE(f.camera);
  EXPECT_NE(f.camera->Id().find("Fake"), std::string::npos) << f.camera->Id();
#endif
}

// A uvc-webcam rig on a fake V4L2 device, driven by the capture controller.
struct FakeWebcamRig {
  RigConfig rig;
  std::vector<std::shared_ptr<FakeV4l2Device>> devices;  // one per (re)open
  std::vector<FakeV4l2Options> plan;                     // what each open finds
  size_t opens = 0;
  std::vector<OperatorRequest> asked;

  explicit FakeWebcamRig(const std::string& policy) {
    rig = ParseRig(
        "[rig]\nname = \"w\"\nkind = \"uvc-webcam\"\n"
        "[site]\nlat_deg = 49.44\nlon_deg = 1.10\n"
        "[camera]\nid = \"uvc0\"\ndevice = \"/dev/video0\"\npixel_format = \"YUYV\"\n"
        "control_latency_frames = 3\ntimeout_s = 1.0\n"
        "[gps]\nsource = \"none\"\n"
        "[plan]\ntargets = [\"sun\", \"architecture\"]\nviews = { architecture = 3 }\n"
        "sun_start_exposure_s = 0.01\n"
        "[capture]\non_device_lost = \"" +
            policy + "\"\nreconnect_timeout_s = 5\n",
        "webcam.toml");
  }
  OpenRigOptions Options() {
    OpenRigOptions o;
    o.prompt = [this](const OperatorRequest& r) { asked.push_back(r); };
    o.v4l2_io = [this]() -> std::shared_ptr<V4l2Io> {
      size_t i = std::min(opens++, plan.size() - 1);
      devices.push_back(std::make_shared<FakeV4l2Device>(plan[i]));
      return devices.back();
    };
    return o;
  }
};

TEST(DevicesTest, WebcamUnpluggedMidCaptureStopsWithAConsistentSession) {
  FakeWebcamRig w("stop");
  FakeV4l2Options vanishing;
  vanishing.control_latency_frames = 3;
  vanishing.vanish_after_frames = 30;
  w.plan = {vanishing};
  RigDevices d = OpenRig(w.rig, w.Options());
  EXPECT_TRUE(d.clock->IsLaptopClock());
  d.plan.allow_night = true;  // the laptop's clock: any hour of the day
  ASSERT_EQ(d.plan.slots.size(), 1u);
  const fs::path dir =
      fs::temp_directory_path() / ("rouen_devices_stop_" + std::to_string(getpid()));
  fs::remove_all(dir);
  CaptureSummary s;
  size_t journalled = 0;
  {
    SessionWriter writer = SessionWriter::Create(dir, SessionInfo{});
    DeviceLossOptions loss{w.rig.on_device_lost, w.rig.reconnect_timeout_s};
    s = CaptureController(d.Devices(), d.plan, w.rig.site, loss).Run(writer, nullptr, nullptr);
    journalled = writer.frames().size();
  }
  EXPECT_TRUE(s.camera_lost);
  EXPECT_GT(journalled, 0u);
  Session loaded = Session::Load(dir);
  ASSERT_EQ(loaded.frames().size(), journalled);
  for (const FrameRecord& f : loaded.frames()) {
    EXPECT_EQ(f.device, "uvc0");
    EXPECT_EQ(Sha256File(loaded.dir() / f.file), f.sha256);
  }
  // The operator was asked to aim at the sun and to fit the rig's ND filter.
  ASSERT_GE(w.asked.size(), 2u);
  EXPECT_EQ(w.asked[0].target, Target::kSun);
  EXPECT_EQ(w.asked[1].kind, OperatorRequest::Kind::kFitNd);
  fs::remove_all(dir);
}

TEST(DevicesTest, WebcamUnpluggedMidCaptureReconnectsAndCompletes) {
  FakeWebcamRig w("reconnect");
  FakeV4l2Options vanishing, gone, back;
  vanishing.vanish_after_frames = 30;
  gone.path = "/dev/video9";  // the first reopen finds no /dev/video0 yet
  w.plan = {vanishing, gone, back};
  RigDevices d = OpenRig(w.rig, w.Options());
  d.plan.allow_night = true;  // the laptop's clock: any hour of the day
  const fs::path dir =
      fs::temp_directory_path() / ("rouen_devices_reconnect_" + std::to_string(getpid()));
  fs::remove_all(dir);
  SessionWriter writer = SessionWriter::Create(dir, SessionInfo{});
  DeviceLossOptions loss{w.rig.on_device_lost, w.rig.reconnect_timeout_s, 0.01};
  CaptureSummary s =
      CaptureController(d.Devices(), d.plan, w.rig.site, loss).Run(writer, nullptr, nullptr);
  EXPECT_FALSE(s.stopped);
  EXPECT_EQ(s.reconnects, 1);
  EXPECT_EQ(w.opens, 3u);
  std::set<std::string> groups;
  for (const FrameRecord& f : writer.frames()) groups.insert(f.group);
  EXPECT_EQ(groups,
            (std::set<std::string>{"slot0/sun/view0", "slot0/architecture/view0",
                                   "slot0/architecture/view1", "slot0/architecture/view2"}));
  // The reopened camera got the settings back: frames after the reconnect have the ND
  // filter state and exposures the controller asked for.
  for (const FrameRecord& f : writer.frames())
    EXPECT_EQ(f.nd_density > 0, f.target == Target::kSun) << f.group;
  fs::remove_all(dir);
}

TEST(DevicesTest, UsbWatchStartsAndStopsWhereHotplugExists) {
  std::vector<std::string> events;
  std::shared_ptr<void> watch = WatchUsb([&](const std::string& m) { events.push_back(m); });
#ifdef ROUEN_HAVE_USB
  // libusb reports hotplug support on Linux; no device comes or goes during the test.
  EXPECT_TRUE(watch != nullptr);
#endif
  watch.reset();  // stops and joins the event thread
  EXPECT_TRUE(events.empty());
}

}  // namespace
}  // namespace rouen
