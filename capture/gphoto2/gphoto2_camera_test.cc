// The gphoto2 driver end to end without a camera: libgphoto2's own ptp2 driver talks PTP/IP
// over loopback to PtpIpResponder (testing/ptpip_responder.h), a camera double whose frames
// scale with the exposure it was set to and whose faults (Device Busy, a dropped connection,
// a corrupt file, EXIF that disagrees with the settings) are injected per operation.
#include "capture/gphoto2/gphoto2_camera.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <string>

#include "capture/gphoto2/testing/ptpip_responder.h"
#include "core/error.h"
#include "core/exif.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

double Mean(const Image& im) {
  double sum = 0;
  for (float v : im.data) sum += v;
  return im.data.empty() ? 0 : sum / im.data.size();
}

// Expects `f` to throw DeviceError whose message contains every one of `parts`.
template <class F>
void ExpectDeviceError(F f, std::initializer_list<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "no DeviceError";
  } catch (const DeviceError& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << msg;
  }
}

class Gphoto2PtpIpTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // libgphoto2 keeps its PTP/IP GUID in $HOME/.gphoto/settings: give it a private HOME.
    std::string tmpl = (fs::temp_directory_path() / "rouen-gphoto2-test-XXXXXX").string();
    ASSERT_NE(::mkdtemp(tmpl.data()), nullptr);
    dir_ = tmpl;
    ::setenv("HOME", dir_.c_str(), 1);
    responder_ = std::make_unique<PtpIpResponder>();
  }
  void TearDown() override {
    camera_.reset();
    if (responder_) {
      const std::vector<std::string> errors = responder_->ProtocolErrors();
      for (const std::string& e : errors) ADD_FAILURE() << "PTP/IP protocol error: " << e;
    }
    responder_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  Gphoto2Options Options() const {
    Gphoto2Options o;
    o.port = responder_->PortPath();
    o.model = "PTP/IP Camera";
    o.max_attempts = 4;
    o.backoff_initial_s = 0.001;
    o.backoff_max_s = 0.004;
    o.capture_timeout_s = 5;
    o.download_dir = (fs::path(dir_) / "frames").string();
    return o;
  }
  Gphoto2Camera& Open() {
    camera_ = std::make_unique<Gphoto2Camera>(Options());
    return *camera_;
  }

  std::string dir_;
  std::unique_ptr<PtpIpResponder> responder_;
  std::unique_ptr<Gphoto2Camera> camera_;
};

TEST(Gphoto2ParseTest, ShutterSpeedsAndApertures) {
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("1/125"), 1.0 / 125);
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("0.0080s"), 0.008);
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("30"), 30.0);
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("2.5s"), 2.5);
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("1\"3"), 1.3);
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("15\""), 15.0);
  EXPECT_DOUBLE_EQ(*ParseShutterSpeed("1 1/2"), 1.5);
  for (const char* bad : {"Bulb", "bulb", "Time", "Auto", "", "1/0", "-1/30", "0", "abc"})
    EXPECT_FALSE(ParseShutterSpeed(bad)) << bad;
  EXPECT_DOUBLE_EQ(*ParseAperture("f/5.6"), 5.6);
  EXPECT_DOUBLE_EQ(*ParseAperture("8"), 8.0);
  EXPECT_DOUBLE_EQ(*ParseAperture("F11"), 11.0);
  EXPECT_FALSE(ParseAperture("implicit auto"));
}

TEST(Gphoto2OptionsTest, InvalidOptionsExplainThemselves) {
  Gphoto2Options o;
  o.max_attempts = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.backoff_max_s = o.backoff_initial_s / 2;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.exif_tolerance_stops = 0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  EXPECT_NO_THROW(o.Validate());
}

// Exposure 1/125 s then 1/30 s at ISO 200: the camera holds what was set, the frames'
// brightness follows the exposure, and their EXIF says so.
TEST_F(Gphoto2PtpIpTest, ExposureAndIsoReachTheCameraAndTheFrames) {
  Gphoto2Camera& cam = Open();
  EXPECT_NE(cam.Id().find("PTP/IP Camera"), std::string::npos) << cam.Id();
  EXPECT_NE(cam.Id().find(responder_->PortPath()), std::string::npos) << cam.Id();
  const std::vector<double> speeds = cam.ShutterSpeeds();
  ASSERT_EQ(speeds.size(), 17u);
  EXPECT_DOUBLE_EQ(speeds.front(), 0.0005);
  EXPECT_DOUBLE_EQ(speeds.back(), 30.0);

  EXPECT_DOUBLE_EQ(cam.SetGain(2.0), 2.0);
  EXPECT_EQ(responder_->Settings().iso, 200);
  EXPECT_DOUBLE_EQ(cam.SetAperture(8.0), 8.0);
  EXPECT_DOUBLE_EQ(cam.SetExposure(1.0 / 125), 0.008);  // ExposureTime 80 x 0.1 ms
  EXPECT_DOUBLE_EQ(responder_->Settings().exposure_s, 0.008);
  const CapturedFrame dark = cam.Grab();
  const fs::path dark_file = cam.LastFile();
  // 1/30 s is 333 x 0.1 ms on the camera.
  EXPECT_NEAR(cam.SetExposure(1.0 / 30), 0.0333, 1e-9);
  EXPECT_NEAR(responder_->Settings().exposure_s, 0.0333, 1e-9);
  const CapturedFrame bright = cam.Grab();

  for (const CapturedFrame* f : {&dark, &bright}) {
    EXPECT_EQ(f->image.width, 64);
    EXPECT_EQ(f->image.height, 48);
    EXPECT_EQ(f->image.units, PixelUnits::kDigital);
    EXPECT_DOUBLE_EQ(f->gain, 2.0);  // EXIF ISO 200 / base ISO 100
  }
  // EXIF exposure times (the float OIIO reads from the rational, 1/125 restored exactly).
  EXPECT_NEAR(dark.exposure_s, 0.008, 1e-7);
  EXPECT_NEAR(bright.exposure_s, 0.0333, 1e-6);
  const PhotoMetadata meta = ReadPhotoMetadata(dark_file.string());
  ASSERT_TRUE(meta.iso);
  EXPECT_DOUBLE_EQ(*meta.iso, 200);
  ASSERT_TRUE(meta.f_number);
  EXPECT_NEAR(*meta.f_number, 8.0, 1e-6);

  // Brightness ratio = exposure ratio, within what 8-bit rounding and JPEG coding can move
  // a mean (1 digital number each way).
  const double m_dark = Mean(dark.image), m_bright = Mean(bright.image);
  ASSERT_GT(m_dark, 20);
  ASSERT_LT(m_bright, 250);
  const double tolerance = 1.0 / m_dark + 1.0 / m_bright;
  EXPECT_NEAR((m_bright / m_dark) / (0.0333 / 0.008), 1.0, tolerance)
      << "means " << m_dark << " and " << m_bright;

  const PtpIpResponderStats st = responder_->Stats();
  EXPECT_EQ(st.captures, 2);
  EXPECT_EQ(st.downloads, 2);
  EXPECT_EQ(st.deletes, 2);  // downloaded, then removed from the card
  EXPECT_EQ(cam.Stats().downloads, 2);
  EXPECT_TRUE(fs::exists(dark_file));
  EXPECT_TRUE(fs::exists(cam.LastFile()));
  EXPECT_NE(dark_file, fs::path(cam.LastFile()));
}

TEST_F(Gphoto2PtpIpTest, ControlsReportTheCamerasRanges) {
  Gphoto2Camera& cam = Open();
  const std::vector<ControlInfo> controls = cam.Controls();
  ASSERT_EQ(controls.size(), 3u);
  EXPECT_EQ(controls[0].name, "exposure_s");
  EXPECT_DOUBLE_EQ(controls[0].min, 0.0005);
  EXPECT_DOUBLE_EQ(controls[0].max, 30.0);
  EXPECT_DOUBLE_EQ(controls[0].value, 0.008);  // the responder starts at 1/125 s
  EXPECT_EQ(controls[1].name, "gain");
  EXPECT_DOUBLE_EQ(controls[1].min, 1.0);
  EXPECT_DOUBLE_EQ(controls[1].max, 32.0);
  EXPECT_EQ(controls[2].name, "aperture_f");
  EXPECT_DOUBLE_EQ(controls[2].min, 2.8);
  EXPECT_DOUBLE_EQ(controls[2].max, 16.0);
  // A request between two speeds gets the nearer in stops, and says so.
  EXPECT_DOUBLE_EQ(cam.SetExposure(0.006), 0.008);
  EXPECT_DOUBLE_EQ(cam.SetExposure(100), 30.0);  // clamped to the longest
  EXPECT_THROW(cam.SetExposure(0), Error);
  EXPECT_THROW(cam.SetExposure(NAN), Error);
}

// A download folder kept between sessions: a second camera's files do not replace the first's,
// even when the camera names them the same (IMG_0001.JPG both times here).
// The camera's battery, card and clock through libgphoto2 ("batterylevel", the storage info,
// "datetime"): the level the camera reports (12%, not the double's default 80%), the card's
// free space less each file kept on it, and its clock 93 s ahead of UTC to PTP's second.
TEST_F(Gphoto2PtpIpTest, StatusReportsBatteryCardAndClock) {
  // libgphoto2 reads the camera's DateTime as the host's local time: the host in UTC here.
  ::setenv("TZ", "UTC", 1);
  ::tzset();
  PtpIpResponderOptions ro;
  ro.clock_offset_s = 93;
  responder_ = std::make_unique<PtpIpResponder>(ro);
  responder_->SetBatteryLevel(12);
  Gphoto2Options o = Options();
  o.delete_on_camera = false;
  camera_ = std::make_unique<Gphoto2Camera>(o);
  const CameraStatus before = camera_->Status();
  ASSERT_TRUE(before.battery_percent);
  EXPECT_EQ(*before.battery_percent, 12);
  ASSERT_TRUE(before.free_bytes);
  EXPECT_EQ(*before.free_bytes, int64_t{32} << 30);
  ASSERT_TRUE(before.clock);
  const double ahead = (before.clock->ns - NowUtc().ns) * 1e-9;
  EXPECT_GT(ahead, 93 - 2.0);  // the second it was read in, and this line's latency
  EXPECT_LT(ahead, 93 + 1.0);

  camera_->Grab();
  const CameraStatus after = camera_->Status();
  ASSERT_TRUE(after.free_bytes);
  const int64_t file = static_cast<int64_t>(fs::file_size(camera_->LastFile()));
  EXPECT_EQ(*before.free_bytes - *after.free_bytes, (file + 1023) / 1024 * 1024)
      << "the card's free space in whole KiB, as libgphoto2 hands it over";
}

TEST_F(Gphoto2PtpIpTest, DownloadsNeverReplaceEarlierFiles) {
  Open().Grab();
  const std::string first = camera_->LastFile();
  camera_.reset();
  responder_ = std::make_unique<PtpIpResponder>();  // a fresh card: IMG_0001.JPG again
  Open().Grab();
  const std::string second = camera_->LastFile();
  EXPECT_NE(first, second);
  EXPECT_TRUE(fs::exists(first));
  EXPECT_TRUE(fs::exists(second));
  EXPECT_EQ(fs::path(first).parent_path(), fs::path(second).parent_path());
}

// Two Device Busy replies to InitiateCapture: the driver tries again and the picture is
// taken once, downloaded once.
TEST_F(Gphoto2PtpIpTest, BusyTwiceOnCaptureStillGivesOneFrame) {
  Gphoto2Camera& cam = Open();
  responder_->ReplyBusy(ptp_op::kInitiateCapture, 2);
  const CapturedFrame f = cam.Grab();
  EXPECT_FALSE(f.image.empty());
  PtpIpResponderStats st = responder_->Stats();
  EXPECT_EQ(st.operations[ptp_op::kInitiateCapture], 3);
  EXPECT_EQ(st.busy_replies, 2);
  EXPECT_EQ(st.captures, 1);
  EXPECT_EQ(st.downloads, 1);
  EXPECT_EQ(cam.Stats().busy_retries, 2);
  EXPECT_EQ(cam.LastFiles().size(), 1u);
  // The next frame is a new capture, not a leftover.
  cam.Grab();
  st = responder_->Stats();
  EXPECT_EQ(st.captures, 2);
  EXPECT_EQ(st.downloads, 2);
  EXPECT_EQ(cam.LastFiles().size(), 1u);
}

// Busy on GetObject and on SetDevicePropValue are retried as well.
TEST_F(Gphoto2PtpIpTest, BusyOnDownloadAndSettingsIsRetried) {
  Gphoto2Camera& cam = Open();
  responder_->ReplyBusy(ptp_op::kSetDevicePropValue, 1);
  EXPECT_NEAR(cam.SetExposure(1.0 / 60), 0.0167, 1e-9);
  EXPECT_NEAR(responder_->Settings().exposure_s, 0.0167, 1e-9);
  responder_->ReplyBusy(ptp_op::kGetObject, 2);
  const CapturedFrame f = cam.Grab();
  EXPECT_NEAR(f.exposure_s, 0.0167, 1e-5);  // EXIF rational
  const PtpIpResponderStats st = responder_->Stats();
  EXPECT_EQ(st.busy_replies, 3);
  EXPECT_EQ(st.captures, 1);
  EXPECT_EQ(st.downloads, 1);
  EXPECT_EQ(cam.Stats().busy_retries, 3);
}

// Busy while the driver looks for the camera's settings at open: they are still found.
TEST_F(Gphoto2PtpIpTest, BusyWhileReadingSettingsAtOpenIsRetried) {
  responder_->ReplyBusy(ptp_op::kGetDevicePropDesc, 2);
  Gphoto2Camera& cam = Open();
  EXPECT_EQ(responder_->Stats().busy_replies, 2);
  EXPECT_EQ(cam.Stats().busy_retries, 2);
  EXPECT_EQ(cam.ShutterSpeeds().size(), 17u);
  EXPECT_DOUBLE_EQ(cam.SetExposure(1.0 / 500), 0.002);
}

// A camera that stays busy: a DeviceError after max_attempts triggers, not a hang.
TEST_F(Gphoto2PtpIpTest, BusyForeverIsADeviceError) {
  Gphoto2Camera& cam = Open();
  responder_->ReplyBusy(ptp_op::kInitiateCapture, PtpIpResponder::kForever);
  ExpectDeviceError([&] { cam.Grab(); },
                    {cam.Id(), "triggering a capture", "after 4 attempts", "Device Busy"});
  const PtpIpResponderStats st = responder_->Stats();
  EXPECT_EQ(st.operations.at(ptp_op::kInitiateCapture), 4);
  EXPECT_EQ(st.captures, 0);
  // Once the camera is free again, capturing works.
  responder_->ReplyBusy(ptp_op::kInitiateCapture, 0);
  EXPECT_FALSE(cam.Grab().image.empty());
}

// The connection drops halfway through GetObject's data: a DeviceError naming the download
// and the closed connection, no crash (no SIGPIPE either, on the writes that follow), and
// every later call says the connection is gone.
TEST_F(Gphoto2PtpIpTest, ConnectionDroppedMidDownloadIsADeviceError) {
  Gphoto2Camera& cam = Open();
  responder_->DropDuring(ptp_op::kGetObject);
  ExpectDeviceError([&] { cam.Grab(); },
                    {cam.Id(), "downloading", "IMG_0001.JPG", "closed the connection"});
  PtpIpResponderStats st = responder_->Stats();
  EXPECT_EQ(st.drops, 1);
  EXPECT_EQ(st.captures, 1);
  EXPECT_EQ(st.downloads, 0);
  EXPECT_EQ(st.operations[ptp_op::kGetObject], 1);  // not retried on a closed connection
  ExpectDeviceError([&] { cam.Grab(); }, {cam.Id(), "lost while downloading", "reopen"});
  ExpectDeviceError([&] { cam.SetExposure(0.01); }, {cam.Id(), "reopen"});
  EXPECT_EQ(responder_->Stats().operations[ptp_op::kInitiateCapture], 1);

  // Reopened, the camera works again; the file whose download was cut off is still on the
  // card (only downloaded files are deleted).
  camera_.reset();
  Gphoto2Camera& again = Open();
  const CapturedFrame f = again.Grab();
  EXPECT_EQ(f.image.width, 64);
  st = responder_->Stats();
  EXPECT_EQ(st.connections, 2);
  EXPECT_EQ(st.captures, 2);
  EXPECT_EQ(st.downloads, 1);
  EXPECT_EQ(st.deletes, 1);
}

// The connection drops when the trigger arrives, before the camera acts: the trigger is not
// repeated (it could have fired), and no picture was taken.
TEST_F(Gphoto2PtpIpTest, ConnectionDroppedAtTheTriggerIsNotRepeated) {
  Gphoto2Camera& cam = Open();
  responder_->DropAfter(1);  // the next request is InitiateCapture
  ExpectDeviceError([&] { cam.Grab(); }, {cam.Id(), "triggering a capture", "closed"});
  const PtpIpResponderStats st = responder_->Stats();
  EXPECT_EQ(st.operations.at(ptp_op::kInitiateCapture), 1);
  EXPECT_EQ(st.captures, 0);
  EXPECT_EQ(st.drops, 1);
}

// Frames come from the responder's frame source, which sees the settings the driver made;
// a grey picture becomes three equal channels.
TEST(Gphoto2FrameSourceTest, TheFrameSourceSeesTheSettings) {
  std::string tmpl = (fs::temp_directory_path() / "rouen-gphoto2-test-XXXXXX").string();
  ASSERT_NE(::mkdtemp(tmpl.data()), nullptr);
  ::setenv("HOME", tmpl.c_str(), 1);
  std::vector<PtpShot> shots;
  PtpIpResponderOptions ro;
  ro.frame = [&](const PtpShot& s) {
    shots.push_back(s);
    return Image(32, 16, 1, PixelUnits::kDigital, 77.f);
  };
  PtpIpResponder responder(ro);
  Gphoto2Options o;
  o.port = responder.PortPath();  // the model defaults to "PTP/IP Camera" on a ptpip: port
  o.download_dir = tmpl + "/frames";
  {
    Gphoto2Camera cam(o);
    cam.SetExposure(1.0 / 250);
    cam.SetGain(4);
    cam.SetAperture(5.6);
    const CapturedFrame f = cam.Grab();
    ASSERT_EQ(shots.size(), 1u);
    EXPECT_DOUBLE_EQ(shots[0].exposure_s, 0.004);
    EXPECT_EQ(shots[0].iso, 400);
    EXPECT_DOUBLE_EQ(shots[0].f_number, 5.6);
    EXPECT_EQ(shots[0].index, 1);
    ASSERT_EQ(f.image.width, 32);
    ASSERT_EQ(f.image.height, 16);
    ASSERT_EQ(f.image.channels, 3);
    EXPECT_NEAR(Mean(f.image), 77.0, 1.0);
    EXPECT_DOUBLE_EQ(f.gain, 4.0);
    EXPECT_NEAR(f.exposure_s, 0.004, 1e-7);
  }
  EXPECT_TRUE(responder.ProtocolErrors().empty());
  std::error_code ec;
  fs::remove_all(tmpl, ec);
}

// A file that is not a JPEG: a DeviceError naming the file, and the camera keeps working.
TEST_F(Gphoto2PtpIpTest, CorruptFileIsADeviceError) {
  Gphoto2Camera& cam = Open();
  responder_->CorruptNextObject();
  ExpectDeviceError([&] { cam.Grab(); }, {cam.Id(), "IMG_0001.JPG", "cannot be decoded"});
  const CapturedFrame next = cam.Grab();
  EXPECT_EQ(next.image.width, 64);
  EXPECT_EQ(responder_->Stats().captures, 2);
}

// The file says 1/60 s while the camera was set to 1/30 s: the driver refuses the frame.
TEST_F(Gphoto2PtpIpTest, ExifDisagreeingWithTheSettingIsADeviceError) {
  Gphoto2Camera& cam = Open();
  cam.SetExposure(1.0 / 30);
  responder_->SetExifExposure(1.0 / 60);
  ExpectDeviceError([&] { cam.Grab(); }, {cam.Id(), "EXIF", "1/60 s", "1/30.03 s"});
  responder_->SetExifExposure(std::nullopt);
  EXPECT_NEAR(cam.Grab().exposure_s, 0.0333, 1e-6);
}

// libgphoto2 closes file descriptor 0 when a PTP/IP camera disconnects; the driver puts it
// back: what fd 0 referred to before opening the camera, it refers to after closing it.
TEST_F(Gphoto2PtpIpTest, ClosingTheCameraKeepsFileDescriptorZero) {
  struct stat before {};
  if (::fstat(0, &before) != 0) {  // no stdin here: put /dev/null there for the test
    const int fd = ::open("/dev/null", O_RDONLY);
    ASSERT_GE(fd, 0);
    if (fd != 0) {
      ASSERT_EQ(::dup2(fd, 0), 0);
      ::close(fd);
    }
    ASSERT_EQ(::fstat(0, &before), 0);
  }
  Open().Grab();
  camera_.reset();  // gp_camera_exit: CloseSession, then the sockets (and fd 0) are closed
  struct stat after {};
  ASSERT_EQ(::fstat(0, &after), 0) << "fd 0 was closed";
  EXPECT_EQ(after.st_dev, before.st_dev);
  EXPECT_EQ(after.st_ino, before.st_ino);
  EXPECT_EQ(responder_->Stats().operations[ptp_op::kCloseSession], 1);
}

// Nobody listening on the port: a DeviceError naming it, after the retries.
TEST_F(Gphoto2PtpIpTest, NoCameraOnThePortIsADeviceError) {
  Gphoto2Options o = Options();
  responder_.reset();  // frees the port
  ExpectDeviceError([&] { Gphoto2Camera cam(o); }, {o.port, "opening the camera"});
}

// The serial number the camera reports (PTP DeviceInfo) is read at open; a rig that names
// another serial is refused, naming both.
TEST_F(Gphoto2PtpIpTest, SerialIsReadAndChecked) {
  Gphoto2Options o = Options();
  o.serial = "RPT0001";  // the responder's
  camera_ = std::make_unique<Gphoto2Camera>(o);
  EXPECT_EQ(camera_->Serial(), "RPT0001");
  camera_.reset();
  o.serial = "ABC123";
  ExpectDeviceError([&] { Gphoto2Camera cam(o); }, {"RPT0001", "ABC123", o.port});
}

// A serial without a port: the detected cameras are searched (a PTP/IP camera never is, and
// this machine has no USB camera), and the error says what was found.
TEST_F(Gphoto2PtpIpTest, SerialWithoutAPortSearchesTheDetectedCameras) {
  Gphoto2Options o = Options();
  o.port.clear();
  o.model.clear();
  o.serial = "NO-SUCH-SERIAL";
  ExpectDeviceError([&] { Gphoto2Camera cam(o); }, {"serial 'NO-SUCH-SERIAL'"});
  EXPECT_EQ(responder_->Stats().connections, 0);
}

// `rouen devices` entries of detected cameras: the rig kind and what a rig puts in [camera].
TEST(Gphoto2ListingTest, DescribesEachCameraWithItsRigKindAndPort) {
  const nlohmann::json j = DescribeGphoto2Cameras(
      {{"Canon EOS 5D Mark IV", "usb:001,004"}, {"Nikon DSC D850", "usb:002,007"}});
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[0]["driver"], "gphoto2");
  EXPECT_EQ(j[0]["rig_kind"], "gphoto2");
  EXPECT_EQ(j[0]["id"], "usb:001,004");
  const std::string d = j[0]["description"];
  EXPECT_NE(d.find("Canon EOS 5D Mark IV"), std::string::npos) << d;
  EXPECT_NE(d.find("model = \"Canon EOS 5D Mark IV\""), std::string::npos) << d;
  EXPECT_NE(d.find("port = \"usb:001,004\""), std::string::npos) << d;
  EXPECT_EQ(j[1]["id"], "usb:002,007");
  EXPECT_TRUE(DescribeGphoto2Cameras({}).empty());
}

TEST_F(Gphoto2PtpIpTest, UnknownModelIsADeviceError) {
  Gphoto2Options o = Options();
  o.model = "No Such Camera 9000";
  ExpectDeviceError([&] { Gphoto2Camera cam(o); }, {"No Such Camera 9000"});
}

}  // namespace
}  // namespace rouen
