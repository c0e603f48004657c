// MergeRadiance: merging frames that already hold radiance (imported RAW/EXR).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

#include "calib/hdr.h"
#include "core/error.h"

namespace rouen {
namespace {

std::vector<const Image*> Pointers(const std::vector<Image>& frames) {
  std::vector<const Image*> p;
  for (const Image& f : frames) p.push_back(&f);
  return p;
}

// Radiance L(x, y, c) over a 40 x 30 field: a ramp over 3 decades, and a 6 x 6 block
// (36 pixels, more than the 16 needed to call a level a clip) brighter than everything.
float TrueRadiance(int x, int y, int c) {
  if (x < 6 && y < 6) return 5000.f;
  return static_cast<float>(std::pow(10.0, (x + 40 * y) / 1200.0)) * (1.f + 0.1f * c);
}

// A frame behind a filter of transmission t (per channel) that clips (RAW white level) at
// `white`, in the frame's units (radiance x transmission).
Image Frame(const std::array<double, 3>& t, float white, int channels = 3) {
  Image f(40, 30, channels, PixelUnits::kRadiance);
  for (int y = 0; y < 30; ++y) {
    for (int x = 0; x < 40; ++x) {
      for (int c = 0; c < channels; ++c) {
        f.at(x, y, c) = std::min(white, static_cast<float>(TrueRadiance(x, y, c) * t[c]));
      }
    }
  }
  return f;
}

// Every pixel below the clip in some frame is the true radiance: the unclipped readings all
// equal L t_c (clipped readings weigh 0), whatever the weights. The bright block clips in
// every frame: it takes the least-weighted frame's reading (a lower bound) and is invalid.
TEST(MergeRadiance, RecoversRadianceThroughClipsAndFilters) {
  const std::vector<std::array<double, 3>> t = {{0.01, 0.012, 0.008}, {0.5, 0.5, 0.5}, {1, 1, 1}};
  const std::vector<double> exposures = {1.0, 0.25, 4.0};  // weights 0.01, 0.125, 4
  // White levels: frame 0 clips only the block; frames 1 and 2 clip the bright half of the
  // ramp too (L t_c above 3 and 4).
  const std::vector<float> white = {10.f, 3.f, 4.f};
  std::vector<Image> frames;
  for (size_t k = 0; k < t.size(); ++k) frames.push_back(Frame(t[k], white[k]));
  std::vector<uint8_t> valid;
  const Image out = MergeRadiance(Pointers(frames), exposures, t, RadianceMergeOptions{}, &valid);
  ASSERT_EQ(out.units, PixelUnits::kRadiance);
  ASSERT_EQ(valid.size(), 40u * 30u);
  for (int y = 0; y < 30; ++y) {
    for (int x = 0; x < 40; ++x) {
      const bool block = x < 6 && y < 6;
      EXPECT_EQ(valid[static_cast<size_t>(y) * 40 + x], block ? 0 : 1) << x << "," << y;
      for (int c = 0; c < 3; ++c) {
        // Frame 0 (least weight) reads the block as its white level.
        const double expected = block ? white[0] / t[0][c] : TrueRadiance(x, y, c);
        // Float readings divided by a double transmission: a few float ulps.
        EXPECT_NEAR(out.at(x, y, c), expected, 4e-7 * expected) << x << "," << y << "," << c;
      }
    }
  }
}

// Unclipped frames weigh exposure x mean transmission; non-finite readings are skipped; a
// value non-finite in every frame is 0 and invalid.
TEST(MergeRadiance, WeightsByExposureTimesTransmissionAndSkipsNonFinite) {
  const std::vector<std::array<double, 3>> t = {{1, 1, 1}, {0.2, 0.5, 0.8}};
  const std::vector<double> exposures = {2.0, -1.0};  // -1: unknown, counts as 1
  const double w0 = 2.0, w1 = 1.0 * 0.5;
  std::vector<Image> frames = {Frame(t[0], 1e9f), Frame(t[1], 1e9f)};
  // Disagreeing readings at (20, 10): frame 0 reads 3 x truth, frame 1 reads truth.
  for (int c = 0; c < 3; ++c) frames[0].at(20, 10, c) *= 3.f;
  frames[0].at(21, 10, 1) = NAN;
  frames[0].at(22, 10, 2) = INFINITY;
  frames[1].at(22, 10, 2) = NAN;
  std::vector<uint8_t> valid;
  const Image out = MergeRadiance(Pointers(frames), exposures, t, RadianceMergeOptions{}, &valid);
  for (int c = 0; c < 3; ++c) {
    const double l = TrueRadiance(20, 10, c);
    const double expected = (w0 * 3 * l + w1 * l) / (w0 + w1);
    EXPECT_NEAR(out.at(20, 10, c), expected, 1e-6 * expected);
  }
  EXPECT_NEAR(out.at(21, 10, 1), TrueRadiance(21, 10, 1), 1e-6 * TrueRadiance(21, 10, 1));
  EXPECT_EQ(valid[10 * 40 + 21], 1);
  EXPECT_EQ(out.at(22, 10, 2), 0.f);
  EXPECT_EQ(valid[10 * 40 + 22], 0);
  for (float v : out.data) EXPECT_TRUE(std::isfinite(v));
}

// One-channel frames divide by the first (R) transmission.
TEST(MergeRadiance, OneChannelFramesUseTheFirstTransmission) {
  const std::vector<std::array<double, 3>> t = {{0.25, 0.5, 0.75}};
  std::vector<Image> frames = {Frame(t[0], 1e9f, 1)};
  const Image out = MergeRadiance(Pointers(frames), {1.0}, t, RadianceMergeOptions{});
  ASSERT_EQ(out.channels, 1);
  EXPECT_NEAR(out.at(30, 20, 0), TrueRadiance(30, 20, 0), 1e-6 * TrueRadiance(30, 20, 0));
}

TEST(MergeRadiance, RejectsBadInput) {
  const std::array<double, 3> one = {1, 1, 1};
  const Image a = Frame(one, 1e9f), b = Frame(one, 1e9f);
  const RadianceMergeOptions o;
  EXPECT_NO_THROW(MergeRadiance({&a, &b}, {1.0, 2.0}, {one, one}, o));
  EXPECT_THROW(MergeRadiance({}, {}, {}, o), Error);
  EXPECT_THROW(MergeRadiance({&a, nullptr}, {1.0, 2.0}, {one, one}, o), Error);
  EXPECT_THROW(MergeRadiance({&a, &b}, {1.0}, {one, one}, o), Error);
  EXPECT_THROW(MergeRadiance({&a, &b}, {1.0, 2.0}, {one}, o), Error);
  Image digital = b;
  digital.units = PixelUnits::kDigital;
  EXPECT_THROW(MergeRadiance({&a, &digital}, {1.0, 2.0}, {one, one}, o), Error);
  const Image small(39, 30, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(MergeRadiance({&a, &small}, {1.0, 2.0}, {one, one}, o), Error);
  const Image two(40, 30, 2, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(MergeRadiance({&two}, {1.0}, {one}, o), Error);
  EXPECT_THROW(MergeRadiance({&a, &b}, {1.0, 2.0}, {one, {1, 0, 1}}, o), Error);
  EXPECT_THROW(MergeRadiance({&a, &b}, {1.0, 2.0}, {one, {1, NAN, 1}}, o), Error);
  RadianceMergeOptions bad;
  bad.clip_ramp = 0;
  EXPECT_THROW(MergeRadiance({&a}, {1.0}, {one}, bad), Error);
  bad = RadianceMergeOptions{};
  bad.clip_divisor = 0;
  EXPECT_THROW(bad.Validate(), Error);
  try {
    MergeRadiance({&a, &digital}, {1.0, 2.0}, {one, one}, o);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("frame 1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace rouen
