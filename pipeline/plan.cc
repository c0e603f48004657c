#include "pipeline/plan.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/files.h"
#include "core/json_text.h"
#include "core/limits.h"
#include "core/text.h"
#include "solve/grid.h"
#include "solve/raycast.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

enum SunState : uint8_t { kGrazing = 0, kSunlit = 1, kShadowed = 2 };

std::string Facing(const Eigen::Vector3d& n) {
  if (n.z() > 0.7) return "up";
  if (n.z() < -0.7) return "down";
  double az = std::atan2(n.x(), n.y()) * 180 / M_PI;  // from north through east
  if (az < 0) az += 360;
  static const char* kNames[8] = {"N", "NE", "E", "SE", "S", "SW", "W", "NW"};
  return kNames[static_cast<int>(std::floor((az + 22.5) / 45)) % 8];
}

// A grid point's sun state for the sun direction `s` (§4.1: shadowed means no direct sun).
uint8_t SunState(const GridPoint& p, const Eigen::Vector3d& s, const RayCaster& caster,
                 double min_sun_cosine) {
  const double c = p.normal.dot(s);
  if (c <= 0) return kShadowed;
  if (caster.Occluded(p.position + caster.surface_offset() * p.normal, s)) return kShadowed;
  return c >= min_sun_cosine ? kSunlit : kGrazing;
}

// Which grid points some view sees (in its image, facing it, nothing in between); all of them
// without views.
std::vector<uint8_t> SeenBy(const SurfaceGrid& grid, const RayCaster& caster,
                            const std::vector<PlanView>& views) {
  const int np = grid.size();
  std::vector<uint8_t> seen(np, views.empty() ? 1 : 0);
  const double eps = caster.surface_offset();
  if (views.empty()) return seen;
  tbb::parallel_for(0, np, [&](int i) {
    const GridPoint& p = grid.points[i];
    const Eigen::Vector3d origin = p.position + eps * p.normal;
    for (const PlanView& v : views) {
      const Eigen::Vector3d to_cam = v.pose.position - origin;
      const double dist = to_cam.norm();
      if (!(dist > eps) || p.normal.dot(to_cam) <= 0) continue;
      const auto px = Project(v.intrinsics, v.pose.WorldToCamera(p.position));
      if (!px || px->x() < 0 || px->y() < 0 || px->x() >= v.intrinsics.width ||
          px->y() >= v.intrinsics.height)
        continue;
      if (caster.Occluded(origin, to_cam / dist, 0, dist)) continue;
      seen[i] = 1;
      break;
    }
  });
  return seen;
}

void Log(const std::function<void(const std::string&)>& log, const std::string& s) {
  if (log) log(s);
}

}  // namespace

std::vector<PlanView> ReadPlanViews(const fs::path& file) {
  if (!fs::is_regular_file(file)) throw Error(file.string() + ": no such views file");
  const nlohmann::json j = ParseJsonText(ReadFileToString(file), file.string());
  const nlohmann::json& list = j.is_object() && j.contains("views") ? j["views"] : j;
  if (!list.is_array() || list.empty())
    throw Error(file.string() +
                ": expected a list of views [{\"name\", \"intrinsics\", \"pose\"}, ...] (or "
                "{\"views\": [...]})");
  std::vector<PlanView> views;
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string where = file.string() + ": view " + std::to_string(i);
    const nlohmann::json& v = list[i];
    if (!v.is_object() || !v.contains("intrinsics") || !v.contains("pose"))
      throw Error(where + ": needs \"intrinsics\" and \"pose\"");
    PlanView view;
    view.name = v.contains("name") && v["name"].is_string() ? v["name"].get<std::string>()
                                                            : "view" + std::to_string(i);
    try {
      view.intrinsics = v["intrinsics"].get<Intrinsics>();
      view.pose = v["pose"].get<Pose>();
      view.intrinsics.Validate();
    } catch (const Error& e) {
      throw Error(where + " (" + view.name + "): " + e.what());
    } catch (const nlohmann::json::exception& e) {
      throw Error(where + " (" + view.name + "): " + e.what());
    }
    views.push_back(view);
  }
  return views;
}

void PlanOptions::Validate() const {
  CheckSite(site, "--site");
  if (!(spacing_m > 0.01 && spacing_m <= 100))
    throw Error("--spacing " + FormatNumber(spacing_m) + ": must be in 0.01..100 m");
  if (max_times < 1 || max_times > 100)
    throw Error("--max-times " + std::to_string(max_times) + ": must be 1..100");
  if (!(min_sun_cosine >= 0 && min_sun_cosine < 1))
    throw Error("the minimum sun cosine must be in 0..1");
}

PlanResult PlanCapture(const Mesh& mesh, const PlanOptions& options,
                       const std::function<void(const std::string&)>& log) {
  options.Validate();
  const auto start = std::chrono::steady_clock::now();
  PlanResult plan;
  const TimelapseTimes times = TimelapseTimesOf(options.site, options.schedule);
  plan.daylight = times.daylight;
  GridOptions grid_options;
  grid_options.spacing_m = options.spacing_m;
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, grid_options);
  if (grid.size() == 0)
    throw Error("the model has no surface to plan for (every triangle is degenerate)");
  const RayCaster caster(mesh);
  const int np = grid.size(), nt = static_cast<int>(times.times.size());
  plan.points = np;
  Log(log, std::to_string(np) + " grid points (spacing " + FormatNumber(options.spacing_m) +
               " m), " + std::to_string(nt) + " candidate times");

  // Faces: a block's triangles grouped by plane (normal within about 1 deg, offset within 1 cm).
  std::vector<int> face_of_triangle(mesh.triangles.size(), -1);
  std::vector<double> face_offset;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    if (grid.triangle_n[t] == 0) continue;
    const Eigen::Vector3d n = mesh.Normal(static_cast<int>(t));
    const double d = n.dot(mesh.vertices[mesh.triangles[t].x()]);
    const int block = mesh.triangle_block[t];
    int found = -1;
    for (size_t f = 0; f < plan.faces.size() && found < 0; ++f)
      if (plan.faces[f].block == block && plan.faces[f].normal.dot(n) > 0.99985 &&
          std::abs(face_offset[f] - d) < 0.01)
        found = static_cast<int>(f);
    if (found < 0) {
      PlanFace face;
      face.block = block;
      face.block_name = block >= 0 && block < static_cast<int>(mesh.block_names.size())
                            ? mesh.block_names[block]
                            : "block" + std::to_string(block);
      face.normal = n;
      face.facing = Facing(n);
      plan.faces.push_back(face);
      face_offset.push_back(d);
      found = static_cast<int>(plan.faces.size()) - 1;
    }
    face_of_triangle[t] = found;
    plan.faces[found].area_m2 += mesh.Area(static_cast<int>(t));
  }

  const std::vector<uint8_t> seen = SeenBy(grid, caster, options.views);

  // Each point's sun state at each candidate time (§4.1: shadowed means no direct sun).
  std::vector<uint8_t> state(static_cast<size_t>(np) * nt, kGrazing);
  for (int k = 0; k < nt; ++k) {
    const SunPosition sun = ComputeSunPosition(times.times[k], options.site);
    const Eigen::Vector3d s = sun.DirectionEnu();
    PlanTime pt;
    pt.time = times.times[k];
    pt.sun_azimuth_deg = sun.azimuth_deg;
    pt.sun_elevation_deg = sun.elevation_deg;
    tbb::parallel_for(0, np, [&](int i) {
      state[static_cast<size_t>(i) * nt + k] =
          SunState(grid.points[i], s, caster, options.min_sun_cosine);
    });
    for (int i = 0; i < np; ++i) {
      if (!seen[i]) continue;
      const uint8_t st = state[static_cast<size_t>(i) * nt + k];
      pt.sunlit += st == kSunlit;
      pt.shadowed += st == kShadowed;
    }
    plan.candidates.push_back(pt);
  }

  // Per point: ever sunlit, ever shadowed; the coverable ones are both and seen.
  std::vector<uint8_t> coverable(np, 0);
  for (int i = 0; i < np; ++i) {
    PlanFace& face = plan.faces[face_of_triangle[grid.points[i].triangle]];
    ++face.points;
    if (!seen[i]) {
      ++face.unseen;
      continue;
    }
    bool lit = false, dark = false;
    for (int k = 0; k < nt; ++k) {
      lit |= state[static_cast<size_t>(i) * nt + k] == kSunlit;
      dark |= state[static_cast<size_t>(i) * nt + k] == kShadowed;
    }
    if (!lit) ++face.never_sunlit;
    if (!dark) ++face.never_shadowed;
    if (lit && dark) {
      coverable[i] = 1;
      ++face.coverable;
      ++plan.coverable;
    }
  }

  // Greedy set cover over the pairs (point, sunlit) and (point, shadowed) of coverable points,
  // each pair weighted by 1 / its face's points, so that every face counts alike (a large plaza
  // does not outweigh a belfry wall).
  std::vector<double> weight(np);
  for (int i = 0; i < np; ++i)
    weight[i] = 1.0 / plan.faces[face_of_triangle[grid.points[i].triangle]].points;
  std::vector<uint8_t> have(np, 0);  // bit kSunlit, bit kShadowed
  std::vector<uint8_t> taken(nt, 0);
  int remaining = 2 * plan.coverable;
  for (int round = 1; round <= options.max_times && remaining > 0; ++round) {
    int best = -1, best_gain = 0;
    double best_weight = 0;
    for (int k = 0; k < nt; ++k) {
      if (taken[k]) continue;
      int gain = 0;
      double w = 0;
      for (int i = 0; i < np; ++i) {
        if (!coverable[i]) continue;
        const uint8_t st = state[static_cast<size_t>(i) * nt + k];
        if (st == kGrazing || (have[i] & st)) continue;
        ++gain;
        w += weight[i];
      }
      if (w > best_weight) best = k, best_gain = gain, best_weight = w;
    }
    if (best < 0) break;
    taken[best] = 1;
    for (int i = 0; i < np; ++i)
      if (coverable[i]) have[i] |= state[static_cast<size_t>(i) * nt + best];
    remaining -= best_gain;
    PlanTime pt = plan.candidates[best];
    pt.gain = best_gain;
    pt.face_gain = best_weight;
    pt.order = round;
    plan.chosen.push_back(pt);
  }
  std::sort(plan.chosen.begin(), plan.chosen.end(),
            [](const PlanTime& a, const PlanTime& b) { return a.time < b.time; });
  for (int i = 0; i < np; ++i)
    if (coverable[i] && have[i] == (kSunlit | kShadowed)) {
      ++plan.faces[face_of_triangle[grid.points[i].triangle]].covered;
      ++plan.covered;
    }
  plan.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return plan;
}

std::vector<SlotCoverage> SessionCoverage(const Session& session, double spacing_m,
                                          double min_sun_cosine) {
  const SessionInfo& info = session.info();
  if (info.model.empty())
    throw Error(session.dir().string() +
                ": the session has no building model (session.json "
                "\"model\")");
  const Mesh mesh = ReadObj(ResolveInside(session.dir(), info.model).string());
  GridOptions grid_options;
  grid_options.spacing_m = spacing_m;
  const SurfaceGrid grid = BuildSurfaceGrid(mesh, grid_options);
  if (grid.size() == 0) throw Error(info.model + ": the model has no surface (degenerate)");
  const RayCaster caster(mesh);
  std::map<int, UtcTime> slot_time;
  std::map<std::string, PlanView> views;  // the architecture frames' cameras, one per bracket
  bool every_frame_posed = true;
  for (const FrameRecord& f : session.frames()) {
    if (f.target != Target::kArchitecture) continue;
    if (!slot_time.count(f.slot) || f.utc < slot_time[f.slot]) slot_time[f.slot] = f.utc;
    if (f.intrinsics && f.pose)
      views[f.group] = {f.group, *f.intrinsics, *f.pose};
    else
      every_frame_posed = false;
  }
  std::vector<PlanView> cameras;
  if (every_frame_posed)
    for (const auto& [name, v] : views) cameras.push_back(v);
  const std::vector<uint8_t> seen = SeenBy(grid, caster, cameras);
  std::vector<SlotCoverage> out;
  std::vector<uint8_t> have(grid.size(), 0);
  for (const auto& [slot, utc] : slot_time) {
    const Eigen::Vector3d s = ComputeSunPosition(utc, info.site).DirectionEnu();
    SlotCoverage c;
    c.slot = slot;
    c.time = utc;
    c.points = grid.size();
    c.seen = static_cast<int>(std::count(seen.begin(), seen.end(), 1));
    std::vector<uint8_t> st(grid.size());
    tbb::parallel_for(0, grid.size(),
                      [&](int i) { st[i] = SunState(grid.points[i], s, caster, min_sun_cosine); });
    for (int i = 0; i < grid.size(); ++i) {
      if (!seen[i]) continue;
      have[i] |= st[i];
      c.sunlit += st[i] == kSunlit;
      c.covered += have[i] == (kSunlit | kShadowed);
    }
    out.push_back(c);
  }
  return out;
}

nlohmann::json PlanToJson(const PlanResult& plan, const PlanOptions& options) {
  const int tz = options.schedule.utc_offset_minutes;
  auto time_json = [&](const PlanTime& t) {
    return nlohmann::json{{"utc", t.time.Iso8601(0)},
                          {"local", FormatLocalClock(t.time, tz)},
                          {"sun_azimuth_deg", t.sun_azimuth_deg},
                          {"sun_elevation_deg", t.sun_elevation_deg},
                          {"sunlit_points", t.sunlit},
                          {"shadowed_points", t.shadowed},
                          {"gain_pairs", t.gain},
                          {"gain_faces", t.face_gain},
                          {"greedy_order", t.order}};
  };
  nlohmann::json j;
  j["site"] = {options.site.lat_deg, options.site.lon_deg, options.site.height_m};
  const std::string date = Formatted("%04d-%02d-%02d", options.schedule.date.year,
                                     options.schedule.date.month, options.schedule.date.day);
  j["date"] = date;
  j["utc_offset"] = FormatUtcOffset(tz);
  j["step_s"] = options.schedule.step_s;
  j["min_sun_elevation_deg"] = options.schedule.min_elevation_deg;
  j["sunrise"] = plan.daylight.sunrise.Iso8601(0);
  j["sunset"] = plan.daylight.sunset.Iso8601(0);
  j["points"] = plan.points;
  j["coverable_points"] = plan.coverable;
  j["covered_points"] = plan.covered;
  j["schedule"] = nlohmann::json::array();
  for (const PlanTime& t : plan.chosen) j["schedule"].push_back(time_json(t));
  j["faces"] = nlohmann::json::array();
  for (const PlanFace& f : plan.faces) {
    nlohmann::json lacks = nlohmann::json::array();
    if (f.never_sunlit) lacks.push_back("never sunlit");
    if (f.never_shadowed) lacks.push_back("never shadowed");
    if (f.unseen) lacks.push_back("unseen");
    j["faces"].push_back({{"block", f.block_name},
                          {"facing", f.facing},
                          {"normal", {f.normal.x(), f.normal.y(), f.normal.z()}},
                          {"area_m2", f.area_m2},
                          {"points", f.points},
                          {"unseen", f.unseen},
                          {"never_sunlit", f.never_sunlit},
                          {"never_shadowed", f.never_shadowed},
                          {"coverable", f.coverable},
                          {"covered", f.covered},
                          {"covered_percent", f.CoveredPercent()},
                          {"lacks", lacks}});
  }
  return j;
}

}  // namespace rouen
