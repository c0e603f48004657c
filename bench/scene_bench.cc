// The persisted pipeline on the quick demo world (rigs/sim.toml): how long `rouen solve` takes
// per stage, how long an unchanged re-solve takes (it only hashes the inputs), and how long
// the scene takes to load and to render a 640x480 view from it, under measured and predicted
// lighting -- the costs a user pays per image once the scene is solved.
//
// Setup (not timed by Google Benchmark, printed): the quick simulated session is captured
// through the capture controller and solved into a scene, as `rouen demo --quick` does.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>
#include <sys/resource.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/results.h"
#include "capture/devices/devices.h"
#include "capture/rig.h"
#include "core/camera.h"
#include "core/process.h"
#include "core/session.h"
#include "pipeline/capture_session.h"
#include "pipeline/render_scene.h"
#include "pipeline/scene.h"
#include "pipeline/solve_config.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

struct Fixture {
  fs::path dir;
  fs::path scene;
  fs::path session;
  PipelineOptions options;
};

Fixture& Shared() {
  static Fixture f = [] {
    Fixture x;
    x.dir = fs::temp_directory_path() / ("rouen_scene_bench_" + std::to_string(getpid()));
    fs::remove_all(x.dir);
    fs::create_directories(x.dir);
    RigConfig rig = LoadRig(fs::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml");
    rig.quick = true;
    RigDevices dev = OpenRig(rig);
    x.session = x.dir / "session";
    const auto t0 = std::chrono::steady_clock::now();
    CaptureToSession(rig, dev, x.session, CaptureSessionOptions{});
    const auto t1 = std::chrono::steady_clock::now();
    std::printf("capture (quick demo session): %.2f s\n",
                std::chrono::duration<double>(t1 - t0).count());
    x.options.work_dir = x.dir / "work";
    const Session session = Session::Load(x.session);
    x.options.config = SessionSolveConfig(session.info(), "session.json", true);
    if (rig.heldout_slot >= 0) x.options.exclude_albedo_slots = {rig.heldout_slot};
    x.scene = x.dir / "scene";
    const SceneSolve solved = SolveToScene(session, x.options, x.scene);
    double total = 0;
    for (const StageTime& t : solved.stages) {
      std::printf("solve stage %-44s %8.2f s\n", t.stage.c_str(), t.seconds);
      total += t.seconds;
    }
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    const double peak_mb = usage.ru_maxrss / 1024.0;  // capture and solve, in this process
    std::printf("solve total %.2f s (%d grid points), peak memory %.0f MB\n", total,
                solved.solved.grid.size(), peak_mb);
    for (const StageTime& t : solved.stages) {
      std::string key = t.stage;
      for (char& c : key) c = std::isalnum(static_cast<unsigned char>(c)) ? std::tolower(c) : '_';
      bench::Record("solve.quick_demo.stage." + key + "_s", t.seconds, "s");
    }
    bench::Record("solve.quick_demo.total_s", total, "s");
    bench::Record("solve.quick_demo.peak_memory_mb", peak_mb, "MB");
    bench::Record("solve.quick_demo.grid_points", solved.solved.grid.size(), "points");
    return x;
  }();
  return f;
}

// A second solve with nothing changed: the inputs are hashed and nothing else is done.
void BM_UnchangedSolve(benchmark::State& state) {
  Fixture& f = Shared();
  const Session session = Session::Load(f.session);
  for (auto _ : state) {
    const SceneSolve r = SolveToScene(session, f.options, f.scene);
    if (!r.up_to_date) state.SkipWithError("the scene was solved again");
  }
}
BENCHMARK(BM_UnchangedSolve)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_LoadScene(benchmark::State& state) {
  Fixture& f = Shared();
  for (auto _ : state) benchmark::DoNotOptimize(LoadScene(f.scene));
}
BENCHMARK(BM_LoadScene)->Unit(benchmark::kMillisecond)->UseRealTime();

// 640x480 from the first architecture view's position, measured (slot) or predicted (time).
void RenderView(benchmark::State& state, bool predicted) {
  Fixture& f = Shared();
  const LoadedScene scene = LoadScene(f.scene);
  const SceneView& view = FindView(scene, "");
  RenderRequest request;
  request.intrinsics = Intrinsics::PinholeFov(640, 480, 50);
  request.pose = view.pose;
  if (predicted)
    request.time = scene.scene.slots[1].utc.PlusSeconds(1800);
  else
    request.slot = 1;
  CheckRenderRequest(scene, request);
  for (auto _ : state) benchmark::DoNotOptimize(RenderSceneView(scene, request));
  state.counters["pixels_per_s"] =
      benchmark::Counter(640.0 * 480 * state.iterations(), benchmark::Counter::kIsRate);
}
void BM_Render640x480Measured(benchmark::State& state) { RenderView(state, false); }
void BM_Render640x480Predicted(benchmark::State& state) { RenderView(state, true); }
BENCHMARK(BM_Render640x480Measured)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Render640x480Predicted)->Unit(benchmark::kMillisecond)->UseRealTime();

// The peer of the render: Embree alone casting the same 640x480 primary rays at the scene's
// mesh (one rtcIntersect1 per pixel, rows in parallel with TBB like the renderer), nothing
// shaded. The ratio render / rays is what rouen's shading costs on top of finding the surface.
void BM_EmbreePrimaryRays640x480(benchmark::State& state) {
  Fixture& f = Shared();
  const LoadedScene scene = LoadScene(f.scene);
  const Mesh& mesh = scene.solved.mesh;
  RTCDevice device = rtcNewDevice(nullptr);
  RTCScene rtc = rtcNewScene(device);
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.vertices.size()));
  for (size_t i = 0; i < mesh.vertices.size(); ++i)
    for (int k = 0; k < 3; ++k) vb[3 * i + k] = static_cast<float>(mesh.vertices[i][k]);
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                            RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                            mesh.triangles.size()));
  for (size_t i = 0; i < mesh.triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) ib[3 * i + k] = static_cast<unsigned>(mesh.triangles[i][k]);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(rtc, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(rtc);
  const Intrinsics k = Intrinsics::PinholeFov(640, 480, 50);
  const Pose pose = FindView(scene, "").pose;
  std::vector<int> hit(640 * 480);
  for (auto _ : state) {
    tbb::parallel_for(0, 480, [&](int y) {
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      for (int x = 0; x < 640; ++x) {
        const Eigen::Vector3d d = pose.rotation * Unproject(k, Eigen::Vector2d(x + 0.5, y + 0.5));
        RTCRayHit rh{};
        rh.ray.org_x = static_cast<float>(pose.position.x());
        rh.ray.org_y = static_cast<float>(pose.position.y());
        rh.ray.org_z = static_cast<float>(pose.position.z());
        rh.ray.dir_x = static_cast<float>(d.x());
        rh.ray.dir_y = static_cast<float>(d.y());
        rh.ray.dir_z = static_cast<float>(d.z());
        rh.ray.tfar = std::numeric_limits<float>::infinity();
        rh.ray.mask = ~0u;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(rtc, &context, &rh);
        hit[y * 640 + x] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : rh.hit.primID;
      }
    });
    benchmark::DoNotOptimize(hit.data());
  }
  state.counters["rays_per_s"] =
      benchmark::Counter(640.0 * 480 * state.iterations(), benchmark::Counter::kIsRate);
  rtcReleaseScene(rtc);
  rtcReleaseDevice(device);
}
BENCHMARK(BM_EmbreePrimaryRays640x480)->Unit(benchmark::kMillisecond)->UseRealTime();

// End-to-end `rouen solve --quick` of the quick session as a user runs it (a process of its
// own: wall time and peak resident memory from wait4), then with the grid's spacing divided by
// sqrt(2) (about twice the grid points). How the solve grows with the surface it solves for.
struct CliSolve {
  double seconds = 0, peak_mb = 0;
  int64_t points = 0;
};

CliSolve SolveWithCli(const Fixture& f, const std::string& name, const std::string& toml) {
  const fs::path out = f.dir / name;
  std::vector<std::string> args = {ROUEN_BINARY, "solve", f.session.string(), "--quick",
                                   "--force",    "--out", out.string()};
  for (int s : f.options.exclude_albedo_slots) {
    args.push_back("--holdout-slot");
    args.push_back(std::to_string(s));
  }
  if (!toml.empty()) {
    const fs::path config = f.dir / (name + ".toml");
    std::ofstream(config) << toml;
    args.push_back("--config");
    args.push_back(config.string());
  }
  const auto t0 = std::chrono::steady_clock::now();
  rusage usage{};
  CliSolve r;
  if (RunProcess(args, f.dir / (name + ".log"), &usage) != 0) return r;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.peak_mb = usage.ru_maxrss / 1024.0;
  std::ifstream in(out / "scene.json");
  r.points = nlohmann::json::parse(in).value("points", int64_t{0});
  return r;
}

void ScalingStudy() {
  const Fixture& f = Shared();
  const nlohmann::json grid = nlohmann::json::parse(std::ifstream(f.scene / "scene.json"))["grid"];
  const double spacing = grid["spacing_m"].get<double>() / std::sqrt(2.0);
  std::string toml =
      "[grid]\nspacing_m = " + std::to_string(spacing) + "\n[grid.block_spacing_m]\n";
  for (const auto& [block, m] : grid["block_spacing_m"].items())
    toml += block + " = " + std::to_string(m.get<double>() / std::sqrt(2.0)) + "\n";
  const CliSolve base = SolveWithCli(f, "scene_cli", "");
  const CliSolve dense = SolveWithCli(f, "scene_cli_dense", toml);
  if (base.points == 0 || dense.points == 0) {
    std::printf("rouen solve (CLI): failed; is %s built?\n", ROUEN_BINARY);
    return;
  }
  std::printf(
      "rouen solve --quick (CLI, whole process): %lld points %.1f s %.0f MB; spacing / sqrt(2): "
      "%lld points (x%.2f) %.1f s (x%.2f) %.0f MB (x%.2f)\n",
      static_cast<long long>(base.points), base.seconds, base.peak_mb,
      static_cast<long long>(dense.points), static_cast<double>(dense.points) / base.points,
      dense.seconds, dense.seconds / base.seconds, dense.peak_mb, dense.peak_mb / base.peak_mb);
  bench::Record("solve.cli_quick.seconds", base.seconds, "s");
  bench::Record("solve.cli_quick.peak_memory_mb", base.peak_mb, "MB");
  bench::Record("solve.cli_quick.points", static_cast<double>(base.points), "points");
  bench::Record("solve.cli_quick_dense.points_ratio",
                static_cast<double>(dense.points) / base.points, "ratio");
  bench::Record("solve.cli_quick_dense.time_ratio", dense.seconds / base.seconds, "ratio",
                "the same solve with about twice the grid points");
  bench::Record("solve.cli_quick_dense.memory_ratio", dense.peak_mb / base.peak_mb, "ratio",
                "the same solve with about twice the grid points");
}

// The modelled ground ([ground] radius_m) around the quick session's building, as a user
// sets it: 30, 60 and 100 m against none, wall time and peak memory. The solve's peak is set
// by other stages until the ground's points outgrow them, so the memory a ground point costs
// is read at the largest radius: (peak - peak without ground) / points added, an upper bound.
void GroundApronStudy() {
  const Fixture& f = Shared();
  const CliSolve none = SolveWithCli(f, "scene_ground0", "");
  if (none.points == 0) {
    std::printf("rouen solve (CLI): failed; is %s built?\n", ROUEN_BINARY);
    return;
  }
  std::printf("rouen solve --quick, no modelled ground: %lld points %.1f s %.0f MB\n",
              static_cast<long long>(none.points), none.seconds, none.peak_mb);
  CliSolve widest;
  for (int radius : {30, 60, 100}) {
    const CliSolve r = SolveWithCli(f, "scene_ground" + std::to_string(radius),
                                    "[ground]\nradius_m = " + std::to_string(radius) + "\n");
    if (r.points <= none.points) {
      std::printf("rouen solve --quick, [ground] radius_m = %d: failed or no ground points\n",
                  radius);
      return;
    }
    std::printf("rouen solve --quick, [ground] radius_m = %d: %lld points %.1f s %.0f MB\n", radius,
                static_cast<long long>(r.points), r.seconds, r.peak_mb);
    const std::string key = "solve.ground_apron_" + std::to_string(radius) + "m";
    bench::Record(key + ".seconds", r.seconds, "s");
    bench::Record(key + ".peak_memory_mb", r.peak_mb, "MB");
    widest = r;
  }
  const double added = static_cast<double>(widest.points - none.points);
  const double bytes = std::max(0.0, widest.peak_mb - none.peak_mb) * 1024 * 1024 / added;
  std::printf("  at 100 m: %.0f points added, at most %.0f bytes of peak memory each\n", added,
              bytes);
  bench::Record("solve.ground_apron_100m.bytes_per_added_point", bytes, "bytes",
                "upper bound: peak memory over the ground's grid points, against no ground");
}

// The whole `rouen demo` as a user runs it (a process of its own): simulated capture, solve,
// validation and report, wall time and peak resident memory. The field's bar: 20 s.
void DemoStudy() {
  const Fixture& f = Shared();
  const fs::path out = f.dir / "demo_full";
  const auto t0 = std::chrono::steady_clock::now();
  rusage usage{};
  if (RunProcess({ROUEN_BINARY, "demo", "--out", out.string()}, f.dir / "demo_full.log", &usage) !=
      0) {
    std::printf("rouen demo (CLI): failed; see %s\n", (f.dir / "demo_full.log").c_str());
    return;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("rouen demo (CLI, whole process): %.1f s, %.0f MB\n", seconds,
              usage.ru_maxrss / 1024.0);
  bench::Record("demo.full.seconds", seconds, "s");
  bench::Record("demo.full.peak_memory_mb", usage.ru_maxrss / 1024.0, "MB");
}

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  rouen::Shared();
  rouen::ScalingStudy();
  rouen::GroundApronStudy();
  rouen::DemoStudy();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::error_code ec;
  std::filesystem::remove_all(rouen::Shared().dir, ec);
  return 0;
}
