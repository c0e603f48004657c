#include "capture/devices/devices.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <set>

#include "capture/v4l2/fake_v4l2.h"
#ifdef ROUEN_HAVE_GPHOTO2
#include <stdlib.h>

#include "capture/gphoto2/testing/ptpip_responder.h"
#endif
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
#ifdef ROUEN_HAVE_GPHOTO2
  EXPECT_TRUE(built.count("gphoto2"));
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

// A gphoto2 rig (rigs/dslr-gphoto2.toml's [camera] with the port of a PTP/IP camera double).
std::string Gphoto2Rig(const std::string& port, const std::string& download_dir) {
  return "[rig]\nname = \"g\"\nkind = \"gphoto2\"\n"
         "[site]\nlat_deg = 49.44\nlon_deg = 1.10\n"
         "[camera]\nid = \"dslr0\"\nport = \"" +
         port + "\"\naperture_f = 5.6\ndownload_dir = \"" + download_dir +
         "\"\nbackoff_initial_s = 0.001\nbackoff_max_s = 0.004\ncapture_timeout_s = 5\n"
         "[gps]\nsource = \"none\"\n"
         "[plan]\ntargets = [\"architecture\"]\nviews = { architecture = 2 }\n"
         "start_exposure_s = 0.004\n"
         "[capture]\non_device_lost = \"reconnect\"\nreconnect_timeout_s = 5\n";
}

#ifdef ROUEN_HAVE_GPHOTO2
// A private HOME (libgphoto2 keeps its PTP/IP GUID in $HOME/.gphoto) and a folder for the test.
struct Gphoto2Home {
  fs::path dir;
  Gphoto2Home() {
    std::string tmpl = (fs::temp_directory_path() / "rouen-devices-gphoto2-XXXXXX").string();
    if (::mkdtemp(tmpl.data())) dir = tmpl;
    ::setenv("HOME", dir.c_str(), 1);
  }
  ~Gphoto2Home() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

// The rig opens the camera on its port, journals under the rig's camera id, sets the rig's
// aperture; when the connection drops mid-bracket, the rig's reconnect reopens it (the real
// OpenRig path: OperatorCamera over a new Gphoto2Camera) and the bracket is redone.
TEST(DevicesTest, Gphoto2RigCapturesAndReconnectsThroughOpenRig) {
  Gphoto2Home home;
  ASSERT_FALSE(home.dir.empty());
  PtpIpResponder camera;
  const RigConfig rig =
      ParseRig(Gphoto2Rig(camera.PortPath(), (home.dir / "originals").string()), "g.toml");
  RigDevices d = OpenRig(rig);
  ASSERT_TRUE(d.camera && d.clock && d.reopen_camera);
  EXPECT_EQ(d.camera->Id(), "dslr0");
  EXPECT_DOUBLE_EQ(camera.Settings().f_number, 5.6);
  EXPECT_TRUE(d.clock->IsLaptopClock());
  d.plan.allow_night = true;  // the laptop's clock: any hour of the day

  int frames = 0;
  auto progress = [&](const CaptureProgress& p) {
    // The double's scene needs two frames per view at 1/250 s (2 stops apart): drop the
    // connection while the second frame of the first view downloads.
    if (p.event.empty() && ++frames == 1) camera.DropDuring(ptp_op::kGetObject);
  };
  const fs::path dir = home.dir / "session";
  SessionWriter writer = SessionWriter::Create(dir, SessionInfo{});
  DeviceLossOptions loss{rig.on_device_lost, rig.reconnect_timeout_s, 0.01};
  const CaptureSummary s =
      CaptureController(d.Devices(), d.plan, rig.site, loss).Run(writer, progress, nullptr);
  EXPECT_FALSE(s.stopped);
  EXPECT_EQ(s.reconnects, 1);
  const PtpIpResponderStats st = camera.Stats();
  EXPECT_EQ(st.drops, 1);
  EXPECT_EQ(st.connections, 2);
  // Every capture but the one cut off is journalled, once.
  EXPECT_EQ(static_cast<int>(writer.frames().size()), st.captures - 1);
  EXPECT_EQ(st.downloads, st.captures - 1);
  std::set<std::string> groups;
  for (const FrameRecord& f : writer.frames()) {
    groups.insert(f.group);
    EXPECT_EQ(f.device, "dslr0");
  }
  EXPECT_EQ(groups,
            (std::set<std::string>{"slot0/architecture/view0", "slot0/architecture/view1"}));
  // The first view: one frame before the drop, then the whole bracket again.
  ASSERT_GE(writer.frames().size(), 3u);
  EXPECT_EQ(writer.frames()[1].group, "slot0/architecture/view0");
  EXPECT_DOUBLE_EQ(writer.frames()[1].exposure_s, writer.frames()[0].exposure_s);
  // The reopened camera got the rig's aperture back, and the files were kept.
  EXPECT_DOUBLE_EQ(camera.Settings().f_number, 5.6);
  int kept = 0;
  for (const auto& e : fs::directory_iterator(home.dir / "originals")) kept += e.is_regular_file();
  EXPECT_EQ(kept, st.downloads);
  EXPECT_TRUE(camera.ProtocolErrors().empty());
}

// No camera on the rig's port: the error names the port.
TEST(DevicesTest, Gphoto2RigWithoutItsCameraFailsNamingThePort) {
  Gphoto2Home home;
  std::string port;
  {
    PtpIpResponder gone;  // a port nobody listens on once it is closed
    port = gone.PortPath();
  }
  const RigConfig rig = ParseRig(Gphoto2Rig(port, ""), "g.toml");
  const std::string e = ErrorOf([&] { OpenRig(rig); });
  EXPECT_NE(e.find(port), std::string::npos) << e;
  EXPECT_NE(e.find("opening the camera"), std::string::npos) << e;
}
#else
TEST(DevicesTest, Gphoto2RigWithoutTheDriverIsAClearError) {
  const RigConfig rig = ParseRig(Gphoto2Rig("ptpip:127.0.0.1", ""), "g.toml");
  const std::string e = ErrorOf([&] { OpenRig(rig); });
  EXPECT_NE(e.find("g.toml"), std::string::npos) << e;
  EXPECT_NE(e.find("libgphoto2-dev"), std::string::npos) << e;
}
#endif

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
