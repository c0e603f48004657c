// A field camera with a person behind it: the driver knows exposure and pixels, the operator
// points the camera at each target and fits or removes the ND filter when asked. Adds the
// rig's lens intrinsics to every frame.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>

#include "capture/device.h"

namespace rouen {

// What the operator is asked to do before the next frame.
struct OperatorRequest {
  enum class Kind { kAim, kFitNd, kRemoveNd } kind = Kind::kAim;
  Target target = Target::kArchitecture;
  int view = 0, views = 1;
  double nd_density = 0;
  std::string text;  // a sentence for the operator, e.g. "Point the camera at the sun ..."
};
// Blocks until the operator has done it (the app waits for Enter); may throw to abort.
using OperatorPrompt = std::function<void(const OperatorRequest&)>;

class OperatorCamera : public Camera {
 public:
  // `views`: how many views per target the operator shoots (missing targets: 1).
  // `lenses`: intrinsics per target (missing: none attached).
  // `id`: the name frames are journalled under ("" = the driver's).
  OperatorCamera(std::unique_ptr<Camera> device, std::map<Target, int> views,
                 std::map<Target, Intrinsics> lenses, OperatorPrompt prompt, std::string id = "");

  std::string Id() const override { return id_.empty() ? device_->Id() : id_; }
  std::vector<ControlInfo> Controls() const override { return device_->Controls(); }
  double SetExposure(double seconds) override;
  double SetGain(double gain) override;
  void SetNdFilter(double density) override;
  double NdFilter() const override { return nd_; }
  int ViewCount(Target target) const override;
  void Aim(Target target, int view) override;
  // The driver's frame with the ND density the operator fitted and the target's lens. A lens
  // whose size differs from the frame's is a rouen::Error naming both sizes.
  CapturedFrame Grab() override;

  // After the device was lost: continue with a reopened one, with the same settings applied.
  void ReplaceDevice(std::unique_ptr<Camera> device);
  Camera& device() { return *device_; }

 private:
  std::unique_ptr<Camera> device_;
  std::map<Target, int> views_;
  std::map<Target, Intrinsics> lenses_;
  OperatorPrompt prompt_;
  std::string id_;
  double exposure_ = 0, gain_ = 1, nd_ = 0;
  bool aimed_ = false;
  Target target_ = Target::kArchitecture;
  int view_ = 0;
};

}  // namespace rouen
