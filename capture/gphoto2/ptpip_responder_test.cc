// The PTP/IP camera double on its own, over raw sockets: the handshake, the session rule and
// a data phase as CIPA DC-X005 lays them out, and a refused handshake.
#include "capture/gphoto2/testing/ptpip_responder.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <string>
#include <vector>

namespace rouen {
namespace {

struct Packet {
  uint32_t type = 0;
  std::vector<uint8_t> payload;
};

uint32_t Le32(const std::vector<uint8_t>& b, size_t at) {
  return b[at] | (b[at + 1] << 8) | (b[at + 2] << 16) | (static_cast<uint32_t>(b[at + 3]) << 24);
}
uint16_t Le16(const std::vector<uint8_t>& b, size_t at) {
  return static_cast<uint16_t>(b[at] | (b[at + 1] << 8));
}
void Put32(std::vector<uint8_t>& b, uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<uint8_t>(v >> (8 * i)));
}
void Put16(std::vector<uint8_t>& b, uint16_t v) {
  b.push_back(static_cast<uint8_t>(v));
  b.push_back(static_cast<uint8_t>(v >> 8));
}

// A blocking TCP client with a 5-s limit on every read.
class Client {
 public:
  explicit Client(uint16_t port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(port);
    ok_ = fd_ >= 0 && ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
  }
  ~Client() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool ok() const { return ok_; }

  void Send(uint32_t type, const std::vector<uint8_t>& payload) {
    std::vector<uint8_t> b;
    Put32(b, static_cast<uint32_t>(payload.size() + 8));
    Put32(b, type);
    b.insert(b.end(), payload.begin(), payload.end());
    ASSERT_EQ(::send(fd_, b.data(), b.size(), MSG_NOSIGNAL), static_cast<ssize_t>(b.size()));
  }
  // The next packet; type 0 on end of stream or after 5 s.
  Packet Read() {
    Packet p;
    std::vector<uint8_t> h(8);
    if (!ReadExact(h.data(), 8)) return p;
    p.payload.resize(Le32(h, 0) - 8);
    if (!ReadExact(p.payload.data(), p.payload.size())) return p;
    p.type = Le32(h, 4);
    return p;
  }
  // An operation request (data phase 1: none or camera to host).
  void Request(uint16_t op, uint32_t transaction, const std::vector<uint32_t>& params) {
    std::vector<uint8_t> b;
    Put32(b, 1);
    Put16(b, op);
    Put32(b, transaction);
    for (uint32_t p : params) Put32(b, p);
    Send(6, b);
  }

 private:
  bool ReadExact(uint8_t* out, size_t n) {
    size_t got = 0;
    while (got < n) {
      pollfd p = {fd_, POLLIN, 0};
      if (::poll(&p, 1, 5000) <= 0) return false;
      const ssize_t r = ::recv(fd_, out + got, n - got, 0);
      if (r <= 0) return false;
      got += static_cast<size_t>(r);
    }
    return true;
  }
  int fd_ = -1;
  bool ok_ = false;
};

TEST(PtpIpResponderTest, HandshakeSessionAndDataPhase) {
  PtpIpResponder responder;
  EXPECT_GT(responder.Port(), 0);
  EXPECT_EQ(responder.PortPath(), "ptpip:127.0.0.1:" + std::to_string(responder.Port()) + ":" +
                                      std::to_string(responder.Port()));
  Client cmd(responder.Port());
  ASSERT_TRUE(cmd.ok());
  std::vector<uint8_t> init(16, 0x11);  // GUID
  for (char c : std::string("host")) Put16(init, static_cast<uint16_t>(c));
  Put16(init, 0);
  Put32(init, 0x00010000);
  cmd.Send(1, init);
  const Packet ack = cmd.Read();
  ASSERT_EQ(ack.type, 2u);  // Init_Command_Ack
  ASSERT_GE(ack.payload.size(), 4u + 16 + 2 + 4);
  const uint32_t connection = Le32(ack.payload, 0);
  std::string name;
  for (size_t i = 20; i + 1 < ack.payload.size() && Le16(ack.payload, i) != 0; i += 2)
    name += static_cast<char>(Le16(ack.payload, i));
  EXPECT_EQ(name, "rouen PTP/IP double");

  Client evt(responder.Port());
  ASSERT_TRUE(evt.ok());
  std::vector<uint8_t> ev;
  Put32(ev, connection);
  evt.Send(3, ev);
  EXPECT_EQ(evt.Read().type, 4u);  // Init_Event_Ack

  // No session yet: Session_Not_Open.
  cmd.Request(ptp_op::kGetStorageIds, 1, {});
  Packet r = cmd.Read();
  ASSERT_EQ(r.type, 7u);
  EXPECT_EQ(Le16(r.payload, 0), 0x2003);
  EXPECT_EQ(Le32(r.payload, 2), 1u);  // the transaction answered

  cmd.Request(ptp_op::kOpenSession, 0, {1});
  r = cmd.Read();
  ASSERT_EQ(r.type, 7u);
  EXPECT_EQ(Le16(r.payload, 0), 0x2001);

  // GetStorageIDs: Start_Data (transaction, 64-bit length), End_Data, then the response.
  cmd.Request(ptp_op::kGetStorageIds, 1, {});
  r = cmd.Read();
  ASSERT_EQ(r.type, 9u);
  EXPECT_EQ(Le32(r.payload, 0), 1u);
  EXPECT_EQ(Le32(r.payload, 4), 8u);
  EXPECT_EQ(Le32(r.payload, 8), 0u);
  r = cmd.Read();
  ASSERT_EQ(r.type, 12u);
  ASSERT_EQ(r.payload.size(), 12u);
  EXPECT_EQ(Le32(r.payload, 4), 1u);           // one storage
  EXPECT_EQ(Le32(r.payload, 8), 0x00010001u);  // its id
  r = cmd.Read();
  ASSERT_EQ(r.type, 7u);
  EXPECT_EQ(Le16(r.payload, 0), 0x2001);

  // An operation it does not know.
  cmd.Request(0x9999, 2, {});
  r = cmd.Read();
  ASSERT_EQ(r.type, 7u);
  EXPECT_EQ(Le16(r.payload, 0), 0x2005);

  EXPECT_EQ(responder.Stats().connections, 1);
  EXPECT_TRUE(responder.ProtocolErrors().empty());
}

TEST(PtpIpResponderTest, RefusesAHandshakeThatIsNotPtpIp) {
  PtpIpResponder responder;
  {
    Client c(responder.Port());
    ASSERT_TRUE(c.ok());
    c.Send(6, std::vector<uint8_t>(10, 0));  // an operation before any handshake
    const Packet p = c.Read();
    EXPECT_EQ(p.type, 5u);  // Init_Fail
  }
  const std::vector<std::string> errors = responder.ProtocolErrors();
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("Init_Command_Request"), std::string::npos) << errors[0];
  // It still serves the next host.
  Client c(responder.Port());
  ASSERT_TRUE(c.ok());
  std::vector<uint8_t> init(16, 0);
  Put16(init, 0);
  Put32(init, 0x00010000);
  c.Send(1, init);
  EXPECT_EQ(c.Read().type, 2u);
}

}  // namespace
}  // namespace rouen
