#include "app/render_options.h"

#include <cstdint>
#include <cstdio>
#include <vector>

#include "app/options.h"
#include "core/error.h"
#include "core/image.h"
#include "core/lens.h"
#include "solve/sky_time.h"

namespace rouen {
namespace {

// --sky-interp: "airmass" (default), "elevation" or "angular" (solve/sky_time.h SkyInterpMode).
constexpr char kSkyInterpHelp[] =
    "How the sky at a new time is made from the captured ones: airmass (by the sun's elevation, "
    "the zenith and the gradation dimming along the sun's air mass, the rest log-linear, "
    "extrapolating to lower suns), elevation (every part log-linear in the sun's elevation) or "
    "angular (the paper's inverse angular distance average, §5.1)";

SkyInterpMode ParseSkyInterp(const std::string& text) {
  if (text == "elevation") return SkyInterpMode::kElevation;
  if (text == "airmass") return SkyInterpMode::kAirMass;
  if (text == "angular") return SkyInterpMode::kAngularDistance;
  throw Error("--sky-interp takes elevation, airmass or angular, not '" + text + "'");
}

}  // namespace

void AddPredictionOptions(CLI::App* c, PredictionArgs* a, unsigned which, CLI::Option* slot) {
  std::vector<CLI::Option*> added;
  if (which & kUseHeldOutOption)
    added.push_back(c->add_flag("--use-held-out", a->use_held_out,
                                "At a predicted time: predict also from the lighting of held-out "
                                "slots"));
  if (which & kSkyInterpOption)
    added.push_back(c->add_option("--sky-interp", a->sky_interp, kSkyInterpHelp)
                        ->check(CLI::IsMember({"elevation", "airmass", "angular"}))
                        ->capture_default_str());
  if (which & kSkyInterpOption)
    added.push_back(c->add_flag("--no-sky-residual", a->no_sky_residual,
                                "The sky at a new time from the interpolated model alone, without "
                                "the photographed sky's residual against it (default: the "
                                "residual, taken relative to the sun, keeps what the model "
                                "misses near the horizon and the sun)"));
  if (which & kPbsOption)
    added.push_back(
        c->add_option("--pbs", a->pbs, "Blocked sunlight fraction 0..1 (0 clear, 1 overcast)")
            ->check(Within(0, 1))
            ->capture_default_str());
  // A captured slot's lighting is measured, not predicted: these options mean nothing there.
  if (slot != nullptr)
    for (CLI::Option* o : added) o->excludes(slot);
}

void ApplyPrediction(const PredictionArgs& a, RelightOptions* relight) {
  relight->pbs = a.pbs;
  relight->sky.mode = ParseSkyInterp(a.sky_interp);
  relight->sky_residual = !a.no_sky_residual;
}

void AddCameraOptions(CLI::App* c, CameraArgs* a) {
  c->add_option("--view", a->view,
                "Camera of this bracket (e.g. slot0/architecture/view1; default: the first)");
  c->add_option("--lens", a->lens, "Camera intrinsics JSON (with --pose)");
  c->add_option("--pose", a->pose, "Camera pose JSON (with --lens)");
  c->add_option("--look-at", a->look_at, "A new camera looking at this point X,Y,Z (metres, ENU)");
  c->add_option("--from-point", a->from_point, "... from this point X,Y,Z (with --look-at)");
  c->add_option("--fov", a->fov_deg,
                "Horizontal field of view of the --look-at camera (deg; default 50)")
      ->check(Within(1, 170, "deg"));
  c->add_option("--size", a->size,
                "Image size WIDTHxHEIGHT of the --look-at camera (default 640x480)");
}

std::pair<int, int> ParseImageSize(const std::string& text, const std::string& option) {
  int w = 0, h = 0;
  char x = 0, rest = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || x != 'x' || w < 1 || h < 1 ||
      w > kMaxImageSide || h > kMaxImageSide || static_cast<int64_t>(w) * h > kMaxImagePixels)
    throw Error(option + " '" + text + "': expected WIDTHxHEIGHT, each 1.." +
                std::to_string(kMaxImageSide));
  return {w, h};
}

bool CameraFromArgs(const CameraArgs& a, Intrinsics* intrinsics, Pose* pose) {
  if (!a.lens.empty() != !a.pose.empty()) throw Error("--lens and --pose go together");
  if (a.look_at.empty() != a.from_point.empty())
    throw Error("--look-at and --from-point go together");
  if (static_cast<int>(!a.view.empty()) + static_cast<int>(!a.lens.empty()) +
          static_cast<int>(!a.look_at.empty()) >
      1)
    throw Error("give one camera: --view, --lens/--pose or --look-at/--from-point");
  if (a.look_at.empty() && (!a.size.empty() || a.fov_deg > 0))
    throw Error(std::string(a.size.empty() ? "--fov" : "--size") +
                " sets the --look-at camera; --view and --lens keep their camera's own");
  if (!a.look_at.empty()) {
    const std::vector<double> target = ParseNumberList(a.look_at, 3, "--look-at");
    const std::vector<double> eye = ParseNumberList(a.from_point, 3, "--from-point");
    const Eigen::Vector3d t(target[0], target[1], target[2]), e(eye[0], eye[1], eye[2]);
    if ((t - e).norm() < 1e-6)
      throw Error("--look-at and --from-point are the same point: no direction to look in");
    const auto [w, h] = ParseImageSize(a.size.empty() ? "640x480" : a.size, "--size");
    *intrinsics = Intrinsics::PinholeFov(w, h, a.fov_deg > 0 ? a.fov_deg : 50);
    *pose = Pose::LookAt(e, t);
    return true;
  }
  if (!a.lens.empty()) {
    *intrinsics = ReadLensFile(a.lens).intrinsics;
    *pose = ReadPoseFile(a.pose);
    return true;
  }
  return false;
}

}  // namespace rouen
