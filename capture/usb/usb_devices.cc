#include "capture/usb/usb_devices.h"

#include <libusb.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <tuple>

#include "capture/device.h"
#include "capture/usb/usb_internal.h"

namespace rouen {
namespace {

constexpr uint8_t kClassCdc = 0x02;     // communications (CDC control)
constexpr uint8_t kSubclassAcm = 0x02;  // abstract control model: a serial port
constexpr uint8_t kClassVideo = 0x0E;   // USB Video Class
constexpr uint8_t kClassMisc = 0xEF;    // miscellaneous
constexpr uint8_t kSubclassU3v = 0x05;  // USB3 Vision (with class 0xEF)

struct KnownId {
  uint16_t vendor, product;
  bool any_product;
  UsbDeviceKind kind;
  const char* what;
};

// From gpsd's udev rules (60-gpsd.rules) shipped with gpsd 3.22.
constexpr KnownId kKnownIds[] = {
    {0x1546, 0, true, UsbDeviceKind::kGpsReceiver, "u-blox GNSS receiver"},
    {0x091E, 0x0003, false, UsbDeviceKind::kGpsReceiver, "Garmin USB GPS (garmin_gps)"},
    {0x1163, 0x0100, false, UsbDeviceKind::kGpsReceiver, "DeLorme Earthmate GPS"},
    {0x1163, 0x0200, false, UsbDeviceKind::kGpsReceiver, "DeLorme Earthmate GPS"},
    {0x0E8D, 0x3329, false, UsbDeviceKind::kGpsReceiver, "MediaTek GPS"},
    {0x067B, 0x2303, false, UsbDeviceKind::kSerialMaybeGps, "Prolific PL2303 USB-serial bridge"},
    {0x067B, 0xAAA0, false, UsbDeviceKind::kSerialMaybeGps, "Prolific PL2303 USB-serial bridge"},
    {0x0557, 0x2008, false, UsbDeviceKind::kSerialMaybeGps, "ATEN UC-232A USB-serial bridge"},
    {0x10C4, 0xEA60, false, UsbDeviceKind::kSerialMaybeGps,
     "Silicon Labs CP210x USB-serial bridge"},
    {0x10C4, 0xEA71, false, UsbDeviceKind::kSerialMaybeGps,
     "Silicon Labs CP210x USB-serial bridge"},
    {0x0403, 0x6001, false, UsbDeviceKind::kSerialMaybeGps, "FTDI FT232 USB-serial bridge"},
};

std::string Hex2(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "0x%02x", v & 0xffu);
  return buf;
}

std::string Hex4(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "%04x", v & 0xffffu);
  return buf;
}

const char* DriversFor(UsbDeviceKind kind) {
  switch (kind) {
    case UsbDeviceKind::kUvcCamera:
      return "v4l2 / libcamera";
    case UsbDeviceKind::kUsb3VisionCamera:
      return "aravis";
    case UsbDeviceKind::kGpsReceiver:
    case UsbDeviceKind::kSerialMaybeGps:
      return "nmea / gpsd";
    case UsbDeviceKind::kOther:
      return "";
  }
  return "";
}

std::string SpeedName(int speed) {
  switch (speed) {
    case LIBUSB_SPEED_LOW:
      return "1.5 Mb/s (low)";
    case LIBUSB_SPEED_FULL:
      return "12 Mb/s (full)";
    case LIBUSB_SPEED_HIGH:
      return "480 Mb/s (high)";
    case LIBUSB_SPEED_SUPER:
      return "5 Gb/s (super)";
    case LIBUSB_SPEED_SUPER_PLUS:
      return "10 Gb/s (super+)";
    default:
      return "unknown";
  }
}

}  // namespace

const char* UsbDeviceKindName(UsbDeviceKind kind) {
  switch (kind) {
    case UsbDeviceKind::kUvcCamera:
      return "uvc camera";
    case UsbDeviceKind::kUsb3VisionCamera:
      return "usb3 vision camera";
    case UsbDeviceKind::kGpsReceiver:
      return "gps receiver";
    case UsbDeviceKind::kSerialMaybeGps:
      return "serial, maybe gps";
    case UsbDeviceKind::kOther:
      return "other";
  }
  return "other";
}

UsbClassification ClassifyUsbDevice(const UsbDescriptors& d) {
  auto make = [](UsbDeviceKind kind, std::string reason) {
    return UsbClassification{kind, DriversFor(kind), std::move(reason)};
  };
  // Cameras first: a webcam may also carry audio or serial functions.
  for (const UsbInterfaceInfo& i : d.interfaces) {
    if (i.interface_class == kClassVideo) {
      return make(UsbDeviceKind::kUvcCamera,
                  "interface " + std::to_string(i.number) + " class 0x0e (video): USB Video Class");
    }
  }
  if (d.device_class == kClassVideo) {
    return make(UsbDeviceKind::kUvcCamera, "device class 0x0e (video)");
  }
  for (const UsbInterfaceInfo& i : d.interfaces) {
    if (i.interface_class == kClassMisc && i.interface_subclass == kSubclassU3v) {
      return make(UsbDeviceKind::kUsb3VisionCamera,
                  "interface " + std::to_string(i.number) +
                      " class 0xef subclass 0x05: USB3 Vision (protocol " +
                      Hex2(i.interface_protocol) + ")");
    }
  }
  for (const KnownId& k : kKnownIds) {
    if (d.vendor_id == k.vendor && (k.any_product || d.product_id == k.product)) {
      std::string reason =
          std::string(k.what) + " (" + Hex4(d.vendor_id) + ":" + Hex4(d.product_id) + ")";
      if (k.kind == UsbDeviceKind::kSerialMaybeGps) {
        reason += ": common in GPS receivers, but any serial device may use it";
      }
      return make(k.kind, reason);
    }
  }
  for (const UsbInterfaceInfo& i : d.interfaces) {
    if (i.interface_class == kClassCdc && i.interface_subclass == kSubclassAcm) {
      return make(UsbDeviceKind::kSerialMaybeGps,
                  "interface " + std::to_string(i.number) +
                      " is a CDC-ACM serial port: many GNSS receivers are, so are modems and "
                      "microcontroller boards");
    }
  }
  return make(UsbDeviceKind::kOther, "no camera or GPS signature");
}

std::string UsbPortPath(int bus, const std::vector<uint8_t>& ports) {
  if (ports.empty()) return "usb" + std::to_string(bus);
  std::string path = std::to_string(bus) + "-";
  for (size_t i = 0; i < ports.size(); ++i) {
    if (i > 0) path += ".";
    path += std::to_string(ports[i]);
  }
  return path;
}

std::string UsbDeviceInfo::Summary() const {
  char head[32];
  std::snprintf(head, sizeof head, "%03d:%03d ", bus, address);
  std::string s =
      head + port_path + " " + Hex4(descriptors.vendor_id) + ":" + Hex4(descriptors.product_id);
  if (!manufacturer.empty()) s += " " + manufacturer;
  if (!product.empty()) s += " " + product;
  s += " -- ";
  s += UsbDeviceKindName(classification.kind);
  if (!classification.drivers.empty()) s += " (" + classification.drivers + ")";
  return s;
}

namespace usb_internal {

std::string LibusbErrorText(int code) {
  return std::string(libusb_error_name(code)) + ": " + libusb_strerror(code);
}

void ReadStrings(libusb_device* device, UsbDeviceInfo* info) {
  libusb_device_descriptor desc{};
  if (libusb_get_device_descriptor(device, &desc) != 0) return;
  libusb_device_handle* handle = nullptr;
  const int ret = libusb_open(device, &handle);
  if (ret != 0) {
    info->strings_read = false;
    info->strings_error = "cannot open (" + LibusbErrorText(ret) + ")";
    return;
  }
  auto read = [&](uint8_t index) -> std::string {
    if (index == 0) return "";
    unsigned char buf[256];
    const int n = libusb_get_string_descriptor_ascii(handle, index, buf, sizeof buf);
    return n > 0 ? std::string(reinterpret_cast<char*>(buf), static_cast<size_t>(n)) : "";
  };
  info->manufacturer = read(desc.iManufacturer);
  info->product = read(desc.iProduct);
  info->serial_number = read(desc.iSerialNumber);
  info->strings_read = true;
  info->strings_error.clear();
  libusb_close(handle);
}

UsbDeviceInfo DescribeDevice(libusb_device* device, bool read_strings) {
  UsbDeviceInfo info;
  info.bus = libusb_get_bus_number(device);
  info.address = libusb_get_device_address(device);
  uint8_t ports[8];
  const int n = libusb_get_port_numbers(device, ports, sizeof ports);
  info.port_path = UsbPortPath(info.bus, std::vector<uint8_t>(ports, ports + std::max(n, 0)));
  info.speed = SpeedName(libusb_get_device_speed(device));
  libusb_device_descriptor desc{};
  if (libusb_get_device_descriptor(device, &desc) == 0) {
    info.descriptors.vendor_id = desc.idVendor;
    info.descriptors.product_id = desc.idProduct;
    info.descriptors.device_class = desc.bDeviceClass;
    info.descriptors.device_subclass = desc.bDeviceSubClass;
    info.descriptors.device_protocol = desc.bDeviceProtocol;
  }
  libusb_config_descriptor* config = nullptr;
  if (libusb_get_active_config_descriptor(device, &config) != 0) {
    config = nullptr;
    if (desc.bNumConfigurations > 0 && libusb_get_config_descriptor(device, 0, &config) != 0) {
      config = nullptr;
    }
  }
  if (config != nullptr) {
    for (int i = 0; i < config->bNumInterfaces; ++i) {
      const libusb_interface& itf = config->interface[i];
      for (int a = 0; a < itf.num_altsetting; ++a) {
        const libusb_interface_descriptor& alt = itf.altsetting[a];
        info.descriptors.interfaces.push_back({alt.bInterfaceNumber, alt.bAlternateSetting,
                                               alt.bInterfaceClass, alt.bInterfaceSubClass,
                                               alt.bInterfaceProtocol});
      }
    }
    libusb_free_config_descriptor(config);
  }
  info.classification = ClassifyUsbDevice(info.descriptors);
  if (read_strings) ReadStrings(device, &info);
  return info;
}

}  // namespace usb_internal

std::vector<UsbDeviceInfo> ListUsbDevices(const UsbListOptions& options) {
  libusb_context* ctx = nullptr;
  if (const int ret = libusb_init(&ctx); ret != 0) {
    throw DeviceError("libusb: cannot initialise (" + usb_internal::LibusbErrorText(ret) + ")");
  }
  std::unique_ptr<libusb_context, void (*)(libusb_context*)> guard(ctx, libusb_exit);
  libusb_device** list = nullptr;
  const ssize_t count = libusb_get_device_list(ctx, &list);
  if (count < 0) {
    throw DeviceError("libusb: cannot list devices (" +
                      usb_internal::LibusbErrorText(static_cast<int>(count)) + ")");
  }
  std::vector<UsbDeviceInfo> out;
  for (ssize_t i = 0; i < count; ++i) {
    out.push_back(usb_internal::DescribeDevice(list[i], options.read_strings));
  }
  libusb_free_device_list(list, 1);
  std::sort(out.begin(), out.end(), [](const UsbDeviceInfo& a, const UsbDeviceInfo& b) {
    return std::tie(a.bus, a.address) < std::tie(b.bus, b.address);
  });
  return out;
}

}  // namespace rouen
