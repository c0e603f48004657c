// Planning a capture: the times of one day that show every face of a model both sunlit and in
// shadow, which is what separating the two pseudo-albedos needs (§4.1, eqs. 11-12: each point
// seen once in the sun and once in shadow).
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/mesh.h"
#include "core/session.h"
#include "core/solar.h"
#include "pipeline/timelapse.h"

namespace rouen {

// A camera that will photograph the building (the same at every capture time).
struct PlanView {
  std::string name;
  Intrinsics intrinsics;
  Pose pose;
};
// A views file: a JSON array, or an object whose "views" is one, of {"name": ..., "intrinsics":
// {...}, "pose": {...}} (core/camera.h's JSON, as lens and pose files hold them). Throws
// rouen::Error naming the file and the entry.
std::vector<PlanView> ReadPlanViews(const std::filesystem::path& file);

struct PlanOptions {
  Site site;
  // The day and its candidate times (pipeline/timelapse.h: sunrise to sunset every step, here
  // 15 min and the sun at least 5 deg up, a sun a capture can measure).
  TimelapseSchedule schedule = [] {
    TimelapseSchedule s;
    s.step_s = 900;
    s.min_elevation_deg = 5;
    return s;
  }();
  double spacing_m = 1.0;  // grid spacing of the points checked (solve/grid.h)
  int max_times = 5;       // at most this many capture times
  // A point is sunlit when the sun is unoccluded and at least this cosine off its plane
  // (about 6 deg: a grazing sun lights it too little to measure the sun albedo), shadowed when
  // occluded or behind its plane; in between it is neither.
  double min_sun_cosine = 0.1;
  std::vector<PlanView> views;  // empty: every point is assumed seen
  void Validate() const;        // throws rouen::Error naming the option
};

// A face: the model's triangles of one block in one plane.
struct PlanFace {
  int block = -1;
  std::string block_name;
  std::string facing;  // "up", "down" (within 45 deg), or a wall's compass direction ("N", "SE")
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double area_m2 = 0;
  int points = 0;          // grid points on it
  int unseen = 0;          // seen by no view
  int never_sunlit = 0;    // seen, and in shadow at every candidate time
  int never_shadowed = 0;  // seen, and sunlit at every candidate time (that is not grazing)
  int coverable = 0;       // seen, sunlit at some candidate time and shadowed at another
  int covered = 0;         // sunlit at a chosen time and shadowed at another chosen time
  // Percent of the face's points covered at the chosen times.
  double CoveredPercent() const { return points ? 100.0 * covered / points : 0; }
};

struct PlanTime {
  UtcTime time;
  double sun_azimuth_deg = 0, sun_elevation_deg = 0;
  int sunlit = 0, shadowed = 0;  // seen points in each state at this time
  int gain = 0;          // new (point, sunlit) and (point, shadowed) pairs when it was chosen
  double face_gain = 0;  // the same, each pair weighted by 1 / its face's points
  int order = 0;         // 1: chosen first by the greedy cover
};

struct PlanResult {
  Daylight daylight;
  std::vector<PlanTime> candidates;  // every time of the day considered, in time order
  std::vector<PlanTime> chosen;      // the schedule, in time order
  std::vector<PlanFace> faces;
  int points = 0, coverable = 0, covered = 0;
  double seconds = 0;
};

// Builds the grid of `mesh`, casts each point's ray to the sun at every candidate time
// (solve/raycast.h), and chooses times by greedy set cover: each step takes the time that adds
// the most (point, sunlit) and (point, shadowed) pairs not yet covered, each weighted by 1 / its
// face's points (every face counts alike), until every coverable point is both or max_times are
// chosen. Throws rouen::Error when the model has no surface
// (degenerate geometry) or the options are wrong.
PlanResult PlanCapture(const Mesh& mesh, const PlanOptions& options,
                       const std::function<void(const std::string&)>& log = {});

// The coverage a session's captures achieve so far (rouen capture prints it): each slot's time
// (its first architecture frame), and after it the percent of the model's grid points seen both
// sunlit and in shadow at that slot's time and the earlier ones. Seen: by the cameras of the
// architecture frames when every one carries its intrinsics and pose, else every point.
struct SlotCoverage {
  int slot = 0;
  UtcTime time;
  int points = 0;
  int seen = 0;     // by the session's architecture cameras (all points without them)
  int covered = 0;  // after this slot, cumulatively
  int sunlit = 0;   // at this slot's time
  double CoveredPercent() const { return points ? 100.0 * covered / points : 0; }
};
// Throws rouen::Error when the session has no model (session.json "model"), the model cannot
// be read, or it has no surface.
std::vector<SlotCoverage> SessionCoverage(const Session& session, double spacing_m = 1.0,
                                          double min_sun_cosine = 0.1);

// The plan as JSON (times in UTC and local, the faces' coverage and what they lack).
nlohmann::json PlanToJson(const PlanResult& plan, const PlanOptions& options);

}  // namespace rouen
