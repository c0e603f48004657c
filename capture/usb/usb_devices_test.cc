#include "capture/usb/usb_devices.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace rouen {
namespace {

UsbInterfaceInfo Itf(int number, uint8_t cls, uint8_t sub, uint8_t proto) {
  return UsbInterfaceInfo{number, 0, cls, sub, proto};
}

UsbDescriptors Dev(uint16_t vid, uint16_t pid, std::vector<UsbInterfaceInfo> itfs,
                   uint8_t dev_class = 0) {
  UsbDescriptors d;
  d.vendor_id = vid;
  d.product_id = pid;
  d.device_class = dev_class;
  d.interfaces = std::move(itfs);
  return d;
}

TEST(ClassifyUsbDevice, UvcWebcam) {
  // A typical webcam: IAD device class (0xEF/0x02/0x01), video control + streaming, audio.
  UsbDescriptors d = Dev(0x046d, 0x0825,
                         {Itf(0, 0x0E, 0x01, 0x00), Itf(1, 0x0E, 0x02, 0x00),
                          Itf(2, 0x01, 0x01, 0x00), Itf(3, 0x01, 0x02, 0x00)},
                         0xEF);
  d.device_subclass = 0x02;
  d.device_protocol = 0x01;
  const UsbClassification c = ClassifyUsbDevice(d);
  EXPECT_EQ(c.kind, UsbDeviceKind::kUvcCamera);
  EXPECT_EQ(c.drivers, "v4l2 / libcamera");
  EXPECT_NE(c.reason.find("interface 0"), std::string::npos) << c.reason;
}

TEST(ClassifyUsbDevice, VideoInterfaceAnywhereWinsOverSerial) {
  // A composite device with a CDC-ACM port first and the camera last, on a bridge vendor id.
  const UsbDescriptors d =
      Dev(0x10C4, 0xEA60,
          {Itf(0, 0x02, 0x02, 0x01), Itf(1, 0x0A, 0x00, 0x00), Itf(2, 0x0E, 0x01, 0x00)});
  EXPECT_EQ(ClassifyUsbDevice(d).kind, UsbDeviceKind::kUvcCamera);
}

TEST(ClassifyUsbDevice, Usb3Vision) {
  const UsbDescriptors d =
      Dev(0x2676, 0xBA02,
          {Itf(0, 0xEF, 0x05, 0x00), Itf(1, 0xEF, 0x05, 0x01), Itf(2, 0xEF, 0x05, 0x02)}, 0xEF);
  const UsbClassification c = ClassifyUsbDevice(d);
  EXPECT_EQ(c.kind, UsbDeviceKind::kUsb3VisionCamera);
  EXPECT_EQ(c.drivers, "aravis");
  EXPECT_NE(c.reason.find("USB3 Vision"), std::string::npos);
}

TEST(ClassifyUsbDevice, MiscClassWithOtherSubclassIsNotUsb3Vision) {
  // 0xEF/0x02 is the interface-association "common class", not USB3 Vision.
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x1234, 0x5678, {Itf(0, 0xEF, 0x02, 0x01)})).kind,
            UsbDeviceKind::kOther);
  // And the subclass alone on another class is not it either.
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x1234, 0x5678, {Itf(0, 0xFF, 0x05, 0x00)})).kind,
            UsbDeviceKind::kOther);
}

TEST(ClassifyUsbDevice, UbloxAnyProductIsAGpsReceiver) {
  for (uint16_t pid : {0x01a5, 0x01a7, 0x01a9, 0x0502}) {
    const UsbClassification c =
        ClassifyUsbDevice(Dev(0x1546, pid, {Itf(0, 0x02, 0x02, 0x01), Itf(1, 0x0A, 0, 0)}));
    EXPECT_EQ(c.kind, UsbDeviceKind::kGpsReceiver) << pid;
    EXPECT_EQ(c.drivers, "nmea / gpsd");
    EXPECT_NE(c.reason.find("u-blox"), std::string::npos);
  }
}

TEST(ClassifyUsbDevice, OtherKnownGpsReceivers) {
  for (auto [vid, pid] : {std::pair<uint16_t, uint16_t>{0x091E, 0x0003},
                          {0x1163, 0x0100},
                          {0x1163, 0x0200},
                          {0x0E8D, 0x3329}}) {
    EXPECT_EQ(ClassifyUsbDevice(Dev(vid, pid, {Itf(0, 0xFF, 0, 0)})).kind,
              UsbDeviceKind::kGpsReceiver)
        << std::hex << vid << ":" << pid;
  }
  // Other products of the same vendors are not.
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x091E, 0x0004, {Itf(0, 0xFF, 0, 0)})).kind,
            UsbDeviceKind::kOther);
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x0E8D, 0x2000, {Itf(0, 0xFF, 0, 0)})).kind,
            UsbDeviceKind::kOther);
}

TEST(ClassifyUsbDevice, SerialBridgesAreMaybeGps) {
  for (auto [vid, pid] : {std::pair<uint16_t, uint16_t>{0x067B, 0x2303},
                          {0x067B, 0xAAA0},
                          {0x0557, 0x2008},
                          {0x10C4, 0xEA60},
                          {0x10C4, 0xEA71},
                          {0x0403, 0x6001}}) {
    const UsbClassification c = ClassifyUsbDevice(Dev(vid, pid, {Itf(0, 0xFF, 0, 0)}));
    EXPECT_EQ(c.kind, UsbDeviceKind::kSerialMaybeGps) << std::hex << vid << ":" << pid;
    EXPECT_EQ(c.drivers, "nmea / gpsd");
    EXPECT_NE(c.reason.find("any serial device"), std::string::npos);
  }
  EXPECT_NE(ClassifyUsbDevice(Dev(0x067B, 0x2303, {})).reason.find("Prolific"), std::string::npos);
  // Other chips of the same vendors (FTDI FT2232, another Prolific product) are not.
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x0403, 0x6010, {Itf(0, 0xFF, 0, 0)})).kind,
            UsbDeviceKind::kOther);
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x067B, 0x2304, {Itf(0, 0xFF, 0, 0)})).kind,
            UsbDeviceKind::kOther);
}

TEST(ClassifyUsbDevice, CdcAcmIsMaybeGpsButOtherCdcIsNot) {
  const UsbClassification acm =
      ClassifyUsbDevice(Dev(0x2341, 0x0043, {Itf(0, 0x02, 0x02, 0x01), Itf(1, 0x0A, 0, 0)}));
  EXPECT_EQ(acm.kind, UsbDeviceKind::kSerialMaybeGps);
  EXPECT_NE(acm.reason.find("CDC-ACM"), std::string::npos);
  // CDC-ECM (subclass 0x06): a network adapter.
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x0BDA, 0x8153, {Itf(0, 0x02, 0x06, 0x00)})).kind,
            UsbDeviceKind::kOther);
}

TEST(ClassifyUsbDevice, HubsAndEmptyDescriptorsAreOther) {
  const UsbClassification hub = ClassifyUsbDevice(Dev(0x1d6b, 0x0002, {Itf(0, 0x09, 0, 0)}, 0x09));
  EXPECT_EQ(hub.kind, UsbDeviceKind::kOther);
  EXPECT_EQ(hub.drivers, "");
  EXPECT_EQ(ClassifyUsbDevice(UsbDescriptors{}).kind, UsbDeviceKind::kOther);
  // A device-level video class with no interfaces listed still counts as a camera.
  EXPECT_EQ(ClassifyUsbDevice(Dev(0x1234, 0x0001, {}, 0x0E)).kind, UsbDeviceKind::kUvcCamera);
}

TEST(UsbDeviceKindName, AllKindsNamed) {
  EXPECT_STREQ(UsbDeviceKindName(UsbDeviceKind::kUvcCamera), "uvc camera");
  EXPECT_STREQ(UsbDeviceKindName(UsbDeviceKind::kUsb3VisionCamera), "usb3 vision camera");
  EXPECT_STREQ(UsbDeviceKindName(UsbDeviceKind::kGpsReceiver), "gps receiver");
  EXPECT_STREQ(UsbDeviceKindName(UsbDeviceKind::kSerialMaybeGps), "serial, maybe gps");
  EXPECT_STREQ(UsbDeviceKindName(UsbDeviceKind::kOther), "other");
}

TEST(UsbPortPath, FollowsSysfsNaming) {
  EXPECT_EQ(UsbPortPath(1, {}), "usb1");
  EXPECT_EQ(UsbPortPath(1, {2}), "1-2");
  EXPECT_EQ(UsbPortPath(3, {1, 4, 2}), "3-1.4.2");
}

TEST(UsbDeviceInfo, SummaryNamesIdsStringsAndKind) {
  UsbDeviceInfo info;
  info.bus = 1;
  info.address = 4;
  info.port_path = "1-2.3";
  info.descriptors = Dev(0x046d, 0x0825, {Itf(0, 0x0E, 1, 0)});
  info.manufacturer = "Logitech";
  info.product = "Webcam C270";
  info.classification = ClassifyUsbDevice(info.descriptors);
  EXPECT_EQ(info.Summary(),
            "001:004 1-2.3 046d:0825 Logitech Webcam C270 -- uvc camera (v4l2 / libcamera)");
  info.classification = ClassifyUsbDevice(UsbDescriptors{});
  info.manufacturer.clear();
  info.product.clear();
  EXPECT_EQ(info.Summary(), "001:004 1-2.3 046d:0825 -- other");
}

// The number of USB devices the kernel exposes (sysfs names devices "1-2" or "usb1";
// interfaces carry a ':').
size_t SysfsDeviceCount() {
  const std::filesystem::path dir = "/sys/bus/usb/devices";
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec)) return 0;
  size_t n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (entry.path().filename().string().find(':') == std::string::npos) ++n;
  }
  return n;
}

TEST(ListUsbDevices, MatchesWhatTheKernelExposes) {
  const std::vector<UsbDeviceInfo> devices = ListUsbDevices();
  EXPECT_EQ(devices.size(), SysfsDeviceCount());
  for (const UsbDeviceInfo& d : devices) {
    EXPECT_FALSE(d.port_path.empty());
    EXPECT_EQ(d.classification.kind, ClassifyUsbDevice(d.descriptors).kind);
    EXPECT_TRUE(d.strings_read || !d.strings_error.empty()) << d.Summary();
  }
  // Without strings, nothing is opened.
  for (const UsbDeviceInfo& d : ListUsbDevices({.read_strings = false})) {
    EXPECT_FALSE(d.strings_read);
    EXPECT_TRUE(d.strings_error.empty());
  }
}

}  // namespace
}  // namespace rouen
