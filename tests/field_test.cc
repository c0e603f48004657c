// The field path end to end, through the CLI: `rouen devices` finds Aravis's fake GigE Vision
// camera on loopback (the real GVCP/GVSP protocol), and `rouen capture` with a gige-aravis rig
// and an NMEA GPS log journals a 7-exposure bracket with the applied exposures, the GPS fixes
// and the sun positions derived from them.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "capture/nmea/nmea_test_util.h"
#include "core/files.h"
#include "core/session.h"
#include "core/solar.h"

extern char** environ;

namespace rouen {
namespace {

namespace fs = std::filesystem;

std::string RunRouen(const std::string& args, int* code) {
  std::string cmd = std::string(ROUEN_BINARY) + " " + args + " 2>&1 </dev/null";
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  int status = pclose(p);
  *code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

// arv-fake-gv-camera-0.8 on 127.0.0.1 with its own serial number. Simulators share the GVCP
// port, so tests in parallel take turns through the lock the Aravis driver tests use.
class FakeGvCamera {
 public:
  explicit FakeGvCamera(const std::string& serial) {
    for (const char* dir : {"/usr/bin", "/usr/local/bin"}) {
      fs::path p = fs::path(dir) / "arv-fake-gv-camera-0.8";
      if (fs::exists(p)) binary_ = p;
    }
    if (binary_.empty()) return;
    lock_fd_ = ::open("/tmp/rouen_aravis_gv_test.lock", O_RDWR | O_CREAT, 0666);
    if (lock_fd_ >= 0) ::flock(lock_fd_, LOCK_EX);
    std::vector<std::string> args = {binary_.string(), "-i", "127.0.0.1", "-s", serial};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
    if (posix_spawn(&pid_, argv[0], &fa, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~FakeGvCamera() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (lock_fd_ >= 0) ::close(lock_fd_);
  }
  bool missing() const { return binary_.empty(); }
  bool running() const { return pid_ > 0 && ::waitpid(pid_, nullptr, WNOHANG) == 0; }

 private:
  fs::path binary_;
  pid_t pid_ = -1;
  int lock_fd_ = -1;
};

TEST(FieldTest, GigeFakeCameraListedThenBracketJournalledWithGpsAndSun) {
  const std::string serial = "ROUEN" + std::to_string(getpid() % 100000);
  FakeGvCamera fake(serial);
  if (fake.missing()) GTEST_SKIP() << "arv-fake-gv-camera-0.8 not installed (aravis-tools)";
  ASSERT_TRUE(fake.running());

  // `rouen devices` lists it (discovery over loopback; the simulator takes a moment to start).
  std::string id;
  int code = -1;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (id.empty() && std::chrono::steady_clock::now() < deadline) {
    std::string out = RunRouen("devices --json", &code);
    ASSERT_EQ(code, 0) << out;
    nlohmann::json j = nlohmann::json::parse(out);
    for (const auto& c : j["cameras"])
      if (c["driver"] == "aravis" && c["id"].get<std::string>().find(serial) != std::string::npos) {
        id = c["id"];
        EXPECT_EQ(c["rig_kind"], "gige-aravis");
      }
    if (id.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(200));  // discovery
  }
  ASSERT_FALSE(id.empty()) << "rouen devices never listed the fake camera " << serial;

  const fs::path dir = fs::temp_directory_path() / ("rouen_field_test_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  // A GPS log near Rouen: 3D fixes, 9 satellites, altitude 20 m + geoid 47 m.
  std::string log;
  for (int s = 0; s < 5; ++s) {
    char t[16];
    std::snprintf(t, sizeof t, "1200%02d.00", s);
    log += NmeaSentence(std::string("GPRMC,") + t + ",A,4926.586,N,00105.958,E,0.0,0.0,210626,,");
    log += NmeaSentence(std::string("GPGGA,") + t +
                        ",4926.586,N,00105.958,E,1,09,0.9,20.0,M,47.0,M,,");
    log += NmeaSentence(std::string("GPGSA,A,3,01,02,03,04,05,06,07,08,09,,,,1.5,0.9,1.2"));
  }
  WriteFileAtomic(dir / "gps.nmea", log);
  const std::vector<double> exposures = {1.0 / 8000, 1.0 / 4000, 1.0 / 2000, 1.0 / 1000,
                                         1.0 / 500,  1.0 / 250,  1.0 / 125};
  // The aureole lens carries a vignetting model (as `rouen calib vignetting --lens` writes it):
  // capture copies it into the session for the frames' device and target.
  const std::string lens =
      "{\"projection\": \"pinhole\", \"width\": 512, \"height\": 512, \"fx\": 400, "
      "\"fy\": 400, \"cx\": 256, \"cy\": 256, \"vignetting\": {\"width\": 512, "
      "\"height\": 512, \"cx\": 256, \"cy\": 256, \"a\": [-0.3, 0.05, 0]}}";
  WriteFileAtomic(dir / "lens.json", lens);
  std::string list;
  for (double e : exposures) list += (list.empty() ? "" : ", ") + std::to_string(e);
  WriteFileAtomic(dir / "rig.toml",
                  "[rig]\nname = \"gige-fake\"\nkind = \"gige-aravis\"\n"
                  "[site]\nlat_deg = 0\nlon_deg = 0\n"
                  "[camera]\nid = \"gige0\"\ndevice = \"" +
                      id +
                      "\"\n"
                      "pixel_format = \"Mono8\"\ntimeout_s = 3.0\n"
                      "[gps]\nsource = \"nmea\"\ndevice = \"" +
                      (dir / "gps.nmea").string() +
                      "\"\nbaud = 0\n"
                      "[lens]\naureole = \"lens.json\"\n"
                      "[plan]\ntargets = [\"aureole\"]\n"
                      "aureole_exposures_s = [" +
                      list + "]\n");
  std::string out = RunRouen("capture --rig " + (dir / "rig.toml").string() + " --out " +
                                 (dir / "session").string() + " --no-prompt --allow-night",
                             &code);
  ASSERT_EQ(code, 0) << out;

  Session s = Session::Load(dir / "session");
  ASSERT_EQ(s.frames().size(), exposures.size()) << out;
  EXPECT_EQ(s.info().site_source, "gps");
  EXPECT_NEAR(s.info().site.lat_deg, 49 + 26.586 / 60, 1e-9);
  EXPECT_NEAR(s.info().site.height_m, 67.0, 1e-9);  // ellipsoidal: 20 m + 47 m geoid
  for (size_t i = 0; i < exposures.size(); ++i) {
    const FrameRecord& f = s.frames()[i];
    EXPECT_EQ(f.device, "gige0");
    // The fake's exposure register holds whole microseconds.
    EXPECT_NEAR(f.exposure_s, exposures[i], 1e-6) << i;
    ASSERT_TRUE(f.gps) << i;
    EXPECT_EQ(f.gps->mode, 3);
    // The journalled sun position is the one for the frame's time at the GPS position.
    SunPosition sp =
        ComputeSunPosition(f.utc, Site{f.gps->lat_deg, f.gps->lon_deg, f.gps->height_m});
    EXPECT_NEAR(f.sun_azimuth_deg, sp.azimuth_deg, 1e-9);
    EXPECT_NEAR(f.sun_elevation_deg, sp.elevation_deg, 1e-9);
    EXPECT_EQ(Sha256File(s.dir() / f.file), f.sha256);
  }
  ASSERT_TRUE(s.info().vignetting.count("gige0/aureole")) << nlohmann::json(s.info()).dump();
  const VignettingModel& vig = s.info().vignetting.at("gige0/aureole");
  EXPECT_DOUBLE_EQ(vig.a[0], -0.3);
  EXPECT_DOUBLE_EQ(vig.a[1], 0.05);
  // A recorded log is not live: no clock offset is derived from it.
  EXPECT_DOUBLE_EQ(s.info().clock_offset_s, 0.0);

  // Later in the day: the same session gets a second time-of-day slot.
  out = RunRouen("capture --rig " + (dir / "rig.toml").string() + " --out " +
                     (dir / "session").string() + " --no-prompt --allow-night --new-slot",
                 &code);
  ASSERT_EQ(code, 0) << out;
  Session two = Session::Load(dir / "session");
  ASSERT_EQ(two.frames().size(), 2 * exposures.size());
  for (size_t i = 0; i < two.frames().size(); ++i) {
    const FrameRecord& f = two.frames()[i];
    const int slot = i < exposures.size() ? 0 : 1;
    EXPECT_EQ(f.slot, slot);
    EXPECT_EQ(f.group, "slot" + std::to_string(slot) + "/aureole/view0");
  }
  EXPECT_EQ(two.info().extra["plan"]["slots"].size(), 2u);
  // --new-slot is for field sessions that exist.
  out = RunRouen("capture --rig " + (dir / "rig.toml").string() + " --out " +
                     (dir / "nothing").string() + " --no-prompt --allow-night --new-slot",
                 &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(out.find("needs an existing session"), std::string::npos) << out;
  // A lens whose vignetting model is impossible (the fall-off goes negative) stops the
  // capture before any frame, naming the rig, the lens file and the problem.
  WriteFileAtomic(dir / "lens.json", lens.substr(0, lens.find("-0.3")) + "-2, 0, 0]}}");
  out = RunRouen("capture --rig " + (dir / "rig.toml").string() + " --out " +
                     (dir / "bad").string() + " --no-prompt --allow-night",
                 &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(out.find("lens.json: vignetting: the fall-off drops"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "bad" / "session.json"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
