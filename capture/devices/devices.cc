#include "capture/devices/devices.h"

#include <glob.h>

#include <algorithm>
#include <fstream>

#include "capture/clock.h"
#ifdef ROUEN_HAVE_V4L2
#include "capture/v4l2/v4l2_camera.h"
#include "capture/v4l2/v4l2_io.h"
#endif
#ifdef ROUEN_HAVE_LIBCAMERA
#include "capture/libcamera/libcamera_camera.h"
#endif
#ifdef ROUEN_HAVE_ARAVIS
#include "capture/aravis/aravis_camera.h"
#endif
#ifdef ROUEN_HAVE_USB
#include "capture/usb/usb_devices.h"
#include "capture/usb/usb_hotplug.h"
#endif
#ifdef ROUEN_HAVE_NMEA
#include "capture/nmea/nmea.h"
#endif
#ifdef ROUEN_HAVE_GPSD
#include "capture/gpsd/gpsd.h"
#endif
#ifdef ROUEN_HAVE_GPHOTO2
#include "capture/gphoto2/gphoto2_camera.h"
#endif
#include "capture/replay/replay_devices.h"
#include "capture/sim/sim_devices.h"
#include "core/error.h"
#include "core/files.h"
#include "core/lens.h"

namespace rouen {
namespace {

std::vector<std::string> Glob(const std::string& pattern) {
  std::vector<std::string> out;
  glob_t g{};
  if (glob(pattern.c_str(), 0, nullptr, &g) == 0)
    for (size_t i = 0; i < g.gl_pathc; ++i) out.push_back(g.gl_pathv[i]);
  globfree(&g);
  return out;
}

std::map<Target, Intrinsics> LoadLenses(const RigConfig& rig) {
  std::map<Target, Intrinsics> lenses;
  for (Target t : rig.plan.targets) {
    std::string path = rig.LensPath(t);
    if (path.empty()) continue;
    try {
      lenses[t] = ReadLensFile(path).intrinsics;
    } catch (const Error& e) {  // missing, malformed JSON, bad intrinsics or vignetting
      throw Error(rig.path + ": lens file " + e.what());
    }
  }
  return lenses;
}

RigDevices OpenReplay(const RigConfig& rig, const OpenRigOptions& o) {
  RigDevices d;
  d.plan = rig.plan;
  if (o.from_session.empty()) throw Error(rig.path + ": a replay rig needs --from SESSION");
  auto src = std::make_shared<ReplaySource>(o.from_session);
  const nlohmann::json& extra = src->session().info().extra;
  if (extra.contains("plan")) d.plan = PlanFromJson(extra["plan"]);  // the recorded plan
  d.plan.slots = src->slot_times();
  d.camera = std::make_unique<ReplayCamera>(src);
  d.gps = std::make_unique<ReplayGps>(src);
  d.clock = std::make_unique<ReplayClock>(src);
  d.keep_alive = src;
  return d;
}

RigDevices OpenSim(const RigConfig& rig) {
  RigDevices d;
  d.plan = rig.plan;
  SimWorldOptions wo;
  wo.site = rig.site;
  wo.quick = rig.quick;
  wo.seed = rig.seed;
  auto world = std::make_shared<SimWorld>(wo);
  auto clock = std::make_unique<SimClock>();
  if (rig.kind == "sim") {
    d.camera = std::make_unique<SimCamera>(world, clock.get(), rig.quick, rig.seed);
  } else {
#ifdef ROUEN_HAVE_ARAVIS
    d.camera = OpenSimAravisCamera(world, clock.get(), rig.quick, rig.seed);
#else
    throw Error(rig.path + ": rig kind '" + rig.kind +
                "' needs the aravis driver, which this "
                "build does not have (install libaravis-dev and rebuild)");
#endif
  }
  if (rig.gps.source == "sim") d.gps = std::make_unique<SimGps>(world, clock.get(), rig.seed + 7);
  d.clock = std::move(clock);
  d.model = world->Model();
  d.keep_alive = world;
  return d;
}

[[noreturn, maybe_unused]] void NoDriver(const RigConfig& rig, const char* driver,
                                         const char* package) {
  throw Error(rig.path + ": rig kind '" + rig.kind + "' needs the " + driver +
              " driver, which this build does not have (install " + package + " and rebuild)");
}

// The field camera the rig names, opened with the rig's settings. Throws DeviceError (or
// rouen::Error) when it is not there.
std::unique_ptr<Camera> OpenFieldCamera(const RigConfig& rig, const OpenRigOptions& options) {
  const CameraConfig& c = rig.camera;
  if (rig.kind == "uvc-webcam") {
#ifdef ROUEN_HAVE_V4L2
    V4l2Options o;
    if (!c.device.empty()) o.device = c.device;
    o.width = c.width;
    o.height = c.height;
    o.pixel_format = c.pixel_format;
    o.buffers = c.buffers;
    o.control_latency_frames = c.control_latency_frames;
    o.timeout_s = c.timeout_s;
    if (options.v4l2_io) return OpenV4l2Camera(o, options.v4l2_io());
    return OpenV4l2Camera(o);
#else
    NoDriver(rig, "v4l2", "linux-libc-dev");
#endif
  }
  if (rig.kind == "rpi-libcamera") {
#ifdef ROUEN_HAVE_LIBCAMERA
    LibcameraOptions o;
    o.camera_id = c.device;
    o.width = c.width;
    o.height = c.height;
    o.pixel_format = c.pixel_format;
    o.request_count = c.buffers;
    o.grab_timeout_s = c.timeout_s;
    return std::make_unique<LibcameraCamera>(o);
#else
    NoDriver(rig, "libcamera", "libcamera-dev");
#endif
  }
  if (rig.kind == "gige-aravis") {
#ifdef ROUEN_HAVE_ARAVIS
    AravisOptions o;
    o.device_id = c.device;
    o.pixel_format = c.pixel_format;
    o.buffers = c.buffers;
    o.timeout_s = c.timeout_s;
    o.width = c.width;
    o.height = c.height;
    return OpenAravisCamera(o);
#else
    NoDriver(rig, "aravis", "libaravis-dev");
#endif
  }
  if (rig.kind == "gphoto2") {
#ifdef ROUEN_HAVE_GPHOTO2
    const Gphoto2CameraConfig& g = c.gphoto2;
    Gphoto2Options o;
    o.model = g.model;
    o.port = g.port;
    o.serial = g.serial;
    o.download_dir = rig.Resolve(g.download_dir);
    o.max_attempts = g.max_attempts;
    o.backoff_initial_s = g.backoff_initial_s;
    o.backoff_max_s = g.backoff_max_s;
    o.capture_timeout_s = g.capture_timeout_s;
    o.exif_tolerance_stops = g.exif_tolerance_stops;
    o.base_iso = g.base_iso;
    o.delete_on_camera = g.delete_on_camera;
    try {
      o.Validate();
    } catch (const Error& e) {
      throw Error(rig.path + ": [camera]: " + e.what());
    }
    auto cam = std::make_unique<Gphoto2Camera>(o);
    if (g.aperture_f > 0) cam->SetAperture(g.aperture_f);
    return cam;
#else
    NoDriver(rig, "gphoto2", "libgphoto2-dev");
#endif
  }
  throw Error(rig.path + ": rig kind '" + rig.kind + "' has no field camera");
}

// The rig's GPS; a receiver that cannot be opened leaves the capture on the fallback site
// with a note (a missing fix must not stop a field session).
std::unique_ptr<Gps> OpenFieldGps(const RigConfig& rig, std::vector<std::string>* notes) {
  const GpsConfig& g = rig.gps;
  try {
    if (g.source == "nmea") {
#ifdef ROUEN_HAVE_NMEA
      NmeaOptions o;
      o.path = g.device;
      o.baud = g.baud;
      o.timeout_s = g.timeout_s;
      return OpenNmeaGps(o);
#else
      NoDriver(rig, "nmea", "a C++ compiler");
#endif
    }
    if (g.source == "gpsd") {
#ifdef ROUEN_HAVE_GPSD
      GpsdOptions o;
      o.host = g.host;
      o.port = g.port;
      o.timeout_s = g.timeout_s;
      return OpenGpsdGps(o);
#else
      NoDriver(rig, "gpsd", "libgps-dev");
#endif
    }
  } catch (const Error& e) {
    notes->push_back(std::string("warning: GPS not available (") + e.what() +
                     "); sun positions use the rig's fallback site");
  }
  return nullptr;
}

RigDevices OpenField(const RigConfig& rig, const OpenRigOptions& o) {
  RigDevices d;
  d.plan = rig.plan;
  d.clock = std::make_unique<SystemClock>();
  d.plan.slots = {d.clock->Now()};  // a field rig captures one time-of-day slot per run
  auto op = std::make_unique<OperatorCamera>(OpenFieldCamera(rig, o), rig.views, LoadLenses(rig),
                                             o.prompt, rig.camera.id);
  OperatorCamera* raw = op.get();
  d.camera = std::move(op);
  d.reopen_camera = [rig, o, raw]() -> Camera* {
    try {
      raw->ReplaceDevice(OpenFieldCamera(rig, o));
      return raw;
    } catch (const DeviceError&) {
      throw;  // not back yet; the controller retries until its timeout
    } catch (const Error& e) {
      throw DeviceError(e.what());  // e.g. the node is not there yet
    }
  };
  d.gps = OpenFieldGps(rig, &d.notes);
  if (rig.gps.source == "none")
    d.notes.push_back("warning: the rig has no GPS; sun positions use its fallback site");
  return d;
}

}  // namespace

std::vector<std::string> BuiltDrivers() {
  std::vector<std::string> d;
#ifdef ROUEN_HAVE_V4L2
  d.push_back("v4l2");
#endif
#ifdef ROUEN_HAVE_LIBCAMERA
  d.push_back("libcamera");
#endif
#ifdef ROUEN_HAVE_ARAVIS
  d.push_back("aravis");
#endif
#ifdef ROUEN_HAVE_USB
  d.push_back("usb");
#endif
#ifdef ROUEN_HAVE_NMEA
  d.push_back("nmea");
#endif
#ifdef ROUEN_HAVE_GPSD
  d.push_back("gpsd");
#endif
#ifdef ROUEN_HAVE_GPHOTO2
  d.push_back("gphoto2");
#endif
  return d;
}

RigDevices OpenRig(const RigConfig& rig, const OpenRigOptions& options) {
  if (rig.kind == "replay") return OpenReplay(rig, options);
  if (rig.simulated()) return OpenSim(rig);
  return OpenField(rig, options);
}

nlohmann::json ListDevices() {
  using json = nlohmann::json;
  json out = {{"drivers", BuiltDrivers()},
              {"cameras", json::array()},
              {"gps", json::array()},
              {"usb", json::array()},
              {"errors", json::array()}};
  auto guarded = [&](const char* driver, const std::function<void()>& f) {
    try {
      f();
    } catch (const std::exception& e) {
      out["errors"].push_back({{"driver", driver}, {"error", e.what()}});
    }
  };
#ifdef ROUEN_HAVE_V4L2
  guarded("v4l2", [&] {
    SystemV4l2Io io;
    for (const V4l2DeviceInfo& v : ListV4l2Devices(io)) {
      if (!v.error.empty()) {
        out["errors"].push_back({{"driver", "v4l2"}, {"error", v.path + ": " + v.error}});
        continue;
      }
      if (!v.can_capture) continue;  // metadata and output nodes of the same camera
      json formats = json::array();
      for (const V4l2FormatInfo& f : v.formats) {
        std::string sizes;
        if (!f.sizes.empty())
          sizes = " up to " + std::to_string(f.sizes.back().first) + "x" +
                  std::to_string(f.sizes.back().second);
        formats.push_back(f.fourcc + sizes + (f.supported ? "" : " (unsupported)"));
      }
      out["cameras"].push_back({{"driver", "v4l2"},
                                {"rig_kind", "uvc-webcam"},
                                {"id", v.path},
                                {"description", v.card + " (" + v.driver + ", " + v.bus_info + ")"},
                                {"formats", formats}});
    }
  });
#endif
#ifdef ROUEN_HAVE_LIBCAMERA
  guarded("libcamera", [&] {
    for (const LibcameraCameraInfo& c : ListLibcameraCameras())
      out["cameras"].push_back({{"driver", "libcamera"},
                                {"rig_kind", "rpi-libcamera"},
                                {"id", c.id},
                                {"description", c.model + "; " + c.exposure_controls},
                                {"formats", c.still_formats}});
  });
#endif
#ifdef ROUEN_HAVE_ARAVIS
  guarded("aravis", [&] {
    for (const AravisDeviceInfo& a : ListAravisDevices())
      out["cameras"].push_back(
          {{"driver", "aravis"},
           {"rig_kind", "gige-aravis"},
           {"id", a.id},
           {"description", a.vendor + " " + a.model + " (" + a.protocol + ", " + a.address +
                               ", serial " + a.serial + ")"}});
  });
#endif
#ifdef ROUEN_HAVE_GPHOTO2
  guarded("gphoto2", [&] {
    for (const auto& c : DescribeGphoto2Cameras(ListGphoto2Cameras())) out["cameras"].push_back(c);
  });
#endif
#ifdef ROUEN_HAVE_USB
  guarded("usb", [&] {
    for (const UsbDeviceInfo& u : ListUsbDevices())
      out["usb"].push_back({{"id", u.port_path},
                            {"kind", UsbDeviceKindName(u.classification.kind)},
                            {"drivers", u.classification.drivers},
                            {"description", u.Summary()}});
  });
#endif
  // Serial ports a GPS receiver may sit behind (USB CDC-ACM and USB-serial bridges).
  for (const char* pattern : {"/dev/ttyACM*", "/dev/ttyUSB*", "/dev/serial/by-id/*"})
    for (const std::string& p : Glob(pattern))
      out["gps"].push_back({{"driver", "nmea"}, {"id", p}, {"description", "serial port"}});
#ifdef ROUEN_HAVE_GPSD
  try {
    GpsdOptions o;
    o.timeout_s = 0.3;
    GpsdGps gpsd(o);
    out["gps"].push_back(
        {{"driver", "gpsd"}, {"id", o.host + ":" + o.port}, {"description", "gpsd is running"}});
  } catch (const Error&) {
    // No gpsd on this machine: nothing to list.
  }
#endif
  return out;
}

std::shared_ptr<void> WatchUsb(std::function<void(const std::string&)> on_event) {
#ifdef ROUEN_HAVE_USB
  try {
    auto monitor = std::make_shared<UsbHotplugMonitor>(
        [on_event](UsbHotplugEvent e, const UsbDeviceInfo& info) {
          on_event(std::string("USB ") + UsbHotplugEventName(e) + ": " + info.Summary());
        });
    if (monitor->Start()) return monitor;
  } catch (const Error&) {
    // No USB access (e.g. no /dev/bus/usb in a container): capture goes on without it.
  }
#else
  (void)on_event;
#endif
  return nullptr;
}

int MeasureV4l2Latency(const std::string& device) {
#ifdef ROUEN_HAVE_V4L2
  V4l2Options o;
  o.device = device;
  o.control_latency_frames = 0;
  std::unique_ptr<V4l2Camera> cam = OpenV4l2Camera(o);
  return MeasureControlLatency(*cam);
#else
  throw Error(device + ": this build has no V4L2 driver");
#endif
}

}  // namespace rouen
