#include <fcntl.h>
#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <vector>

#include "capture/clock.h"
#include "capture/nmea/nmea.h"
#include "capture/nmea/nmea_test_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using SteadyClock = std::chrono::steady_clock;

std::string Sentence(const std::string& body) { return NmeaSentence(body); }

// One epoch (RMC, GGA, GSA) at 12:00:ss on 15 June 2025; latitude minutes grow with ss.
std::string Epoch(int ss) {
  char t[16], lat[16];
  std::snprintf(t, sizeof(t), "1200%02d.00", ss);
  std::snprintf(lat, sizeof(lat), "4807.%03d", ss);
  return Sentence(std::string("GPRMC,") + t + ",A," + lat + ",N,01131.000,E,0,0,150625,,") +
         Sentence(std::string("GPGGA,") + t + "," + lat +
                  ",N,01131.000,E,1,09,0.8,100.0,M,47.0,M,,") +
         Sentence("GPGSA,A,3,04,05,09,12,24,,,,,,,,1.6,0.8,1.4") +
         Sentence("GPGSV,1,1,01,04,40,083,46");
}
double LatOf(int ss) { return 48 + (7 + ss / 1000.0) / 60; }
UtcTime TimeOf(int ss) { return FromCivil(CivilTime{2025, 6, 15, 12, 0, static_cast<double>(ss)}); }

UtcTime LaptopNow() {
  return UtcTime{std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::system_clock::now().time_since_epoch())
                     .count()};
}

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "rouen_nmea_XXXXXX").string();
    path_ = mkdtemp(tmpl.data());
  }
  ~TempDir() { fs::remove_all(path_); }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

TEST(NmeaOptions, ValidateExplains) {
  NmeaOptions o;
  EXPECT_THROW(o.Validate(), Error);
  o.path = "/dev/ttyACM0";
  EXPECT_NO_THROW(o.Validate());
  o.baud = 1234;
  try {
    o.Validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("1234"), std::string::npos);
  }
  o.baud = 0;
  o.timeout_s = -1;
  EXPECT_THROW(o.Validate(), Error);
  o.timeout_s = std::nan("");
  EXPECT_THROW(o.Validate(), Error);
}

TEST(NmeaGps, MissingDeviceOrFileNamesThePath) {
  for (int baud : {0, 9600}) {
    NmeaOptions o;
    o.path = "/nonexistent/rouen-gps";
    o.baud = baud;
    try {
      OpenNmeaGps(o);
      FAIL() << "opened a missing path";
    } catch (const DeviceError& e) {
      EXPECT_NE(std::string(e.what()).find("/nonexistent/rouen-gps"), std::string::npos);
    }
  }
}

TEST(NmeaGps, RegularFileWithBaudIsNotASerialPort) {
  TempDir dir;
  const fs::path log = dir.path() / "log.nmea";
  std::ofstream(log) << Epoch(0);
  NmeaOptions o;
  o.path = log.string();
  o.baud = 9600;
  try {
    OpenNmeaGps(o);
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("not a serial port"), std::string::npos) << e.what();
  }
}

TEST(NmeaGps, LogFileLineByLine) {
  TempDir dir;
  const fs::path log = dir.path() / "log.nmea";
  {
    std::ofstream out(log);
    out << Epoch(0) << "garbage line\r\n" << Epoch(1) << Epoch(2);
  }
  NmeaOptions o;
  o.path = log.string();
  o.baud = 0;
  NmeaGps gps(o);
  EXPECT_EQ(gps.Id(), "nmea:" + log.string());
  const UtcTime before = LaptopNow();
  std::vector<UtcTime> seen;
  int polls = 0;
  while (!gps.at_end() && polls < 100) {
    auto fix = gps.Poll();
    ++polls;
    if (polls == 1) {
      EXPECT_TRUE(fix) << "an RMC alone already makes a (2D) fix";
    }
    if (fix && (seen.empty() || seen.back() != fix->utc)) seen.push_back(fix->utc);
  }
  const UtcTime after = LaptopNow();
  EXPECT_EQ(polls, 3 * 4 + 1 + 1) << "one line per Poll, plus the end-of-file Poll";
  ASSERT_EQ(seen.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(seen[i], TimeOf(i));
  auto last = gps.Poll();
  ASSERT_TRUE(last);
  EXPECT_EQ(last->mode, 3);
  EXPECT_NEAR(last->lat_deg, LatOf(2), 1e-12);
  EXPECT_NEAR(last->height_m, 147.0, 1e-9);
  // A recorded log is not live: no laptop time, so no clock offset is derived from it.
  EXPECT_FALSE(last->received_utc);
  EXPECT_LE(before, after);
  EXPECT_EQ(gps.decoder().stats().rejected, 1);
  EXPECT_EQ(gps.decoder().stats().epochs, 3);
}

TEST(NmeaGps, LogFileEpochPerPoll) {
  TempDir dir;
  const fs::path log = dir.path() / "log.nmea";
  {
    std::ofstream out(log);
    for (int i = 0; i < 4; ++i) out << Epoch(i);
  }
  NmeaOptions o;
  o.path = log.string();
  o.baud = 0;
  o.epoch_per_poll = true;
  NmeaGps gps(o);
  for (int i = 0; i < 4; ++i) {
    auto fix = gps.Poll();
    ASSERT_TRUE(fix) << i;
    EXPECT_EQ(fix->utc, TimeOf(i));
    EXPECT_EQ(fix->mode, 3);
    EXPECT_EQ(fix->satellites, 9);
    EXPECT_NEAR(fix->lat_deg, LatOf(i), 1e-12);
  }
  EXPECT_TRUE(gps.at_end());
  EXPECT_EQ(gps.Poll()->utc, TimeOf(3));
}

TEST(NmeaGps, RawLogKeepsEveryLineAsRead) {
  TempDir dir;
  const fs::path log = dir.path() / "in.nmea", raw = dir.path() / "gps.nmea";
  const std::string text = Epoch(0) + "garbage\r\n" + Epoch(1);
  std::ofstream(log) << text;
  NmeaOptions o;
  o.path = log.string();
  o.baud = 0;
  o.raw_log_path = raw.string();
  {
    NmeaGps gps(o);
    while (!gps.at_end()) gps.Poll();
    EXPECT_TRUE(gps.raw_log_error().empty());
  }
  std::ifstream in(raw, std::ios::binary);
  const std::string copy((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(copy, text);
  o.raw_log_path = log.string();
  EXPECT_THROW(o.Validate(), Error);
  o.raw_log_path = (dir.path() / "no/such/dir/gps.nmea").string();
  EXPECT_THROW(NmeaGps{o}, DeviceError);
}

// A pseudo-terminal stands in for the receiver: the test writes NMEA into the master, the
// driver reads the slave as a tty.
class Pty {
 public:
  Pty() {
    master_ = posix_openpt(O_RDWR | O_NOCTTY);
    if (master_ >= 0 && grantpt(master_) == 0 && unlockpt(master_) == 0) {
      slave_ = ptsname(master_);
    }
  }
  ~Pty() { Close(); }
  bool ok() const { return !slave_.empty(); }
  const std::string& slave() const { return slave_; }
  void Write(const std::string& s) {
    ASSERT_EQ(::write(master_, s.data(), s.size()), static_cast<ssize_t>(s.size()));
  }
  void Close() {
    if (master_ >= 0) ::close(master_);
    master_ = -1;
  }

 private:
  int master_ = -1;
  std::string slave_;
};

// Polls until `pred(fix)` or a deadline.
template <typename Pred>
std::optional<GpsFix> PollUntil(Gps& gps, Pred pred, double seconds = 5.0) {
  const auto deadline = SteadyClock::now() + std::chrono::duration<double>(seconds);
  while (SteadyClock::now() < deadline) {
    auto fix = gps.Poll();
    if (fix && pred(*fix)) return fix;
  }
  return std::nullopt;
}

TEST(NmeaGps, SerialThroughPseudoTerminal) {
  Pty pty;
  if (!pty.ok()) GTEST_SKIP() << "no pseudo-terminals here (posix_openpt failed)";
  NmeaOptions o;
  o.path = pty.slave();
  o.baud = 9600;
  o.timeout_s = 0.2;
  NmeaGps gps(o);
  EXPECT_EQ(gps.Id(), "nmea:" + pty.slave());

  // Nothing sent: Poll() returns nothing and waits no longer than the timeout.
  auto t0 = SteadyClock::now();
  EXPECT_FALSE(gps.Poll());
  double waited = std::chrono::duration<double>(SteadyClock::now() - t0).count();
  EXPECT_GE(waited, 0.15);
  EXPECT_LT(waited, 0.2 + 2.0);  // returns by its timeout, not when data comes (load-tolerant)

  const UtcTime before = LaptopNow();
  pty.Write(Epoch(0));
  auto fix = PollUntil(gps, [](const GpsFix& f) { return f.mode == 3; });
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->utc, TimeOf(0));
  EXPECT_NEAR(fix->lat_deg, LatOf(0), 1e-12);
  ASSERT_TRUE(fix->received_utc);
  EXPECT_LE(before, *fix->received_utc);
  EXPECT_LE(*fix->received_utc, LaptopNow());

  // A line split across two writes (and so across reads): nothing new until it completes.
  const std::string next = Epoch(1);
  const size_t cut = next.find(",N,") + 1;  // inside the RMC, before its checksum
  pty.Write(next.substr(0, cut));
  t0 = SteadyClock::now();
  fix = gps.Poll();
  waited = std::chrono::duration<double>(SteadyClock::now() - t0).count();
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->utc, TimeOf(0)) << "half a sentence must not be decoded";
  EXPECT_LT(waited, 0.2 + 2.0);  // returns by its timeout, not when data comes (load-tolerant)
  pty.Write(next.substr(cut));
  fix = PollUntil(gps, [](const GpsFix& f) { return f.utc == TimeOf(1) && f.mode == 3; });
  ASSERT_TRUE(fix);
  EXPECT_NEAR(fix->lat_deg, LatOf(1), 1e-12);
  EXPECT_EQ(gps.decoder().stats().rejected, 0) << gps.decoder().stats().Summary();

  // The receiver goes away: DeviceError naming the device.
  pty.Close();
  const auto deadline = SteadyClock::now() + std::chrono::seconds(5);
  bool thrown = false;
  while (!thrown && SteadyClock::now() < deadline) {
    try {
      gps.Poll();
    } catch (const DeviceError& e) {
      thrown = true;
      EXPECT_NE(std::string(e.what()).find(pty.slave()), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(thrown);
  EXPECT_THROW(gps.Poll(), DeviceError) << "stays failed";
}

// Closing the master hangs the slave up; Linux discards input still queued in the tty, so
// the epoch may or may not arrive. Either way Poll() ends in a DeviceError, and a fix that
// does arrive is the one sent.
TEST(NmeaGps, HangupRightAfterDataEndsInDeviceError) {
  Pty pty;
  if (!pty.ok()) GTEST_SKIP() << "no pseudo-terminals here (posix_openpt failed)";
  NmeaOptions o;
  o.path = pty.slave();
  o.timeout_s = 0.2;
  NmeaGps gps(o);
  pty.Write(Epoch(7));
  pty.Close();
  std::optional<GpsFix> last;
  bool thrown = false;
  const auto deadline = SteadyClock::now() + std::chrono::seconds(5);
  while (!thrown && SteadyClock::now() < deadline) {
    try {
      if (auto f = gps.Poll()) last = f;
    } catch (const DeviceError&) {
      thrown = true;
    }
  }
  EXPECT_TRUE(thrown);
  if (last) {
    EXPECT_EQ(last->utc, TimeOf(7));
  }
}

TEST(NmeaGps, NoiseWithoutNewlinesIsBoundedAndCounted) {
  Pty pty;
  if (!pty.ok()) GTEST_SKIP() << "no pseudo-terminals here (posix_openpt failed)";
  NmeaOptions o;
  o.path = pty.slave();
  o.baud = 115200;
  o.timeout_s = 0.1;
  NmeaGps gps(o);
  pty.Write(std::string(3000, 'x'));
  pty.Write(std::string(3000, 'y'));  // > 4096 bytes without '\n': dropped as one bad line
  pty.Write("\n" + Epoch(3));
  auto fix = PollUntil(gps, [](const GpsFix& f) { return f.mode == 3; });
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->utc, TimeOf(3));
  EXPECT_GE(gps.decoder().stats().by_kind[static_cast<int>(NmeaErrorKind::kFraming)], 1);
}

// End to end: a "receiver" whose clock runs 3 s ahead of the laptop sends epochs stamped with
// its time as it sends them; the estimator recovers the offset from the fixes the driver read.
TEST(NmeaGps, ClockOffsetFromFixesReadThroughPty) {
  Pty pty;
  if (!pty.ok()) GTEST_SKIP() << "no pseudo-terminals here (posix_openpt failed)";
  NmeaOptions o;
  o.path = pty.slave();
  o.timeout_s = 0.2;
  NmeaGps gps(o);
  const double true_offset = 3.0;  // GPS minus laptop
  std::vector<GpsFix> fixes;
  ClockOffsetEstimator est;
  int last_cs = -1;
  for (int i = 0; i < 5; ++i) {
    // Time printed to centiseconds, rounded down: the stamp is at most 0.01 s early. Each
    // epoch needs its own stamp: wait for the next centisecond (at most 10 ms).
    CivilTime c;
    int cs = 0;
    do {
      c = ToCivil(LaptopNow().PlusSeconds(true_offset));
      cs = static_cast<int>(std::floor(c.second * 100));
    } while (cs == last_cs);
    last_cs = cs;
    char t[32], date[16];
    std::snprintf(t, sizeof(t), "%02d%02d%02d.%02d", c.hour, c.minute, cs / 100, cs % 100);
    std::snprintf(date, sizeof(date), "%02d%02d%02d", c.day, c.month, c.year % 100);
    pty.Write(
        Sentence(std::string("GPRMC,") + t + ",A,4807.038,N,01131.000,E,0,0," + date + ",,") +
        Sentence(std::string("GPGGA,") + t + ",4807.038,N,01131.000,E,1,09,0.8,100.0,M,47.0,M,,"));
    const UtcTime stamped =
        FromCivil(CivilTime{c.year, c.month, c.day, c.hour, c.minute, cs / 100.0});
    auto fix = PollUntil(gps, [&](const GpsFix& f) { return f.utc == stamped && f.mode == 3; });
    ASSERT_TRUE(fix) << i;
    fixes.push_back(*fix);
    est.Add(*fix);
  }
  ASSERT_TRUE(est.Offset());
  EXPECT_EQ(est.count(), 5);
  for (size_t i = 1; i < fixes.size(); ++i) EXPECT_NE(fixes[i].utc, fixes[i - 1].utc);
  // d = offset - (stamp rounding <= 0.01 s) - (pty transfer + poll wake-up lag >= 0).
  EXPECT_LE(*est.Offset(), true_offset + 1e-6);
  EXPECT_GT(*est.Offset(), true_offset - 0.25);
  std::printf("clock offset: true %.3f s, estimated %.4f s (spread %.4f s)\n", true_offset,
              *est.Offset(), est.Spread());
}

}  // namespace
}  // namespace rouen
