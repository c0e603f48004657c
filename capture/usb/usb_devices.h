// USB discovery for `rouen devices` and the capture layer: what is plugged in, and which rouen
// driver talks to it. libusb only identifies devices here; cameras and GPS receivers are then
// opened through their own drivers (V4L2/libcamera for UVC, Aravis for USB3 Vision, NMEA or
// gpsd for GPS receivers, which appear as serial ports).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace rouen {

struct UsbInterfaceInfo {
  int number = 0;       // bInterfaceNumber
  int alt_setting = 0;  // bAlternateSetting
  uint8_t interface_class = 0, interface_subclass = 0, interface_protocol = 0;
};

// The descriptor values classification looks at.
struct UsbDescriptors {
  uint16_t vendor_id = 0, product_id = 0;
  uint8_t device_class = 0, device_subclass = 0, device_protocol = 0;
  std::vector<UsbInterfaceInfo> interfaces;  // of the active (else first) configuration
};

enum class UsbDeviceKind {
  kUvcCamera,         // an interface of class 0x0E (video): USB Video Class
  kUsb3VisionCamera,  // an interface of class 0xEF (misc), subclass 0x05: USB3 Vision
  kGpsReceiver,       // a known GPS receiver (u-blox 0x1546, Garmin, DeLorme, MediaTek GPS)
  kSerialMaybeGps,    // a USB-serial bridge or CDC-ACM port: often a GPS, could be anything
  kOther,
};
// "uvc camera", "usb3 vision camera", "gps receiver", "serial, maybe gps", "other".
const char* UsbDeviceKindName(UsbDeviceKind kind);

struct UsbClassification {
  UsbDeviceKind kind = UsbDeviceKind::kOther;
  std::string drivers;  // the rouen drivers to use: "v4l2 / libcamera", "aravis", ...; "" = none
  std::string reason;   // why, in words ("interface 0 class 0x0e (video)")
};

// Pure classification over descriptor values. Cameras win over serial functions on composite
// devices; the GPS/serial vendor:product table follows gpsd's own udev rules
// (/lib/udev/rules.d/60-gpsd.rules): u-blox 1546:*, Garmin 091e:0003, DeLorme 1163:0100 and
// 1163:0200, MediaTek 0e8d:3329 are GPS receivers; Prolific 067b:2303 and 067b:aaa0, ATEN
// 0557:2008, Silicon Labs CP210x 10c4:ea60 and 10c4:ea71, FTDI 0403:6001 are serial bridges
// used in GPS receivers (and much else); any CDC-ACM interface (class 0x02, subclass 0x02) is
// a serial port that may be a GNSS receiver.
UsbClassification ClassifyUsbDevice(const UsbDescriptors& descriptors);

struct UsbDeviceInfo {
  int bus = 0, address = 0;
  std::string port_path;  // as sysfs names the device: "1-2.3"; "usb1" for a root hub
  std::string speed;      // "480 Mb/s (high)", "5 Gb/s (super)", "unknown"
  UsbDescriptors descriptors;
  // String descriptors, read when the device can be opened (permissions allowing).
  std::string manufacturer, product, serial_number;
  bool strings_read = false;
  std::string strings_error;  // why they could not be read, when they could not
  UsbClassification classification;

  // "001:004 1-2.3 046d:0825 Logitech HD Webcam C270 -- uvc camera (v4l2 / libcamera)"
  std::string Summary() const;
};

// The sysfs-style port path of a device from its bus and port numbers (root first).
std::string UsbPortPath(int bus, const std::vector<uint8_t>& ports);

struct UsbListOptions {
  // Open each device to read its manufacturer/product/serial strings (may fail without
  // permissions; the failure is recorded per device, not thrown).
  bool read_strings = true;
};

// Every USB device libusb sees (none is fine). Throws rouen::DeviceError when libusb cannot
// start or list.
std::vector<UsbDeviceInfo> ListUsbDevices(const UsbListOptions& options = {});

}  // namespace rouen
