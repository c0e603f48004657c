// GpsdGps against a scripted stand-in for gpsd on loopback: the test is the server and writes
// the JSON reports itself, so partial reports, untimed reports and hang-ups are exact.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <string>

#include "capture/gpsd/gpsd.h"

namespace rouen {
namespace {

using SteadyClock = std::chrono::steady_clock;

// A listening loopback socket. The client's connect() completes from the backlog, so the
// test can construct the driver first and accept() afterwards, on one thread.
class FakeGpsd {
 public:
  FakeGpsd() {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof(a);
    if (listen_fd_ >= 0 && ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
        ::listen(listen_fd_, 4) == 0 &&
        ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
      port_ = ntohs(a.sin_port);
    }
  }
  ~FakeGpsd() {
    CloseClient();
    if (listen_fd_ >= 0) ::close(listen_fd_);
  }
  int port() const { return port_; }
  bool Accept() {
    pollfd p{listen_fd_, POLLIN, 0};
    if (::poll(&p, 1, 5000) != 1) return false;
    client_fd_ = ::accept(listen_fd_, nullptr, nullptr);
    if (client_fd_ < 0) return false;
    // The driver asks for a JSON watch first.
    char buf[512];
    pollfd c{client_fd_, POLLIN, 0};
    if (::poll(&c, 1, 5000) != 1) return false;
    const ssize_t n = ::read(client_fd_, buf, sizeof(buf));
    watch_ = n > 0 ? std::string(buf, static_cast<size_t>(n)) : "";
    return true;
  }
  void Send(const std::string& s) {
    ASSERT_EQ(::write(client_fd_, s.data(), s.size()), static_cast<ssize_t>(s.size()));
  }
  void CloseClient() {
    if (client_fd_ >= 0) ::close(client_fd_);
    client_fd_ = -1;
  }
  const std::string& watch() const { return watch_; }

 private:
  int listen_fd_ = -1, client_fd_ = -1, port_ = -1;
  std::string watch_;
};

const char kVersion[] =
    "{\"class\":\"VERSION\",\"release\":\"3.22\",\"rev\":\"3.22\",\"proto_major\":3,"
    "\"proto_minor\":14}\n";

std::string Tpv(const std::string& fields) {
  return "{\"class\":\"TPV\",\"device\":\"/dev/fake\"," + fields + "}\n";
}

class GpsdProtocol : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_GT(server_.port(), 0);
    GpsdOptions o;
    o.port = std::to_string(server_.port());
    o.timeout_s = 0.2;
    gps_ = std::make_unique<GpsdGps>(o);
    ASSERT_TRUE(server_.Accept());
    server_.Send(kVersion);
  }
  // Polls until a fix satisfying `pred` or a deadline.
  template <typename Pred>
  std::optional<GpsFix> PollUntil(Pred pred) {
    const auto deadline = SteadyClock::now() + std::chrono::seconds(5);
    while (SteadyClock::now() < deadline) {
      auto f = gps_->Poll();
      if (f && pred(*f)) return f;
    }
    return std::nullopt;
  }

  FakeGpsd server_;
  std::unique_ptr<GpsdGps> gps_;
};

TEST_F(GpsdProtocol, AsksForJsonWatch) {
  EXPECT_NE(server_.watch().find("?WATCH"), std::string::npos) << server_.watch();
  EXPECT_NE(server_.watch().find("\"json\":true"), std::string::npos) << server_.watch();
}

TEST_F(GpsdProtocol, TpvBecomesFixWithEllipsoidalHeight) {
  server_.Send(
      Tpv("\"mode\":3,\"time\":\"2025-06-21T12:00:05.250Z\",\"lat\":49.4402,"
          "\"lon\":1.095,\"altHAE\":66.125,\"altMSL\":20.125,\"geoidSep\":46.0"));
  auto f = PollUntil([](const GpsFix&) { return true; });
  ASSERT_TRUE(f);
  EXPECT_EQ(f->utc, FromCivil(CivilTime{2025, 6, 21, 12, 0, 5.25}));
  EXPECT_EQ(f->mode, 3);
  EXPECT_DOUBLE_EQ(f->lat_deg, 49.4402);
  EXPECT_DOUBLE_EQ(f->lon_deg, 1.095);
  EXPECT_DOUBLE_EQ(f->height_m, 66.125);
  EXPECT_TRUE(f->received_utc);
  // Without altHAE: altMSL + geoidSep.
  server_.Send(
      Tpv("\"mode\":3,\"time\":\"2025-06-21T12:00:06.000Z\",\"lat\":49.4402,"
          "\"lon\":1.095,\"altMSL\":20.5,\"geoidSep\":46.0"));
  f = PollUntil([](const GpsFix& g) { return g.utc.ns % 1000000000 == 0; });
  ASSERT_TRUE(f);
  EXPECT_DOUBLE_EQ(f->height_m, 66.5);
  // 3D claimed without any height: reported as 2D.
  server_.Send(
      Tpv("\"mode\":3,\"time\":\"2025-06-21T12:00:07.000Z\",\"lat\":49.4402,"
          "\"lon\":1.095"));
  f = PollUntil([](const GpsFix& g) { return g.utc.ns / 1000000000 % 60 == 7; });
  ASSERT_TRUE(f);
  EXPECT_EQ(f->mode, 2);
  EXPECT_EQ(gps_->stats().fixes, 3);
}

TEST_F(GpsdProtocol, UntimedReportIsNotAFixAndNoFixIsModeZero) {
  server_.Send(Tpv("\"mode\":3,\"lat\":49.4402,\"lon\":1.095,\"altHAE\":66.0"));
  const auto t0 = SteadyClock::now();
  EXPECT_FALSE(gps_->Poll());
  const double waited = std::chrono::duration<double>(SteadyClock::now() - t0).count();
  EXPECT_LT(waited, 0.2 + 2.0);  // by its timeout, not never (load-tolerant bound)
  // The report may need a second Poll to arrive; wait for it to be counted.
  const auto deadline = SteadyClock::now() + std::chrono::seconds(5);
  while (gps_->stats().untimed == 0 && SteadyClock::now() < deadline) EXPECT_FALSE(gps_->Poll());
  EXPECT_EQ(gps_->stats().untimed, 1);
  server_.Send(Tpv("\"mode\":1,\"time\":\"2025-06-21T12:00:08.000Z\""));
  auto f = PollUntil([](const GpsFix&) { return true; });
  ASSERT_TRUE(f);
  EXPECT_EQ(f->mode, 0);
  EXPECT_FALSE(f->valid());
}

TEST_F(GpsdProtocol, PartialReportWaitsAtMostTheTimeout) {
  const std::string tpv =
      Tpv("\"mode\":2,\"time\":\"2025-06-21T12:00:09.000Z\",\"lat\":-33.5,\"lon\":151.25");
  server_.Send(tpv.substr(0, 40));
  for (int i = 0; i < 3; ++i) {
    const auto t0 = SteadyClock::now();
    EXPECT_FALSE(gps_->Poll());
    const double waited = std::chrono::duration<double>(SteadyClock::now() - t0).count();
    EXPECT_LT(waited, 0.2 + 2.0) << "Poll() blocked on half a report";
  }
  server_.Send(tpv.substr(40));
  auto f = PollUntil([](const GpsFix&) { return true; });
  ASSERT_TRUE(f);
  EXPECT_EQ(f->mode, 2);
  EXPECT_DOUBLE_EQ(f->lat_deg, -33.5);
  EXPECT_DOUBLE_EQ(f->lon_deg, 151.25);
}

TEST_F(GpsdProtocol, HangUpIsADeviceError) {
  server_.Send(
      Tpv("\"mode\":3,\"time\":\"2025-06-21T12:00:10.000Z\",\"lat\":49.4,"
          "\"lon\":1.1,\"altHAE\":60"));
  ASSERT_TRUE(PollUntil([](const GpsFix&) { return true; }));
  server_.CloseClient();
  bool thrown = false;
  const auto deadline = SteadyClock::now() + std::chrono::seconds(5);
  while (!thrown && SteadyClock::now() < deadline) {
    try {
      gps_->Poll();
    } catch (const DeviceError& e) {
      thrown = true;
      EXPECT_NE(std::string(e.what()).find("connection lost"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(std::to_string(server_.port())), std::string::npos);
    }
  }
  EXPECT_TRUE(thrown);
}

TEST_F(GpsdProtocol, HangUpInTheMiddleOfAReportIsADeviceError) {
  server_.Send(Tpv("\"mode\":3,\"time\":\"2025-06-21T12:00:11.000Z\"").substr(0, 30));
  server_.CloseClient();
  bool thrown = false;
  const auto deadline = SteadyClock::now() + std::chrono::seconds(5);
  while (!thrown && SteadyClock::now() < deadline) {
    try {
      EXPECT_FALSE(gps_->Poll());
    } catch (const DeviceError& e) {
      thrown = true;
      EXPECT_NE(std::string(e.what()).find("connection lost"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(thrown);
}

}  // namespace
}  // namespace rouen
