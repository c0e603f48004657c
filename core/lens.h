// A lens as the rig and the calibration describe it: intrinsics (core/camera.h), the radial
// vignetting model, and the field of view a lens file may limit. One reader of rig lens files
// (rigs/lenses/*.json) for capture, calibration and the CLI.
#pragma once

#include <array>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "core/camera.h"
#include "core/image.h"

namespace rouen {

// V(r) = 1 + a1 r^2 + a2 r^4 + a3 r^6, r = distance from the optical centre (cx, cy) divided
// by the half-diagonal of the calibration image (r = 1 at the corners of a centred lens).
// A measured radiance is L_true x V. Fitted from flat fields by calib/vignetting.h.
struct VignettingModel {
  int width = 0, height = 0;  // image size the model was calibrated at (pixels)
  double cx = 0, cy = 0;      // optical centre, pixels (pixel centres at integer + 0.5)
  std::array<double, 3> a = {0, 0, 0};

  // Half the diagonal of a width x height image, pixels (the unit of r).
  static double HalfDiagonal(int width, int height);
  // Fall-off at pixel (x, y) (continuous coordinates) of an image of the calibration size.
  double Falloff(double x, double y) const;
  double FalloffAtRadius(double r) const;
  // Largest normalised radius of any image corner from the centre.
  double MaxRadius() const;
  // Checks sizes, a finite centre inside the image, finite coefficients and V > 0.05 from the
  // centre out to the farthest corner; throws rouen::Error.
  void Validate() const;
};

void to_json(nlohmann::json& j, const VignettingModel& v);
void from_json(const nlohmann::json& j, VignettingModel& v);  // validates; throws rouen::Error

// Divides a radiance image by the fall-off (an image of another size with the same aspect
// ratio is mapped by scaling). Throws rouen::Error for a different aspect ratio or a digital
// image.
void RemoveVignetting(const VignettingModel& model, Image* radiance);

// A rig lens file: the Intrinsics keys, plus optional "max_field_deg" (the largest angle
// from the optical axis the lens images, degrees, 0..180; 0 = automatic) and "vignetting" (a
// VignettingModel). Other keys (e.g. the "calibration" record `rouen calib intrinsics` writes) are
// ignored.
struct LensFile {
  Intrinsics intrinsics;
  double max_field_deg = 0;
  std::optional<VignettingModel> vignetting;
};

// Reads and validates a lens file; throws rouen::Error naming the file and the problem
// (missing, not JSON, bad intrinsics, a bad "max_field_deg" or "vignetting").
LensFile ReadLensFile(const std::string& path);
// The same from the text of a lens file; `name` (the file) is used in messages.
LensFile ParseLensFile(std::string_view text, const std::string& name);

// A pose file: {"rotation": 3x3, "position": [x, y, z], ...} (as `rouen calib pose` and
// `rouen calib orient` write them). Throws rouen::Error naming the file.
Pose ReadPoseFile(const std::string& path);

}  // namespace rouen
