// Costs of the Aravis driver: pixel decoding (CPU per frame) and Grab() through Aravis'
// in-process Fake camera (free-running), steady and right after an exposure change. A GigE
// Vision camera is measured when ROUEN_ARAVIS_DEVICE names one (e.g. start
// `arv-fake-gv-camera-0.8 -i 127.0.0.1` and set ROUEN_ARAVIS_DEVICE=Aravis-Fake-GV01).
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <memory>
#include <vector>

#include "capture/aravis/aravis_camera.h"
#include "capture/aravis/pixel_decode.h"

namespace rouen {
namespace {

void BM_Decode(benchmark::State& state, RawFormat format) {
  const int w = 1280, h = 960;
  std::vector<uint8_t> raw(static_cast<size_t>(w) * h * BytesPerPixel(format));
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = static_cast<uint8_t>(i * 31 + (i >> 7));
  for (auto _ : state) {
    Image im = DecodeFrame(raw.data(), raw.size(), w, h, format);
    benchmark::DoNotOptimize(im.data.data());
  }
  state.SetItemsProcessed(state.iterations() * w * h);
  state.SetLabel(RawFormatName(format) + " 1280x960");
}
BENCHMARK_CAPTURE(BM_Decode, mono8, RawFormat::kMono8)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, mono16, RawFormat::kMono16)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, bayer_rg8, RawFormat::kBayerRG8)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, rgb8, RawFormat::kRGB8)->Unit(benchmark::kMillisecond);

AravisOptions FakeOptions() {
  AravisOptions o;
  o.device_id = "Fake_1";
  o.enable_fake_interface = true;
  o.pixel_format = "Mono8";
  o.trigger = AravisTrigger::kFreeRun;
  o.frame_rate = 500;
  o.settle_frames = 1;
  o.width = 512;
  o.height = 512;
  return o;
}

// Time per Grab() minus the exposure = the driver's overhead per frame (plus waiting for the
// camera's next frame: at 500 fps up to 2 ms).
void BM_FakeGrab(benchmark::State& state) {
  const bool change = state.range(0) != 0;
  AravisCamera cam(FakeOptions());
  double e = cam.SetExposure(1e-4);
  for (auto _ : state) {
    if (change) e = cam.SetExposure(e == 1e-4 ? 2e-4 : 1e-4);
    CapturedFrame f = cam.Grab();
    benchmark::DoNotOptimize(f.image.data.data());
  }
  state.counters["fps"] = benchmark::Counter(state.iterations(), benchmark::Counter::kIsRate);
  state.counters["dropped"] = static_cast<double>(cam.DroppedFrames());
  state.SetLabel(change ? "512x512 Mono8, exposure changed before each grab"
                        : "512x512 Mono8, steady");
}
BENCHMARK(BM_FakeGrab)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_GvGrab(benchmark::State& state) {
  const char* id = std::getenv("ROUEN_ARAVIS_DEVICE");
  if (id == nullptr) {
    state.SkipWithError("set ROUEN_ARAVIS_DEVICE to a GigE Vision / USB3 Vision camera id");
    return;
  }
  AravisOptions o;
  o.device_id = id;
  o.trigger = state.range(0) ? AravisTrigger::kSoftware : AravisTrigger::kFreeRun;
  o.frame_rate = 100;
  std::unique_ptr<AravisCamera> cam;
  try {
    cam = std::make_unique<AravisCamera>(o);
  } catch (const Error& e) {
    state.SkipWithError(e.what());
    return;
  }
  const double exposure = cam->SetExposure(1e-3);
  cam->Grab();
  for (auto _ : state) {
    CapturedFrame f = cam->Grab();
    benchmark::DoNotOptimize(f.image.data.data());
  }
  state.counters["fps"] = benchmark::Counter(state.iterations(), benchmark::Counter::kIsRate);
  state.counters["exposure_ms"] = exposure * 1e3;
  state.counters["dropped"] = static_cast<double>(cam->DroppedFrames());
  state.SetLabel(state.range(0) ? "software trigger" : "free run");
}
BENCHMARK(BM_GvGrab)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace rouen

BENCHMARK_MAIN();
