// CLI11 validators for numeric options. CLI11's own ranges let NaN through (every comparison
// with NaN is false); these refuse NaN and infinities, and say the range.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/solar.h"
#include "core/time.h"
#include "solve/sky_time.h"

namespace rouen {

// A finite number within [lo, hi] (hi may be infinite); `unit` (e.g. "mbar") follows the
// range in the message.
CLI::Validator Within(double lo, double hi, const std::string& unit = "");
// A finite number above 0.
CLI::Validator Positive();
// A number one of core/limits.h's rules accepts (LatitudeProblem, HeightProblem, ...).
CLI::Validator Obeys(std::string (*problem)(double));

// `n` comma-separated finite numbers ("1.5,2,3"); throws rouen::Error naming `option`.
std::vector<double> ParseNumberList(const std::string& text, size_t n, const std::string& option);

// A duration "15min", "1h", "30s" (units s, min, h; a bare number is seconds), above 0 and at
// most `max_s`; throws rouen::Error naming `option`.
double ParseDurationSeconds(const std::string& text, double max_s, const std::string& option);

// --sky-interp: "elevation" (default) or "angular" (solve/sky_time.h SkyInterpMode).
inline constexpr char kSkyInterpHelp[] =
    "How the sky at a new time is made from the captured ones: elevation (by the sun's "
    "elevation, log-linear, extrapolates to lower suns) or angular (the paper's inverse angular "
    "distance average, §5.1)";
SkyInterpMode ParseSkyInterp(const std::string& text);

// An ISO 8601 time with its offset (core/time.h); throws rouen::Error naming `option`.
UtcTime ParseTimeOption(const std::string& text, const std::string& option);

// A site "LAT,LON,H" (degrees north, degrees east, metres) within core/limits.h's ranges;
// throws rouen::Error naming `option` and the coordinate at fault.
Site ParseSiteOption(const std::string& text, const std::string& option);

// The camera of a rendered image (rouen render, rouen timelapse): one of the scene's views
// (--view), a lens and a pose file (--lens/--pose), or a pinhole camera at --from-point looking
// at --look-at (ENU metres) with --fov and --size.
struct CameraArgs {
  std::string view, lens, pose, look_at, from_point, size = "640x480";
  double fov_deg = 50;
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
