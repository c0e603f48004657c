// rouen's simulated world photographed through libgphoto2, for tests: a PtpIpResponder whose
// pictures the SimSensor exposes from the SimWorld's radiance at the shutter speed and ISO the
// driver set over PTP, and a Gphoto2Camera that sets them, triggers, downloads and checks the
// EXIF, exactly as it would a DSLR on Wi-Fi.
//
// Each Grab(): the SimCamera renders the radiance of the current aim at the clock's slot (on
// the calling thread); the responder's `frame` callback (its thread) exposes it with the
// settings of the shot the camera takes, through the ND filter fitted (SetNdFilter: the
// operator's filter, applied by the simulation); the Gphoto2Camera delivers the JPEG decoded,
// with the EXIF exposure and ISO; the frame gets the aim's intrinsics and pose and the
// simulated clock's time (mid-exposure), and the clock advances by the exposure plus 0.2 s, as
// a SimCamera's does.
// Noise: seeded by the slot, aim, exposure, ISO and ND, so a shot taken again with the same
// settings (a bracket redone after a reconnect) is the same picture and the adaptive bracket
// takes the same course; a real camera's noise would differ.
#pragma once

#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "capture/device.h"
#include "capture/gphoto2/gphoto2_camera.h"
#include "capture/gphoto2/testing/ptpip_responder.h"
#include "capture/sim/sim_devices.h"

namespace rouen {

// One picture the responder took.
struct SimPtpIpShot {
  PtpShot shot;  // the camera's settings and its capture index (the file is IMG_<index>.JPG)
  Target target = Target::kArchitecture;
  int view = 0;
  double nd_density = 0;
  UtcTime slot;  // the instant the world was lit for (the clock's slot)
};

class SimPtpIpCamera : public Camera {
 public:
  // Starts a responder offering `responder.exposure_times` (its `frame` is replaced) and opens
  // a Gphoto2Camera on it with `camera` (its port and model are replaced). `clock` must outlive
  // the camera. Throws DeviceError when libgphoto2 cannot open it.
  SimPtpIpCamera(std::shared_ptr<SimWorld> world, SimClock* clock, bool quick, uint64_t seed,
                 Gphoto2Options camera, PtpIpResponderOptions responder = {});
  ~SimPtpIpCamera() override;

  std::string Id() const override;
  std::vector<ControlInfo> Controls() const override;
  double SetExposure(double seconds) override;  // the camera's nearest shutter speed
  double SetGain(double gain) override;         // the camera's nearest ISO / base ISO
  void SetNdFilter(double density) override;
  double NdFilter() const override;
  int ViewCount(Target target) const override;  // the SimCamera's mounts
  void Aim(Target target, int view) override;
  // Throws DeviceError as the Gphoto2Camera does (busy for too long, connection lost ...).
  CapturedFrame Grab() override;

  // Opens a new Gphoto2Camera on the responder (after the connection was lost) and closes the
  // old one. Throws DeviceError when the camera cannot be opened (the old one is kept).
  void Reopen();
  PtpIpResponder& Responder() { return *responder_; }
  Gphoto2Camera& Driver() { return *driver_; }
  // Every picture the responder took, in order.
  std::vector<SimPtpIpShot> Shots() const;

 private:
  Image Expose(const PtpShot& shot);  // the responder's frame callback

  SimCamera sim_;
  SimClock* clock_;
  uint64_t seed_;
  Gphoto2Options options_;
  Target target_ = Target::kArchitecture;  // the aim (the SimCamera's default)
  int view_ = 0;
  mutable std::mutex mu_;  // the fields below, shared with the responder's thread
  struct Pending {
    const Image* radiance = nullptr;
    Target target = Target::kArchitecture;
    int view = 0;
    int64_t slot_ns = 0;
  };
  std::optional<Pending> pending_;  // while a Grab() waits for its picture
  double nd_ = 0;
  std::vector<SimPtpIpShot> shots_;
  std::unique_ptr<PtpIpResponder> responder_;
  std::unique_ptr<Gphoto2Camera> driver_;
};

}  // namespace rouen
