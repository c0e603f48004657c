// Options of the commands that render a solved scene (render, validate, envmap, timelapse):
// the camera of the image and the prediction of lighting at a new time.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <utility>

#include "core/camera.h"
#include "solve/relight.h"

namespace rouen {

// How lighting is predicted at a time no slot captured: --sky-interp, --no-sky-residual, --pbs,
// --use-held-out.
struct PredictionArgs {
  std::string sky_interp = "airmass";
  bool no_sky_residual = false;  // the sky model alone, without the measured residual
  double pbs = 0;                // blocked sunlight fraction (§6.3)
  bool use_held_out = false;     // predict also from held-out slots
};
// Which of the prediction options a command takes.
enum PredictionOption : unsigned { kSkyInterpOption = 1, kPbsOption = 2, kUseHeldOutOption = 4 };
// Adds the options named by `which` to `command`; with `slot` (a captured slot's lighting,
// where nothing is predicted), each excludes it.
void AddPredictionOptions(CLI::App* command, PredictionArgs* args, unsigned which,
                          CLI::Option* slot = nullptr);
// Sets `relight`'s pbs, sky interpolation and sky residual from the options; throws rouen::Error.
void ApplyPrediction(const PredictionArgs& args, RelightOptions* relight);

// The camera of a rendered image (rouen render, rouen timelapse): one of the scene's views
// (--view), a lens and a pose file (--lens/--pose), or a pinhole camera at --from-point looking
// at --look-at (ENU metres) with --fov and --size.
struct CameraArgs {
  std::string view, lens, pose, look_at, from_point;
  std::string size;    // empty: 640x480
  double fov_deg = 0;  // 0: 50 deg
};
void AddCameraOptions(CLI::App* command, CameraArgs* args);
// "WIDTHxHEIGHT" within core/image.h's limits; throws rouen::Error naming `option`.
std::pair<int, int> ParseImageSize(const std::string& text, const std::string& option);
// Checks that the camera options go together and sets `intrinsics` and `pose` from the lens and
// pose files or the look-at camera: returns false when the camera is the scene's view
// args.view (pipeline/scene.h FindView, once the scene is loaded). Throws rouen::Error naming
// the option at fault.
bool CameraFromArgs(const CameraArgs& args, Intrinsics* intrinsics, Pose* pose);

}  // namespace rouen
