#include "render/metrics.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"

namespace rouen {
namespace {

Image Ramp(int w, int h) {
  Image img(w, h, 3, PixelUnits::kRadiance);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = 1.0f + x + 2 * y + c;
    }
  }
  return img;
}

Image Scaled(Image im, float s) {
  for (float& v : im.data) v *= s;
  return im;
}

TEST(MetricsTest, IdenticalScaledAndMasked) {
  const Image t = Ramp(20, 10);
  RenderMetrics m = CompareRadiance(t, t, {});
  EXPECT_EQ(m.pixels, 200);
  EXPECT_EQ(m.rel_rmse, 0);
  EXPECT_EQ(m.psnr_db, 99.0);
  EXPECT_EQ(m.median_rel_error, 0);
  EXPECT_DOUBLE_EQ(m.mean_ratio, 1.0);
  // R - T = 0.1 T everywhere: the relative RMSE and every relative error are 0.1 (the ramp's
  // smallest value, 1, is far above the floor of 1% of its 99th percentile).
  m = CompareRadiance(Scaled(t, 1.1f), t, {});
  EXPECT_NEAR(m.rel_rmse, 0.1, 1e-6);
  EXPECT_NEAR(m.median_rel_error, 0.1, 1e-6);
  EXPECT_NEAR(m.mean_ratio, 1.1, 1e-6);
  EXPECT_LT(m.psnr_db, 40);
  // The mask limits the comparison: corrupt unmasked pixels only.
  std::vector<uint8_t> mask(200, 0);
  for (int i = 0; i < 50; ++i) mask[i] = 1;
  Image c = t;
  for (size_t i = 50 * 3; i < c.data.size(); ++i) c.data[i] = 0;
  m = CompareRadiance(c, t, mask);
  EXPECT_EQ(m.pixels, 50);
  EXPECT_EQ(m.rel_rmse, 0);
}

TEST(MetricsTest, LinearPsnrOfAHalfBrightRender) {
  // A constant truth t: its 99th percentile is t, exposed to digital 230; half of it renders
  // as 115. PSNR = 10 log10(255^2 / 115^2).
  const Image t(8, 6, 3, PixelUnits::kRadiance, 4.f);
  const RenderMetrics m = CompareRadiance(Scaled(t, 0.5f), t, {});
  EXPECT_NEAR(m.psnr_db, 20 * std::log10(255.0 / 115.0), 1e-9);
  EXPECT_NEAR(m.median_rel_error, 0.5, 1e-7);
  EXPECT_NEAR(m.rel_rmse, 0.5, 1e-7);
}

TEST(MetricsTest, PsnrThroughAResponseCurve) {
  // g(z) = ln((z + 1) / 231): exposure 1 is digital 230, so a truth of 2 is exposed by 0.5. A
  // render of 2 x 116 / 231 then has exposure 116 / 231: digital 115, 115 below the truth's.
  ResponseCurve rc;
  for (int c = 0; c < 3; ++c)
    for (int z = 0; z < 256; ++z) rc.g[c].push_back(std::log((z + 1) / 231.0));
  ASSERT_TRUE(rc.valid());
  MetricsOptions o;
  o.response = &rc;
  const Image t(5, 5, 3, PixelUnits::kRadiance, 2.f);
  EXPECT_EQ(CompareRadiance(t, t, {}, o).psnr_db, 99.0);
  const Image r(5, 5, 3, PixelUnits::kRadiance, 2.f * 116 / 231);
  EXPECT_NEAR(CompareRadiance(r, t, {}, o).psnr_db, 20 * std::log10(255.0 / 115.0), 1e-9);
}

TEST(MetricsTest, PoolingIsOverEveryPixelOfEveryPair) {
  // Two pairs pooled give the relative RMSE, ratio and median of the pixels side by side.
  const Image t1 = Ramp(10, 4), t2 = Scaled(Ramp(10, 4), 3.f);
  const Image r1 = Scaled(t1, 1.2f), r2 = Scaled(t2, 0.9f);
  MetricsAccumulator acc;
  acc.Add(r1, t1, {});
  acc.Add(r2, t2, {});
  const RenderMetrics pooled = acc.Result();
  Image rs(20, 4, 3, PixelUnits::kRadiance), ts(20, 4, 3, PixelUnits::kRadiance);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 10; ++x)
      for (int c = 0; c < 3; ++c) {
        rs.at(x, y, c) = r1.at(x, y, c);
        ts.at(x, y, c) = t1.at(x, y, c);
        rs.at(x + 10, y, c) = r2.at(x, y, c);
        ts.at(x + 10, y, c) = t2.at(x, y, c);
      }
  const RenderMetrics side = CompareRadiance(rs, ts, {});
  EXPECT_EQ(pooled.pixels, 80);
  EXPECT_NEAR(pooled.rel_rmse, side.rel_rmse, 1e-12);
  EXPECT_NEAR(pooled.mean_ratio, side.mean_ratio, 1e-12);
  EXPECT_NEAR(pooled.median_rel_error, 0.1, 1e-6);  // 40 values 0.1, 40 values 0.2: lower middle
  EXPECT_THROW(MetricsAccumulator().Result(), Error);
}

TEST(MetricsTest, RelativeDifferenceIsSignedAndMasked) {
  const Image t = Ramp(6, 4);
  std::vector<uint8_t> mask(24, 1);
  mask[5] = 0;
  const Image d = RelativeDifference(Scaled(t, 0.75f), t, mask);
  EXPECT_NEAR(d.at(0, 0, 0), -0.25, 1e-6);
  EXPECT_NEAR(d.at(3, 2, 2), -0.25, 1e-6);
  EXPECT_EQ(d.at(5, 0, 1), 0.f);  // outside the mask
}

TEST(MetricsTest, ErodeMaskDropsEdgePixels) {
  // A 4x3 block inside a 6x5 image: erosion by 1 keeps its 2x1 interior.
  std::vector<uint8_t> mask(30, 0);
  for (int y = 1; y <= 3; ++y) {
    for (int x = 1; x <= 4; ++x) mask[y * 6 + x] = 1;
  }
  const auto e = ErodeMask(mask, 6, 5, 1);
  int kept = 0;
  for (int i = 0; i < 30; ++i) kept += e[i];
  EXPECT_EQ(kept, 2);
  EXPECT_EQ(e[2 * 6 + 2], 1);
  EXPECT_EQ(e[2 * 6 + 3], 1);
  EXPECT_EQ(ErodeMask(mask, 6, 5, 0), mask);
  EXPECT_THROW(ErodeMask(mask, 5, 5, 1), Error);
}

TEST(MetricsTest, BadInputThrows) {
  const Image t = Ramp(20, 10);
  EXPECT_THROW(CompareRadiance(Ramp(10, 10), t, {}), Error);
  EXPECT_THROW(CompareRadiance(t, t, std::vector<uint8_t>(3, 1)), Error);
  EXPECT_THROW(CompareRadiance(t, t, std::vector<uint8_t>(200, 0)), Error);
  Image nan = t;
  nan.data[7] = NAN;
  EXPECT_THROW(CompareRadiance(nan, t, {}), Error);
  EXPECT_THROW(CompareRadiance(t, Image(20, 10, 3, PixelUnits::kRadiance, 0.f), {}), Error);
  MetricsOptions bad;
  bad.percentile = 0;
  EXPECT_THROW(MetricsAccumulator{bad}, Error);
}

}  // namespace
}  // namespace rouen
