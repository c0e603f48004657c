// The report of a solved scene (`rouen report`, and `rouen demo` for its world): one
// self-contained HTML page (render/html_report.h) with what the scene folder records and, when
// given, what its session and work folders hold: the capture timeline, the sun's path with the
// capture times, the response curves, the sky fits and their errors, the environment maps and
// their photometric-stereo normals, the albedo atlases with their flagged points, the
// validation against photographs, and the timings of every stage. A section whose data is
// absent says so; only a missing or unreadable scene.json stops the report.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "pipeline/validate.h"

namespace rouen {

struct ReportRequest {
  std::filesystem::path scene;  // scene folder (rouen solve)
  // Optional: the session the scene was solved from (capture timeline, sky masks).
  std::filesystem::path session;
  // Optional: the solve's work folder, whose calib/hdr holds the merged sky photos the sky
  // errors by elevation and by angle from the sun are computed on (rouen solve --work; the
  // demo's DIR/work).
  std::filesystem::path work;
  // Optional JSON figures shown in the validation section: `rouen demo`'s metrics.json,
  // `rouen validate --json` output.
  std::vector<std::filesystem::path> metrics;
  // Optional: photos compared with renders (ValidateSlot), shown side by side with their error
  // maps. Not owned.
  const Validation* validation = nullptr;
  std::function<void(const std::string&)> log;
};

struct ReportSection {
  std::string id, title;
  std::vector<std::string> absent;  // what the section could not show, and why
};

struct ReportSummary {
  std::vector<ReportSection> sections;  // in page order
  int plots = 0, images = 0;
  size_t bytes = 0;
  double seconds = 0;
};

// The page as text. Throws rouen::Error naming scene.json when it is missing or not a JSON
// object; anything else missing or unreadable is said in its section (and in `summary`).
std::string BuildReport(const ReportRequest& request, ReportSummary* summary = nullptr);

// BuildReport written atomically to `out` (its folder must exist).
ReportSummary WriteReport(const ReportRequest& request, const std::filesystem::path& out);

}  // namespace rouen
