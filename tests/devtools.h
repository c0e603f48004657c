// Headless Chromium driven through its DevTools protocol from the tests, over the pipe transport
// (--remote-debugging-pipe): no node, no WebSocket, no driver; the Debian package `chromium` is
// all it needs.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/error.h"

extern char** environ;

namespace rouen::devtools {

// The chromium binary on PATH ("chromium", then "chromium-browser"), or nothing.
inline std::optional<std::string> FindChromium() {
  const char* path = std::getenv("PATH");
  if (!path) return std::nullopt;
  for (const char* name : {"chromium", "chromium-browser"}) {
    std::string dirs = path;
    size_t start = 0;
    while (start <= dirs.size()) {
      const size_t end = std::min(dirs.find(':', start), dirs.size());
      const std::filesystem::path p = std::filesystem::path(dirs.substr(start, end - start)) / name;
      if (::access(p.c_str(), X_OK) == 0) return p.string();
      start = end + 1;
    }
  }
  return std::nullopt;
}

inline std::string DecodeBase64(const std::string& in) {
  std::string out;
  int bits = 0, value = 0;
  for (char c : in) {
    int d;
    if (c >= 'A' && c <= 'Z')
      d = c - 'A';
    else if (c >= 'a' && c <= 'z')
      d = c - 'a' + 26;
    else if (c >= '0' && c <= '9')
      d = c - '0' + 52;
    else if (c == '+')
      d = 62;
    else if (c == '/')
      d = 63;
    else
      continue;  // padding, line breaks
    value = (value << 6) | d;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<char>((value >> bits) & 0xff));
    }
  }
  return out;
}

// One headless browser driven through --remote-debugging-pipe (commands on its fd 3, answers
// and events on its fd 4, each message JSON ended by a NUL byte); commands go to a page through
// a flattened target session. Every wait has a deadline; nothing sleeps.
class Browser {
 public:
  // Starts `chromium` with a fresh profile in `profile_dir`, its stderr into `log`, and
  // `extra_args` after the usual ones (e.g. the software WebGL flags).
  Browser(const std::string& chromium, const std::filesystem::path& profile_dir,
          const std::filesystem::path& log, double timeout_s = 60,
          const std::vector<std::string>& extra_args = {})
      : timeout_s_(timeout_s) {
    int to_child[2], from_child[2];
    if (::pipe2(to_child, O_CLOEXEC) != 0 || ::pipe2(from_child, O_CLOEXEC) != 0)
      throw Error("pipe: " + std::string(std::strerror(errno)));
    std::vector<std::string> args = {chromium,
                                     "--headless",
                                     "--no-sandbox",
                                     "--disable-gpu",
                                     "--no-first-run",
                                     "--no-default-browser-check",
                                     "--disable-extensions",
                                     "--hide-scrollbars",
                                     "--remote-debugging-pipe",
                                     "--user-data-dir=" + profile_dir.string()};
    args.insert(args.end(), extra_args.begin(), extra_args.end());
    args.push_back("about:blank");
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, to_child[0], 3);
    posix_spawn_file_actions_adddup2(&fa, from_child[1], 4);
    const int rc = posix_spawn(&pid_, argv[0], &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    ::close(to_child[0]);
    ::close(from_child[1]);
    out_fd_ = to_child[1];
    in_fd_ = from_child[0];
    if (rc != 0) {
      pid_ = -1;
      throw Error("cannot start " + chromium + ": " + std::strerror(rc));
    }
  }
  ~Browser() {
    if (out_fd_ >= 0) {
      try {
        Send({{"id", ++next_id_}, {"method", "Browser.close"}});
      } catch (const std::exception&) {
      }
      ::close(out_fd_);  // the end of the pipe also tells it to quit
    }
    if (pid_ > 0) {
      // It ends once its pipe is closed: read until it closes its side (bounded), then reap.
      char buf[65536];
      while (WaitReadable(in_fd_, 20) && ::read(in_fd_, buf, sizeof buf) > 0) {
      }
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == 0) {
        ::kill(pid_, SIGKILL);  // the browser this test started, by its id
        ::waitpid(pid_, &status, 0);
      }
    }
    if (in_fd_ >= 0) ::close(in_fd_);
  }
  Browser(const Browser&) = delete;
  Browser& operator=(const Browser&) = delete;

  // Opens a page target and attaches to it; later calls with to_page go there.
  void OpenPage() {
    const nlohmann::json t = Call("Target.createTarget", {{"url", "about:blank"}}, false);
    const nlohmann::json a =
        Call("Target.attachToTarget", {{"targetId", t.at("targetId")}, {"flatten", true}}, false);
    session_ = a.at("sessionId").get<std::string>();
  }

  // Sends a command (to the page's session when `to_page`) and returns its result; events
  // arriving meanwhile are kept (events()). Throws rouen::Error for a protocol error.
  nlohmann::json Call(const std::string& method,
                      const nlohmann::json& params = nlohmann::json::object(),
                      bool to_page = true) {
    const int id = ++next_id_;
    nlohmann::json msg = {{"id", id}, {"method", method}, {"params", params}};
    if (to_page) msg["sessionId"] = session_;
    Send(msg);
    for (;;) {
      nlohmann::json r = Receive();
      if (r.contains("id") && r["id"] == id) {
        if (r.contains("error")) throw Error(method + ": " + r["error"].dump());
        return r.value("result", nlohmann::json::object());
      }
      if (r.contains("method")) events_.push_back(std::move(r));
    }
  }

  // Waits for the event `method`, keeping the others.
  nlohmann::json WaitEvent(const std::string& method) {
    for (const nlohmann::json& e : events_)
      if (e["method"] == method) return e;
    for (;;) {
      nlohmann::json r = Receive();
      if (!r.contains("method")) continue;
      events_.push_back(r);
      if (r["method"] == method) return r;
    }
  }

  const std::deque<nlohmann::json>& events() const { return events_; }
  void ClearEvents() { events_.clear(); }

 private:
  static bool WaitReadable(int fd, double timeout_s) {
    pollfd p{fd, POLLIN, 0};
    int rc;
    while ((rc = ::poll(&p, 1, static_cast<int>(timeout_s * 1000))) < 0 && errno == EINTR) {
    }
    return rc > 0;
  }

  void Send(const nlohmann::json& msg) {
    std::string bytes = msg.dump();
    bytes.push_back('\0');
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(out_fd_, bytes.data() + done, bytes.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error("DevTools pipe: " + std::string(std::strerror(errno)));
      done += static_cast<size_t>(n);
    }
  }

  // The next message.
  nlohmann::json Receive() {
    size_t end;
    while ((end = buffer_.find('\0')) == std::string::npos) {
      if (!WaitReadable(in_fd_, timeout_s_))
        throw Error("DevTools: no answer from chromium in time");
      char buf[65536];
      const ssize_t n = ::read(in_fd_, buf, sizeof buf);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error("DevTools: chromium closed its pipe (did it start?)");
      buffer_.append(buf, n);
    }
    const std::string text = buffer_.substr(0, end);
    buffer_.erase(0, end + 1);
    return nlohmann::json::parse(text);
  }

  double timeout_s_;
  pid_t pid_ = -1;
  int out_fd_ = -1, in_fd_ = -1;
  std::string buffer_, session_;
  int next_id_ = 0;
  std::deque<nlohmann::json> events_;
};

}  // namespace rouen::devtools
