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

TEST(MetricsTest, IdenticalScaledAndMasked) {
  const Image t = Ramp(20, 10);
  RenderMetrics m = CompareRadiance(t, t, {});
  EXPECT_EQ(m.pixels, 200);
  EXPECT_EQ(m.rel_rmse, 0);
  EXPECT_EQ(m.psnr_db, 99.0);
  EXPECT_DOUBLE_EQ(m.mean_ratio, 1.0);
  Image r = t;
  for (float& v : r.data) v *= 1.1f;
  // s R - T = 0.1 T everywhere: relative RMSE is exactly 0.1.
  m = CompareRadiance(r, t, {});
  EXPECT_NEAR(m.rel_rmse, 0.1, 1e-6);
  EXPECT_NEAR(m.mean_ratio, 1.1, 1e-6);
  EXPECT_LT(m.psnr_db, 40);
  EXPECT_NEAR(FitScale(r, t, {}), 1 / 1.1, 1e-6);
  m = CompareRadiance(r, t, {}, 1 / 1.1);
  EXPECT_NEAR(m.rel_rmse, 0, 1e-6);
  // The mask limits the comparison: corrupt unmasked pixels only.
  std::vector<uint8_t> mask(200, 0);
  for (int i = 0; i < 50; ++i) mask[i] = 1;
  Image c = t;
  for (size_t i = 50 * 3; i < c.data.size(); ++i) c.data[i] = 0;
  m = CompareRadiance(c, t, mask);
  EXPECT_EQ(m.pixels, 50);
  EXPECT_EQ(m.rel_rmse, 0);
  // PSNR of a constant offset d on images normalised by the truth's 99th percentile p99:
  // 10 log10(p99^2 / d^2) when nothing clips.
  Image o = t;
  for (float& v : o.data) v -= 0.5f;
  m = CompareRadiance(o, t, mask);
  // Masked truth: rows 0-2 (x + 2y + c + 1 up to 28); its 99th percentile is near the top.
  EXPECT_GT(m.psnr_db, 20 * std::log10(20 / 0.5));
  EXPECT_LT(m.psnr_db, 20 * std::log10(30 / 0.5) + 0.1);
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
  EXPECT_THROW(CompareRadiance(t, t, {}, 0.0), Error);
  EXPECT_THROW(FitScale(Image(20, 10, 3, PixelUnits::kRadiance, 0.f), t, {}), Error);
  EXPECT_THROW(CompareRadiance(t, Image(20, 10, 3, PixelUnits::kRadiance, 0.f), {}), Error);
}

}  // namespace
}  // namespace rouen
