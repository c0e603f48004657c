// The persisted pipeline on the quick demo world (rigs/sim.toml): how long `rouen solve` takes
// per stage, how long an unchanged re-solve takes (it only hashes the inputs), and how long
// the scene takes to load and to render a 640x480 view from it, under measured and predicted
// lighting -- the costs a user pays per image once the scene is solved.
//
// Setup (not timed by Google Benchmark, printed): the quick simulated session is captured
// through the capture controller and solved into a scene, as `rouen demo --quick` does.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>

#include "capture/devices/devices.h"
#include "capture/rig.h"
#include "core/camera.h"
#include "core/session.h"
#include "pipeline/capture_session.h"
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
    std::printf("solve total %.2f s (%d grid points)\n", total, solved.solved.grid.size());
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
  for (auto _ : state) benchmark::DoNotOptimize(RenderScene(scene, request));
  state.counters["pixels_per_s"] =
      benchmark::Counter(640.0 * 480 * state.iterations(), benchmark::Counter::kIsRate);
}
void BM_Render640x480Measured(benchmark::State& state) { RenderView(state, false); }
void BM_Render640x480Predicted(benchmark::State& state) { RenderView(state, true); }
BENCHMARK(BM_Render640x480Measured)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Render640x480Predicted)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  rouen::Shared();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::error_code ec;
  std::filesystem::remove_all(rouen::Shared().dir, ec);
  return 0;
}
