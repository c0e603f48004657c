// rouen calib against OpenCV 4.6 (the peer) on the two real brackets of ../shared/data/hdr:
// response-curve time and stability, HDR merge throughput and agreement. main() prints a
// side-by-side table measured in this run, then runs the Google Benchmark timings.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/photo.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench/results.h"
#include "calib/hdr.h"
#include "calib/response.h"
#include "calib/test_util.h"
#include "core/image.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

using bench::Record;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (char& c : s)
    if (c == '-') c = '_';
  return s;
}

struct DataSet {
  std::string name;
  std::string key;  // in bench/results.json's figure names ("memorial")
  // One bracket of rouen frames (RGB, kDigital), held in the vector RecoverResponse takes so
  // the timed calls do not copy it (St Louis: 285 MB of frames).
  std::vector<Bracket> brackets;
  std::vector<CodeImage> codes;        // the same pixels as rouen 8-bit frames (RGB)
  std::vector<Bracket> code_brackets;  // one bracket of `codes`
  std::vector<cv::Mat> cv;             // the same pixels, 8-bit BGR
  std::vector<float> cv_times;         // seconds
  double input_mp = 0;                 // megapixels over all frames
};

// The bracket in `dir` (calib/test_util.h's loader, cropped by the given margins) and the
// same pixels as 8-bit BGR for OpenCV.
DataSet Load(const std::string& name, const fs::path& dir, int top, int bottom, int left,
             int right) {
  DataSet d;
  d.name = name;
  d.key = Lower(name);
  std::replace(d.key.begin(), d.key.end(), ' ', '_');
  d.brackets.push_back(testing::LoadBracket(dir, top, bottom, left, right));
  if (d.brackets[0].frames.empty()) {
    throw std::runtime_error("no frames listed in " + (dir / "exposures.txt").string());
  }
  for (size_t j = 0; j < d.brackets[0].frames.size(); ++j) {
    Image& f = d.brackets[0].frames[j];
    if (f.channels != 3 || f.units != PixelUnits::kDigital) {
      throw std::runtime_error(dir.string() + ": frame " + std::to_string(j) +
                               " is not 3-channel digital numbers");
    }
    cv::Mat mat(f.height, f.width, CV_8UC3);
    for (int y = 0; y < f.height; ++y) {
      for (int x = 0; x < f.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          mat.at<cv::Vec3b>(y, x)[2 - c] = static_cast<uint8_t>(std::lround(f.at(x, y, c)));
        }
      }
    }
    d.codes.push_back(ToCodes(f));
    d.input_mp += f.width * static_cast<double>(f.height) * 1e-6;
    d.cv.push_back(mat);
    d.cv_times.push_back(static_cast<float>(d.brackets[0].exposures[j]));
  }
  d.code_brackets.resize(1);
  d.code_brackets[0].codes = d.codes;
  d.code_brackets[0].exposures = d.brackets[0].exposures;
  return d;
}

// Median wall time of `runs` calls, seconds.
double Time(int runs, const std::function<void()>& f) {
  std::vector<double> t;
  for (int i = 0; i < runs; ++i) {
    const auto s = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - s).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

// OpenCV response (256x1 CV_32FC3, BGR, linear) as ln curves in RGB, pinned at z = 128.
ResponseCurve FromCv(const cv::Mat& r, int* non_finite) {
  ResponseCurve c;
  *non_finite = 0;
  for (int ch = 0; ch < 3; ++ch) {
    c.g[ch].resize(256);
    for (int z = 0; z < 256; ++z) {
      const double v = r.at<cv::Vec3f>(z, 0)[2 - ch];
      c.g[ch][z] = std::log(v);
      if (!std::isfinite(c.g[ch][z])) ++*non_finite;
    }
    const double pin = c.g[ch][128];
    for (double& v : c.g[ch]) v -= pin;
  }
  return c;
}

cv::Mat ToCv(const ResponseCurve& c) {
  cv::Mat r(256, 1, CV_32FC3);
  for (int z = 0; z < 256; ++z) {
    for (int ch = 0; ch < 3; ++ch) r.at<cv::Vec3f>(z, 0)[2 - ch] = std::exp(c.g[ch][z]);
  }
  return r;
}

// Largest |g1 - g2| over z = 20..235 and all channels (both pinned at g(128) = 0); NaN
// entries count as infinite.
double MaxDelta(const ResponseCurve& a, const ResponseCurve& b) {
  double m = 0;
  for (int c = 0; c < 3; ++c) {
    for (int z = 20; z <= 235; ++z) {
      const double d = std::abs(a.g[c][z] - b.g[c][z]);
      m = std::max(m, std::isfinite(d) ? d : INFINITY);
    }
  }
  return m;
}

bool Monotone(const ResponseCurve& a) {
  for (int c = 0; c < 3; ++c) {
    for (int z = 1; z < 256; ++z) {
      if (!(a.g[c][z] >= a.g[c][z - 1])) return false;
    }
  }
  return true;
}

// Pearson correlation of ln luminance (Rec. 709 weights) between a rouen RGB image and an
// OpenCV BGR CV_32FC3 image, over pixels where both are positive and finite.
double LogLumCorrelation(const Image& a, const cv::Mat& b, int64_t* used) {
  double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  int64_t n = 0;
  for (int y = 0; y < a.height; ++y) {
    for (int x = 0; x < a.width; ++x) {
      const cv::Vec3f p = b.at<cv::Vec3f>(y, x);
      const double la = 0.2126 * a.at(x, y, 0) + 0.7152 * a.at(x, y, 1) + 0.0722 * a.at(x, y, 2);
      const double lb = 0.2126 * p[2] + 0.7152 * p[1] + 0.0722 * p[0];
      if (!(la > 0 && lb > 0 && std::isfinite(la) && std::isfinite(lb))) continue;
      const double u = std::log(la), v = std::log(lb);
      sx += u, sy += v, sxx += u * u, syy += v * v, sxy += u * v;
      ++n;
    }
  }
  *used = n;
  const double cov = sxy / n - sx / n * sy / n;
  return cov / std::sqrt((sxx / n - sx / n * sx / n) * (syy / n - sy / n * sy / n));
}

std::vector<const Image*> Pointers(const Bracket& b) {
  std::vector<const Image*> p;
  for (const Image& f : b.frames) p.push_back(&f);
  return p;
}

std::vector<const CodeImage*> Pointers(const std::vector<CodeImage>& frames) {
  std::vector<const CodeImage*> p;
  for (const CodeImage& f : frames) p.push_back(&f);
  return p;
}

ResponseOptions Samples(int samples, ResponseMethod method = ResponseMethod::kDebevecMalik) {
  ResponseOptions o;
  o.method = method;
  o.samples_per_bracket = samples;
  // Robertson samples at least robertson_min_samples_per_bracket; double that too.
  o.robertson_min_samples_per_bracket = 10 * samples;
  return o;
}

std::vector<DataSet>* g_sets = nullptr;

void PrintTable(std::vector<DataSet>& sets) {
  for (DataSet& d : sets) {
    std::printf("\n== %s: %zu frames, %.2f input MP ==\n", d.name.c_str(), d.cv.size(), d.input_mp);
    // OpenCV curves.
    cv::Mat cv_dm70, cv_dm140, cv_rob;
    auto cal70 = cv::createCalibrateDebevec(70);
    auto cal140 = cv::createCalibrateDebevec(140);
    auto calr = cv::createCalibrateRobertson();
    const double t_cv_dm = Time(3, [&] { cal70->process(d.cv, cv_dm70, d.cv_times); });
    cal140->process(d.cv, cv_dm140, d.cv_times);
    const double t_cv_rob = Time(1, [&] { calr->process(d.cv, cv_rob, d.cv_times); });
    int nf70 = 0, nf140 = 0, nfr = 0;
    const ResponseCurve c70 = FromCv(cv_dm70, &nf70), c140 = FromCv(cv_dm140, &nf140);
    const ResponseCurve crob = FromCv(cv_rob, &nfr);
    std::printf("%-28s %10s %10s %12s %9s %10s\n", "response curve", "time ms", "x OpenCV",
                "stability", "monotone", "resid rms");
    std::printf("%-28s %10.1f %10s %12.3f %9s %10s   (non-finite entries: %d)\n",
                "OpenCV CalibrateDebevec 70", t_cv_dm * 1e3, "1.00", MaxDelta(c70, c140),
                Monotone(c70) && Monotone(c140) ? "yes" : "NO", "-", nf70 + nf140);
    std::printf("%-28s %10.1f %10s %12s %9s %10s   (non-finite entries: %d)\n",
                "OpenCV CalibrateRobertson", t_cv_rob * 1e3, "-", "n/a (all px)",
                Monotone(crob) ? "yes" : "NO", "-", nfr);
    ResponseCurve dm;
    for (ResponseMethod m : {ResponseMethod::kDebevecMalik, ResponseMethod::kRobertson,
                             ResponseMethod::kMitsunagaNayar}) {
      ResponseSummary s1;
      ResponseCurve c1, c2;
      try {
        // From the same 8-bit frames as OpenCV.
        const double t =
            Time(3, [&] { c1 = RecoverResponse(d.code_brackets, Samples(200, m), &s1); });
        c2 = RecoverResponse(d.code_brackets, Samples(400, m), nullptr);
        const std::string name = std::string("rouen ") + ResponseMethodName(m);
        const std::string key = "response." + d.key + "." + Lower(ResponseMethodName(m));
        Record(key + ".ms", t * 1e3, "ms");
        Record(key + ".x_opencv", t_cv_dm / t, "ratio",
               "OpenCV CalibrateDebevec(70), same 8-bit frames");
        std::printf("%-28s %10.1f %10.2f %12.3f %9s %10.3f", name.c_str(), t * 1e3, t_cv_dm / t,
                    MaxDelta(c1, c2), Monotone(c1) && Monotone(c2) ? "yes" : "NO", s1.residual_rms);
        if (m == ResponseMethod::kDebevecMalik) {
          dm = c1;
          std::printf("   (scan stride %d)\n", s1.scan_stride);
          // The same frames as float Images: the same curve, more memory to scan.
          ResponseCurve cf;
          const double tf = Time(3, [&] { cf = RecoverResponse(d.brackets, Samples(200, m)); });
          if (MaxDelta(cf, c1) != 0) {
            throw std::runtime_error(d.name + ": the curves of 8-bit and float frames differ");
          }
          Record(key + ".float_frames_ms", tf * 1e3, "ms");
          Record(key + ".x_opencv_float_frames", t_cv_dm / tf, "ratio",
                 "OpenCV CalibrateDebevec(70) (8-bit frames), rouen from float Images");
          std::printf("%-28s %10.1f %10.2f   (same curve as 8-bit)\n", "  from float frames",
                      tf * 1e3, t_cv_dm / tf);
        } else {
          std::printf("   (vs Debevec-Malik: %.3f; %s %d)\n", MaxDelta(c1, dm),
                      m == ResponseMethod::kRobertson ? "iterations" : "order",
                      m == ResponseMethod::kRobertson ? s1.iterations : s1.polynomial_order);
        }
      } catch (const std::exception& e) {
        std::printf("%-28s failed: %s\n", ResponseMethodName(m), e.what());
      }
    }
    std::printf(
        "  (x OpenCV = OpenCV CalibrateDebevec(70) time / rouen time; stability = max "
        "|delta ln g| over z=20..235, samples 200->400 for rouen (Robertson 2000->4000), "
        "70->140 for OpenCV; resid = common fit residual, ln; vs Debevec-Malik = max |delta "
        "ln g| over z=20..235)\n");

    // Merge with the same (rouen DM) curve: rouen from the same 8-bit frames as OpenCV
    // (CodeImage), and from the frames as float Images (what 16-bit files need).
    const cv::Mat resp = ToCv(dm);
    auto merge = cv::createMergeDebevec();
    cv::Mat cv_hdr;
    Image hdr;
    const auto ptrs = Pointers(d.brackets[0]);
    const auto codes = Pointers(d.codes);
    const std::vector<double>& x = d.brackets[0].exposures;
    const double t_cv = Time(5, [&] { merge->process(d.cv, cv_hdr, d.cv_times, resp); });
    const double t_new = Time(5, [&] {
      hdr = Image();
      MergeHdrInto(codes, x, dm, MergeOptions{}, &hdr);
    });
    Image reused;
    const double t_r = Time(5, [&] { MergeHdrInto(codes, x, dm, MergeOptions{}, &reused); });
    Image from_float;
    const double t_f = Time(5, [&] { MergeHdrInto(ptrs, x, dm, MergeOptions{}, &from_float); });
    if (from_float.data != reused.data) {
      throw std::runtime_error(d.name + ": the merge of 8-bit and float frames differ");
    }
    MergeOptions ghost;
    ghost.ghost_removal = true;
    MergeSummary gs;
    const double t_g = Time(3, [&] { MergeHdrInto(codes, x, dm, ghost, &reused, &gs); });
    int64_t used = 0;
    const double corr = LogLumCorrelation(hdr, cv_hdr, &used);
    std::printf("%-28s %10s %12s %10s\n", "HDR merge (same curve)", "time ms", "input MP/s",
                "x OpenCV");
    std::printf("%-28s %10.1f %12.1f %10s\n", "OpenCV MergeDebevec", t_cv * 1e3, d.input_mp / t_cv,
                "1.00");
    std::printf("%-28s %10.1f %12.1f %10.2f\n", "rouen 8-bit (new image)", t_new * 1e3,
                d.input_mp / t_new, t_cv / t_new);
    std::printf("%-28s %10.1f %12.1f %10.2f\n", "rouen 8-bit (reused image)", t_r * 1e3,
                d.input_mp / t_r, t_cv / t_r);
    std::printf("%-28s %10.1f %12.1f %10.2f   (same floats as 8-bit)\n",
                "rouen float frames (reused)", t_f * 1e3, d.input_mp / t_f, t_cv / t_f);
    std::printf("%-28s %10.1f %12.1f %10.2f   (%lld ghost pixels)\n", "rouen + ghost removal",
                t_g * 1e3, d.input_mp / t_g, t_cv / t_g, static_cast<long long>(gs.ghost_pixels));
    Record("merge." + d.key + ".opencv_ms", t_cv * 1e3, "ms");
    Record("merge." + d.key + ".ms", t_r * 1e3, "ms");
    Record("merge." + d.key + ".x_opencv", t_cv / t_r, "ratio",
           "OpenCV MergeDebevec, same 8-bit frames and curve (rouen into a reused image)");
    Record("merge." + d.key + ".x_opencv_new_image", t_cv / t_new, "ratio",
           "OpenCV MergeDebevec, same 8-bit frames and curve (rouen allocating its image)");
    Record("merge." + d.key + ".float_frames_ms", t_f * 1e3, "ms");
    Record("merge." + d.key + ".x_opencv_float_frames", t_cv / t_f, "ratio",
           "OpenCV MergeDebevec (8-bit frames), rouen from the same frames as float Images");
    Record("merge." + d.key + ".log_luminance_correlation", corr, "");
    std::printf("  log-luminance correlation rouen vs OpenCV: %.4f over %lld pixels\n", corr,
                static_cast<long long>(used));
  }
  std::fflush(stdout);
}

void BM_Response(benchmark::State& state, int set, ResponseMethod m) {
  const DataSet& d = (*g_sets)[set];
  for (auto _ : state) {
    benchmark::DoNotOptimize(RecoverResponse(d.code_brackets, Samples(200, m), nullptr));
  }
}

void BM_CvCalibrateDebevec(benchmark::State& state, int set) {
  const DataSet& d = (*g_sets)[set];
  auto cal = cv::createCalibrateDebevec(70);
  cv::Mat r;
  for (auto _ : state) cal->process(d.cv, r, d.cv_times);
}

void BM_CvCalibrateRobertson(benchmark::State& state, int set) {
  const DataSet& d = (*g_sets)[set];
  auto cal = cv::createCalibrateRobertson();
  cv::Mat r;
  for (auto _ : state) cal->process(d.cv, r, d.cv_times);
}

void BM_MergeHdr(benchmark::State& state, int set) {
  const DataSet& d = (*g_sets)[set];
  const ResponseCurve curve = RecoverResponse(d.brackets, ResponseOptions{}, nullptr);
  const auto codes = Pointers(d.codes);
  Image out;
  for (auto _ : state) {
    MergeHdrInto(codes, d.brackets[0].exposures, curve, MergeOptions{}, &out);
    benchmark::DoNotOptimize(out.data.data());
  }
  state.counters["input_MP/s"] =
      benchmark::Counter(d.input_mp * state.iterations(), benchmark::Counter::kIsRate);
}

void BM_CvMergeDebevec(benchmark::State& state, int set) {
  const DataSet& d = (*g_sets)[set];
  const cv::Mat resp = ToCv(RecoverResponse(d.brackets, ResponseOptions{}, nullptr));
  auto merge = cv::createMergeDebevec();
  cv::Mat out;
  for (auto _ : state) merge->process(d.cv, out, d.cv_times, resp);
  state.counters["input_MP/s"] =
      benchmark::Counter(d.input_mp * state.iterations(), benchmark::Counter::kIsRate);
}

}  // namespace
}  // namespace rouen

int main(int argc, char** argv) {
  using namespace rouen;
  const fs::path hdr = fs::path(ROUEN_SHARED_DIR) / "data" / "hdr";
  if (!fs::exists(hdr)) {
    std::printf("calib_bench: skipped, no data at %s\n", hdr.string().c_str());
    return 0;
  }
  std::vector<DataSet> sets;
  // Memorial: crop the blue registration padding as its README says.
  sets.push_back(Load("Memorial", hdr / "memorial", 30, 20, 3, 4));
  // St Louis arch: exposure times from exposures.txt, generated from the EXIF ExposureTime
  // (README table: 1/30, 1/4, 2.5, 15 s).
  sets.push_back(Load("St Louis arch", hdr / "stlouis_arch", 0, 0, 0, 0));
  g_sets = &sets;
  std::printf("OpenCV %s, %d threads\n", CV_VERSION, cv::getNumThreads());
  // ROUEN_CALIB_BENCH_NO_TABLE=1 runs only the Google Benchmark timings.
  if (!std::getenv("ROUEN_CALIB_BENCH_NO_TABLE")) PrintTable(sets);

  for (int s = 0; s < static_cast<int>(sets.size()); ++s) {
    const std::string n = s == 0 ? "Memorial" : "StLouis";
    benchmark::RegisterBenchmark(("Response/DebevecMalik/" + n).c_str(), BM_Response, s,
                                 ResponseMethod::kDebevecMalik)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("Response/Robertson/" + n).c_str(), BM_Response, s,
                                 ResponseMethod::kRobertson)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("Response/MitsunagaNayar/" + n).c_str(), BM_Response, s,
                                 ResponseMethod::kMitsunagaNayar)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("CvCalibrateDebevec/" + n).c_str(), BM_CvCalibrateDebevec, s)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("CvCalibrateRobertson/" + n).c_str(), BM_CvCalibrateRobertson, s)
        ->Unit(benchmark::kMillisecond)
        ->Iterations(1);
    // Both merges are multi-threaded: rates over wall time.
    benchmark::RegisterBenchmark(("MergeHdr/" + n).c_str(), BM_MergeHdr, s)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("CvMergeDebevec/" + n).c_str(), BM_CvMergeDebevec, s)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
  }
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
