// Internal to rouen_usb: reading a libusb device into UsbDeviceInfo.
#pragma once

#include <libusb.h>

#include <string>

#include "capture/usb/usb_devices.h"

namespace rouen::usb_internal {

// Descriptors, port path, speed and classification (no I/O: libusb caches descriptors).
// With `read_strings`, also opens the device to read its strings (records failures).
UsbDeviceInfo DescribeDevice(libusb_device* device, bool read_strings);
// Reads the string descriptors of `device` into `info` (opens and closes it).
void ReadStrings(libusb_device* device, UsbDeviceInfo* info);

std::string LibusbErrorText(int code);

}  // namespace rouen::usb_internal
