#include "capture/sim/sensor.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"

namespace rouen {
namespace {

Image Flat(int w, int h, double value) {
  return Image(w, h, 3, PixelUnits::kRadiance, static_cast<float>(value));
}

TEST(SensorTest, CurveIsMonotoneFromBlackToWhiteAndNotAGamma) {
  const SimSensor s;
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(s.Curve(c, 0), 0, 1e-12);
    EXPECT_NEAR(s.Curve(c, 1), 255, 1e-9);
    double prev = -1;
    for (int i = 0; i <= 10000; ++i) {
      const double v = s.Curve(c, i / 10000.0);
      EXPECT_GT(v, prev);
      prev = v;
    }
    // A pure gamma has a constant log-log slope; this curve does not.
    auto slope = [&](double x) {
      return (std::log(s.Curve(c, 1.01 * x)) - std::log(s.Curve(c, x))) / std::log(1.01);
    };
    EXPECT_GT(std::abs(slope(0.003) - slope(0.3)), 0.1);
    // Inverse.
    for (double dn : {1.0, 17.5, 128.0, 254.0})
      EXPECT_NEAR(s.Curve(c, s.InverseCurve(c, dn)), dn, 1e-6);
  }
  // Channels differ slightly.
  EXPECT_NE(s.Curve(0, 0.1), s.Curve(1, 0.1));
}

// Capture quantises through thresholds found once; the reference is the curve at each noisy
// signal rounded to an integer. The curve rises strictly from one float signal to the next, so
// the two agree exactly, at every digital value (a ramp from black to beyond saturation).
TEST(SensorTest, QuantisationIsTheRoundedCurve) {
  const SimSensor s;
  Image ramp(1024, 64, 3, PixelUnits::kRadiance);
  for (int y = 0; y < ramp.height; ++y)
    for (int x = 0; x < ramp.width; ++x)
      for (int c = 0; c < 3; ++c)
        ramp.at(x, y, c) = static_cast<float>(300.0 * std::pow((x + 0.5) / ramp.width, 3.0) *
                                              (1 + 0.01 * y) * (1 + 0.1 * c));
  for (uint64_t seed : {1, 2, 3}) {
    const Image linear = s.CaptureLinear(ramp, 0.002, 1.0, 0.0, seed);
    const Image digital = s.Capture(ramp, 0.002, 1.0, 0.0, seed);
    std::vector<int> seen(256, 0);
    for (size_t i = 0; i < digital.data.size(); ++i) {
      const double expected = std::clamp(
          std::floor(s.Curve(static_cast<int>(i % 3), linear.data[i]) + 0.5), 0.0, 255.0);
      ASSERT_EQ(digital.data[i], expected) << "value " << i << ", signal " << linear.data[i];
      ++seen[static_cast<int>(expected)];
    }
    for (int dn = 0; dn < 256; ++dn) EXPECT_GT(seen[dn], 0) << "digital value " << dn;
  }
}

TEST(SensorTest, TrueLogExposureInvertsTheNoiseFreeResponse) {
  const SimSensor s;
  for (int c = 0; c < 3; ++c) {
    for (double dn : {3.0, 50.0, 128.0, 200.0, 250.0}) {
      EXPECT_NEAR(s.DigitalValue(c, std::exp(s.TrueLogExposure(c, dn))), dn, 1e-6);
    }
  }
  const ResponseCurve r = s.TrueResponse();
  EXPECT_TRUE(r.valid());
  for (int c = 0; c < 3; ++c) {
    for (int z = 1; z < 256; ++z) EXPECT_GT(r.g[c][z], r.g[c][z - 1]);
  }
}

TEST(SensorTest, SaturatesAt255AndAtTheFullWell) {
  const SimSensor s;
  const Image bright = Flat(16, 16, 1e4);
  const Image out = s.Capture(bright, 1.0 / 500, 1, 0, 3);
  EXPECT_EQ(out.units, PixelUnits::kDigital);
  for (float v : out.data) EXPECT_EQ(v, 255.0f);
  // With gain 16 the converter saturates at 1/16 of the full well: an exposure that fills
  // 1/8 of the well saturates.
  const double l = 0.125 / (s.Sensitivity() * 0.01);
  const Image g16 = s.Capture(Flat(16, 16, l), 0.01, 16, 0, 4);
  for (float v : g16.data) EXPECT_EQ(v, 255.0f);
  const Image g1 = s.Capture(Flat(16, 16, l), 0.01, 1, 0, 4);
  for (float v : g1.data) EXPECT_LT(v, 250.0f);
}

TEST(SensorTest, NoiseMatchesShotAndReadNoiseModel) {
  const SimSensor s;
  const int w = 200, h = 200;
  for (double gain : {1.0, 4.0}) {
    for (double x : {0.01, 0.05, 0.2}) {
      // Radiance giving a normalised level x at 1/100 s and this gain.
      const double l = x / (s.Sensitivity() * 0.01 * gain);
      const Image lin = s.CaptureLinear(Flat(w, h, l), 0.01, gain, 0, 11);
      double sum = 0, sum2 = 0;
      for (float v : lin.data) {
        sum += v;
        sum2 += double(v) * v;
      }
      const double n = lin.data.size();
      const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
      const double expected = s.LinearNoiseStd(x, gain);
      // Sample mean and standard deviation: tolerances of 5 standard errors.
      EXPECT_NEAR(mean, x, 5 * expected / std::sqrt(n) + 1e-6) << gain << " " << x;
      EXPECT_NEAR(sd, expected, 5 * expected / std::sqrt(2 * n)) << gain << " " << x;
    }
  }
}

TEST(SensorTest, DeterministicGivenSeed) {
  const SimSensor s;
  const Image r = Flat(32, 32, 10.0);
  const Image a = s.Capture(r, 1.0 / 250, 2, 0, 42), b = s.Capture(r, 1.0 / 250, 2, 0, 42);
  const Image c = s.Capture(r, 1.0 / 250, 2, 0, 43);
  EXPECT_EQ(a.data, b.data);
  EXPECT_NE(a.data, c.data);
  for (float v : a.data) EXPECT_EQ(v, std::round(v));
}

TEST(SensorTest, NdFilterAndExposureTradeOff) {
  // Density 1 transmits 1/10: the same as a 10x shorter exposure (noise-free mean).
  const SimSensor s;
  const Image r = Flat(100, 100, 20.0);
  const Image a = s.CaptureLinear(r, 0.01, 1, 1.0, 5), b = s.CaptureLinear(r, 0.001, 1, 0, 5);
  double ma = 0, mb = 0;
  for (size_t i = 0; i < a.data.size(); ++i) {
    ma += a.data[i];
    mb += b.data[i];
  }
  EXPECT_NEAR(ma / mb, 1.0, 0.01);
}

TEST(SensorTest, RejectsBadInput) {
  const SimSensor s;
  EXPECT_THROW(s.Capture(Flat(4, 4, 1), -1, 1, 0, 1), Error);
  EXPECT_THROW(s.Capture(Flat(4, 4, 1), 0.01, 0.5, 0, 1), Error);
  EXPECT_THROW(s.Capture(Flat(4, 4, 1), 0.01, 1, -1, 1), Error);
  EXPECT_THROW(s.Capture(Image(4, 4, 1, PixelUnits::kRadiance), 0.01, 1, 0, 1), Error);
  SensorParams p;
  p.full_well_e = 0;
  EXPECT_THROW(SimSensor{p}, Error);
}

}  // namespace
}  // namespace rouen
