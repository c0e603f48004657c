#include "calib/response.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "calib/test_util.h"
#include "core/error.h"

namespace rouen {
namespace {

using testing::MakeBracket;
using testing::RadianceField;
using testing::TrueLogExposure;
using testing::TrueSlope;

const std::vector<double>& kExposures = testing::kTwoStopExposures;
using testing::StrictlyIncreasing;

TEST(RecoverResponse, MatchesSyntheticCurveUpToConstant) {
  // Radiance spans e^-5..e^4; with exposures 1/64..16 every value is well exposed somewhere.
  const Image radiance = RadianceField(240, 160, -5.0, 4.0, 7);
  std::vector<Bracket> brackets = {MakeBracket(radiance, kExposures, 0.7, 11)};
  ResponseSummary summary;
  const ResponseCurve curve = RecoverResponse(brackets, ResponseOptions{}, &summary);
  EXPECT_GT(summary.samples_used, 150);
  EXPECT_GT(summary.residual_rms, 0);
  // Quantisation (uniform, +-0.5 DN) plus 0.7 DN Gaussian noise is ~0.76 DN per reading;
  // through the slope (0.017 ln/DN at z = 128, ~1.25/z in the toe) and the hat weight that is
  // 0.03-0.07 ln, depending on how many readings fall in the toe and shoulder; a curve off by
  // a few DN anywhere in the middle would exceed 0.1.
  EXPECT_LT(summary.residual_rms, 0.1);
  EXPECT_TRUE(curve.valid());
  for (int c = 0; c < 3; ++c) {
    ASSERT_EQ(curve.g[c].size(), 256u);
    EXPECT_TRUE(StrictlyIncreasing(curve.g[c])) << "channel " << c;
    EXPECT_DOUBLE_EQ(curve.g[c][128], 0.0);
    const double offset = TrueLogExposure(c, 128);
    for (int z = 20; z <= 235; ++z) {
      // Hundreds of readings per level average the noise away; what remains is the bias of
      // the smoothness term and of the discrete levels: allow 0.05 (1 DN of slope in the
      // middle, 3 DN at z = 128) or half a DN of the local slope where it is steeper.
      const double tol = std::max(0.05, 0.5 * TrueSlope(c, z));
      EXPECT_NEAR(curve.g[c][z], TrueLogExposure(c, z) - offset, tol)
          << "channel " << c << " z " << z;
    }
  }
}

TEST(RecoverResponse, PoolsBracketsOfDifferentScenes) {
  const Image dark = RadianceField(120, 90, -5.0, 0.0, 3);
  const Image bright = RadianceField(100, 80, -1.0, 4.0, 4);
  std::vector<Bracket> brackets = {MakeBracket(dark, {1.0 / 4, 1.0, 4.0, 16.0}, 0.5, 1),
                                   MakeBracket(bright, {1.0 / 64, 1.0 / 16, 1.0 / 4, 1.0}, 0.5, 2)};
  ResponseSummary summary;
  const ResponseCurve curve = RecoverResponse(brackets, ResponseOptions{}, &summary);
  EXPECT_GT(summary.samples_used, 300);
  for (int c = 0; c < 3; ++c) {
    EXPECT_TRUE(StrictlyIncreasing(curve.g[c]));
    const double offset = TrueLogExposure(c, 128);
    for (int z = 20; z <= 235; ++z) {
      EXPECT_NEAR(curve.g[c][z], TrueLogExposure(c, z) - offset,
                  std::max(0.05, 0.5 * TrueSlope(c, z)))
          << "channel " << c << " z " << z;
    }
  }
}

TEST(RecoverResponse, SingleChannelFramesGiveOneCurveForAllChannels) {
  const Image radiance = RadianceField(120, 90, -5.0, 4.0, 5);
  Bracket rgb = MakeBracket(radiance, kExposures, 0.5, 3);
  Bracket mono;
  mono.exposures = rgb.exposures;
  for (const Image& f : rgb.frames) {
    Image m(f.width, f.height, 1, PixelUnits::kDigital);
    for (int y = 0; y < f.height; ++y) {
      for (int x = 0; x < f.width; ++x) m.at(x, y) = f.at(x, y, 1);
    }
    mono.frames.push_back(m);
  }
  const ResponseCurve curve = RecoverResponse({mono}, ResponseOptions{}, nullptr);
  EXPECT_EQ(curve.g[0], curve.g[1]);
  EXPECT_EQ(curve.g[2], curve.g[1]);
  const double offset = TrueLogExposure(1, 128);
  for (int z = 20; z <= 235; ++z) {
    EXPECT_NEAR(curve.g[1][z], TrueLogExposure(1, z) - offset,
                std::max(0.05, 0.5 * TrueSlope(1, z)));
  }
}

TEST(RecoverResponse, MonotoneAndFiniteWhereLevelsNeverOccur) {
  // Radiance confined to a narrow range and two exposures: most levels never occur.
  const Image radiance = RadianceField(80, 60, -1.0, -0.5, 9);
  std::vector<Bracket> brackets = {MakeBracket(radiance, {1.0, 2.0}, 0.0, 1)};
  const ResponseCurve curve = RecoverResponse(brackets, ResponseOptions{}, nullptr);
  for (int c = 0; c < 3; ++c) {
    for (double v : curve.g[c]) ASSERT_TRUE(std::isfinite(v));
    EXPECT_TRUE(StrictlyIncreasing(curve.g[c]));
  }
}

TEST(RecoverResponse, MaskAndMisregisteredPixelsAreNotSampled) {
  const Image radiance = RadianceField(120, 90, -5.0, 4.0, 5);
  Bracket b = MakeBracket(radiance, kExposures, 0.5, 3);
  // Pure-blue padding in the shortest frame only (as in the Memorial set): its pixels darken
  // as exposure grows, so they must be rejected, or they would bend the blue curve.
  for (int y = 0; y < 30; ++y) {
    for (int x = 0; x < b.frames[0].width; ++x) {
      b.frames[0].at(x, y, 0) = 0;
      b.frames[0].at(x, y, 1) = 0;
      b.frames[0].at(x, y, 2) = 255;
    }
  }
  const ResponseCurve curve = RecoverResponse({b}, ResponseOptions{}, nullptr);
  const double offset = TrueLogExposure(2, 128);
  for (int z = 20; z <= 235; ++z) {
    EXPECT_NEAR(curve.g[2][z], TrueLogExposure(2, z) - offset,
                std::max(0.05, 0.5 * TrueSlope(2, z)));
  }
  // A mask that excludes everything leaves no samples.
  b.mask.assign(static_cast<size_t>(b.frames[0].width) * b.frames[0].height, 0);
  EXPECT_THROW(RecoverResponse({b}, ResponseOptions{}, nullptr), Error);
}

TEST(RecoverResponse, RejectsBadInput) {
  const Image radiance = RadianceField(40, 30, -3.0, 2.0, 1);
  const Bracket good = MakeBracket(radiance, {0.25, 1.0, 4.0}, 0.0, 1);
  const ResponseOptions opt;
  EXPECT_NO_THROW(RecoverResponse({good}, opt, nullptr));

  EXPECT_THROW(RecoverResponse({}, opt, nullptr), Error);
  Bracket b = good;
  b.exposures = {1.0, 1.0, 1.0};
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);  // all exposures equal
  b = good;
  b.frames.resize(1);
  b.exposures.resize(1);
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);  // fewer than 2 exposures
  b = good;
  b.exposures[1] = -1;
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b.exposures[1] = 0;
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b.exposures[1] = std::nan("");
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b.exposures[1] = INFINITY;
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b = good;
  b.exposures.pop_back();
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);  // count mismatch
  b = good;
  b.frames[2] = Image(41, 30, 3, PixelUnits::kDigital);
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);  // size mismatch
  b = good;
  b.frames[2] = Image(40, 30, 1, PixelUnits::kDigital);
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);  // channels within a bracket
  b = good;
  for (Image& f : b.frames) f = Image(40, 30, 1, PixelUnits::kDigital, 100.f);
  EXPECT_THROW(RecoverResponse({good, b}, opt, nullptr), Error);  // channels across brackets
  b = good;
  b.frames[0].units = PixelUnits::kRadiance;
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b = good;
  b.frames[1].at(3, 3, 1) = std::nan("");
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b = good;
  b.frames[1].at(3, 3, 1) = 300;
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);
  b = good;
  b.mask.assign(10, 1);
  EXPECT_THROW(RecoverResponse({b}, opt, nullptr), Error);  // mask size

  ResponseOptions bad;
  bad.samples_per_bracket = 0;
  EXPECT_THROW(bad.Validate(), Error);
  bad = ResponseOptions{};
  bad.lambda = -1;
  EXPECT_THROW(bad.Validate(), Error);
  bad.lambda = std::nan("");
  EXPECT_THROW(bad.Validate(), Error);
  bad = ResponseOptions{};
  bad.weight_epsilon = 0;
  EXPECT_THROW(bad.Validate(), Error);
  EXPECT_THROW(RecoverResponse({good}, bad, nullptr), Error);
}

// The AVX2 sample scan (used where the CPU has it) must choose the same samples as the
// portable one: the same curve to the bit and the same summary, for 3 and 1 channels, widths
// that leave a tail for the portable kernel, and with a mask.
TEST(RecoverResponse, SimdScanChoosesTheSameSamplesAsThePortableOne) {
  for (int w : {37, 64}) {
    const Image radiance = RadianceField(w, 50, -5.0, 4.0, 3 + w);
    Bracket b = MakeBracket(radiance, kExposures, 0.7, 13);
    for (int nc : {3, 1}) {
      if (nc == 1) {
        for (Image& f : b.frames) {
          Image g(f.width, f.height, 1, PixelUnits::kDigital);
          for (int y = 0; y < f.height; ++y)
            for (int x = 0; x < f.width; ++x) g.at(x, y) = f.at(x, y, 1);
          f = std::move(g);
        }
      }
      b.mask.assign(static_cast<size_t>(w) * 50, 1);
      for (size_t i = 0; i < b.mask.size(); i += 5) b.mask[i] = 0;
      ResponseOptions simd, portable;
      portable.use_simd = false;
      ResponseSummary ss, sp;
      const ResponseCurve a = RecoverResponse({b}, simd, &ss);
      const ResponseCurve c = RecoverResponse({b}, portable, &sp);
      for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(a.g[ch], c.g[ch]) << "w " << w << " nc " << nc;
      EXPECT_EQ(ss.samples_used, sp.samples_used);
      EXPECT_EQ(ss.residual_rms, sp.residual_rms);
    }
  }
}

// A bracket given as 8-bit codes gives the same curve, to the bit, as the same frames as
// float Images, for every method, both scan kernels, 3 and 1 channels, with a mask.
TEST(RecoverResponse, CodeFramesGiveTheSameCurveAsFloatFrames) {
  const Image radiance = RadianceField(45, 40, -5.0, 4.0, 19);
  Bracket frames = MakeBracket(radiance, kExposures, 0.7, 23);
  frames.mask.assign(45 * 40, 1);
  for (size_t i = 0; i < frames.mask.size(); i += 7) frames.mask[i] = 0;
  for (int nc : {3, 1}) {
    if (nc == 1) {
      for (Image& f : frames.frames) {
        Image g(f.width, f.height, 1, PixelUnits::kDigital);
        for (int y = 0; y < f.height; ++y)
          for (int x = 0; x < f.width; ++x) g.at(x, y) = f.at(x, y, 2);
        f = std::move(g);
      }
    }
    Bracket codes;
    for (const Image& f : frames.frames) codes.codes.push_back(ToCodes(f));
    codes.exposures = frames.exposures;
    codes.mask = frames.mask;
    for (ResponseMethod m : {ResponseMethod::kDebevecMalik, ResponseMethod::kRobertson,
                             ResponseMethod::kMitsunagaNayar}) {
      for (bool simd : {true, false}) {
        ResponseOptions o;
        o.method = m;
        o.use_simd = simd;
        ResponseSummary sf, sc;
        const ResponseCurve a = RecoverResponse({frames}, o, &sf);
        const ResponseCurve b = RecoverResponse({codes}, o, &sc);
        for (int c = 0; c < 3; ++c) {
          EXPECT_EQ(a.g[c], b.g[c]) << ResponseMethodName(m) << " nc " << nc << " simd " << simd;
        }
        EXPECT_EQ(sf.samples_used, sc.samples_used);
        EXPECT_EQ(sf.residual_rms, sc.residual_rms);
      }
    }
  }
}

TEST(RecoverResponse, CodeBracketsAreChecked) {
  const Image radiance = RadianceField(20, 16, -2.0, 2.0, 2);
  const Bracket frames = MakeBracket(radiance, kExposures, 0.0, 1);
  Bracket codes;
  for (const Image& f : frames.frames) codes.codes.push_back(ToCodes(f));
  codes.exposures = frames.exposures;
  EXPECT_NO_THROW(RecoverResponse({codes}, ResponseOptions{}, nullptr));
  Bracket both = codes;
  both.frames = frames.frames;
  EXPECT_THROW(RecoverResponse({both}, ResponseOptions{}, nullptr), Error);
  Bracket b = codes;
  b.codes[2].width = 19;
  EXPECT_THROW(RecoverResponse({b}, ResponseOptions{}, nullptr), Error);  // size
  b = codes;
  b.codes[1].data.pop_back();
  EXPECT_THROW(RecoverResponse({b}, ResponseOptions{}, nullptr), Error);  // buffer
  b = codes;
  b.codes.pop_back();
  EXPECT_THROW(RecoverResponse({b}, ResponseOptions{}, nullptr), Error);  // frames vs exposures
  b = codes;
  b.mask.assign(10, 1);
  EXPECT_THROW(RecoverResponse({b}, ResponseOptions{}, nullptr), Error);  // mask size
  // A code bracket pools with a float one.
  EXPECT_NO_THROW(RecoverResponse({codes, frames}, ResponseOptions{}, nullptr));
}

// A value outside 0..255 (or NaN) is named by frame and pixel, by both scan kernels, in the
// vector part of a row and in its tail.
TEST(RecoverResponse, BothScanKernelsNameTheFrameAndPixelOfABadValue) {
  const Image radiance = RadianceField(21, 12, -2.0, 2.0, 5);  // 16 points vectorised, 5 not
  const Bracket good = MakeBracket(radiance, kExposures, 0.0, 3);
  for (bool simd : {true, false}) {
    for (int x : {4, 19}) {
      for (float bad : {-1.f, 256.f, std::nanf("")}) {
        Bracket b = good;
        b.frames[3].at(x, 7, 2) = bad;
        ResponseOptions o;
        o.use_simd = simd;
        try {
          RecoverResponse({b}, o, nullptr);
          ADD_FAILURE() << "accepted " << bad << " at x " << x << " simd " << simd;
        } catch (const Error& e) {
          const std::string what = e.what();
          EXPECT_NE(what.find("frame 3: pixel (" + std::to_string(x) + ", 7)"), std::string::npos)
              << what;
        }
      }
    }
  }
}

// ---- Real data: Debevec's Memorial Church bracket. ----

using testing::LoadMemorial;
using testing::MemorialDir;

TEST(RecoverResponse, MemorialIsMonotoneAndStableUnderResampling) {
  if (!std::filesystem::exists(std::filesystem::path(ROUEN_SHARED_DIR) / "data")) {
    GTEST_SKIP() << "no shared data directory at " << ROUEN_SHARED_DIR << "/data";
  }
  const Bracket memorial = LoadMemorial();
  ASSERT_EQ(memorial.frames.size(), 16u);
  ResponseOptions opt;
  opt.samples_per_bracket = 200;
  ResponseSummary s1, s2;
  const ResponseCurve c1 = RecoverResponse({memorial}, opt, &s1);
  opt.samples_per_bracket = 400;
  opt.seed = 2;
  const ResponseCurve c2 = RecoverResponse({memorial}, opt, &s2);
  double max_diff = 0;
  for (int c = 0; c < 3; ++c) {
    for (double v : c1.g[c]) ASSERT_TRUE(std::isfinite(v));
    EXPECT_TRUE(StrictlyIncreasing(c1.g[c])) << "channel " << c;
    EXPECT_TRUE(StrictlyIncreasing(c2.g[c])) << "channel " << c;
    // Both are pinned at g(128) = 0, so they are already aligned there.
    for (int z = 20; z <= 235; ++z)
      max_diff = std::max(max_diff, std::abs(c1.g[c][z] - c2.g[c][z]));
    // One stop apart, 16 frames: the curve spans several stops between z = 20 and 235.
    EXPECT_GT(c1.g[c][235] - c1.g[c][20], std::log(8.0));
  }
  EXPECT_LE(max_diff, 0.1);
  RecordProperty("max_abs_delta_g", std::to_string(max_diff));
  RecordProperty("seconds_200", std::to_string(s1.seconds));
  RecordProperty("seconds_400", std::to_string(s2.seconds));
  RecordProperty("residual_rms", std::to_string(s1.residual_rms));
}

}  // namespace
}  // namespace rouen
