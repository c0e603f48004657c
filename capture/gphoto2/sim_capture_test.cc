// The simulated world's plan captured through libgphoto2: the capture controller drives a
// Gphoto2Camera whose PTP/IP camera double exposes rouen's simulated world at the shutter speed
// and ISO the driver set (testing/sim_ptpip_camera.h). One time-of-day slot of rigs/sim.toml
// (its five targets, nine brackets); the whole plan is five of these.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "capture/controller.h"
#include "capture/gphoto2/testing/sim_ptpip_camera.h"
#include "capture/rig.h"
#include "core/exif.h"
#include "core/image.h"
#include "core/session.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

class SimGphoto2CaptureTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    rig_ = new RigConfig(LoadRig(fs::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml"));
    SimWorldOptions o;
    o.site = rig_->site;
    o.quick = true;
    o.seed = rig_->seed;
    world_ = new std::shared_ptr<SimWorld>(std::make_shared<SimWorld>(o));
  }
  static void TearDownTestSuite() {
    delete world_;
    delete rig_;
  }

  void SetUp() override {
    // libgphoto2 keeps its PTP/IP GUID in $HOME/.gphoto/settings: give it a private HOME.
    std::string tmpl = (fs::temp_directory_path() / "rouen-gphoto2-sim-XXXXXX").string();
    ASSERT_NE(::mkdtemp(tmpl.data()), nullptr);
    dir_ = tmpl;
    ::setenv("HOME", dir_.c_str(), 1);
  }
  void TearDown() override {
    camera_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // Reopen the camera when it is lost (the rig's `reconnect`), trying every 10 ms for 10 s.
  static DeviceLossOptions Reconnecting() {
    DeviceLossOptions loss;
    loss.policy = DeviceLostPolicy::kReconnect;
    loss.reconnect_timeout_s = 10;
    loss.retry_interval_s = 0.01;
    return loss;
  }

  // The sim rig's 13:30 slot (`whole`: its five slots), with the double's shortest shutter speed
  // (1/10000 s) as the bracket's shortest and the aureole's exposures among its speeds.
  static CapturePlan Plan(bool whole = false) {
    CapturePlan p = rig_->plan;
    if (!whole) p.slots = {rig_->plan.slots.at(2)};
    p.bracket.min_exposure_s = 1e-4;
    p.aureole_exposures_s = {1e-4, 5e-4, 2e-3};
    return p;
  }

  SimPtpIpCamera& OpenCamera() {
    Gphoto2Options o;
    o.max_attempts = 4;
    o.backoff_initial_s = 0.001;
    o.backoff_max_s = 0.004;
    o.capture_timeout_s = 10;
    o.download_dir = Downloads().string();
    PtpIpResponderOptions r;
    // ExposureTime in 0.1 ms: 1/10000 s .. 30 s.
    r.exposure_times = {1,    2,    5,    10,    20,    40,    80,    167,    333,   667,
                        1250, 2500, 5000, 10000, 20000, 40000, 80000, 150000, 300000};
    camera_ = std::make_unique<SimPtpIpCamera>(*world_, &clock_, true, rig_->seed, o, r);
    return *camera_;
  }
  fs::path Downloads() const { return fs::path(dir_) / "downloads"; }

  struct Run {
    CaptureSummary summary;
    std::vector<FrameRecord> frames;
    fs::path session;
  };
  // Runs the plan into a new session `name`.
  Run Capture(const std::string& name, const std::function<void(const CaptureProgress&)>& progress,
              DeviceLossOptions loss = {}, std::function<Camera*()> reopen = nullptr,
              bool whole_plan = false) {
    SimGps gps(*world_, &clock_, rig_->seed + 7);
    Run r;
    r.session = fs::path(dir_) / name;
    SessionWriter w = SessionWriter::Create(r.session, SessionInfo{});
    CaptureDevices devices{camera_.get(), &gps, &clock_, std::move(reopen)};
    r.summary =
        CaptureController(devices, Plan(whole_plan), rig_->site, loss).Run(w, progress, nullptr);
    r.frames = w.frames();
    return r;
  }

  static RigConfig* rig_;
  static std::shared_ptr<SimWorld>* world_;
  std::string dir_;
  SimClock clock_;
  std::unique_ptr<SimPtpIpCamera> camera_;
};

RigConfig* SimGphoto2CaptureTest::rig_ = nullptr;
std::shared_ptr<SimWorld>* SimGphoto2CaptureTest::world_ = nullptr;

// How far apart two exposure times are, in stops.
double Stops(double a, double b) { return std::abs(std::log2(a / b)); }
// The EXIF rational the double's JPEG writer (OpenImageIO) makes of an exposure time is off by
// up to 1% (1/10000 s is written as 0.99e-4 s).
constexpr double kExifRounding = 0.015;

// The brackets of `slots` slots of the sim rig's plan.
std::set<std::string> PlannedGroups(int slots = 1) {
  std::set<std::string> g;
  for (int s = 0; s < slots; ++s) {
    for (Target t : {Target::kSun, Target::kAureole, Target::kSky}) g.insert(BracketName(s, t, 0));
    for (int v = 0; v < 2; ++v) g.insert(BracketName(s, Target::kLandscape, v));
    for (int v = 0; v < 4; ++v) g.insert(BracketName(s, Target::kArchitecture, v));
  }
  return g;
}

std::set<std::string> Groups(const std::vector<FrameRecord>& frames) {
  std::set<std::string> g;
  for (const FrameRecord& f : frames) g.insert(f.group);
  return g;
}

// The downloaded files by capture index (the double names them IMG_<index>.JPG; the driver
// puts a counter in front).
std::map<int, fs::path> DownloadedFiles(const fs::path& dir) {
  std::map<int, fs::path> files;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    const size_t at = name.find("IMG_");
    if (at == std::string::npos) {
      ADD_FAILURE() << "unexpected file " << name;
      continue;
    }
    const int index = std::stoi(name.substr(at + 4, 4));
    EXPECT_TRUE(files.emplace(index, e.path()).second) << "two files of capture " << index;
  }
  return files;
}

// Every journalled frame is one picture the camera took, in order, each once: `shots` are the
// captures of the run but those in `lost` (downloads cut off), and frame i is shot i's file:
// its pixels are the JPEG's, its exposure and gain the JPEG's EXIF, which states the settings
// the double exposed it with, at the aim, ND filter and slot (of `slots`) it was taken with.
void ExpectFramesAreTheCamerasFiles(const fs::path& session, const std::vector<FrameRecord>& frames,
                                    const std::vector<SimPtpIpShot>& shots,
                                    const std::map<int, fs::path>& files,
                                    const std::set<int>& lost = {},
                                    const std::vector<UtcTime>& slots = {}) {
  std::vector<SimPtpIpShot> kept;
  for (const SimPtpIpShot& s : shots)
    if (!lost.count(s.shot.index)) kept.push_back(s);
  ASSERT_EQ(frames.size(), kept.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameRecord& f = frames[i];
    const SimPtpIpShot& s = kept[i];
    SCOPED_TRACE("frame " + std::to_string(i) + " (" + f.group + "), capture " +
                 std::to_string(s.shot.index));
    int slot = 0;  // one slot unless `slots` lists them
    if (!slots.empty()) {
      const auto at = std::find(slots.begin(), slots.end(), s.slot);
      ASSERT_NE(at, slots.end()) << "a shot outside the plan's slots";
      slot = static_cast<int>(at - slots.begin());
    }
    EXPECT_EQ(f.slot, slot);
    EXPECT_EQ(f.group, BracketName(slot, s.target, s.view));
    EXPECT_DOUBLE_EQ(f.nd_density, s.nd_density);
    const auto file = files.find(s.shot.index);
    ASSERT_NE(file, files.end()) << "capture " << s.shot.index << " was not downloaded";
    const PhotoMetadata exif = ReadPhotoMetadata(file->second.string());
    ASSERT_TRUE(exif.exposure_s && exif.iso);
    EXPECT_DOUBLE_EQ(f.exposure_s, *exif.exposure_s);
    EXPECT_LT(Stops(*exif.exposure_s, s.shot.exposure_s), kExifRounding);
    EXPECT_DOUBLE_EQ(*exif.iso, s.shot.iso);
    EXPECT_DOUBLE_EQ(f.gain, s.shot.iso / 100.0);
    const Image journalled = ReadImage((session / f.file).string());
    const Image jpeg = ReadImage(file->second.string());
    EXPECT_TRUE(journalled.data == jpeg.data) << f.file << " is not " << file->second;
  }
}

// Device Busy replies to the trigger, the download and a setting, in the middle of the aureole
// bracket: the driver retries them; the journal is, frame for frame, the one of the same slot
// captured without them.
TEST_F(SimGphoto2CaptureTest, BusyRepliesMidBracketLoseNoFrameAndDuplicateNone) {
  SimPtpIpCamera& cam = OpenCamera();
  const Run clean = Capture("clean", nullptr);
  const size_t clean_shots = cam.Shots().size();
  EXPECT_EQ(Groups(clean.frames), PlannedGroups());
  EXPECT_FALSE(clean.summary.stopped);
  EXPECT_EQ(cam.Responder().Stats().busy_replies, 0);

  bool injected = false;
  const Run busy = Capture("busy", [&](const CaptureProgress& p) {
    if (injected || !p.event.empty() || p.target != Target::kAureole) return;
    // After the aureole's first frame: its next trigger, download and exposure change.
    cam.Responder().ReplyBusy(ptp_op::kInitiateCapture, 2);
    cam.Responder().ReplyBusy(ptp_op::kGetObject, 1);
    cam.Responder().ReplyBusy(ptp_op::kSetDevicePropValue, 1);
    injected = true;
  });
  ASSERT_TRUE(injected);
  const PtpIpResponderStats st = cam.Responder().Stats();
  EXPECT_EQ(st.busy_replies, 4);
  EXPECT_EQ(cam.Driver().Stats().busy_retries, 4);
  EXPECT_FALSE(busy.summary.stopped);
  EXPECT_EQ(busy.summary.reconnects, 0);

  const std::vector<SimPtpIpShot> shots = cam.Shots();
  const std::map<int, fs::path> files = DownloadedFiles(Downloads());
  EXPECT_EQ(st.captures, static_cast<int>(shots.size()));
  EXPECT_EQ(st.downloads, st.captures);
  EXPECT_EQ(st.deletes, st.captures);
  ExpectFramesAreTheCamerasFiles(clean.session, clean.frames,
                                 {shots.begin(), shots.begin() + clean_shots}, files);
  ExpectFramesAreTheCamerasFiles(busy.session, busy.frames,
                                 {shots.begin() + clean_shots, shots.end()}, files);
  ASSERT_EQ(busy.frames.size(), clean.frames.size());
  for (size_t i = 0; i < busy.frames.size(); ++i) {
    const FrameRecord &a = clean.frames[i], &b = busy.frames[i];
    EXPECT_EQ(b.group, a.group) << i;
    EXPECT_EQ(b.exposure_s, a.exposure_s) << i;
    EXPECT_EQ(b.utc, a.utc) << i;
    EXPECT_EQ(b.sha256, a.sha256) << i;  // the same picture
  }
  EXPECT_TRUE(cam.Responder().ProtocolErrors().empty());
}

// The connection drops while the aureole bracket's third frame downloads: the capture reopens
// the camera and redoes that bracket, and goes on; the brackets before it are not taken again,
// the frames journalled before the drop stay, and only the frame whose download was cut off
// (still on the card) is not journalled.
TEST_F(SimGphoto2CaptureTest, DroppedConnectionMidBracketResumesAtTheBracketInFlight) {
  SimPtpIpCamera& cam = OpenCamera();
  int aureole_frames = 0;
  int lost_capture = 0;
  int reopens = 0;
  const DeviceLossOptions loss = Reconnecting();
  const Run run = Capture(
      "dropped",
      [&](const CaptureProgress& p) {
        if (!p.event.empty() || p.target != Target::kAureole || ++aureole_frames != 2) return;
        cam.Responder().DropDuring(ptp_op::kGetObject);  // the next frame's download
        lost_capture = cam.Responder().Stats().captures + 1;
      },
      loss,
      [&]() -> Camera* {
        ++reopens;
        cam.Reopen();
        return &cam;
      });
  ASSERT_GT(lost_capture, 0);
  EXPECT_FALSE(run.summary.stopped);
  EXPECT_FALSE(run.summary.camera_lost);
  EXPECT_EQ(run.summary.reconnects, 1);
  EXPECT_EQ(reopens, 1);
  ASSERT_FALSE(run.summary.warnings.empty());
  bool lost_warning = false;
  for (const std::string& w : run.summary.warnings)
    lost_warning = lost_warning || (w.find("camera lost") != std::string::npos &&
                                    w.find("closed the connection") != std::string::npos);
  EXPECT_TRUE(lost_warning);

  const PtpIpResponderStats st = cam.Responder().Stats();
  EXPECT_EQ(st.drops, 1);
  EXPECT_EQ(st.connections, 2);
  const std::vector<SimPtpIpShot> shots = cam.Shots();
  EXPECT_EQ(st.captures, static_cast<int>(shots.size()));
  EXPECT_EQ(st.downloads, st.captures - 1);
  EXPECT_EQ(static_cast<int>(run.frames.size()), st.captures - 1);
  ExpectFramesAreTheCamerasFiles(run.session, run.frames, shots, DownloadedFiles(Downloads()),
                                 {lost_capture});
  EXPECT_EQ(Groups(run.frames), PlannedGroups());

  // Where the capture resumed: the aureole bracket in flight, from its first exposure. The
  // frames before the drop are the captures before the lost one.
  const std::string aureole = BracketName(0, Target::kAureole, 0);
  const size_t drop_at = static_cast<size_t>(lost_capture - 1);
  ASSERT_LT(drop_at, run.frames.size());
  EXPECT_EQ(run.frames[drop_at].group, aureole);
  const std::vector<double> planned = Plan().aureole_exposures_s;
  std::vector<double> before, after;
  std::set<std::string> groups_before, groups_after;
  for (size_t i = 0; i < run.frames.size(); ++i) {
    (i < drop_at ? groups_before : groups_after).insert(run.frames[i].group);
    if (run.frames[i].group == aureole)
      (i < drop_at ? before : after).push_back(run.frames[i].exposure_s);
  }
  EXPECT_EQ(before.size(), 2u);  // journalled before the drop, kept
  ASSERT_EQ(after.size(), planned.size());
  for (size_t k = 0; k < planned.size(); ++k) EXPECT_LT(Stops(after[k], planned[k]), kExifRounding);
  // Only the bracket in flight has frames on both sides of the drop.
  std::set<std::string> both;
  for (const std::string& g : groups_before)
    if (groups_after.count(g)) both.insert(g);
  EXPECT_EQ(both, std::set<std::string>{aureole});
  EXPECT_TRUE(cam.Responder().ProtocolErrors().empty());
}

// The sim rig's whole plan (five slots, 45 brackets) through libgphoto2, with Device Busy
// replies in the second slot's sun bracket and the connection dropped during a download in the
// fourth slot's aureole bracket: every bracket of the plan is journalled, every picture the
// camera took is journalled once but the one cut off, each with its EXIF exposure.
TEST_F(SimGphoto2CaptureTest, WholePlanWithBusyRepliesAndADropJournalsEveryFrameOnce) {
  SimPtpIpCamera& cam = OpenCamera();
  int busy_at = -1, drop_at = -1, lost_capture = 0, aureole_frames = 0;
  const DeviceLossOptions loss = Reconnecting();
  const Run run = Capture(
      "whole",
      [&](const CaptureProgress& p) {
        if (!p.event.empty()) return;
        if (p.slot == 1 && p.target == Target::kSun && busy_at < 0) {
          busy_at = p.frames_total;
          cam.Responder().ReplyBusy(ptp_op::kInitiateCapture, 2);
          cam.Responder().ReplyBusy(ptp_op::kGetObject, 1);
          cam.Responder().ReplyBusy(ptp_op::kSetDevicePropValue, 1);
        }
        if (p.slot == 3 && p.target == Target::kAureole && ++aureole_frames == 2) {
          drop_at = p.frames_total;
          cam.Responder().DropDuring(ptp_op::kGetObject);
          lost_capture = cam.Responder().Stats().captures + 1;
        }
      },
      loss,
      [&]() -> Camera* {
        cam.Reopen();
        return &cam;
      },
      true);
  ASSERT_GT(busy_at, 0);
  ASSERT_GT(drop_at, busy_at);
  EXPECT_FALSE(run.summary.stopped);
  EXPECT_EQ(run.summary.slots_done, 5);
  EXPECT_EQ(run.summary.reconnects, 1);
  EXPECT_EQ(Groups(run.frames), PlannedGroups(5));

  const PtpIpResponderStats st = cam.Responder().Stats();
  EXPECT_EQ(st.busy_replies, 4);
  EXPECT_EQ(st.drops, 1);
  EXPECT_EQ(st.connections, 2);
  const std::vector<SimPtpIpShot> shots = cam.Shots();
  EXPECT_EQ(st.captures, static_cast<int>(shots.size()));
  EXPECT_EQ(static_cast<int>(run.frames.size()), st.captures - 1);
  RecordProperty("frames", static_cast<int>(run.frames.size()));
  ExpectFramesAreTheCamerasFiles(run.session, run.frames, shots, DownloadedFiles(Downloads()),
                                 {lost_capture}, Plan(true).slots);
  EXPECT_TRUE(cam.Responder().ProtocolErrors().empty());
}

}  // namespace
}  // namespace rouen
