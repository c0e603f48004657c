// GpsdGps against a real gpsd fed by gpsfake on loopback.
#include "capture/gpsd/gpsd.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "capture/nmea/nmea_test_util.h"
#include "core/solar.h"

extern char** environ;

namespace rouen {
namespace {

namespace fs = std::filesystem;
using SteadyClock = std::chrono::steady_clock;

std::string Sentence(const std::string& body) { return NmeaSentence(body); }

// The recorded track: epoch k at 2025-06-21 12:00:k UTC near Rouen cathedral, latitude
// minutes 26.412 + 0.003 k (N), longitude minutes 5.700 + 0.002 k (E), 20.0 m above MSL,
// geoid separation 46.0 m -> 66.0 m above the ellipsoid.
constexpr int kEpochs = 8;
constexpr double kHae = 20.0 + 46.0;
double LatOf(int k) { return 49 + (26.412 + 0.003 * k) / 60; }
double LonOf(int k) { return 1 + (5.700 + 0.002 * k) / 60; }
UtcTime TimeOf(int k) { return FromCivil(CivilTime{2025, 6, 21, 12, 0, static_cast<double>(k)}); }
std::string Log() {
  std::string s;
  for (int k = 0; k < kEpochs; ++k) {
    char t[16], lat[16], lon[16];
    std::snprintf(t, sizeof(t), "1200%02d.00", k);
    std::snprintf(lat, sizeof(lat), "4926.%03d", 412 + 3 * k);
    std::snprintf(lon, sizeof(lon), "00105.%03d", 700 + 2 * k);
    s += Sentence(std::string("GPGGA,") + t + "," + lat + ",N," + lon +
                  ",E,1,08,0.9,20.0,M,46.0,M,,");
    s += Sentence("GPGSA,A,3,02,05,07,13,15,20,24,30,,,,,1.6,0.9,1.3");
    s += Sentence("GPGSV,2,1,08,02,45,050,40,05,30,120,38,07,60,200,45,13,15,300,33");
    s += Sentence("GPGSV,2,2,08,15,50,090,42,20,25,240,36,24,70,010,47,30,10,160,30");
    s += Sentence(std::string("GPRMC,") + t + ",A," + lat + ",N," + lon + ",E,0.0,0.0,210625,,,A");
  }
  return s;
}

// Tolerances from the log's printed precision: half a unit of the last digit.
constexpr double kLatLonTolDeg = 0.0005 / 60;  // 0.0005 arc-minute
constexpr double kHeightTolM = 0.05;
constexpr double kTimeTolS = 0.0005;  // centiseconds printed, exact values used

int FreePort() {
  const int s = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof(a);
  int port = -1;
  if (s >= 0 && ::bind(s, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
      ::getsockname(s, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
    port = ntohs(a.sin_port);
  }
  if (s >= 0) ::close(s);
  return port;
}

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "rouen_gpsd_XXXXXX").string();
    path_ = mkdtemp(tmpl.data());
  }
  ~TempDir() { fs::remove_all(path_); }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// gpsfake (and the gpsd it starts, same process group) as a child; always killed and reaped.
class GpsFake {
 public:
  GpsFake(const fs::path& dir, const fs::path& log, int port) : out_(dir / "gpsfake.out") {
    std::vector<std::string> args = {
        "/usr/bin/python3",   "/usr/bin/gpsfake", "-1", "-p", "-c", "0.1", "-P",
        std::to_string(port), log.string()};
    // A clean environment: the system python and gpsd, not a pyenv shim; gpsfake's control
    // socket in our temp dir.
    std::vector<std::string> env = {"PATH=/usr/sbin:/usr/bin:/sbin:/bin", "TMPDIR=" + dir.string()};
    for (char** e = environ; *e; ++e) {
      const std::string v = *e;
      if (v.rfind("HOME=", 0) == 0 || v.rfind("LANG=", 0) == 0) env.push_back(v);
    }
    std::vector<char*> argv, envp;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    for (auto& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);

    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 1, out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);
    posix_spawnattr_setpgroup(&attr, 0);  // own group: gpsd inherits it, one kill ends both
    const int rc = posix_spawn(&pid_, argv[0], &fa, &attr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&attr);
    if (rc != 0) pid_ = -1;
  }
  ~GpsFake() { Stop(); }

  bool started() const { return pid_ > 0; }
  // True once gpsfake itself has exited (reaped).
  bool Exited() {
    if (pid_ <= 0) return true;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      ::kill(-pid_, SIGKILL);  // whatever of its group is left (gpsd)
      pid_ = -1;
      return true;
    }
    return false;
  }
  void Stop() {
    if (pid_ <= 0) return;
    ::kill(-pid_, SIGTERM);
    const auto deadline = SteadyClock::now() + std::chrono::seconds(3);
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (SteadyClock::now() > deadline) {
        ::kill(-pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        break;
      }
      ::poll(nullptr, 0, 20);  // waiting for the child to exit, bounded by the deadline
    }
    ::kill(-pid_, SIGKILL);  // gpsd, if gpsfake left it behind
    pid_ = -1;
  }
  std::string Output() const {
    std::ifstream in(out_);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

 private:
  fs::path out_;
  pid_t pid_ = -1;
};

UtcTime LaptopNow() {
  return UtcTime{std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::system_clock::now().time_since_epoch())
                     .count()};
}

TEST(GpsdOptions, ValidateExplains) {
  GpsdOptions o;
  EXPECT_NO_THROW(o.Validate());
  o.port = "gps";
  EXPECT_THROW(o.Validate(), Error);
  o.port = "70000";
  EXPECT_THROW(o.Validate(), Error);
  o.port = "2947";
  o.host = "";
  EXPECT_THROW(o.Validate(), Error);
  o.host = "127.0.0.1";
  o.timeout_s = -0.5;
  EXPECT_THROW(o.Validate(), Error);
}

TEST(GpsdGps, NotRunningIsADeviceErrorNamingTheAddress) {
  const int port = FreePort();
  ASSERT_GT(port, 0);
  GpsdOptions o;
  o.port = std::to_string(port);
  try {
    OpenGpsdGps(o);
    FAIL() << "connected to a port where nothing listens";
  } catch (const DeviceError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("127.0.0.1:" + o.port), std::string::npos) << msg;
    EXPECT_NE(msg.find("not reachable"), std::string::npos) << msg;
  }
}

TEST(GpsdGps, RecordedFixesThroughGpsfake) {
  for (const char* p : {"/usr/bin/python3", "/usr/bin/gpsfake", "/usr/sbin/gpsd"}) {
    if (!fs::exists(p)) GTEST_SKIP() << p << " missing (needs gpsd, gpsd-clients, python3-gps)";
  }
  if (!fs::exists("/usr/lib/python3/dist-packages/gps/fake.py")) {
    GTEST_SKIP() << "python3-gps missing: gpsfake cannot run";
  }
  TempDir dir;
  const fs::path log = dir.path() / "track.nmea";
  std::ofstream(log) << Log();
  const int port = FreePort();
  ASSERT_GT(port, 0);
  const UtcTime test_start = LaptopNow();
  GpsFake fake(dir.path(), log, port);
  ASSERT_TRUE(fake.started()) << "posix_spawn of gpsfake failed";

  GpsdOptions o;
  o.port = std::to_string(port);
  o.timeout_s = 0.3;
  // gpsd needs a moment to listen: retry the connection until a deadline.
  std::unique_ptr<Gps> gps;
  std::string last_error;
  const auto connect_deadline = SteadyClock::now() + std::chrono::seconds(8);
  while (!gps && SteadyClock::now() < connect_deadline) {
    try {
      gps = OpenGpsdGps(o);
    } catch (const DeviceError& e) {
      last_error = e.what();
      if (fake.Exited()) break;
      ::poll(nullptr, 0, 50);  // next connection attempt
    }
  }
  if (!gps) {
    const std::string out = fake.Output();
    if (out.find("No module named") != std::string::npos) {
      GTEST_SKIP() << "gpsfake cannot run here: " << out;
    }
    FAIL() << "no connection to gpsd: " << last_error << "\ngpsfake output:\n" << out;
  }
  EXPECT_EQ(gps->Id(), "gpsd:127.0.0.1:" + o.port);

  // Collect fixes until the last epoch arrives, gpsd goes away, or a deadline.
  std::map<int, GpsFix> by_epoch;  // epoch index -> fix
  std::vector<std::string> problems;
  bool lost = false;
  double max_poll_s = 0;
  const auto deadline = SteadyClock::now() + std::chrono::seconds(15);
  while (SteadyClock::now() < deadline && !by_epoch.count(kEpochs - 1)) {
    std::optional<GpsFix> fix;
    const auto poll_start = SteadyClock::now();
    try {
      fix = gps->Poll();
      max_poll_s = std::max(max_poll_s,
                            std::chrono::duration<double>(SteadyClock::now() - poll_start).count());
    } catch (const DeviceError& e) {
      lost = true;  // gpsfake -1 ends (and stops gpsd) after the log
      EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + o.port), std::string::npos);
      break;
    }
    if (!fix || !fix->valid()) continue;
    const double k_real = (fix->utc.ns - TimeOf(0).ns) * 1e-9;
    const int k = static_cast<int>(std::lround(k_real));
    if (std::abs(k_real - k) > kTimeTolS || k < 0 || k >= kEpochs) {
      problems.push_back("fix at unexpected time " + fix->utc.Iso8601(6));
      continue;
    }
    by_epoch[k] = *fix;
  }
  if (!lost) {
    // Stop gpsfake and gpsd ourselves: the driver must report the loss.
    fake.Stop();
    const auto lost_deadline = SteadyClock::now() + std::chrono::seconds(5);
    while (!lost && SteadyClock::now() < lost_deadline) {
      try {
        gps->Poll();
      } catch (const DeviceError& e) {
        lost = true;
        EXPECT_NE(std::string(e.what()).find("connection lost"), std::string::npos) << e.what();
      }
    }
  }
  fake.Stop();
  EXPECT_TRUE(lost) << "gpsd went away without a DeviceError";
  EXPECT_THROW(gps->Poll(), DeviceError);
  const UtcTime test_end = LaptopNow();

  EXPECT_TRUE(problems.empty()) << problems.front();
  // Poll() waits at most timeout_s (plus scheduling slack on a shared machine).
  EXPECT_LT(max_poll_s, o.timeout_s + 2.0);  // load-tolerant: catches a Poll that blocks
  // The first epochs can be lost (gpsd opens the device when we watch); most must arrive.
  EXPECT_GE(by_epoch.size(), static_cast<size_t>(kEpochs / 2)) << "gpsfake output:\n"
                                                               << fake.Output();
  for (const auto& [k, f] : by_epoch) {
    SCOPED_TRACE("epoch " + std::to_string(k));
    EXPECT_EQ(f.mode, 3);
    EXPECT_NEAR(f.lat_deg, LatOf(k), kLatLonTolDeg);
    EXPECT_NEAR(f.lon_deg, LonOf(k), kLatLonTolDeg);
    EXPECT_NEAR(f.height_m, kHae, kHeightTolM) << "height above the ellipsoid (altHAE)";
    ASSERT_TRUE(f.received_utc);
    EXPECT_LE(test_start, *f.received_utc);
    EXPECT_LE(*f.received_utc, test_end);
    // Satellites and hdop come from gpsd's SKY (GSA + GSV), which may trail the first TPV.
    if (f.satellites > 0) {
      EXPECT_EQ(f.satellites, 8);
      EXPECT_NEAR(f.hdop, 0.9, 0.005);
    }
    std::cout << std::setprecision(10) << "fix epoch " << k << ": " << f.utc.Iso8601(3) << " lat "
              << f.lat_deg << " lon " << f.lon_deg << " hae " << f.height_m << " m mode " << f.mode
              << " sats " << f.satellites << " hdop " << f.hdop << " (received "
              << f.received_utc->Iso8601(3) << ")\n";
  }
  ASSERT_FALSE(by_epoch.empty());
  EXPECT_EQ(by_epoch.rbegin()->second.satellites, 8) << "no SKY report reached the driver";

  // The sun from a recorded fix equals the sun computed for the logged time and place.
  const auto& [k, f] = *by_epoch.rbegin();
  const SunPosition from_fix = ComputeSunPosition(f.utc, Site{f.lat_deg, f.lon_deg, f.height_m});
  const SunPosition direct = ComputeSunPosition(TimeOf(k), Site{LatOf(k), LonOf(k), kHae});
  // Position within 8.3e-6 deg and time within 0.5 ms move the sun by < 1e-4 deg here
  // (elevation ~64 deg: azimuth sensitivity ~1/cos(el) ~ 2.3x).
  EXPECT_NEAR(from_fix.azimuth_deg, direct.azimuth_deg, 1e-4);
  EXPECT_NEAR(from_fix.elevation_deg, direct.elevation_deg, 1e-4);
  // Midsummer noon-ish in Normandy: the sun is high in the south.
  EXPECT_GT(direct.elevation_deg, 55);
  EXPECT_GT(direct.azimuth_deg, 150);
  EXPECT_LT(direct.azimuth_deg, 230);
  std::ostringstream sun;
  sun << "epoch " << k << " " << f.utc.Iso8601(3) << ": sun azimuth " << from_fix.azimuth_deg
      << " deg, elevation " << from_fix.elevation_deg << " deg (direct: " << direct.azimuth_deg
      << ", " << direct.elevation_deg << ")";
  std::cout << sun.str() << "\n";
  RecordProperty("fixes", static_cast<int>(by_epoch.size()));
  RecordProperty("sun", sun.str());
}

}  // namespace
}  // namespace rouen
