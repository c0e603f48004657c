#include "calib/hdr.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "calib/test_util.h"
#include "core/error.h"

namespace rouen {
namespace {

using testing::MakeBracket;
using testing::RadianceField;
using testing::TrueCurve;
using testing::TrueSlope;

std::vector<const Image*> Pointers(const Bracket& b) {
  std::vector<const Image*> p;
  for (const Image& f : b.frames) p.push_back(&f);
  return p;
}

TEST(MergeHdr, ReproducesTrueRadianceWithinNoise) {
  const Image radiance = RadianceField(200, 150, -5.0, 4.0, 21);
  const std::vector<double> exposures = {1.0 / 64, 1.0 / 16, 1.0 / 4, 1.0, 4.0, 16.0};
  const double noise_dn = 0.7;
  const Bracket b = MakeBracket(radiance, exposures, noise_dn, 5);
  MergeSummary summary;
  std::vector<uint8_t> mask;
  const Image hdr = MergeHdr(Pointers(b), exposures, TrueCurve(), MergeOptions{}, &summary, &mask);
  ASSERT_EQ(hdr.units, PixelUnits::kRadiance);
  ASSERT_EQ(hdr.width, 200);
  EXPECT_EQ(summary.pixels, 200 * 150);
  EXPECT_EQ(summary.saturated_pixels, 0);
  EXPECT_EQ(summary.dark_pixels, 0);
  double sum_sq = 0;
  int n = 0;
  for (int y = 0; y < hdr.height; ++y) {
    for (int x = 0; x < hdr.width; ++x) {
      EXPECT_EQ(mask[static_cast<size_t>(y) * hdr.width + x], 1);
      for (int c = 0; c < 3; ++c) {
        const double err = std::log(hdr.at(x, y, c) / radiance.at(x, y, c));
        ASSERT_TRUE(std::isfinite(err));
        // Worst case: a single usable frame near the toe, where the slope is 0.2 ln/DN:
        // noise of 3 sigma plus half a DN of quantisation there.
        EXPECT_LT(std::abs(err), (3 * noise_dn + 0.5) * 0.2);
        sum_sq += err * err;
        ++n;
      }
    }
  }
  // Typical: 2-3 frames well exposed at ~0.02-0.05 ln/DN, 0.76 DN per reading -> ~2%.
  const double rms = std::sqrt(sum_sq / n);
  EXPECT_LT(rms, 0.03);
}

TEST(MergeHdr, SaturatedAndDarkEverywhereArePinnedAndCounted) {
  const std::vector<double> exposures = {0.5, 1.0, 2.0};
  Bracket b;
  b.exposures = exposures;
  for (size_t j = 0; j < exposures.size(); ++j) {
    Image f(4, 1, 3, PixelUnits::kDigital, 128.f);
    for (int c = 0; c < 3; ++c) {
      f.at(0, 0, c) = 255;  // saturated in every frame
      f.at(1, 0, c) = 0;    // dark in every frame
    }
    f.at(2, 0, 1) = 255;  // one channel saturated only
    b.frames.push_back(f);
  }
  const ResponseCurve curve = TrueCurve();
  MergeSummary summary;
  std::vector<uint8_t> mask;
  const Image hdr = MergeHdr(Pointers(b), exposures, curve, MergeOptions{}, &summary, &mask);
  EXPECT_EQ(summary.saturated_pixels, 2);
  EXPECT_EQ(summary.dark_pixels, 1);
  EXPECT_EQ(mask, (std::vector<uint8_t>{0, 0, 0, 1}));
  for (int c = 0; c < 3; ++c) {
    // Lower bound from the shortest exposure at z = 255.
    EXPECT_NEAR(std::log(hdr.at(0, 0, c)), curve.g[c][255] - std::log(0.5), 1e-5);
    // Longest exposure's reading of z = 0.
    EXPECT_NEAR(std::log(hdr.at(1, 0, c)), curve.g[c][0] - std::log(2.0), 1e-5);
    // Ordinary pixel: 128 in every frame averages g(128) - ln X over the three exposures.
    EXPECT_NEAR(std::log(hdr.at(3, 0, c)), curve.g[c][128], 1e-5);
    for (int x = 0; x < 4; ++x) EXPECT_TRUE(std::isfinite(hdr.at(x, 0, c)));
  }
}

TEST(MergeHdr, FractionalDigitalNumbersInterpolateTheCurve) {
  // 16-bit sources arrive as fractional digital numbers.
  Image f(1, 1, 3, PixelUnits::kDigital, 100.25f);
  const ResponseCurve curve = TrueCurve();
  const Image hdr = MergeHdr({&f}, {1.0}, curve, MergeOptions{}, nullptr);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(std::log(hdr.at(0, 0, c)), 0.75 * curve.g[c][100] + 0.25 * curve.g[c][101], 1e-5);
  }
}

TEST(MergeHdr, RejectsBadInput) {
  const ResponseCurve curve = TrueCurve();
  Image a(8, 6, 3, PixelUnits::kDigital, 100.f), b(8, 6, 3, PixelUnits::kDigital, 120.f);
  EXPECT_NO_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, curve, MergeOptions{}, nullptr));
  Image wrong_size(8, 7, 3, PixelUnits::kDigital, 100.f);
  EXPECT_THROW(MergeHdr({&a, &wrong_size}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  Image wrong_channels(8, 6, 1, PixelUnits::kDigital, 100.f);
  EXPECT_THROW(MergeHdr({&a, &wrong_channels}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({}, {}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 0.0}, curve, MergeOptions{}, nullptr), Error);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, std::nan("")}, curve, MergeOptions{}, nullptr), Error);
  Image radiance = a;
  radiance.units = PixelUnits::kRadiance;
  EXPECT_THROW(MergeHdr({&a, &radiance}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  Image nan_pixel = a;
  nan_pixel.at(2, 2, 1) = std::nan("");
  EXPECT_THROW(MergeHdr({&a, &nan_pixel}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
  ResponseCurve broken = curve;
  broken.g[1][50] = std::nan("");
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, broken, MergeOptions{}, nullptr), Error);
  broken = curve;
  broken.g[2].resize(10);
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, broken, MergeOptions{}, nullptr), Error);
  MergeOptions bad;
  bad.dark_level = 200;
  bad.saturation_level = 100;
  EXPECT_THROW(MergeHdr({&a, &b}, {1.0, 2.0}, curve, bad, nullptr), Error);
  // Absurd exposures push the radiance out of float range: an error, not inf.
  EXPECT_THROW(MergeHdr({&a, &b}, {1e-60, 2e-60}, curve, MergeOptions{}, nullptr), Error);
}

// A bright square moves between frames: without ghost removal the merge mixes the square
// and the background where it passed; with it, each pixel follows the reference (median
// exposure) frame.
TEST(MergeHdr, GhostRemovalFollowsTheReferenceFrame) {
  const int w = 120, h = 90;
  const Image background = RadianceField(w, h, -2.0, 1.0, 31);
  const std::vector<double> exposures = {1.0 / 16, 1.0 / 4, 1.0, 4.0, 16.0};
  const double noise_dn = 0.7;
  // Frame j sees the square (radiance 3, ~2.5 stops above the background mean) at x0 = 10 +
  // 20 j; the reference is frame 2 (median exposure), square at x = 50..69.
  std::mt19937_64 rng(8);
  Bracket b;
  b.exposures = exposures;
  auto square_x = [](int j) { return 10 + 20 * j; };
  for (int j = 0; j < 5; ++j) {
    Image scene = background;
    for (int y = 30; y < 50; ++y) {
      for (int x = square_x(j); x < square_x(j) + 20; ++x) {
        for (int c = 0; c < 3; ++c) scene.at(x, y, c) = 3.0f;
      }
    }
    b.frames.push_back(testing::Expose(scene, exposures[j], noise_dn, &rng));
  }
  Image truth = background;  // the reference frame's scene
  for (int y = 30; y < 50; ++y) {
    for (int x = 50; x < 70; ++x) {
      for (int c = 0; c < 3; ++c) truth.at(x, y, c) = 3.0f;
    }
  }
  const auto ptrs = Pointers(b);
  MergeOptions plain;
  MergeOptions ghost;
  ghost.ghost_removal = true;
  Image merged_plain, merged_ghost;
  MergeSummary s_plain, s_ghost;
  std::vector<uint8_t> ghost_mask;
  MergeHdrInto(ptrs, exposures, TrueCurve(), plain, &merged_plain, &s_plain);
  MergeHdrInto(ptrs, exposures, TrueCurve(), ghost, &merged_ghost, &s_ghost, nullptr, &ghost_mask);
  EXPECT_EQ(s_plain.ghost_pixels, 0);
  // Worst error inside the square's paths (rows 30..49, x 10..109) and elsewhere.
  double worst_plain = 0, worst_ghost = 0, worst_static = 0;
  int64_t flagged_static = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const bool path = y >= 30 && y < 50 && x >= 10 && x < 110;
      flagged_static += !path && ghost_mask[static_cast<size_t>(y) * w + x];
      for (int c = 0; c < 3; ++c) {
        const double ep = std::abs(std::log(merged_plain.at(x, y, c) / truth.at(x, y, c)));
        const double eg = std::abs(std::log(merged_ghost.at(x, y, c) / truth.at(x, y, c)));
        ASSERT_TRUE(std::isfinite(eg));
        if (path) {
          worst_plain = std::max(worst_plain, ep);
          worst_ghost = std::max(worst_ghost, eg);
        } else {
          worst_static = std::max(worst_static, eg);
        }
      }
    }
  }
  // The square is ~1-4 stops from the background: mixing it in is off by well over 0.5 ln.
  EXPECT_GT(worst_plain, 0.5);
  // With ghost removal: the bound of ReproducesTrueRadianceWithinNoise (3 sigma + half a DN
  // at 0.2 ln/DN) everywhere, on the path as off it.
  const double bound = (3 * noise_dn + 0.5) * 0.2;
  EXPECT_LT(worst_ghost, bound);
  EXPECT_LT(worst_static, bound);
  // Most of the path is flagged: the other 4 frames' squares cover 80 x 20 px, and the
  // reference's square is missing from them there (where the background happens to be as
  // bright as the square, there is nothing to flag). Few static pixels are flagged (noise
  // beyond 3 DN).
  EXPECT_GE(s_ghost.ghost_pixels, 80 * 20 / 2);
  EXPECT_LT(flagged_static, (w * h - 100 * 20) / 100);
}

// A static scene bracketed widely: every pixel is clipped in the long frames and dark in the
// short ones. Those readings are bounds that agree with the reference, so ghost removal must
// flag (next to) nothing and leave the merge unchanged.
TEST(MergeHdr, GhostRemovalLeavesAStaticSceneAlone) {
  const Image radiance = RadianceField(96, 64, -3.0, 3.0, 17);
  std::vector<double> exposures;
  for (int j = -6; j <= 6; ++j) exposures.push_back(std::pow(2.0, j));
  const Bracket b = MakeBracket(radiance, exposures, 0.7, 5);
  int64_t clipped = 0, dark = 0;
  for (const Image& f : b.frames) {
    for (float z : f.data) {
      clipped += z >= 250;
      dark += z <= 5;
    }
  }
  // Many bounds of both kinds to compare (the film curve's toe makes dark readings rarer).
  ASSERT_GT(clipped, static_cast<int64_t>(radiance.data.size()));
  ASSERT_GT(dark, static_cast<int64_t>(radiance.data.size() / 10));
  MergeOptions ghost;
  ghost.ghost_removal = true;
  MergeSummary s;
  const Image with = MergeHdr(Pointers(b), exposures, TrueCurve(), ghost, &s);
  const Image without = MergeHdr(Pointers(b), exposures, TrueCurve(), MergeOptions{});
  // Noise beyond 3 DN through the curve's slope is rare: under 1% of pixels.
  EXPECT_LT(s.ghost_pixels, s.pixels / 100);
  double worst = 0;
  for (size_t i = 0; i < with.data.size(); ++i)
    worst = std::max(worst, std::abs(std::log(double(with.data[i]) / without.data[i])));
  EXPECT_LT(worst, (3 * 0.7 + 0.5) * 0.2);  // ReproducesTrueRadianceWithinNoise's bound
}

TEST(MergeHdr, IntoReusesTheOutputAndMatchesTheReturningForm) {
  const Image radiance = RadianceField(64, 48, -3.0, 2.0, 4);
  const std::vector<double> exposures = {1.0 / 8, 1.0, 8.0};
  const Bracket b = MakeBracket(radiance, exposures, 0.5, 3);
  const Image a = MergeHdr(Pointers(b), exposures, TrueCurve(), MergeOptions{});
  Image out(64, 48, 3, PixelUnits::kRadiance);
  const float* buffer = out.data.data();
  MergeHdrInto(Pointers(b), exposures, TrueCurve(), MergeOptions{}, &out);
  EXPECT_EQ(out.data.data(), buffer);  // reused, not reallocated
  EXPECT_EQ(out.data, a.data);
  Image wrong(3, 3, 1, PixelUnits::kDigital);  // resized to fit
  MergeHdrInto(Pointers(b), exposures, TrueCurve(), MergeOptions{}, &wrong);
  EXPECT_EQ(wrong.width, 64);
  EXPECT_EQ(wrong.units, PixelUnits::kRadiance);
  EXPECT_EQ(wrong.data, a.data);
  MergeOptions bad;
  bad.ghost_threshold = -1;
  EXPECT_THROW(bad.Validate(), Error);
  EXPECT_THROW(MergeHdrInto(Pointers(b), exposures, TrueCurve(), MergeOptions{}, nullptr), Error);
}

// The AVX2 kernel (used where the CPU has it) must give the same floats as the portable one
// the CI machine may run: fractional (16-bit) and integer values, 0 and 255 exactly, 1 and 3
// channels, widths that leave a tail for the portable kernel, ghost removal on and off.
TEST(MergeHdr, SimdKernelMatchesThePortableOne) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "this CPU has no AVX2";
#else
  GTEST_SKIP() << "no AVX2 kernel on this architecture";
#endif
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<float> u(0.f, 255.f);
  // 6 frames: the AVX2 kernel adds 4 per pass, then the rest one by one.
  const std::vector<double> exposures = {0.01, 0.03, 0.08, 0.2, 0.6, 5.0};
  for (int nc : {1, 3}) {
    for (int w : {37, 64}) {
      const int h = 9;
      std::vector<Image> frames;
      for (size_t j = 0; j < exposures.size(); ++j) {
        Image f(w, h, nc, PixelUnits::kDigital);
        for (size_t i = 0; i < f.data.size(); ++i) {
          const float z = u(rng);
          f.data[i] = i % 7 == 0 ? 0.f : i % 11 == 0 ? 255.f : i % 2 ? std::round(z) : z;
        }
        frames.push_back(std::move(f));
      }
      std::vector<const Image*> ptrs;
      for (const Image& f : frames) ptrs.push_back(&f);
      for (bool ghost : {false, true}) {
        MergeOptions simd, portable;
        simd.ghost_removal = portable.ghost_removal = ghost;
        portable.use_simd = false;
        MergeSummary ss, sp;
        std::vector<uint8_t> vs, vp;
        const Image a = MergeHdr(ptrs, exposures, TrueCurve(), simd, &ss, &vs);
        const Image b = MergeHdr(ptrs, exposures, TrueCurve(), portable, &sp, &vp);
        EXPECT_EQ(a.data, b.data) << "nc " << nc << " w " << w << " ghost " << ghost;
        EXPECT_EQ(vs, vp);
        EXPECT_EQ(ss.saturated_pixels, sp.saturated_pixels);
        EXPECT_EQ(ss.dark_pixels, sp.dark_pixels);
        EXPECT_EQ(ss.ghost_pixels, sp.ghost_pixels);
      }
    }
  }
}

// Values are accepted up to the rounding margin of the 1/16-DN levels, z in (-3/32, 255 +
// 1/32); beyond it, or NaN, both kernels name the frame, whether the value falls in the
// vector part of a row or its tail, in a frame merged in a pass of 4 frames or alone.
TEST(MergeHdr, BothKernelsRejectOutOfRangeValuesNamingTheFrame) {
  const ResponseCurve curve = TrueCurve();
  const int w = 13;  // 39 values a row: 24 through the vector loop, 15 in the tail
  const std::vector<double> exposures = {1, 2, 3, 4, 5};
  const Image good(w, 2, 3, PixelUnits::kDigital, 100.f);
  for (bool simd : {true, false}) {
    MergeOptions o;
    o.use_simd = simd;
    for (int j : {2, 4}) {
      for (int x : {2, 11}) {  // value 6 or 33 of the row
        std::vector<Image> frames(exposures.size(), good);
        std::vector<const Image*> ptrs;
        for (const Image& f : frames) ptrs.push_back(&f);
        for (float bad : {-0.1f, 255.04f, std::nanf(""), 1e10f, -1e10f}) {
          frames[j].at(x, 1, 0) = bad;
          try {
            MergeHdr(ptrs, exposures, curve, o, nullptr);
            ADD_FAILURE() << "accepted " << bad << " at x " << x << " simd " << simd;
          } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("frame " + std::to_string(j)), std::string::npos)
                << e.what();
          }
        }
        for (float edge : {-0.09f, 255.03f}) {
          frames[j].at(x, 1, 0) = edge;
          EXPECT_NO_THROW(MergeHdr(ptrs, exposures, curve, o, nullptr)) << edge;
        }
      }
    }
  }
}

}  // namespace
}  // namespace rouen

namespace rouen {
namespace {

// 8-bit frames merge to the same floats as Image frames holding the same numbers, for every
// code value in every frame (each row of frame j shifts the codes by a different amount, so
// all 256 codes meet every exposure), exposures far apart and one stop apart, 1 and 3
// channels, widths that leave a tail for the portable kernel, both kernels, ghost removal on
// and off; masks and counts too.
TEST(MergeHdr, CodeFramesMergeToTheSameFloatsAsFloatFrames) {
  const std::vector<std::vector<double>> brackets = {
      {1.0 / 1024, 1.0 / 64, 1.0 / 4, 1.0, 16.0, 250.0},
      {1.0 / 8, 1.0 / 4, 1.0 / 2, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0}};
  for (const std::vector<double>& exposures : brackets) {
    for (int nc : {1, 3}) {
      for (int w : {256, 301}) {
        const int h = 7;
        std::vector<Image> frames;
        std::vector<CodeImage> codes;
        for (size_t j = 0; j < exposures.size(); ++j) {
          Image f(w, h, nc, PixelUnits::kDigital);
          for (int y = 0; y < h; ++y) {
            for (int x = 0; x < w; ++x) {
              for (int c = 0; c < nc; ++c) {
                f.at(x, y, c) = static_cast<float>((x + 37 * y + 11 * c + 53 * j) % 256);
              }
            }
          }
          codes.push_back(ToCodes(f));
          frames.push_back(std::move(f));
        }
        std::vector<const Image*> fp;
        for (const Image& f : frames) fp.push_back(&f);
        std::vector<const CodeImage*> cp;
        for (const CodeImage& c : codes) cp.push_back(&c);
        for (bool simd : {true, false}) {
          for (bool ghost : {false, true}) {
            MergeOptions o;
            o.use_simd = simd;
            o.ghost_removal = ghost;
            Image a, b;
            MergeSummary sa, sb;
            std::vector<uint8_t> va, vb, ga, gb;
            MergeHdrInto(fp, exposures, TrueCurve(), o, &a, &sa, &va, &ga);
            MergeHdrInto(cp, exposures, TrueCurve(), o, &b, &sb, &vb, &gb);
            const std::string where = "frames " + std::to_string(exposures.size()) + " nc " +
                                      std::to_string(nc) + " w " + std::to_string(w) + " simd " +
                                      std::to_string(simd) + " ghost " + std::to_string(ghost);
            EXPECT_EQ(a.data, b.data) << where;
            EXPECT_EQ(b.units, PixelUnits::kRadiance);
            EXPECT_EQ(va, vb) << where;
            EXPECT_EQ(ga, gb) << where;
            EXPECT_EQ(sa.saturated_pixels, sb.saturated_pixels) << where;
            EXPECT_EQ(sa.dark_pixels, sb.dark_pixels) << where;
            EXPECT_EQ(sa.ghost_pixels, sb.ghost_pixels) << where;
          }
        }
      }
    }
  }
}

using Codes = std::vector<const CodeImage*>;

// ToCodes keeps whole numbers 0..255 and refuses anything else by pixel; the 8-bit merge
// checks its frames as the float one does.
TEST(MergeHdr, CodeFramesAreCheckedAndConvertedExactly) {
  Image f(4, 3, 3, PixelUnits::kDigital, 0.f);
  for (size_t i = 0; i < f.data.size(); ++i) f.data[i] = static_cast<float>(i * 7 % 256);
  f.data[5] = 255.f;
  const CodeImage c = ToCodes(f);
  ASSERT_EQ(c.width, 4);
  ASSERT_EQ(c.height, 3);
  ASSERT_EQ(c.channels, 3);
  ASSERT_EQ(c.data.size(), f.data.size());
  for (size_t i = 0; i < f.data.size(); ++i) EXPECT_EQ(c.data[i], f.data[i]);
  for (float bad : {0.5f, -1.f, 256.f, std::nanf("")}) {
    Image g = f;
    g.at(2, 1, 1) = bad;
    try {
      ToCodes(g);
      ADD_FAILURE() << "accepted " << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("pixel (2, 1) channel 1"), std::string::npos)
          << e.what();
    }
  }
  Image radiance = f;
  radiance.units = PixelUnits::kRadiance;
  EXPECT_THROW(ToCodes(radiance), Error);

  const ResponseCurve curve = TrueCurve();
  CodeImage a = c, b = c;
  Image out;
  EXPECT_NO_THROW(MergeHdrInto(Codes{&a, &b}, {1.0, 2.0}, curve, MergeOptions{}, &out));
  CodeImage small = c;
  small.width = 3;
  small.data.resize(3 * 3 * 3);
  EXPECT_THROW(MergeHdrInto(Codes{&a, &small}, {1.0, 2.0}, curve, MergeOptions{}, &out), Error);
  CodeImage short_buffer = c;
  short_buffer.data.pop_back();
  EXPECT_THROW(MergeHdrInto(Codes{&a, &short_buffer}, {1.0, 2.0}, curve, MergeOptions{}, &out),
               Error);
  EXPECT_THROW(MergeHdrInto(Codes{&a, &b}, {1.0, -2.0}, curve, MergeOptions{}, &out), Error);
  EXPECT_THROW(MergeHdrInto(Codes{&a, nullptr}, {1.0, 2.0}, curve, MergeOptions{}, &out), Error);
  EXPECT_THROW(MergeHdrInto(Codes{&a, &b}, {1.0, 2.0}, curve, MergeOptions{}, nullptr), Error);
}

// The merge's e^x: one frame, so ln L = w (g(z) - ln X) / w in float, recomputed here; the
// radiance is e^(that float) to within 2.4e-7 relative (the polynomial's bound, 2 float ulp)
// plus the final rounding, for ln L from -87 to 87 (exposures e^-80..e^80 against the
// curve's -5.3..+7.5 for z = 6..249), with both kernels.
TEST(MergeHdr, RadianceIsTheExponentialOfTheLogMeanWithinTwoUlp) {
  const ResponseCurve curve = TrueCurve();
  const int lo = 6, hi = 249;  // hat weight > 0
  CodeImage f;
  f.width = hi - lo + 1;
  f.height = 1;
  f.channels = 1;
  for (int z = lo; z <= hi; ++z) f.data.push_back(static_cast<uint8_t>(z));
  double worst = 0;
  for (bool simd : {true, false}) {
    MergeOptions o;
    o.use_simd = simd;
    for (double k = -80; k <= 80; k += 2.5) {
      const double x = std::exp(k);
      Image out;
      MergeHdrInto(Codes{&f}, {x}, curve, o, &out);
      const float lx = static_cast<float>(std::log(x));
      for (int z = lo; z <= hi; ++z) {
        const float w = static_cast<float>(std::min(z - 5, 250 - z));
        const float g = static_cast<float>(curve.g[1][z]);  // 1 channel: the green curve
        const float l = (0.f + w * (g - lx)) / w;
        if (std::abs(l) > 87) continue;
        const double expected = std::exp(static_cast<double>(l));
        const double rel = std::abs(out.data[z - lo] - expected) / expected;
        worst = std::max(worst, rel);
        EXPECT_LE(rel, 2.4e-7 + 6e-8) << "z " << z << " ln X " << k << " simd " << simd;
      }
    }
  }
  RecordProperty("worst_relative_error_x1e7", std::to_string(worst * 1e7));
}

}  // namespace
}  // namespace rouen
