// `rouen calib nd` and `rouen calib vignetting` run as a binary on synthetic images, and the
// pipeline's calibration stage on sessions with HDR frames, ND filters and vignetting.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "calib/nd.h"
#include "calib/test_util.h"
#include "calib/vignetting.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/session.h"
#include "core/time.h"
#include "pipeline/session_solve.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using rouen::cli_test::Q;
using rouen::cli_test::Result;
using rouen::cli_test::RunRouen;
using rouen::cli_test::TempDir;

void WriteText(const fs::path& p, const std::string& s) { std::ofstream(p) << s; }

const std::array<double, 3> kTrueDensity = {1.02, 0.95, 1.10};

Image Scaled(const Image& in, const std::array<double, 3>& t) {
  Image out = in;
  for (size_t i = 0; i < out.data.size(); ++i) out.data[i] *= static_cast<float>(t[i % 3]);
  return out;
}

std::array<double, 3> Transmission(const std::array<double, 3>& d) {
  return {std::pow(10.0, -d[0]), std::pow(10.0, -d[1]), std::pow(10.0, -d[2])};
}

// ---- rouen calib nd ----

TEST(CalibNdCliTest, RecoversDensityFromLdrPairsAndStoresIt) {
  const fs::path dir = TempDir("nd");
  const Image scene = testing::RadianceField(96, 64, -2, 1, 3);
  const Bracket open = testing::MakeBracket(scene, {0.25, 1}, 0.7, 1);
  const Bracket nd =
      testing::MakeBracket(Scaled(scene, Transmission(kTrueDensity)), {2.5, 10}, 0.7, 2);
  for (int k = 0; k < 2; ++k) {
    WriteImage((dir / ("open" + std::to_string(k) + ".png")).string(), open.frames[k],
               StoredType::kUint8);
    WriteImage((dir / ("nd" + std::to_string(k) + ".png")).string(), nd.frames[k],
               StoredType::kUint8);
  }
  WriteText(dir / "open.txt", "open0.png 0.25\nopen1.png 1\n");
  WriteText(dir / "nd.txt", "nd0.png 2.5\nnd1.png 10\n");
  WriteResponseCurve((dir / "response.json").string(), testing::TrueCurve());
  const Result r =
      RunRouen("calib nd --with " + Q(dir / "nd.txt") + " --without " + Q(dir / "open.txt") +
               " --response " + Q(dir / "response.json") + " --out " + Q(dir / "nd.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("sun_density = ["), std::string::npos) << r.out;
  const json j = json::parse(ReadFileToString(dir / "nd.json"));
  const NdCalibration cal = j.get<NdCalibration>();
  for (int c = 0; c < 3; ++c) {
    // See calib/nd_test.cc: ~3e-4 from noise, 2e-3 with the curve's interpolation; the PNG
    // round trip is lossless.
    EXPECT_NEAR(cal.channel[c].density, kTrueDensity[c], 2e-3) << c;
    std::printf("nd channel %d: density %.5f true %.5f (error %.1e, 95%% +-%.1e)\n", c,
                cal.channel[c].density, kTrueDensity[c], cal.channel[c].density - kTrueDensity[c],
                j["density_ci95_rgb"][c].get<double>());
  }
  // Swapped lists: brighter through the "filter" is refused.
  const Result sw =
      RunRouen("calib nd --with " + Q(dir / "open.txt") + " --without " + Q(dir / "nd.txt") +
               " --response " + Q(dir / "response.json") + " --out " + Q(dir / "bad.json"));
  EXPECT_EQ(sw.code, 1);
  EXPECT_NE(sw.out.find("swapped"), std::string::npos) << sw.out;
  EXPECT_FALSE(fs::exists(dir / "bad.json"));
  fs::remove_all(dir);
}

TEST(CalibNdCliTest, FloatImagesAndSessionUpdate) {
  const fs::path dir = TempDir("ndexr");
  const Image scene = testing::RadianceField(64, 48, -1, 1, 5);
  // Linear float frames: signal = radiance x seconds (x transmission).
  Image open = scene, nd = Scaled(scene, Transmission(kTrueDensity));
  for (float& v : open.data) v *= 0.5f;
  for (float& v : nd.data) v *= 4.f;
  WriteImage((dir / "open.exr").string(), open, StoredType::kFloat);
  WriteImage((dir / "nd.exr").string(), nd, StoredType::kFloat);
  WriteText(dir / "open.txt", "open.exr 0.5\n");
  WriteText(dir / "nd.txt", "nd.exr 4\n");
  // A session to store the result in.
  SessionInfo info;
  info.created_utc = "2024-06-21T07:00:00Z";
  info.nd_filters["sun"].density_rgb = {4.5, 4.5, 4.5};
  SessionWriter::Create(dir / "session", info);
  const Result r =
      RunRouen("calib nd --with " + Q(dir / "nd.txt") + " --without " + Q(dir / "open.txt") +
               " --session " + Q(dir / "session") + " --filter sun");
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(dir / "session");
  const std::array<double, 3>& d = s.info().nd_filters.at("sun").density_rgb;
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(d[c], kTrueDensity[c], 1e-4) << c;
  fs::remove_all(dir);
}

TEST(CalibNdCliTest, BadInputsFailClearly) {
  const fs::path dir = TempDir("ndbad");
  const Image scene = testing::RadianceField(32, 24, -1, 1, 5);
  WriteImage((dir / "a.exr").string(), scene, StoredType::kFloat);
  WriteImage((dir / "b.exr").string(), testing::RadianceField(30, 24, -1, 1, 5),
             StoredType::kFloat);
  WriteImage((dir / "c.png").string(), testing::Expose(scene, 1, 0, nullptr), StoredType::kUint8);
  WriteText(dir / "junk.png", "not an image");
  WriteText(dir / "a.txt", "a.exr 1\n");
  WriteText(dir / "b.txt", "b.exr 1\n");
  WriteText(dir / "c.txt", "c.png 1\n");
  WriteText(dir / "junk.txt", "junk.png 1\n");
  WriteText(dir / "zero.txt", "a.exr 0\n");
  WriteText(dir / "mixed.txt", "a.exr 1\nc.png 2\n");
  struct Case {
    std::string args, expect;
  } cases[] = {
      {"--with " + Q(dir / "junk.txt") + " --without " + Q(dir / "a.txt"), "junk.png"},
      {"--with " + Q(dir / "a.txt") + " --without " + Q(dir / "b.txt"), "size"},
      {"--with " + Q(dir / "c.txt") + " --without " + Q(dir / "c.txt"), "--response"},
      {"--with " + Q(dir / "zero.txt") + " --without " + Q(dir / "a.txt"), "positive"},
      {"--with " + Q(dir / "mixed.txt") + " --without " + Q(dir / "a.txt"), "mixes"},
      {"--with " + Q(dir / "missing.txt") + " --without " + Q(dir / "a.txt"), "missing.txt"},
  };
  for (const Case& c : cases) {
    const Result r = RunRouen("calib nd " + c.args + " --out " + Q(dir / "o.json"));
    EXPECT_EQ(r.code, 1) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find("rouen: error:"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(c.expect), std::string::npos) << c.expect << " not in: " << r.out;
    EXPECT_FALSE(fs::exists(dir / "o.json"));
  }
  const Result none =
      RunRouen("calib nd --with " + Q(dir / "a.txt") + " --without " + Q(dir / "a.txt"));
  EXPECT_EQ(none.code, 1);
  EXPECT_NE(none.out.find("--out"), std::string::npos) << none.out;
  const Result help = RunRouen("calib nd --help");
  EXPECT_EQ(help.code, 0);
  EXPECT_NE(help.out.find("Example:"), std::string::npos);
  EXPECT_NE(help.out.find("--without"), std::string::npos);
  fs::remove_all(dir);
}

// ---- rouen calib vignetting ----

VignettingModel TrueVignetting(int w, int h) {
  VignettingModel m;
  m.width = w;
  m.height = h;
  m.cx = w / 2.0;
  m.cy = h / 2.0;
  m.a = {-0.3, 0.05, -0.02};
  return m;
}

Image FlatField(const VignettingModel& m, double level, double sigma, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0, sigma);
  Image im(m.width, m.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < m.height; ++y)
    for (int x = 0; x < m.width; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(x, y, c) = static_cast<float>(level * m.Falloff(x + 0.5, y + 0.5) * (1 + n(rng)));
  return im;
}

TEST(CalibVignettingCliTest, FitsFlatsAndUpdatesTheLens) {
  const fs::path dir = TempDir("vig");
  const VignettingModel truth = TrueVignetting(160, 120);
  for (int k = 0; k < 3; ++k)
    WriteImage((dir / ("flat" + std::to_string(k) + ".exr")).string(),
               FlatField(truth, 2.0 + k, 0.01, k + 1), StoredType::kFloat);
  WriteText(dir / "flats.txt", "flat0.exr 1\nflat1.exr 1\n");
  json lens = Intrinsics::PinholeFov(1600, 1200, 60);
  WriteText(dir / "lens.json", lens.dump(2));
  const Result r =
      RunRouen("calib vignetting --flat " + Q(dir / "flats.txt") + " " + Q(dir / "flat2.exr") +
               " --out " + Q(dir / "v.json") + " --lens " + Q(dir / "lens.json"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("3 flat frames"), std::string::npos) << r.out;
  const VignettingModel fit = json::parse(ReadFileToString(dir / "v.json")).get<VignettingModel>();
  double worst = 0;
  for (int y = 0; y <= 120; y += 4)
    for (int x = 0; x <= 160; x += 4)
      worst = std::max(worst, std::abs(fit.Falloff(x, y) - truth.Falloff(x, y)));
  // 1% noise, 8 x 8 x 3 values per bin: 0.072% per bin; 4 bins' noise as in
  // calib/vignetting_test.cc.
  EXPECT_LT(worst, 4 * 0.01 / 13.86);
  std::printf("vignetting: largest model error %.2e (corner fall-off %.4f)\n", worst,
              truth.FalloffAtRadius(1));
  // The lens file keeps its intrinsics and gains the model.
  const json back = json::parse(ReadFileToString(dir / "lens.json"));
  EXPECT_EQ(back.get<Intrinsics>().width, 1600);
  EXPECT_NEAR(back.at("vignetting").get<VignettingModel>().a[0], fit.a[0], 1e-12);
  fs::remove_all(dir);
}

TEST(CalibVignettingCliTest, BadInputsFailClearly) {
  const fs::path dir = TempDir("vigbad");
  const VignettingModel truth = TrueVignetting(64, 48);
  WriteImage((dir / "f.exr").string(), FlatField(truth, 1, 0.01, 1), StoredType::kFloat);
  WriteImage((dir / "g.exr").string(), FlatField(TrueVignetting(48, 48), 1, 0.01, 1),
             StoredType::kFloat);
  WriteImage((dir / "d.png").string(), testing::Expose(FlatField(truth, 1, 0, 1), 1, 0, nullptr),
             StoredType::kUint8);
  WriteText(dir / "junk.exr", "nope");
  WriteText(dir / "lens.json", json(Intrinsics::PinholeFov(100, 100, 60)).dump());
  struct Case {
    std::string args, expect;
  } cases[] = {
      {Q(dir / "junk.exr"), "junk.exr"}, {Q(dir / "f.exr") + " " + Q(dir / "g.exr"), "differs"},
      {Q(dir / "d.png"), "--response"},  {Q(dir / "f.exr") + " --fit-centre", "--no-gradient"},
      {"", "no flat-field images"},      {Q(dir / "f.exr") + " --bin 40", "too small"},
  };
  for (const Case& c : cases) {
    const Result r = RunRouen("calib vignetting " + c.args + " --out " + Q(dir / "o.json"));
    EXPECT_EQ(r.code, 1) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find(c.expect), std::string::npos) << c.expect << " not in: " << r.out;
    EXPECT_FALSE(fs::exists(dir / "o.json"));
  }
  // A lens of another aspect ratio is refused and left as it was.
  const std::string before = ReadFileToString(dir / "lens.json");
  const Result r =
      RunRouen("calib vignetting " + Q(dir / "f.exr") + " --lens " + Q(dir / "lens.json"));
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("aspect"), std::string::npos) << r.out;
  EXPECT_EQ(ReadFileToString(dir / "lens.json"), before);
  const Result help = RunRouen("calib vignetting --help");
  EXPECT_EQ(help.code, 0);
  EXPECT_NE(help.out.find("Example:"), std::string::npos);
  fs::remove_all(dir);
}

// ---- the pipeline's calibration stage ----

FrameRecord Frame(const std::string& group, Target t, double seconds, double nd,
                  const Intrinsics& k, const std::string& utc) {
  FrameRecord f;
  f.device = "cam0";
  f.target = t;
  f.group = group;
  f.slot = 0;
  f.utc = ParseIso8601(utc);
  f.exposure_s = seconds;
  f.gain = 1;
  f.nd_density = nd;
  f.intrinsics = k;
  f.pose = Pose::Level(Eigen::Vector3d(0, 0, 1.5), 90, 10);
  return f;
}

// Largest relative difference over pixels where `valid` is set (all when empty).
double MaxRelError(const Image& got, const Image& want, const std::vector<uint8_t>& valid,
                   int channel) {
  double worst = 0;
  for (int y = 0; y < want.height; ++y)
    for (int x = 0; x < want.width; ++x) {
      if (!valid.empty() && !valid[static_cast<size_t>(y) * want.width + x]) continue;
      const double w = want.at(x, y, channel);
      worst = std::max(worst, std::abs(got.at(x, y, channel) - w) / w);
    }
  return worst;
}

TEST(CalibrateSessionTest, HdrOnlySessionFromImportedExrNeedsNoResponse) {
  const fs::path dir = TempDir("hdrsession");
  fs::create_directories(dir / "photos");
  const Image scene = testing::RadianceField(48, 32, -1, 3, 11);  // radiance e^-1 .. e^3
  // Two RAW-like frames, linear signal clipped at 1 and divided by the exposure (what `rouen
  // import` stores for RAW): the long one clips where radiance x 0.1 > 1.
  for (double t : {0.01, 0.1}) {
    Image f = scene;
    for (float& v : f.data) v = static_cast<float>(std::min(v * t, 1.0) / t);
    WriteImage((dir / "photos" / (t < 0.05 ? "short.exr" : "long.exr")).string(), f,
               StoredType::kFloat);
  }
  WriteText(dir / "list.txt",
            "short.exr 0.01 2024-06-21T09:00:00+02:00 group=a\n"
            "long.exr 0.1 2024-06-21T09:00:02+02:00 group=a\n");
  const Intrinsics k = Intrinsics::PinholeFov(48, 32, 60);
  const json pose = Pose::Level(Eigen::Vector3d(0, 0, 1.5), 90, 10);
  WriteText(dir / "poses.json", json{{"short.exr", {{"intrinsics", k}, {"pose", pose}}},
                                     {"long.exr", {{"intrinsics", k}, {"pose", pose}}}}
                                    .dump());
  const Result r = RunRouen("import --photos " + Q(dir / "photos") + " --list " +
                            Q(dir / "list.txt") + " --poses " + Q(dir / "poses.json") +
                            " --site 48.8566,2.3522,35 --out " + Q(dir / "session"));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(dir / "session");
  ASSERT_EQ(s.frames().size(), 2u);
  ASSERT_TRUE(s.frames()[0].hdr);
  PipelineOptions po;
  po.work_dir = dir / "work";
  const CalibResult cal = CalibrateSession(s, po);
  EXPECT_FALSE(cal.response.valid());
  EXPECT_FALSE(fs::exists(dir / "work" / "calib" / "response.json"));
  ASSERT_EQ(cal.groups.size(), 1u);
  const HdrGroup& g = cal.groups.begin()->second;
  EXPECT_EQ(g.radiance.units, PixelUnits::kRadiance);
  // Frames are stored as half floats (relative precision 2^-11): the merge reproduces the
  // scene within 1e-3, including where the long frame clipped (from the short one alone).
  std::vector<uint8_t> all;
  for (int c = 0; c < 3; ++c) EXPECT_LT(MaxRelError(g.radiance, scene, all, c), 1e-3) << c;
  int clipped = 0;
  for (size_t i = 0; i < scene.data.size(); ++i) clipped += scene.data[i] * 0.1 > 1;
  EXPECT_GT(clipped, 100);  // the clipped region was exercised
  for (uint8_t v : g.valid) EXPECT_EQ(v, 1);
  // The calibration is read back while its inputs are the same, and made again when a merge
  // option it was made with changes ([merge] in the solve's options).
  auto read_back = [](const CalibResult& c) {
    return std::any_of(c.stages.begin(), c.stages.end(),
                       [](const StageTime& t) { return t.stage == "calibration read back"; });
  };
  EXPECT_FALSE(read_back(cal));
  EXPECT_TRUE(read_back(CalibrateSession(s, po)));
  po.config.radiance_merge.clip_ramp = 0.05;
  EXPECT_FALSE(read_back(CalibrateSession(s, po)));
  EXPECT_TRUE(read_back(CalibrateSession(s, po)));
  fs::remove_all(dir);
}

TEST(CalibrateSessionTest, MixedLdrAndHdrBracketsAndPerChannelNdAndVignetting) {
  const fs::path dir = TempDir("mixed");
  const int w = 64, h = 48;
  const Intrinsics k = Intrinsics::PinholeFov(w, h, 60);
  const Image scene = testing::RadianceField(w, h, -2, 1, 21);
  VignettingModel vig = TrueVignetting(w, h);
  Image vignetted = scene;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) vignetted.at(x, y, c) *= vig.Falloff(x + 0.5, y + 0.5);
  SessionInfo info;
  info.created_utc = "2024-06-21T07:00:00Z";
  info.nd_filters["sun"].density_rgb = {kTrueDensity[0], kTrueDensity[1], kTrueDensity[2]};
  info.vignetting["cam0"] = vig;
  {
    SessionWriter wr = SessionWriter::Create(dir / "session", info);
    // LDR architecture bracket (response recovered from it), LDR sun bracket behind the
    // per-channel filter, an HDR landscape frame.
    std::mt19937_64 rng(5);
    for (double t : {0.25, 1.0, 4.0})
      wr.Append(
          Frame("slot0/architecture/view0", Target::kArchitecture, t, 0, k, "2024-06-21T07:00:00Z"),
          testing::Expose(vignetted, t, 0.5, &rng));
    const double mean_d = (kTrueDensity[0] + kTrueDensity[1] + kTrueDensity[2]) / 3;
    const Image behind = Scaled(vignetted, Transmission(kTrueDensity));
    for (double t : {4.0, 16.0})
      wr.Append(Frame("slot0/sun/view0", Target::kSun, t, mean_d, k, "2024-06-21T07:00:05Z"),
                testing::Expose(behind, t, 0.5, &rng));
    FrameRecord land =
        Frame("slot0/landscape/view0", Target::kLandscape, 0, 0, k, "2024-06-21T07:00:09Z");
    land.hdr = true;
    wr.Append(land, vignetted);
  }
  const Session s = Session::Load(dir / "session");
  PipelineOptions po;
  po.work_dir = dir / "work";
  const CalibResult cal = CalibrateSession(s, po);
  ASSERT_TRUE(cal.response.valid());
  EXPECT_TRUE(fs::exists(dir / "work" / "calib" / "response.json"));
  ASSERT_EQ(cal.groups.size(), 3u);
  // HDR landscape: the vignetting divided out, exact up to half-float storage.
  const HdrGroup& land = cal.groups.at("slot0/landscape/view0");
  for (int c = 0; c < 3; ++c) EXPECT_LT(MaxRelError(land.radiance, scene, {}, c), 2e-3) << c;
  // LDR brackets are in the recovered curve's scale (pinned at g(128) = 0): compare the sun
  // bracket with the architecture bracket of the same scene, channel by channel. With the
  // per-channel filter applied they agree; a scalar filter would leave 10^(d_c - mean) =
  // 0.83..1.24 between them.
  const HdrGroup& arch = cal.groups.at("slot0/architecture/view0");
  const HdrGroup& sun = cal.groups.at("slot0/sun/view0");
  for (int c = 0; c < 3; ++c) {
    std::vector<double> ratios;
    for (int i = 0; i < w * h; ++i)
      if (arch.valid[i] && sun.valid[i])
        ratios.push_back(sun.radiance.data[i * 3 + c] / arch.radiance.data[i * 3 + c]);
    ASSERT_GT(ratios.size(), 1000u);
    std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
    // Both brackets see the same radiance through the same curve: the median ratio is 1 up
    // to the noise (0.5 DN, medians over > 1000 pixels) and the curve's error between the
    // levels the two brackets use (a few per cent at most).
    EXPECT_NEAR(ratios[ratios.size() / 2], 1.0, 0.03) << c;
  }
  // Vignetting removed from the LDR merge too: architecture / truth is flat (the curve's
  // scale is one constant): compare corners with the centre.
  auto ratio_at = [&](int x, int y) {
    double sum = 0;
    int n = 0;
    for (int j = y; j < y + 6; ++j)
      for (int i = x; i < x + 6; ++i)
        if (arch.valid[j * w + i]) {
          sum += arch.radiance.at(i, j, 1) / scene.at(i, j, 1);
          ++n;
        }
    return sum / std::max(n, 1);
  };
  const double centre = ratio_at(w / 2 - 3, h / 2 - 3);
  // Fall-off in the corner is ~27%; after removal the corner matches the centre to a few %.
  EXPECT_NEAR(ratio_at(0, 0) / centre, 1.0, 0.05);
  EXPECT_NEAR(ratio_at(w - 6, h - 6) / centre, 1.0, 0.05);
  fs::remove_all(dir);
}

TEST(CalibrateSessionTest, MixingLdrAndHdrInOneBracketIsAnError) {
  const fs::path dir = TempDir("mixbad");
  const Intrinsics k = Intrinsics::PinholeFov(16, 12, 60);
  const Image scene = testing::RadianceField(16, 12, -1, 1, 1);
  SessionInfo info;
  info.created_utc = "2024-06-21T07:00:00Z";
  {
    SessionWriter wr = SessionWriter::Create(dir / "session", info);
    std::mt19937_64 rng(1);
    wr.Append(
        Frame("slot0/architecture/view0", Target::kArchitecture, 1, 0, k, "2024-06-21T07:00:00Z"),
        testing::Expose(scene, 1, 0, &rng));
    FrameRecord f =
        Frame("slot0/architecture/view0", Target::kArchitecture, 1, 0, k, "2024-06-21T07:00:01Z");
    f.hdr = true;
    wr.Append(f, scene);
  }
  PipelineOptions po;
  po.work_dir = dir / "work";
  try {
    CalibrateSession(Session::Load(dir / "session"), po);
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mixes LDR and HDR"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
