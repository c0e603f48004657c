// rouen devices: what is connected, per driver, and which rig kind drives it.
#include <cstdio>
#include <nlohmann/json.hpp>

#include "app/command_list.h"
#include "app/commands.h"
#include "capture/devices/devices.h"

namespace rouen {
namespace {

struct DevicesArgs {
  bool json = false;
  std::string latency;
};

void PrintList(const nlohmann::json& list, const char* title, const char* none) {
  std::printf("%s:\n", title);
  if (list.empty()) std::printf("  %s\n", none);
  for (const auto& d : list) {
    std::printf("  %-28s %s", d.value("id", "").c_str(), d.value("description", "").c_str());
    if (d.contains("rig_kind"))
      std::printf("  [rig kind: %s]", d["rig_kind"].get<std::string>().c_str());
    if (d.contains("kind"))
      std::printf("  [%s -> %s]", d["kind"].get<std::string>().c_str(),
                  d["drivers"].get<std::string>().c_str());
    std::printf("\n");
    if (d.contains("formats"))
      for (const auto& f : d["formats"]) std::printf("      %s\n", f.get<std::string>().c_str());
  }
}

void Run(const DevicesArgs& a) {
  if (!a.latency.empty()) {
    int frames = MeasureV4l2Latency(a.latency);
    std::printf(
        "%s: exposure changes show after %d frame(s); put\n"
        "  control_latency_frames = %d\n"
        "in the rig's [camera] table.\n",
        a.latency.c_str(), frames, frames);
    return;
  }
  nlohmann::json d = ListDevices();
  if (a.json) {
    std::printf("%s\n", d.dump(2).c_str());
    return;
  }
  std::string drivers;
  for (const auto& x : d["drivers"]) drivers += " " + x.get<std::string>();
  std::printf("drivers in this build:%s\n", drivers.c_str());
  PrintList(d["cameras"], "cameras", "none found");
  PrintList(d["gps"], "GPS",
            "no serial port and no gpsd (a rig without GPS uses its fallback site)");
  PrintList(d["usb"], "USB devices", "none");
  for (const auto& e : d["errors"])
    std::printf("warning: %s: %s\n", e["driver"].get<std::string>().c_str(),
                e["error"].get<std::string>().c_str());
}

}  // namespace

void RegisterDevices(CLI::App& app) {
  auto a = std::make_shared<DevicesArgs>();
  CLI::App* c = app.add_subcommand("devices", CommandSummary("devices"));
  c->footer(
      "Cameras: V4L2 nodes that can stream (UVC webcams, rig kind uvc-webcam), libcamera\n"
      "cameras (rpi-libcamera), GigE Vision / USB3 Vision cameras seen by Aravis (gige-aravis).\n"
      "GPS: serial ports (NMEA) and a running gpsd. USB: every device with what it is (UVC\n"
      "camera, USB3 Vision camera, GPS receiver, serial bridge) and the driver to use.\n"
      "Put the id of your camera into the rig's [camera] device, and the serial port into\n"
      "[gps] device.\n"
      "Examples:\n"
      "  rouen devices\n"
      "  rouen devices --json\n"
      "  rouen devices --latency /dev/video0     # frames to drop after an exposure change");
  c->add_flag("--json", a->json, "Print the listing as JSON");
  c->add_option("--latency", a->latency,
                "Measure a V4L2 camera's control latency (brightness-step test) and print the "
                "value for the rig");
  c->callback([a] { Run(*a); });
}

}  // namespace rouen
