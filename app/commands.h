// The rouen CLI: one subcommand per stage, each a thin function over library calls.
#pragma once

#include <CLI/CLI.hpp>

namespace rouen {

// Thrown by a command that has said what it had to say and ends the process with `code`
// instead of 0 (rouen capture stopped by a signal: 128 + the signal; rouen status: 2 when the
// session cannot be solved). main returns the code.
struct ExitStatus {
  int code = 1;
};

void RegisterSun(CLI::App& app);
void RegisterCapture(CLI::App& app);
void RegisterCalib(CLI::App& app);               // rouen calib response
void RegisterCalibGeometry(CLI::App* calib);     // rouen calib intrinsics|pose
void RegisterCalibPhotometric(CLI::App* calib);  // rouen calib nd|vignetting
void RegisterCalibEnvmap(CLI::App* calib);       // rouen calib envmap|orient
void RegisterHdr(CLI::App& app);
void RegisterDemo(CLI::App& app);
void RegisterDevices(CLI::App& app);
void RegisterImport(CLI::App& app);    // rouen import: a session from existing photos
void RegisterSolve(CLI::App& app);     // rouen solve: a session solved into a scene folder
void RegisterRender(CLI::App& app);    // rouen render: a scene at any time of day
void RegisterValidate(CLI::App& app);  // rouen validate: a scene against a slot's photos
void RegisterSky(CLI::App& app);       // rouen sky fit / rouen sky render
void RegisterStatus(CLI::App& app);    // rouen status: what a session holds and what it lacks
void RegisterReport(CLI::App& app);    // rouen report: a scene as one HTML page
void RegisterExport(CLI::App& app);    // rouen export: the building as glTF with its albedos
void RegisterEnvmap(CLI::App& app);    // rouen envmap: a time's lighting as a lat-long EXR
void RegisterView(CLI::App& app);      // rouen view: a web page relighting the building
// rouen timelapse: one local day of a scene, sunrise to sunset, as frames and an MP4
void RegisterTimelapse(CLI::App& app);
// rouen plan: capture times that show every face both sunlit and in shadow
void RegisterPlan(CLI::App& app);

}  // namespace rouen

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "capture/controller.h"

namespace rouen {

class ProgressLine;
// A capture's progress on `line` (slot, target, view, frames, exposure, saturated fraction,
// GPS status) and its events on lines of their own: CaptureSessionOptions::progress for
// `rouen capture` and `rouen demo`.
std::function<void(const CaptureProgress&)> CaptureProgressPrinter(ProgressLine* line);

}  // namespace rouen

#include <nlohmann/json.hpp>

#include "calib/response.h"
#include "core/camera.h"

namespace rouen {

// Reads a list file of whitespace-separated columns, '#' comments and blank lines skipped:
// calls `line` with each line's words and "<file>:<line>" for messages. Throws rouen::Error
// when the file cannot be opened or lists nothing.
void ForEachListLine(const std::string& list,
                     const std::function<void(const std::vector<std::string>& words,
                                              const std::string& where)>& line);

// A JSON file parsed; `what` names it in errors ("no such lens file", "not valid JSON").
nlohmann::json ReadJsonFile(const std::string& path, const char* what);
struct ListedExposure {
  std::string path;
  double seconds;
};
// Reads an exposure list ("image seconds" per line, '#' comments, paths relative to the list).
std::vector<ListedExposure> ReadExposureList(const std::string& list);
// Loads the listed LDR images as one bracket, checking sizes and channels.
Bracket LoadBracket(const std::vector<ListedExposure>& listed);

}  // namespace rouen
