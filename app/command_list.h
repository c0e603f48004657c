// The rouen CLI's top-level commands in the order `rouen --help` lists them, each with its
// one-line summary: one table for the full CLI (app/cli.cc, in the librouen_cli module) and the
// light start-up path (app/main.cc), which answers `rouen --help` and `rouen sun` without
// loading the module and its ~290 shared libraries.
#pragma once

#include <CLI/CLI.hpp>
#include <string_view>

namespace rouen {

struct CommandInfo {
  const char* name;
  const char* summary;
};

inline constexpr CommandInfo kCommands[] = {
    {"demo",
     "The whole pipeline on a built-in simulated world: capture, calibrate, solve, render a "
     "held-out time, score against ground truth"},
    {"capture",
     "Run a rig's capture plan (sun, aureole, sky, landscape, architecture) into a session "
     "folder"},
    {"devices",
     "List the cameras, GPS receivers and USB devices connected, and the rig kind that drives "
     "each"},
    {"calib", "Calibration: response curve, HDR merge, ND filters, vignetting, lenses, poses"},
    {"hdr", "Merge a bracket into a scene-linear radiance EXR"},
    {"sun", "Solar position (topocentric azimuth/elevation) for a place and a UTC time"},
    {"import", "Build a session folder from existing photos (JPEG/PNG/TIFF/EXR/DNG/RAW)"},
    {"status", "What a session holds and what its solve still lacks, with the commands to add it"},
    {"sky", "Sky model (Yu & Malik 1998 §3.2): fit a sky panorama, render a fitted sky"},
    {"solve", "Calibrate and solve a session once; write the scene that render reads"},
    {"render", "Render a solved scene's building at a captured time of day or at any other time"},
    {"validate", "Compare a solved scene's renders with the architecture photos of one slot"},
    {"report", "One self-contained HTML page of a solved scene: plots, maps, albedos, figures"},
    {"export", "Write a solved scene's building with its albedos as binary glTF (.glb)"},
    {"envmap", "Write the sun, sky and environment at a time as a latitude-longitude EXR"},
    {"view", "Write a web page that relights a solved scene's building at any time of its day"},
    {"timelapse", "Render a solved scene through one day, sunrise to sunset, as frames and MP4"},
    {"plan", "Choose capture times that show every face of a model both sunlit and in shadow"},
};

// The summary of top-level command `name`; throws std::logic_error for a name not in
// kCommands (a command registered without a row here).
const char* CommandSummary(std::string_view name);

// The top-level App's description and flags, shared by both start-up paths.
void DescribeRouen(CLI::App& app);

// Parses argv into `app` and runs the chosen command's callback; returns the process's exit
// status and prints rouen's errors ("rouen: error: ...") instead of letting them escape.
int ParseAndRun(CLI::App& app, int argc, char** argv);

}  // namespace rouen
