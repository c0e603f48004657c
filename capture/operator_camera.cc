#include "capture/operator_camera.h"

#include <cmath>
#include <sstream>

#include "core/error.h"

namespace rouen {
namespace {

std::string AimText(Target target, int view, int views) {
  std::ostringstream os;
  switch (target) {
    case Target::kSun:
      os << "Point the camera at the sun (disc near the centre)";
      break;
    case Target::kAureole:
      os << "Point the camera just beside the sun, the disc out of frame or behind an occluder";
      break;
    case Target::kSky:
      os << "Point the camera at the sky (fisheye up, level)";
      break;
    case Target::kLandscape:
      os << "Set up the landscape panorama";
      break;
    case Target::kArchitecture:
      os << "Point the camera at the building";
      break;
    case Target::kCalibration:
      os << "Point the camera at the calibration target";
      break;
  }
  if (views > 1) os << ", view " << view + 1 << " of " << views;
  os << ", keep it still, then press Enter";
  return os.str();
}

}  // namespace

OperatorCamera::OperatorCamera(std::unique_ptr<Camera> device, std::map<Target, int> views,
                               std::map<Target, Intrinsics> lenses, OperatorPrompt prompt,
                               std::string id)
    : device_(std::move(device)),
      views_(std::move(views)),
      lenses_(std::move(lenses)),
      prompt_(std::move(prompt)),
      id_(std::move(id)) {
  if (!device_) throw Error("operator camera: no device");
  for (const auto& [t, n] : views_)
    if (n < 1) throw Error(std::string("operator camera: ") + TargetName(t) + ": views < 1");
}

double OperatorCamera::SetExposure(double seconds) {
  exposure_ = device_->SetExposure(seconds);
  return exposure_;
}

double OperatorCamera::SetGain(double gain) {
  gain_ = device_->SetGain(gain);
  return gain_;
}

void OperatorCamera::SetNdFilter(double density) {
  if (!(density >= 0) || !std::isfinite(density))
    throw Error("operator camera: ND density must be >= 0");
  if (std::abs(density - nd_) < 1e-9) return;
  OperatorRequest r;
  r.target = target_;
  r.view = view_;
  r.nd_density = density;
  std::ostringstream os;
  if (density == 0) {
    r.kind = OperatorRequest::Kind::kRemoveNd;
    os << "Remove the ND filter, then press Enter";
  } else {
    r.kind = OperatorRequest::Kind::kFitNd;
    os << "Fit the ND " << density << " filter (never look at the sun without it), then press "
       << "Enter";
  }
  r.text = os.str();
  if (prompt_) prompt_(r);
  nd_ = density;
  device_->SetNdFilter(density);
}

int OperatorCamera::ViewCount(Target target) const {
  auto it = views_.find(target);
  return it == views_.end() ? 1 : it->second;
}

void OperatorCamera::Aim(Target target, int view) {
  if (aimed_ && target == target_ && view == view_) return;
  OperatorRequest r;
  r.kind = OperatorRequest::Kind::kAim;
  r.target = target;
  r.view = view;
  r.views = ViewCount(target);
  r.nd_density = nd_;
  r.text = AimText(target, view, r.views);
  if (prompt_) prompt_(r);
  target_ = target;
  view_ = view;
  aimed_ = true;
  device_->Aim(target, view);
}

CapturedFrame OperatorCamera::Grab() {
  CapturedFrame f = device_->Grab();
  f.nd_density = nd_;
  auto it = lenses_.find(target_);
  if (it != lenses_.end() && !f.intrinsics) {
    const Intrinsics& k = it->second;
    if (k.width != f.image.width || k.height != f.image.height) {
      std::ostringstream os;
      os << Id() << ": the " << TargetName(target_) << " lens is calibrated for " << k.width << "x"
         << k.height << " but the camera delivers " << f.image.width << "x" << f.image.height
         << " (set [camera] width/height or recalibrate)";
      throw Error(os.str());
    }
    f.intrinsics = k;
  }
  return f;
}

void OperatorCamera::ReplaceDevice(std::unique_ptr<Camera> device) {
  if (!device) throw Error("operator camera: no device");
  device_ = std::move(device);
  device_->SetNdFilter(nd_);
  if (exposure_ > 0) device_->SetExposure(exposure_);
  device_->SetGain(gain_);
  if (aimed_) device_->Aim(target_, view_);
}

}  // namespace rouen
