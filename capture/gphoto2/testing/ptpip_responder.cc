#include "capture/gphoto2/testing/ptpip_responder.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <functional>
#include <mutex>
#include <thread>

#include "core/error.h"

namespace rouen {
namespace {

// PTP/IP packet types (CIPA DC-X005).
enum PacketType : uint32_t {
  kInitCommandRequest = 1,
  kInitCommandAck = 2,
  kInitEventRequest = 3,
  kInitEventAck = 4,
  kInitFail = 5,
  kOperationRequest = 6,
  kOperationResponse = 7,
  kEvent = 8,
  kStartData = 9,
  kData = 10,
  kCancel = 11,
  kEndData = 12,
  kProbeRequest = 13,
  kProbeResponse = 14,
};

// PTP response codes (ISO 15740).
constexpr uint16_t kOk = 0x2001, kGeneralError = 0x2002, kSessionNotOpen = 0x2003,
                   kOperationNotSupported = 0x2005, kInvalidStorageId = 0x2008,
                   kInvalidObjectHandle = 0x2009, kDevicePropNotSupported = 0x200A,
                   kInvalidObjectFormatCode = 0x200B, kAccessDenied = 0x200F, kDeviceBusy = 0x2019,
                   kInvalidDevicePropFormat = 0x201B, kInvalidDevicePropValue = 0x201C,
                   kInvalidParameter = 0x201D, kSessionAlreadyOpen = 0x201E;
// Events, properties, data types, formats.
constexpr uint16_t kObjectAdded = 0x4002, kCaptureComplete = 0x400D;
constexpr uint16_t kBatteryLevel = 0x5001, kFNumber = 0x5007, kExposureTime = 0x500D,
                   kExposureIndex = 0x500F, kDateTime = 0x5011;
constexpr uint16_t kTypeUint8 = 0x0002, kTypeUint16 = 0x0004, kTypeUint32 = 0x0006,
                   kTypeString = 0xFFFF;
constexpr uint16_t kFormatExifJpeg = 0x3801;
constexpr uint32_t kStorageId = 0x00010001;
constexpr uint32_t kAllStorages = 0xFFFFFFFF, kRootParent = 0xFFFFFFFF;
constexpr uint32_t kMaxPacket = 64u << 20;  // larger claims from the host are refused
constexpr size_t kDataChunk = 64 * 1024;    // payload per Data packet sent

// Little-endian serialisation of PTP datasets and PTP/IP packets.
class Writer {
 public:
  void U8(uint8_t v) { data.push_back(v); }
  void U16(uint16_t v) {
    U8(v & 0xFF);
    U8(v >> 8);
  }
  void U32(uint32_t v) {
    U16(v & 0xFFFF);
    U16(v >> 16);
  }
  void U64(uint64_t v) {
    U32(static_cast<uint32_t>(v));
    U32(static_cast<uint32_t>(v >> 32));
  }
  // A PTP string: character count including the terminating null (0 for ""), then UCS-2.
  void Str(const std::string& s) {
    if (s.empty()) {
      U8(0);
      return;
    }
    const size_t n = std::min<size_t>(s.size(), 254);
    U8(static_cast<uint8_t>(n + 1));
    for (size_t i = 0; i < n; ++i) U16(static_cast<unsigned char>(s[i]));
    U16(0);
  }
  void U16Array(const std::vector<uint16_t>& a) {
    U32(static_cast<uint32_t>(a.size()));
    for (uint16_t v : a) U16(v);
  }
  void U32Array(const std::vector<uint32_t>& a) {
    U32(static_cast<uint32_t>(a.size()));
    for (uint32_t v : a) U32(v);
  }
  void Bytes(const std::vector<uint8_t>& b) { data.insert(data.end(), b.begin(), b.end()); }
  std::vector<uint8_t> data;
};

std::string Hex(uint16_t code) {
  char buf[8];
  std::snprintf(buf, sizeof(buf), "0x%04X", code);
  return buf;
}

uint32_t Le32(const uint8_t* p) {
  return p[0] | (p[1] << 8) | (p[2] << 16) | (static_cast<uint32_t>(p[3]) << 24);
}
uint16_t Le16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }

// A packet with its 8-byte header (length, type) in front of `payload`.
std::vector<uint8_t> Packet(uint32_t type, const std::vector<uint8_t>& payload) {
  Writer w;
  w.U32(static_cast<uint32_t>(payload.size() + 8));
  w.U32(type);
  w.Bytes(payload);
  return w.data;
}

struct Received {
  uint32_t type = 0;
  std::vector<uint8_t> payload;
};

// A device property: an enumeration (or a read-only range) of unsigned integers, or a read-only
// string (kTypeString, its value made when asked).
struct Property {
  uint16_t code = 0, type = 0;
  std::function<std::string()> text;  // kTypeString
  bool writable = true;
  uint32_t factory = 0, current = 0;
  std::vector<uint32_t> values;         // enumeration; empty = range
  uint32_t min = 0, max = 0, step = 1;  // range
};

void PutValue(Writer& w, uint16_t type, uint32_t v) {
  if (type == kTypeUint8) w.U8(static_cast<uint8_t>(v));
  if (type == kTypeUint16) w.U16(static_cast<uint16_t>(v));
  if (type == kTypeUint32) w.U32(v);
}

size_t TypeSize(uint16_t type) { return type == kTypeUint8 ? 1 : type == kTypeUint16 ? 2 : 4; }

// The built-in scene (see PtpIpResponderOptions::frame).
Image BuiltinScene(const PtpShot& s, int w, int h) {
  const double gain =
      120.0 * (s.exposure_s * 30.0) * (s.iso / 100.0) * std::pow(8.0 / s.f_number, 2);
  Image im(w, h, 3, PixelUnits::kDigital);
  const float colour[3] = {1.0f, 0.9f, 0.8f};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double ramp = 0.5 + 0.5 * x / std::max(1, w - 1);
      for (int c = 0; c < 3; ++c)
        im.at(x, y, c) = static_cast<float>(std::clamp(gain * ramp * colour[c], 0.0, 255.0));
    }
  return im;
}

// "YYYY:MM:DD HH:MM:SS" (EXIF) or "YYYYMMDDThhmmss" (PTP) of the current UTC time plus
// `offset_s`.
std::string Now(bool exif, double offset_s = 0) {
  const std::time_t t = std::time(nullptr) + static_cast<std::time_t>(std::llround(offset_s));
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), exif ? "%Y:%m:%d %H:%M:%S" : "%Y%m%dT%H%M%S", &tm);
  return buf;
}

}  // namespace

struct PtpIpResponder::State {
  struct Object {
    std::vector<uint8_t> bytes;
    std::string name, date;
    int width = 0, height = 0;
  };
  // What the server thread does after answering a request.
  struct Reply {
    uint16_t code = kOk;
    std::vector<uint32_t> params;
    bool has_data = false;
    std::vector<uint8_t> data;
    std::vector<std::pair<uint16_t, uint32_t>> events;  // sent after the response
    bool download = false;                              // GetObject: counts once the data was sent
  };

  mutable std::mutex mu;
  std::map<uint16_t, int> busy;
  int drop_after = 0;
  std::optional<uint16_t> drop_op;
  bool corrupt_next = false;
  std::optional<double> exif_exposure;
  PtpIpResponderStats stats;
  std::vector<std::string> errors;
  std::map<uint16_t, Property> props;
  std::map<uint32_t, Object> objects;
  uint32_t next_handle = 1;
  bool session_open = false;
  uint32_t session_id = 0;
  uint32_t last_transaction = 0;

  int listen_fd = -1;
  int wake[2] = {-1, -1};
  std::atomic<bool> stopping{false};
  std::thread thread;

  void Error(const std::string& what) {
    std::lock_guard<std::mutex> lock(mu);
    errors.push_back(what);
  }
};

PtpIpResponder::PtpIpResponder(PtpIpResponderOptions options)
    : options_(std::move(options)), state_(std::make_unique<State>()) {
  State& s = *state_;
  auto add = [&](uint16_t code, uint16_t type, uint32_t current, std::vector<uint32_t> values) {
    Property p;
    p.code = code;
    p.type = type;
    p.factory = p.current = current;
    p.values = std::move(values);
    s.props[code] = p;
  };
  // ExposureTime in 0.1 ms; by default 1/2000 .. 30 s in whole stops (1/125 = 80, 1/60 = 167,
  // 1/30 = 333).
  const std::vector<uint32_t>& times = options_.exposure_times;
  if (times.empty() || std::find(times.begin(), times.end(), 0u) != times.end())
    throw Error("ptpip responder: exposure_times must be positive units of 0.1 ms");
  add(kExposureTime, kTypeUint32,
      std::find(times.begin(), times.end(), 80u) != times.end() ? 80u : times.front(), times);
  add(kExposureIndex, kTypeUint16, 100, {100, 200, 400, 800, 1600, 3200});
  add(kFNumber, kTypeUint16, 800, {280, 400, 560, 800, 1100, 1600});
  Property battery;
  battery.code = kBatteryLevel;
  battery.type = kTypeUint8;
  battery.writable = false;
  battery.factory = battery.current = 80;
  battery.min = 0;
  battery.max = 100;
  battery.step = 1;
  s.props[kBatteryLevel] = battery;
  Property clock;
  clock.code = kDateTime;
  clock.type = kTypeString;
  clock.writable = false;
  clock.text = [offset = options_.clock_offset_s] { return Now(false, offset); };
  s.props[kDateTime] = clock;

  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, s.wake) != 0)
    throw Error("ptpip responder: socketpair: " + std::string(strerror(errno)));
  s.listen_fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (s.listen_fd < 0) throw Error("ptpip responder: socket: " + std::string(strerror(errno)));
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(options_.port);
  if (options_.port != 0) {
    const int one = 1;
    ::setsockopt(s.listen_fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  }
  if (::bind(s.listen_fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::listen(s.listen_fd, 4) != 0) {
    const std::string why = strerror(errno);
    ::close(s.listen_fd);
    ::close(s.wake[0]);
    ::close(s.wake[1]);
    throw Error("ptpip responder: cannot listen on 127.0.0.1:" + std::to_string(options_.port) +
                ": " + why);
  }
  socklen_t len = sizeof(addr);
  ::getsockname(s.listen_fd, reinterpret_cast<sockaddr*>(&addr), &len);
  port_ = ntohs(addr.sin_port);
  s.thread = std::thread([this] { Run(); });
}

PtpIpResponder::~PtpIpResponder() {
  State& s = *state_;
  s.stopping = true;
  const char c = 'x';
  [[maybe_unused]] ssize_t n = ::send(s.wake[1], &c, 1, MSG_NOSIGNAL);
  if (s.thread.joinable()) s.thread.join();
  ::close(s.listen_fd);
  ::close(s.wake[0]);
  ::close(s.wake[1]);
}

std::string PtpIpResponder::PortPath() const {
  return "ptpip:127.0.0.1:" + std::to_string(port_) + ":" + std::to_string(port_);
}

void PtpIpResponder::ReplyBusy(uint16_t operation, int times) {
  std::lock_guard<std::mutex> lock(state_->mu);
  state_->busy[operation] = times;
}

void PtpIpResponder::DropAfter(int operations) {
  std::lock_guard<std::mutex> lock(state_->mu);
  state_->drop_after = std::max(0, operations);
}

void PtpIpResponder::DropDuring(uint16_t operation) {
  std::lock_guard<std::mutex> lock(state_->mu);
  state_->drop_op = operation;
}

void PtpIpResponder::CorruptNextObject() {
  std::lock_guard<std::mutex> lock(state_->mu);
  state_->corrupt_next = true;
}

void PtpIpResponder::SetExifExposure(std::optional<double> seconds) {
  std::lock_guard<std::mutex> lock(state_->mu);
  state_->exif_exposure = seconds;
}

void PtpIpResponder::SetBatteryLevel(int percent) {
  if (percent < 0 || percent > 100)
    throw Error("ptpip responder: a battery level is 0..100 percent, not " +
                std::to_string(percent));
  std::lock_guard<std::mutex> lock(state_->mu);
  state_->props[kBatteryLevel].current = static_cast<uint32_t>(percent);
}

PtpIpResponderStats PtpIpResponder::Stats() const {
  std::lock_guard<std::mutex> lock(state_->mu);
  return state_->stats;
}

PtpShot PtpIpResponder::Settings() const {
  std::lock_guard<std::mutex> lock(state_->mu);
  PtpShot shot;
  shot.exposure_s = state_->props.at(kExposureTime).current / 10000.0;
  shot.iso = static_cast<int>(state_->props.at(kExposureIndex).current);
  shot.f_number = state_->props.at(kFNumber).current / 100.0;
  shot.index = state_->stats.captures;
  return shot;
}

std::vector<std::string> PtpIpResponder::ProtocolErrors() const {
  std::lock_guard<std::mutex> lock(state_->mu);
  return state_->errors;
}

namespace {

// Socket I/O for the server thread; every wait also watches the stop socket.
class Io {
 public:
  Io(int wake, const std::atomic<bool>& stopping, double timeout_s)
      : wake_(wake), stopping_(stopping), timeout_ms_(static_cast<int>(timeout_s * 1000)) {}

  // Waits until `fd` is readable; false when stopping, on timeout (timeout_ms < 0: none).
  bool WaitReadable(int fd, int timeout_ms) const {
    pollfd p[2] = {{fd, POLLIN, 0}, {wake_, POLLIN, 0}};
    for (;;) {
      const int r = ::poll(p, 2, timeout_ms);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0 || stopping_ || (p[1].revents & POLLIN)) return false;
      return (p[0].revents & (POLLIN | POLLHUP | POLLERR)) != 0;
    }
  }

  // Reads exactly n bytes; the first may take forever when `idle` (waiting for a request).
  bool ReadExact(int fd, uint8_t* out, size_t n, bool idle) const {
    size_t got = 0;
    while (got < n) {
      if (!WaitReadable(fd, idle && got == 0 ? -1 : timeout_ms_)) return false;
      const ssize_t r = ::recv(fd, out + got, n - got, 0);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      got += static_cast<size_t>(r);
    }
    return true;
  }

  // One packet; false on end of stream, stop, timeout or a length beyond kMaxPacket.
  bool ReadPacket(int fd, Received& p, bool idle, std::string* error) const {
    uint8_t header[8];
    if (!ReadExact(fd, header, 8, idle)) return false;
    const uint32_t length = Le32(header);
    p.type = Le32(header + 4);
    if (length < 8 || length > kMaxPacket) {
      if (error) *error = "packet length " + std::to_string(length) + " out of range";
      return false;
    }
    p.payload.assign(length - 8, 0);
    return p.payload.empty() || ReadExact(fd, p.payload.data(), p.payload.size(), false);
  }

  bool WriteAll(int fd, const std::vector<uint8_t>& data) const {
    size_t sent = 0;
    while (sent < data.size()) {
      const ssize_t r = ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      sent += static_cast<size_t>(r);
    }
    return true;
  }

  // A connection from the listening socket; -1 when stopping (a failed accept, e.g. a
  // connection reset before it was taken, waits for the next one).
  int Accept(int listen_fd) const {
    for (;;) {
      if (!WaitReadable(listen_fd, -1)) return -1;
      const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd >= 0) {
        const int one = 1;
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
        return fd;
      }
      if (errno == EBADF || errno == EINVAL || errno == ENOTSOCK) return -1;
    }
  }

 private:
  int wake_;
  const std::atomic<bool>& stopping_;
  int timeout_ms_;
};

std::vector<uint8_t> ResponsePacket(uint16_t code, uint32_t transaction,
                                    const std::vector<uint32_t>& params) {
  Writer w;
  w.U16(code);
  w.U32(transaction);
  for (uint32_t p : params) w.U32(p);
  return Packet(kOperationResponse, w.data);
}

std::vector<uint8_t> EventPacket(uint16_t code, uint32_t transaction, uint32_t param) {
  Writer w;
  w.U16(code);
  w.U32(transaction);
  w.U32(param);
  return Packet(kEvent, w.data);
}

std::vector<uint8_t> StartDataPacket(uint32_t transaction, uint64_t total) {
  Writer w;
  w.U32(transaction);
  w.U64(total);
  return Packet(kStartData, w.data);
}

// The payload of a Data or End_Data packet.
std::vector<uint8_t> DataPacket(uint32_t type, uint32_t transaction, const uint8_t* p, size_t n) {
  Writer w;
  w.U32(transaction);
  w.data.insert(w.data.end(), p, p + n);
  return Packet(type, w.data);
}

bool HasSideEffects(uint16_t op) {
  return op == ptp_op::kInitiateCapture || op == ptp_op::kSetDevicePropValue ||
         op == ptp_op::kDeleteObject || op == ptp_op::kOpenSession || op == ptp_op::kCloseSession;
}

}  // namespace

void PtpIpResponder::Run() {
  State& s = *state_;
  const Io io(s.wake[0], s.stopping, options_.io_timeout_s);
  const std::vector<uint16_t> operations = {
      ptp_op::kGetDeviceInfo,     ptp_op::kOpenSession,       ptp_op::kCloseSession,
      ptp_op::kGetStorageIds,     ptp_op::kGetStorageInfo,    ptp_op::kGetObjectHandles,
      ptp_op::kGetObjectInfo,     ptp_op::kGetObject,         ptp_op::kDeleteObject,
      ptp_op::kInitiateCapture,   ptp_op::kGetDevicePropDesc, ptp_op::kGetDevicePropValue,
      ptp_op::kSetDevicePropValue};

  // The answer to one request (called with the lock held).
  auto handle = [&](uint16_t op, const std::vector<uint32_t>& p, uint32_t transaction,
                    const std::vector<uint8_t>& data_in) {
    State::Reply r;
    auto param = [&](size_t i) { return i < p.size() ? p[i] : 0u; };
    if (op != ptp_op::kGetDeviceInfo && op != ptp_op::kOpenSession && !s.session_open) {
      r.code = kSessionNotOpen;
      return r;
    }
    Writer w;
    switch (op) {
      case ptp_op::kGetDeviceInfo: {
        w.U16(100);  // StandardVersion 1.00
        w.U32(0);    // VendorExtensionID: none
        w.U16(0);
        w.Str("");
        w.U16(0);  // FunctionalMode
        w.U16Array(operations);
        w.U16Array({kObjectAdded, kCaptureComplete});
        std::vector<uint16_t> props;
        for (const auto& [code, prop] : s.props) props.push_back(code);
        w.U16Array(props);
        w.U16Array({kFormatExifJpeg});
        w.U16Array({kFormatExifJpeg});
        w.Str(options_.manufacturer);
        w.Str(options_.model);
        w.Str("1.0");
        w.Str(options_.serial);
        r.has_data = true;
        break;
      }
      case ptp_op::kOpenSession:
        if (param(0) == 0) {
          r.code = kInvalidParameter;
        } else if (s.session_open) {
          r.code = kSessionAlreadyOpen;
          r.params = {s.session_id};
        } else {
          s.session_open = true;
          s.session_id = param(0);
        }
        break;
      case ptp_op::kCloseSession:
        s.session_open = false;
        break;
      case ptp_op::kGetStorageIds:
        w.U32Array({kStorageId});
        r.has_data = true;
        break;
      case ptp_op::kGetStorageInfo: {
        if (param(0) != kStorageId) {
          r.code = kInvalidStorageId;
          break;
        }
        uint64_t used = 0;
        for (const auto& [h, o] : s.objects) used += o.bytes.size();
        const uint64_t capacity = uint64_t{32} << 30;
        w.U16(0x0004);  // removable RAM (a memory card)
        w.U16(0x0002);  // generic hierarchical
        w.U16(0x0000);  // read-write
        w.U64(capacity);
        w.U64(capacity - used);
        w.U32(static_cast<uint32_t>((capacity - used) / (1 << 20)));
        w.Str("SD");
        w.Str("ROUEN");
        r.has_data = true;
        break;
      }
      case ptp_op::kGetObjectHandles: {
        if (param(0) != kAllStorages && param(0) != kStorageId) {
          r.code = kInvalidStorageId;
          break;
        }
        std::vector<uint32_t> handles;
        const bool root = param(2) == 0 || param(2) == kRootParent;
        for (const auto& [h, o] : s.objects)
          if (root && (param(1) == 0 || param(1) == kFormatExifJpeg)) handles.push_back(h);
        w.U32Array(handles);
        r.has_data = true;
        break;
      }
      case ptp_op::kGetObjectInfo: {
        auto it = s.objects.find(param(0));
        if (it == s.objects.end()) {
          r.code = kInvalidObjectHandle;
          break;
        }
        const State::Object& o = it->second;
        w.U32(kStorageId);
        w.U16(kFormatExifJpeg);
        w.U16(0);  // no protection
        w.U32(static_cast<uint32_t>(o.bytes.size()));
        w.U16(0);  // no thumbnail
        w.U32(0);
        w.U32(0);
        w.U32(0);
        w.U32(static_cast<uint32_t>(o.width));
        w.U32(static_cast<uint32_t>(o.height));
        w.U32(24);
        w.U32(0);  // parent: the storage's root
        w.U16(0);  // not an association
        w.U32(0);
        w.U32(0);
        w.Str(o.name);
        w.Str(o.date);
        w.Str(o.date);
        w.Str("");
        r.has_data = true;
        break;
      }
      case ptp_op::kGetObject: {
        auto it = s.objects.find(param(0));
        if (it == s.objects.end()) {
          r.code = kInvalidObjectHandle;
          break;
        }
        w.Bytes(it->second.bytes);
        r.has_data = true;
        r.download = true;
        break;
      }
      case ptp_op::kDeleteObject:
        if (param(0) == 0xFFFFFFFF) {
          s.stats.deletes += static_cast<int>(s.objects.size());
          s.objects.clear();
        } else if (s.objects.erase(param(0)) == 1) {
          ++s.stats.deletes;
        } else {
          r.code = kInvalidObjectHandle;
        }
        break;
      case ptp_op::kInitiateCapture: {
        if (param(0) != 0 && param(0) != kStorageId) {
          r.code = kInvalidStorageId;
          break;
        }
        if (param(1) != 0 && param(1) != kFormatExifJpeg) {
          r.code = kInvalidObjectFormatCode;
          break;
        }
        PtpShot shot;
        shot.exposure_s = s.props[kExposureTime].current / 10000.0;
        shot.iso = static_cast<int>(s.props[kExposureIndex].current);
        shot.f_number = s.props[kFNumber].current / 100.0;
        shot.index = s.stats.captures + 1;
        State::Object o;
        try {
          const Image im = options_.frame ? options_.frame(shot)
                                          : BuiltinScene(shot, options_.width, options_.height);
          const double exif_t = s.exif_exposure.value_or(shot.exposure_s);
          const std::string jpeg = EncodeImage("capture.jpg", im, StoredType::kUint8,
                                               {{"ExposureTime", static_cast<float>(exif_t)},
                                                {"FNumber", static_cast<float>(shot.f_number)},
                                                {"Exif:ISOSpeedRatings", shot.iso},
                                                {"Make", options_.manufacturer},
                                                {"Model", options_.model},
                                                {"Exif:DateTimeOriginal", Now(true)}});
          o.bytes.assign(jpeg.begin(), jpeg.end());
          o.width = im.width;
          o.height = im.height;
        } catch (const std::exception& e) {
          s.errors.push_back(std::string("capture: the frame could not be made: ") + e.what());
          r.code = kGeneralError;
          break;
        }
        if (s.corrupt_next) {
          // A start-of-image marker, then no marker at all: no JPEG decoder finds a frame.
          static const char kFill[] = "corrupt ";
          for (size_t i = 2; i < o.bytes.size(); ++i) o.bytes[i] = kFill[i % 8];
          s.corrupt_next = false;
        }
        ++s.stats.captures;
        char name[16];
        std::snprintf(name, sizeof(name), "IMG_%04d.JPG", shot.index % 10000);
        o.name = name;
        o.date = Now(false);
        const uint32_t handle = s.next_handle++;
        s.objects[handle] = std::move(o);
        r.events = {{kObjectAdded, handle}, {kCaptureComplete, transaction}};
        break;
      }
      case ptp_op::kGetDevicePropDesc:
      case ptp_op::kGetDevicePropValue: {
        auto it = s.props.find(static_cast<uint16_t>(param(0)));
        if (it == s.props.end()) {
          r.code = kDevicePropNotSupported;
          break;
        }
        const Property& prop = it->second;
        if (prop.type == kTypeString) {
          const std::string v = prop.text();
          if (op == ptp_op::kGetDevicePropDesc) {
            w.U16(prop.code);
            w.U16(prop.type);
            w.U8(0);  // read-only
            w.Str(v);
            w.Str(v);
            w.U8(0);  // no form
          } else {
            w.Str(v);
          }
          r.has_data = true;
          break;
        }
        if (op == ptp_op::kGetDevicePropDesc) {
          w.U16(prop.code);
          w.U16(prop.type);
          w.U8(prop.writable ? 1 : 0);
          PutValue(w, prop.type, prop.factory);
          PutValue(w, prop.type, prop.current);
          if (prop.values.empty()) {
            w.U8(1);  // range
            PutValue(w, prop.type, prop.min);
            PutValue(w, prop.type, prop.max);
            PutValue(w, prop.type, prop.step);
          } else {
            w.U8(2);  // enumeration
            w.U16(static_cast<uint16_t>(prop.values.size()));
            for (uint32_t v : prop.values) PutValue(w, prop.type, v);
          }
        } else {
          PutValue(w, prop.type, prop.current);
        }
        r.has_data = true;
        break;
      }
      case ptp_op::kSetDevicePropValue: {
        auto it = s.props.find(static_cast<uint16_t>(param(0)));
        if (it == s.props.end()) {
          r.code = kDevicePropNotSupported;
          break;
        }
        Property& prop = it->second;
        if (!prop.writable) {
          r.code = kAccessDenied;
          break;
        }
        if (data_in.size() != TypeSize(prop.type)) {
          r.code = kInvalidDevicePropFormat;
          break;
        }
        const uint32_t v = prop.type == kTypeUint8    ? data_in[0]
                           : prop.type == kTypeUint16 ? Le16(data_in.data())
                                                      : Le32(data_in.data());
        if (std::find(prop.values.begin(), prop.values.end(), v) == prop.values.end()) {
          r.code = kInvalidDevicePropValue;
          break;
        }
        prop.current = v;
        break;
      }
      default:
        r.code = kOperationNotSupported;
        break;
    }
    r.data = std::move(w.data);
    return r;
  };

  while (!s.stopping) {
    // --- the command connection and its handshake
    const int cmd = io.Accept(s.listen_fd);
    if (cmd < 0) break;
    int evt = -1;
    auto close_all = [&] {
      ::close(cmd);
      if (evt >= 0) ::close(evt);
      std::lock_guard<std::mutex> lock(s.mu);
      s.session_open = false;  // a session lives as long as its connection
    };
    Received p;
    std::string error;
    if (!io.ReadPacket(cmd, p, false, &error)) {
      s.Error("init command request: " + (error.empty() ? "connection closed" : error));
      close_all();
      continue;
    }
    // GUID (16), friendly name (UCS-2, null-terminated), protocol version (u32).
    if (p.type != kInitCommandRequest || p.payload.size() < 16 + 2 + 4) {
      s.Error("expected Init_Command_Request, got packet type " + std::to_string(p.type));
      Writer fail;
      fail.U32(1);  // rejected
      io.WriteAll(cmd, Packet(kInitFail, fail.data));
      close_all();
      continue;
    }
    Writer ack;
    ack.U32(1);                                                           // connection number
    for (int i = 0; i < 16; ++i) ack.U8(static_cast<uint8_t>(0xA0 + i));  // camera GUID
    const std::string friendly = options_.manufacturer + " " + options_.model;
    for (char c : friendly) ack.U16(static_cast<unsigned char>(c));
    ack.U16(0);
    ack.U32(0x00010000);  // protocol version 1.0
    if (!io.WriteAll(cmd, Packet(kInitCommandAck, ack.data))) {
      close_all();
      continue;
    }
    // --- the event connection
    evt = io.Accept(s.listen_fd);
    if (evt < 0) {
      close_all();
      break;
    }
    if (!io.ReadPacket(evt, p, false, &error) || p.type != kInitEventRequest ||
        p.payload.size() < 4 || Le32(p.payload.data()) != 1) {
      s.Error("expected Init_Event_Request for connection 1");
      close_all();
      continue;
    }
    if (!io.WriteAll(evt, Packet(kInitEventAck, {}))) {
      close_all();
      continue;
    }
    {
      std::lock_guard<std::mutex> lock(s.mu);
      ++s.stats.connections;
    }

    // --- operations until the host closes, a drop is injected, or the responder stops
    for (;;) {
      Received req;
      error.clear();
      if (!io.ReadPacket(cmd, req, true, &error)) {
        if (!error.empty()) s.Error(error);
        break;
      }
      if (req.type == kProbeRequest) {
        if (!io.WriteAll(cmd, Packet(kProbeResponse, {}))) break;
        continue;
      }
      if (req.type != kOperationRequest || req.payload.size() < 10 ||
          (req.payload.size() - 10) % 4 != 0 || req.payload.size() > 10 + 5 * 4) {
        s.Error("expected Operation_Request, got packet type " + std::to_string(req.type) +
                " with " + std::to_string(req.payload.size()) + " bytes");
        break;
      }
      const uint32_t phase = Le32(req.payload.data());
      const uint16_t op = Le16(req.payload.data() + 4);
      const uint32_t transaction = Le32(req.payload.data() + 6);
      std::vector<uint32_t> params;
      for (size_t off = 10; off + 4 <= req.payload.size(); off += 4)
        params.push_back(Le32(req.payload.data() + off));

      bool drop = false;
      int busy_left = 0;
      {
        std::lock_guard<std::mutex> lock(s.mu);
        ++s.stats.operations[op];
        if (op != ptp_op::kOpenSession && transaction != s.last_transaction + 1) {
          s.errors.push_back("operation " + Hex(op) + ": transaction " +
                             std::to_string(transaction) + " after " +
                             std::to_string(s.last_transaction));
        }
        s.last_transaction = transaction;
        if (s.drop_after > 0 && --s.drop_after == 0) drop = true;
        if (s.drop_op && *s.drop_op == op) {
          drop = true;
          s.drop_op.reset();
        }
        auto b = s.busy.find(op);
        if (!drop && b != s.busy.end() && b->second != 0) {
          busy_left = b->second;
          if (b->second > 0) --b->second;
          ++s.stats.busy_replies;
        }
      }

      if (drop) {
        // A pure read sends half of its data first; anything else is cut before it acts.
        if (!HasSideEffects(op)) {
          State::Reply r;
          {
            std::lock_guard<std::mutex> lock(s.mu);
            r = handle(op, params, transaction, {});
          }
          if (r.code == kOk && r.has_data && !r.data.empty()) {
            io.WriteAll(cmd, StartDataPacket(transaction, r.data.size()));
            io.WriteAll(cmd, DataPacket(kData, transaction, r.data.data(), r.data.size() / 2));
          }
        }
        std::lock_guard<std::mutex> lock(s.mu);
        ++s.stats.drops;
        break;
      }

      // Data from the host (SetDevicePropValue): Start_Data, then Data... End_Data.
      std::vector<uint8_t> data_in;
      if (phase == 2) {
        Received d;
        if (!io.ReadPacket(cmd, d, false, &error) || d.type != kStartData ||
            d.payload.size() < 12) {
          s.Error("operation " + Hex(op) + ": expected Start_Data from the host");
          break;
        }
        const uint64_t total =
            Le32(d.payload.data() + 4) | (static_cast<uint64_t>(Le32(d.payload.data() + 8)) << 32);
        bool ok = total <= kMaxPacket;
        while (ok) {
          if (!io.ReadPacket(cmd, d, false, &error) || (d.type != kData && d.type != kEndData) ||
              d.payload.size() < 4) {
            ok = false;
            break;
          }
          data_in.insert(data_in.end(), d.payload.begin() + 4, d.payload.end());
          if (data_in.size() > total) ok = false;
          if (d.type == kEndData) break;
        }
        if (!ok || data_in.size() != total) {
          s.Error("operation " + Hex(op) + ": data phase from the host broken");
          break;
        }
      }

      if (busy_left != 0) {
        if (!io.WriteAll(cmd, ResponsePacket(kDeviceBusy, transaction, {}))) break;
        continue;
      }

      State::Reply r;
      {
        std::lock_guard<std::mutex> lock(s.mu);
        r = handle(op, params, transaction, data_in);
      }
      bool ok = true;
      if (r.code == kOk && r.has_data) {
        ok = io.WriteAll(cmd, StartDataPacket(transaction, r.data.size()));
        size_t off = 0;
        do {
          const size_t n = std::min(kDataChunk, r.data.size() - off);
          const bool last = off + n == r.data.size();
          ok = ok && io.WriteAll(cmd, DataPacket(last ? kEndData : kData, transaction,
                                                 r.data.data() + off, n));
          off += n;
        } while (ok && off < r.data.size());
      }
      ok = ok && io.WriteAll(cmd, ResponsePacket(r.code, transaction, r.params));
      if (!ok) break;
      if (r.download) {
        std::lock_guard<std::mutex> lock(s.mu);
        ++s.stats.downloads;
      }
      for (const auto& [code, param] : r.events) {
        if (!io.WriteAll(evt, EventPacket(code, transaction, param))) {
          ok = false;
          break;
        }
      }
      if (!ok) break;
    }
    close_all();
  }
}

}  // namespace rouen
