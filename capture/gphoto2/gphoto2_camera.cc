#include "capture/gphoto2/gphoto2_camera.h"

#include <fcntl.h>
#include <gphoto2/gphoto2.h>
#include <pthread.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>

#include "core/error.h"
#include "core/exif.h"
#include "core/files.h"
#include "core/image.h"
#include "core/text.h"

namespace rouen {
namespace {

using SteadyClock = std::chrono::steady_clock;

// Wraps every libgphoto2 call that may touch the camera:
// - SIGPIPE is blocked in this thread while libgphoto2 runs and one it raised is discarded
//   (libgphoto2 writes to PTP/IP sockets with write(); a camera that closed the connection
//   would otherwise kill the process);
// - file descriptor 0 survives: libgphoto2 2.5.30 (and upstream to date) closes fd 0 when a
//   PTP/IP camera disconnects (its unused "jpgfd" is zero-initialised), which would close
//   stdin or whatever file or socket holds fd 0; the guard keeps a duplicate and puts it back
//   when fd 0 was closed during the call.
// Nested guards are harmless.
class CallGuard {
 public:
  CallGuard() {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    sigset_t pending;
    sigpending(&pending);
    was_pending_ = sigismember(&pending, SIGPIPE) == 1;
    pthread_sigmask(SIG_BLOCK, &pipe_, &old_);
    stdin_copy_ = ::fcntl(0, F_DUPFD_CLOEXEC, 3);
  }
  ~CallGuard() {
    if (stdin_copy_ >= 0) {
      if (::fcntl(0, F_GETFD) == -1 && errno == EBADF) ::dup2(stdin_copy_, 0);
      ::close(stdin_copy_);
    }
    sigset_t pending;
    sigpending(&pending);
    if (!was_pending_ && sigismember(&pending, SIGPIPE) == 1) {
      const timespec zero = {0, 0};
      while (sigtimedwait(&pipe_, nullptr, &zero) == SIGPIPE) {
      }
    }
    pthread_sigmask(SIG_SETMASK, &old_, nullptr);
  }
  CallGuard(const CallGuard&) = delete;
  CallGuard& operator=(const CallGuard&) = delete;

 private:
  sigset_t pipe_, old_;
  bool was_pending_ = false;
  int stdin_copy_ = -1;
};

// libgphoto2's error log lines while a call of this thread runs (see LogHook).
thread_local std::vector<std::string>* t_log = nullptr;

void OnLog(GPLogLevel, const char*, const char* text, void*) {
  if (t_log && text && t_log->size() < 32) t_log->push_back(text);
}

// libgphoto2 explains most failures only in its log (the socket error, the PTP code): an
// error-level log function, installed once per process, collects the lines a call produced.
void LogHook() {
  static std::once_flag once;
  std::call_once(once, [] { gp_log_add_func(GP_LOG_ERROR, &OnLog, nullptr); });
}

// Errors worth another try: transfers that failed or timed out, a USB device gone for a moment
// or claimed by another program (not: an unsupported port, bad parameters, a camera error).
bool IsIoError(int rc) {
  switch (rc) {
    case GP_ERROR_IO:
    case GP_ERROR_TIMEOUT:
    case GP_ERROR_IO_INIT:
    case GP_ERROR_IO_READ:
    case GP_ERROR_IO_WRITE:
    case GP_ERROR_IO_UPDATE:
    case GP_ERROR_IO_USB_CLEAR_HALT:
    case GP_ERROR_IO_USB_FIND:
    case GP_ERROR_IO_USB_CLAIM:
    case GP_ERROR_IO_LOCK:
      return true;
    default:
      return false;
  }
}

// A whole-string decimal number (no sign), or nothing.
std::optional<double> Number(const std::string& s) {
  if (s.empty() || !(std::isdigit(static_cast<unsigned char>(s[0])) || s[0] == '.'))
    return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

// "1/125", "1.5/10": a fraction, or nothing.
std::optional<double> Fraction(const std::string& s) {
  const size_t slash = s.find('/');
  if (slash == std::string::npos) return Number(s);
  const auto a = Number(s.substr(0, slash)), b = Number(s.substr(slash + 1));
  if (!a || !b || *b <= 0) return std::nullopt;
  return *a / *b;
}

std::string FormatSeconds(double t) {
  char buf[32];
  if (t > 0 && t < 0.5)
    std::snprintf(buf, sizeof(buf), "1/%.4g s", 1.0 / t);
  else
    std::snprintf(buf, sizeof(buf), "%.4g s", t);
  return buf;
}

}  // namespace

std::optional<double> ParseShutterSpeed(const std::string& text) {
  std::string s = Trimmed(text);
  if (s.empty()) return std::nullopt;
  // 1"3 is 1.3 s (the cameras' own notation); a trailing " or s is the unit.
  const size_t quote = s.find('"');
  if (quote != std::string::npos && quote + 1 < s.size()) {
    s[quote] = '.';
  } else if (s.back() == '"' || s.back() == 's') {
    s.pop_back();
    s = Trimmed(s);
  }
  std::optional<double> v;
  const size_t space = s.find(' ');
  if (space != std::string::npos) {  // "1 1/2": whole seconds and a fraction
    const auto whole = Number(s.substr(0, space));
    const auto frac = Fraction(Trimmed(s.substr(space + 1)));
    if (whole && frac) v = *whole + *frac;
  } else {
    v = Fraction(s);
  }
  if (!v || !(*v > 0)) return std::nullopt;
  return v;
}

std::optional<double> ParseAperture(const std::string& text) {
  std::string s = Trimmed(text);
  if (s.size() >= 2 && (s[0] == 'f' || s[0] == 'F') && s[1] == '/') {
    s = s.substr(2);
  } else if (!s.empty() && (s[0] == 'f' || s[0] == 'F')) {
    s = s.substr(1);
  }
  const auto v = Number(Trimmed(s));
  if (!v || !(*v > 0)) return std::nullopt;
  return v;
}

void Gphoto2Options::Validate() const {
  const std::string where = "gphoto2 options: ";
  if (max_attempts < 1 || max_attempts > 100)
    throw Error(where + "max_attempts = " + std::to_string(max_attempts) + " must be in 1..100");
  if (!(backoff_initial_s > 0) || backoff_initial_s > 60)
    throw Error(where + "backoff_initial_s must be in (0, 60] s");
  if (!(backoff_max_s >= backoff_initial_s) || backoff_max_s > 600)
    throw Error(where + "backoff_max_s must be at least backoff_initial_s and at most 600 s");
  if (!(capture_timeout_s > 0) || capture_timeout_s > 3600)
    throw Error(where + "capture_timeout_s must be in (0, 3600] s");
  if (!(complete_timeout_s >= 0) || complete_timeout_s > 600)
    throw Error(where + "complete_timeout_s must be in [0, 600] s");
  if (!(exif_tolerance_stops > 0) || exif_tolerance_stops > 10)
    throw Error(where + "exif_tolerance_stops must be in (0, 10]");
  if (!(base_iso > 0) || !std::isfinite(base_iso))
    throw Error(where + "base_iso must be a positive ISO");
}

// ---------------------------------------------------------------------------------------------

struct Gphoto2Camera::Impl {
  GPContext* context = nullptr;
  ::Camera* camera = nullptr;
  bool initialised = false;
  std::string id, model, port;
  std::string context_error;     // what libgphoto2 reported through the context since the last call
  std::vector<std::string> log;  // libgphoto2's error log lines of the last call
  // Widget names found at open (empty = the camera has no such setting).
  std::string shutter_widget, iso_widget, aperture_widget;
  double exposure_s = 0, iso = 0, aperture = 0;  // as read back
  std::string serial;                            // as the camera reports it ("" = none)
  std::string dir;                               // download folder
  bool own_dir = false;
  int file_counter = 0;
  std::vector<std::string> last_files;
  std::string last_file;

  static void OnError(GPContext*, const char* text, void* data) {
    auto* self = static_cast<Impl*>(data);
    if (!text) return;
    if (!self->context_error.empty()) self->context_error += "; ";
    self->context_error += Trimmed(text);
  }

  bool lost = false;        // the camera closed the connection: every call fails at once
  std::string lost_during;  // the operation it happened in

  // libgphoto2's text for `rc`, then the distinct explanations its log and the context gave
  // (the socket or PTP error), without its source-location lines.
  std::string Text(int rc) const {
    std::string t = gp_result_as_string(rc);
    t += " (" + std::to_string(rc) + ")";
    std::vector<std::string> parts;
    auto add = [&](const std::string& line) {
      const std::string s = Trimmed(line);
      if (s.empty() || s.front() == '\'' || parts.size() >= 4) return;
      if (std::find(parts.begin(), parts.end(), s) == parts.end()) parts.push_back(s);
    };
    for (const std::string& l : log) add(l);
    size_t from = 0;
    while (from < context_error.size()) {
      const size_t to = std::min(context_error.find("; ", from), context_error.size());
      add(context_error.substr(from, to - from));
      from = to + 2;
    }
    for (size_t i = 0; i < parts.size(); ++i) t += (i == 0 ? ": " : "; ") + parts[i];
    return t;
  }

  // True when the last call's log shows the camera's end of the connection closed.
  bool ConnectionClosed() const {
    for (const std::string& l : log)
      if (l.find("End of stream") != std::string::npos) return true;
    return false;
  }
};

namespace {

// Runs `call` until it succeeds, retrying Device Busy always and I/O errors when `retry_io`,
// with bounded exponential backoff; throws DeviceError naming the camera and `what` (for an
// error that is neither, `tolerate` returns its code instead).
template <class F>
int Retry(Gphoto2Camera::Impl& im, const Gphoto2Options& o, Gphoto2Stats& stats,
          const std::string& what, bool retry_io, F call, bool tolerate = false) {
  if (im.lost)
    throw DeviceError(im.id + ": " + what + ": the connection to the camera was lost while " +
                      im.lost_during + "; reopen the camera");
  double wait = o.backoff_initial_s;
  for (int attempt = 1;; ++attempt) {
    im.context_error.clear();
    im.log.clear();
    int rc;
    {
      CallGuard guard;
      t_log = &im.log;
      rc = call();
      t_log = nullptr;
    }
    if (rc >= GP_OK) return rc;
    if (im.ConnectionClosed()) {  // nothing to retry on a closed connection
      im.lost = true;
      im.lost_during = what;
      throw DeviceError(im.id + ": " + what + " failed: the camera closed the connection (" +
                        im.Text(rc) + "); reopen the camera");
    }
    // libgphoto2 2.5.30 turns a busy SetDevicePropValue into GP_ERROR_BAD_PARAMETERS ("not
    // found") and keeps the PTP code (0x2019) only in its context text and log.
    bool busy = rc == GP_ERROR_CAMERA_BUSY || im.context_error.find("0x2019") != std::string::npos;
    for (const std::string& l : im.log) busy = busy || l.find("0x2019") != std::string::npos;
    const bool io = IsIoError(rc);
    if (!(busy || (retry_io && io)) && tolerate) return rc;
    if (!(busy || (retry_io && io)) || attempt >= o.max_attempts) {
      std::string msg = im.id + ": " + what + " failed";
      if (attempt > 1) msg += " after " + std::to_string(attempt) + " attempts";
      msg += ": " + im.Text(rc);
      if (busy) msg += " (the camera stayed busy: Device Busy)";
      throw DeviceError(msg);
    }
    if (busy)
      ++stats.busy_retries;
    else
      ++stats.io_retries;
    std::this_thread::sleep_for(std::chrono::duration<double>(wait));  // backoff, bounded
    wait = std::min(wait * 2, o.backoff_max_s);
  }
}

// A configuration widget by name (busy and I/O errors retried); nullptr when the camera has
// none (the caller frees it).
CameraWidget* FindWidget(Gphoto2Camera::Impl& im, const Gphoto2Options& o, Gphoto2Stats& st,
                         const std::string& name) {
  CameraWidget* w = nullptr;
  const int rc = Retry(
      im, o, st, "reading setting '" + name + "'", true,
      [&] { return gp_camera_get_single_config(im.camera, name.c_str(), &w, im.context); }, true);
  if (rc < GP_OK) return nullptr;
  return w;
}

std::string FirstWidget(Gphoto2Camera::Impl& im, const Gphoto2Options& o, Gphoto2Stats& st,
                        const std::vector<std::string>& names) {
  for (const std::string& n : names) {
    if (CameraWidget* w = FindWidget(im, o, st, n)) {
      gp_widget_free(w);
      return n;
    }
  }
  return "";
}

// The widget's choices (radio/menu), or empty.
std::vector<std::string> Choices(CameraWidget* w) {
  std::vector<std::string> out;
  CameraWidgetType type;
  if (gp_widget_get_type(w, &type) < GP_OK) return out;
  if (type != GP_WIDGET_RADIO && type != GP_WIDGET_MENU) return out;
  const int n = gp_widget_count_choices(w);
  for (int i = 0; i < n; ++i) {
    const char* c = nullptr;
    if (gp_widget_get_choice(w, i, &c) == GP_OK && c) out.push_back(c);
  }
  return out;
}

// The widget's current value as text (radio/menu/text) or number (range).
std::string ValueText(CameraWidget* w) {
  CameraWidgetType type;
  if (gp_widget_get_type(w, &type) < GP_OK) return "";
  if (type == GP_WIDGET_RANGE) {
    float f = 0;
    if (gp_widget_get_value(w, &f) < GP_OK) return "";
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", f);
    return buf;
  }
  if (type == GP_WIDGET_RADIO || type == GP_WIDGET_MENU || type == GP_WIDGET_TEXT) {
    const char* v = nullptr;
    if (gp_widget_get_value(w, &v) < GP_OK || !v) return "";
    return v;
  }
  return "";
}

struct WidgetPtr {
  CameraWidget* w = nullptr;
  ~WidgetPtr() {
    if (w) gp_widget_free(w);
  }
};

// Reads `name`'s widget (retrying busy and I/O); throws DeviceError.
void ReadWidget(Gphoto2Camera::Impl& im, const Gphoto2Options& o, Gphoto2Stats& st,
                const std::string& name, WidgetPtr& out) {
  if (out.w) gp_widget_free(out.w);
  out.w = nullptr;
  Retry(im, o, st, "reading setting '" + name + "'", true,
        [&] { return gp_camera_get_single_config(im.camera, name.c_str(), &out.w, im.context); });
}

// Numeric choices of a widget by `parse`, with their texts.
template <class P>
std::vector<std::pair<double, std::string>> NumericChoices(CameraWidget* w, P parse) {
  std::vector<std::pair<double, std::string>> out;
  for (const std::string& c : Choices(w))
    if (const auto v = parse(c)) out.emplace_back(*v, c);
  std::sort(out.begin(), out.end());
  return out;
}

std::optional<double> ParseIso(const std::string& s) {
  const auto v = Number(Trimmed(s));
  if (!v || *v <= 0) return std::nullopt;
  return v;
}

// The serial number from the "serialnumber" setting, else from the summary's "Serial Number:"
// line (libgphoto2's ptp2 driver has both); "" when the camera reports none.
std::string ReadSerial(Gphoto2Camera::Impl& im, const Gphoto2Options& o, Gphoto2Stats& st) {
  if (CameraWidget* w = FindWidget(im, o, st, "serialnumber")) {
    const std::string v = Trimmed(ValueText(w));
    gp_widget_free(w);
    if (!v.empty()) return v;
  }
  CameraText summary;
  const int rc = Retry(
      im, o, st, "reading the summary", true,
      [&] { return gp_camera_get_summary(im.camera, &summary, im.context); }, true);
  if (rc < GP_OK) return "";
  summary.text[sizeof(summary.text) - 1] = 0;
  for (const std::string& line : TextLines(summary.text)) {
    const std::string t = Trimmed(line);
    const std::string key = "Serial Number:";
    if (t.rfind(key, 0) == 0) return Trimmed(t.substr(key.size()));
  }
  return "";
}

}  // namespace

namespace {

// The port of the detected camera (of `o.model`, when given) whose serial is `o.serial`: each is
// opened in turn and closed again. Throws DeviceError listing what was found.
std::string PortOfSerial(const Gphoto2Options& o) {
  std::vector<Gphoto2CameraInfo> cameras;
  try {
    cameras = ListGphoto2Cameras();
  } catch (const DeviceError& e) {
    throw DeviceError("gphoto2: looking for the camera with serial '" + o.serial +
                      "': " + e.what());
  }
  std::string found;
  for (const Gphoto2CameraInfo& c : cameras) {
    if (!o.model.empty() && c.model != o.model) continue;
    Gphoto2Options probe = o;
    probe.port = c.port;
    probe.model = c.model;
    probe.serial.clear();
    try {
      const Gphoto2Camera cam(probe);
      if (cam.Serial() == o.serial) return c.port;
      found += (found.empty() ? "" : ", ") + c.model + " on " + c.port + " (serial '" +
               cam.Serial() + "')";
    } catch (const DeviceError& e) {
      found += (found.empty() ? "" : ", ") + c.model + " on " + c.port + " (" + e.what() + ")";
    }
  }
  throw DeviceError(
      "gphoto2: no camera " + (o.model.empty() ? "" : "'" + o.model + "' ") + "with serial '" +
      o.serial + "' is connected (found: " + (found.empty() ? std::string("none") : found) + ")");
}

}  // namespace

Gphoto2Camera::Gphoto2Camera(const Gphoto2Options& options)
    : options_(options), impl_(std::make_unique<Impl>()) {
  options_.Validate();
  if (!options_.serial.empty() && options_.port.empty()) options_.port = PortOfSerial(options_);
  Impl& im = *impl_;
  im.port = options_.port;
  im.model = options_.model;
  if (im.model.empty() && im.port.rfind("ptpip:", 0) == 0) im.model = "PTP/IP Camera";
  im.id = "gphoto2:" + (im.model.empty() ? std::string("auto") : im.model) + "@" +
          (im.port.empty() ? std::string("auto") : im.port);

  LogHook();
  im.context = gp_context_new();
  gp_context_set_error_func(im.context, &Impl::OnError, &im);
  if (gp_camera_new(&im.camera) < GP_OK) {
    gp_context_unref(im.context);
    throw DeviceError(im.id + ": libgphoto2 could not create a camera object");
  }
  auto fail = [&](const std::string& msg) {
    {
      CallGuard guard;
      gp_camera_unref(im.camera);
    }
    gp_context_unref(im.context);
    im.camera = nullptr;
    im.context = nullptr;
    throw DeviceError(msg);
  };

  if (!im.model.empty()) {
    CameraAbilitiesList* list = nullptr;
    gp_abilities_list_new(&list);
    int rc = gp_abilities_list_load(list, im.context);
    const int index = rc < GP_OK ? rc : gp_abilities_list_lookup_model(list, im.model.c_str());
    CameraAbilities a;
    if (index >= GP_OK) rc = gp_abilities_list_get_abilities(list, index, &a);
    gp_abilities_list_free(list);
    if (index < GP_OK || rc < GP_OK)
      fail(im.id + ": libgphoto2 knows no camera model '" + im.model + "' (" +
           gp_result_as_string(index < GP_OK ? index : rc) + ")");
    gp_camera_set_abilities(im.camera, a);
  }
  if (!im.port.empty()) {
    GPPortInfoList* list = nullptr;
    gp_port_info_list_new(&list);
    int rc = gp_port_info_list_load(list);
    const int index = rc < GP_OK ? rc : gp_port_info_list_lookup_path(list, im.port.c_str());
    GPPortInfo info;
    if (index >= GP_OK) rc = gp_port_info_list_get_info(list, index, &info);
    if (index >= GP_OK && rc >= GP_OK) rc = gp_camera_set_port_info(im.camera, info);
    gp_port_info_list_free(list);
    if (index < GP_OK || rc < GP_OK)
      fail(im.id + ": libgphoto2 has no port '" + im.port + "' (" +
           gp_result_as_string(index < GP_OK ? index : rc) + ")");
  }
  try {
    Retry(im, options_, stats_, "opening the camera", true,
          [&] { return gp_camera_init(im.camera, im.context); });
  } catch (const DeviceError& e) {
    fail(e.what());
  }
  im.initialised = true;
  CameraAbilities a;
  if (gp_camera_get_abilities(im.camera, &a) == GP_OK && a.model[0]) im.model = a.model;
  GPPortInfo info;
  char* path = nullptr;
  if (gp_camera_get_port_info(im.camera, &info) == GP_OK &&
      gp_port_info_get_path(info, &path) == GP_OK && path)
    im.port = path;
  im.id = "gphoto2:" + im.model + "@" + im.port;

  try {
    im.shutter_widget =
        FirstWidget(im, options_, stats_, {"shutterspeed", "shutterspeed2", "eos-shutterspeed"});
    im.iso_widget = FirstWidget(im, options_, stats_, {"iso", "isospeed"});
    im.aperture_widget = FirstWidget(im, options_, stats_, {"f-number", "aperture"});
    WidgetPtr w;
    if (!im.shutter_widget.empty()) {
      ReadWidget(im, options_, stats_, im.shutter_widget, w);
      im.exposure_s = ParseShutterSpeed(ValueText(w.w)).value_or(0);
    }
    if (!im.iso_widget.empty()) {
      ReadWidget(im, options_, stats_, im.iso_widget, w);
      im.iso = ParseIso(ValueText(w.w)).value_or(0);
    }
    if (!im.aperture_widget.empty()) {
      ReadWidget(im, options_, stats_, im.aperture_widget, w);
      im.aperture = ParseAperture(ValueText(w.w)).value_or(0);
    }
    im.serial = ReadSerial(im, options_, stats_);
    if (!options_.serial.empty() && im.serial != options_.serial)
      throw DeviceError(im.id + ": the camera's serial number is '" + im.serial + "', not '" +
                        options_.serial + "' (is another camera on that port?)");
    if (options_.download_dir.empty()) {
      std::string tmpl = (std::filesystem::temp_directory_path() / "rouen-gphoto2-XXXXXX").string();
      if (!::mkdtemp(tmpl.data()))
        throw DeviceError(im.id + ": cannot make a download folder: " + std::strerror(errno));
      im.dir = tmpl;
      im.own_dir = true;
    } else {
      im.dir = options_.download_dir;
      std::error_code ec;
      std::filesystem::create_directories(im.dir, ec);
      if (ec)
        throw DeviceError(im.id + ": cannot make the download folder " + im.dir + ": " +
                          ec.message());
    }
  } catch (...) {
    CallGuard guard;
    gp_camera_exit(im.camera, im.context);
    gp_camera_unref(im.camera);
    gp_context_unref(im.context);
    im.camera = nullptr;
    im.context = nullptr;
    throw;
  }
}

Gphoto2Camera::~Gphoto2Camera() {
  Impl& im = *impl_;
  if (im.camera) {
    CallGuard guard;
    if (im.initialised) gp_camera_exit(im.camera, im.context);
    gp_camera_unref(im.camera);
  }
  if (im.context) gp_context_unref(im.context);
  if (im.own_dir) {
    std::error_code ec;
    std::filesystem::remove_all(im.dir, ec);
  }
}

std::string Gphoto2Camera::Id() const { return impl_->id; }
std::string Gphoto2Camera::Serial() const { return impl_->serial; }

std::vector<double> Gphoto2Camera::ShutterSpeeds() const {
  Impl& im = *impl_;
  std::vector<double> out;
  if (im.shutter_widget.empty()) return out;
  WidgetPtr w;
  ReadWidget(im, options_, stats_, im.shutter_widget, w);
  for (const auto& [v, text] : NumericChoices(w.w, ParseShutterSpeed)) out.push_back(v);
  return out;
}

std::vector<ControlInfo> Gphoto2Camera::Controls() const {
  Impl& im = *impl_;
  std::vector<ControlInfo> out;
  auto add = [&](const std::string& widget, const std::string& name, auto parse, double scale,
                 double value) {
    if (widget.empty()) return;
    WidgetPtr w;
    ReadWidget(im, options_, stats_, widget, w);
    const auto choices = NumericChoices(w.w, parse);
    if (choices.empty()) return;
    out.push_back({name, choices.front().first / scale, choices.back().first / scale, value});
  };
  add(im.shutter_widget, "exposure_s", ParseShutterSpeed, 1.0, im.exposure_s);
  add(im.iso_widget, "gain", ParseIso, options_.base_iso, im.iso / options_.base_iso);
  add(im.aperture_widget, "aperture_f", ParseAperture, 1.0, im.aperture);
  return out;
}

namespace {

// Sets `widget` to the choice nearest `target` in stops (log2) and returns the value read back.
template <class P>
double SetNearest(Gphoto2Camera::Impl& im, const Gphoto2Options& o, Gphoto2Stats& st,
                  const std::string& widget, const std::string& what, double target, P parse) {
  WidgetPtr w;
  ReadWidget(im, o, st, widget, w);
  CameraWidgetType type;
  gp_widget_get_type(w.w, &type);
  if (type == GP_WIDGET_RANGE) {  // e.g. an aperture given as a float range
    float lo = 0, hi = 0, step = 0;
    gp_widget_get_range(w.w, &lo, &hi, &step);
    float v =
        static_cast<float>(std::clamp(target, static_cast<double>(lo), static_cast<double>(hi)));
    if (step > 0) v = lo + step * std::round((v - lo) / step);
    gp_widget_set_value(w.w, &v);
  } else {
    const auto choices = NumericChoices(w.w, parse);
    if (choices.empty())
      throw DeviceError(im.id + ": the camera offers no " + what + " values ('" + widget + "')");
    auto best = choices.front();
    for (const auto& c : choices)
      if (std::abs(std::log2(c.first / target)) < std::abs(std::log2(best.first / target)))
        best = c;
    gp_widget_set_value(w.w, best.second.c_str());
  }
  Retry(im, o, st, "setting " + what, true,
        [&] { return gp_camera_set_single_config(im.camera, widget.c_str(), w.w, im.context); });
  ReadWidget(im, o, st, widget, w);
  const std::string text = ValueText(w.w);
  const auto applied = parse(text);
  if (!applied)
    throw DeviceError(im.id + ": the camera reports " + what + " '" + text +
                      "', not a value (is it in an automatic or bulb mode?)");
  return *applied;
}

}  // namespace

double Gphoto2Camera::SetExposure(double seconds) {
  if (!(seconds > 0) || !std::isfinite(seconds))
    throw Error(impl_->id + ": exposure " + std::to_string(seconds) + " s must be positive");
  if (impl_->shutter_widget.empty())
    throw DeviceError(impl_->id + ": the camera has no shutter speed setting");
  impl_->exposure_s = SetNearest(*impl_, options_, stats_, impl_->shutter_widget,
                                 "the shutter speed", seconds, ParseShutterSpeed);
  return impl_->exposure_s;
}

double Gphoto2Camera::SetGain(double gain) {
  if (!(gain > 0) || !std::isfinite(gain))
    throw Error(impl_->id + ": gain " + std::to_string(gain) + " must be positive");
  if (impl_->iso_widget.empty()) throw DeviceError(impl_->id + ": the camera has no ISO setting");
  impl_->iso = SetNearest(*impl_, options_, stats_, impl_->iso_widget, "the ISO",
                          gain * options_.base_iso, ParseIso);
  return impl_->iso / options_.base_iso;
}

double Gphoto2Camera::SetAperture(double f_number) {
  if (!(f_number > 0) || !std::isfinite(f_number))
    throw Error(impl_->id + ": f-number " + std::to_string(f_number) + " must be positive");
  if (impl_->aperture_widget.empty())
    throw DeviceError(impl_->id + ": the camera has no aperture setting");
  impl_->aperture = SetNearest(*impl_, options_, stats_, impl_->aperture_widget, "the aperture",
                               f_number, ParseAperture);
  return impl_->aperture;
}

void Gphoto2Camera::SetNdFilter(double density) {
  if (!(density >= 0) || !std::isfinite(density))
    throw Error(impl_->id + ": ND density must be >= 0");
  nd_ = density;
}

std::string Gphoto2Camera::LastFile() const { return impl_->last_file; }
std::vector<std::string> Gphoto2Camera::LastFiles() const { return impl_->last_files; }

CapturedFrame Gphoto2Camera::Grab() {
  Impl& im = *impl_;
  auto t0 = std::chrono::system_clock::now();  // of the trigger that the camera took
  Retry(im, options_, stats_, "triggering a capture", false, [&] {
    t0 = std::chrono::system_clock::now();
    return gp_camera_trigger_capture(im.camera, im.context);
  });
  ++stats_.captures;
  im.last_files.clear();
  im.last_file.clear();

  // Files as the camera reports them, each downloaded at once; then capture-complete.
  const auto start = SteadyClock::now();
  const auto file_deadline =
      start + std::chrono::duration_cast<SteadyClock::duration>(
                  std::chrono::duration<double>(im.exposure_s + options_.capture_timeout_s));
  std::optional<SteadyClock::time_point> complete_deadline;
  bool complete = false;
  while (!complete) {
    const auto now = SteadyClock::now();
    if (complete_deadline ? now >= *complete_deadline : now >= file_deadline) break;
    CameraEventType type = GP_EVENT_UNKNOWN;
    void* data = nullptr;
    Retry(im, options_, stats_, "waiting for the capture", true,
          [&] { return gp_camera_wait_for_event(im.camera, 100, &type, &data, im.context); });
    if (type == GP_EVENT_FILE_ADDED && data) {
      const CameraFilePath path = *static_cast<CameraFilePath*>(data);
      std::free(data);
      const std::string name = path.name, folder = path.folder;
      CameraFile* file = nullptr;
      gp_file_new(&file);
      std::string bytes;
      try {
        Retry(im, options_, stats_, "downloading " + folder + "/" + name, true, [&] {
          gp_file_clean(file);
          return gp_camera_file_get(im.camera, folder.c_str(), name.c_str(), GP_FILE_TYPE_NORMAL,
                                    file, im.context);
        });
        const char* p = nullptr;
        unsigned long n = 0;
        if (gp_file_get_data_and_size(file, &p, &n) < GP_OK || !p || n == 0)
          throw DeviceError(im.id + ": " + folder + "/" + name + " downloaded empty");
        bytes.assign(p, n);
      } catch (...) {
        gp_file_unref(file);
        throw;
      }
      gp_file_unref(file);
      // A numbered name that no earlier file in the folder has (a kept download_dir).
      std::string local;
      do {
        char prefix[16];
        std::snprintf(prefix, sizeof(prefix), "%06d_", ++im.file_counter);
        local = (std::filesystem::path(im.dir) / (prefix + name)).string();
      } while (std::filesystem::exists(local));
      try {
        WriteFileAtomic(local, bytes);
      } catch (const std::exception& e) {
        throw DeviceError(im.id + ": cannot keep " + name + ": " + e.what());
      }
      ++stats_.downloads;
      im.last_files.push_back(local);
      if (options_.delete_on_camera) {
        try {
          Retry(im, options_, stats_, "deleting " + folder + "/" + name, true, [&] {
            return gp_camera_file_delete(im.camera, folder.c_str(), name.c_str(), im.context);
          });
        } catch (const DeviceError&) {
          ++stats_.delete_failures;  // the frame is safe on disk; the card keeps a copy
        }
      }
      if (!complete_deadline)
        complete_deadline =
            SteadyClock::now() + std::chrono::duration_cast<SteadyClock::duration>(
                                     std::chrono::duration<double>(options_.complete_timeout_s));
    } else if (type == GP_EVENT_CAPTURE_COMPLETE) {
      complete = !im.last_files.empty();
      if (!complete && !complete_deadline)  // complete before the file: give it its time
        complete_deadline =
            SteadyClock::now() + std::chrono::duration_cast<SteadyClock::duration>(
                                     std::chrono::duration<double>(options_.complete_timeout_s));
    } else if (data) {
      std::free(data);  // unknown events carry a string; folder-added a path
    }
  }
  if (im.last_files.empty())
    throw DeviceError(im.id + ": the camera reported no new file within " +
                      FormatSeconds(im.exposure_s + options_.capture_timeout_s) +
                      " of the trigger");

  // The frame: the first file OpenImageIO decodes as an image (JPEG before RAW).
  std::string chosen;
  for (const std::string& f : im.last_files)
    if (!IsRawFileName(f)) {
      chosen = f;
      break;
    }
  if (chosen.empty())
    throw DeviceError(im.id + ": the capture gave only RAW files (" +
                      std::filesystem::path(im.last_files.front()).filename().string() +
                      "); set the camera to JPEG or RAW+JPEG");
  im.last_file = chosen;
  const std::string shown = std::filesystem::path(chosen).filename().string();
  CapturedFrame frame;
  PhotoMetadata meta;
  try {
    frame.image = ReadImage(chosen);
    meta = ReadPhotoMetadata(chosen);
  } catch (const std::exception& e) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(chosen, ec);
    throw DeviceError(im.id + ": the camera's file " + shown + " (" +
                      (ec ? std::string("?") : std::to_string(size)) +
                      " bytes) cannot be decoded: " + e.what());
  }
  frame.image.units = PixelUnits::kDigital;
  if (frame.image.channels == 1) {  // a grey JPEG: three equal channels, as other drivers give
    Image rgb(frame.image.width, frame.image.height, 3, PixelUnits::kDigital);
    for (size_t p = 0; p < frame.image.data.size(); ++p)
      for (int c = 0; c < 3; ++c) rgb.data[p * 3 + c] = frame.image.data[p];
    frame.image = std::move(rgb);
  }
  if (frame.image.channels != 3)
    throw DeviceError(im.id + ": " + shown + " has " + std::to_string(frame.image.channels) +
                      " channels; expected grey or RGB");

  // EXIF against the settings read back.
  auto stops = [](double a, double b) { return std::abs(std::log2(a / b)); };
  if (meta.exposure_s && im.exposure_s > 0 &&
      stops(*meta.exposure_s, im.exposure_s) > options_.exif_tolerance_stops) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%.2f", stops(*meta.exposure_s, im.exposure_s));
    throw DeviceError(im.id + ": " + shown + " was exposed " + FormatSeconds(*meta.exposure_s) +
                      " (EXIF) but the camera was set to " + FormatSeconds(im.exposure_s) + ", " +
                      buf + " stops apart: is the camera in manual (M) mode?");
  }
  if (meta.iso && im.iso > 0 && stops(*meta.iso, im.iso) > options_.exif_tolerance_stops) {
    throw DeviceError(im.id + ": " + shown + " was taken at ISO " +
                      std::to_string(static_cast<int>(std::lround(*meta.iso))) +
                      " (EXIF) but the camera was set to ISO " +
                      std::to_string(static_cast<int>(std::lround(im.iso))) + ": is auto ISO on?");
  }
  frame.exposure_s = meta.exposure_s.value_or(im.exposure_s);
  const double iso = meta.iso.value_or(im.iso);
  frame.gain = iso > 0 ? iso / options_.base_iso : 1.0;
  frame.nd_density = nd_;
  frame.hdr = false;
  const double t0_s =
      std::chrono::duration<double>(t0.time_since_epoch()).count() + 0.5 * frame.exposure_s;
  frame.utc = UtcTime::FromUnixSeconds(t0_s);
  return frame;
}

CameraStatus Gphoto2Camera::Status() {
  Impl& im = *impl_;
  CameraStatus out;
  if (CameraWidget* w = FindWidget(im, options_, stats_, "batterylevel")) {
    // "80%", "80" or a range widget's number.
    const std::string t = Trimmed(ValueText(w));
    gp_widget_free(w);
    if (const auto v = Number(Trimmed(t.substr(0, t.find('%')))); v && *v >= 0 && *v <= 100)
      out.battery_percent = *v;
  }
  CameraStorageInformation* info = nullptr;
  int n = 0;
  const int rc = Retry(
      im, options_, stats_, "reading the card's free space", true,
      [&] { return gp_camera_get_storageinfo(im.camera, &info, &n, im.context); }, true);
  if (rc >= GP_OK && info) {
    for (int i = 0; i < n; ++i) {
      if (info[i].fields & GP_STORAGEINFO_FREESPACEKBYTES) {
        out.free_bytes = static_cast<int64_t>(info[i].freekbytes) * 1024;
        if (info[i].fields & GP_STORAGEINFO_FREESPACEIMAGES)
          out.free_images = static_cast<int64_t>(info[i].freeimages);
        break;
      }
    }
    std::free(info);
  }
  if (CameraWidget* w = FindWidget(im, options_, stats_, "datetime")) {
    CameraWidgetType type;
    int t = 0;
    if (gp_widget_get_type(w, &type) == GP_OK && type == GP_WIDGET_DATE &&
        gp_widget_get_value(w, &t) == GP_OK && t > 0)
      out.clock = UtcTime::FromUnixSeconds(t);
    gp_widget_free(w);
  }
  return out;
}

std::vector<Gphoto2CameraInfo> ListGphoto2Cameras() {
  LogHook();
  GPContext* context = gp_context_new();
  CameraList* list = nullptr;
  gp_list_new(&list);
  int rc;
  {
    CallGuard guard;
    rc = gp_camera_autodetect(list, context);
  }
  std::vector<Gphoto2CameraInfo> out;
  for (int i = 0; rc >= GP_OK && i < gp_list_count(list); ++i) {
    const char* model = nullptr;
    const char* port = nullptr;
    if (gp_list_get_name(list, i, &model) == GP_OK && gp_list_get_value(list, i, &port) == GP_OK &&
        model && port)
      out.push_back({model, port});
  }
  gp_list_unref(list);
  gp_context_unref(context);
  if (rc < GP_OK)
    throw DeviceError(std::string("gphoto2: detecting cameras failed: ") + gp_result_as_string(rc));
  return out;
}

nlohmann::json DescribeGphoto2Cameras(const std::vector<Gphoto2CameraInfo>& cameras) {
  nlohmann::json out = nlohmann::json::array();
  for (const Gphoto2CameraInfo& c : cameras) {
    std::string description = c.model + " (libgphoto2; in the rig's [camera]: model = \"" +
                              c.model + "\", port = \"" + c.port + "\")";
    out.push_back({{"driver", "gphoto2"},
                   {"rig_kind", "gphoto2"},
                   {"id", c.port},
                   {"description", description}});
  }
  return out;
}

}  // namespace rouen
