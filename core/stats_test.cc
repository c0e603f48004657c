#include "core/stats.h"

#include <gtest/gtest.h>

namespace rouen {
namespace {

TEST(StatsTest, QuantileIsTheLowerNearestRank) {
  // Ranks 0..4 of {10, 20, 30, 40, 50}: p (n - 1) = 4p, rounded down.
  const std::vector<double> v{50, 10, 40, 20, 30};
  EXPECT_EQ(Quantile(v, 0.0), 10);
  EXPECT_EQ(Quantile(v, 0.5), 30);
  EXPECT_EQ(Quantile(v, 0.74), 30);  // 2.96 -> rank 2
  EXPECT_EQ(Quantile(v, 0.75), 40);
  EXPECT_EQ(Quantile(v, 1.0), 50);
  EXPECT_EQ(Quantile(v, 7.0), 50);  // clamped
  // An even count's median is the lower middle.
  EXPECT_EQ(Quantile(std::vector<double>{4, 1, 3, 2}, 0.5), 2);
  EXPECT_EQ(Quantile(std::vector<float>{4, 1, 3, 2}, 0.5), 2.0f);
  EXPECT_EQ(Quantile(std::vector<double>{}, 0.5), 0);
}

TEST(StatsTest, WeightedQuantileCountsEachElementByItsWeight) {
  // Equal weights: the lower nearest rank, as Quantile, at every p on a fine grid.
  const std::vector<double> v{50, 10, 40, 20, 30, 60, 70};
  for (double p = 0; p <= 1.0; p += 0.01) {
    EXPECT_EQ(WeightedQuantile(v, std::vector<double>(v.size(), 0.1), p), Quantile(v, p)) << p;
  }
  // Weight 3 on the value 10 is that value three times over.
  const std::vector<double> rep{10, 10, 10, 20, 30};
  const std::vector<double> once{10, 20, 30};
  for (double p = 0; p <= 1.0; p += 0.01) {
    EXPECT_EQ(WeightedQuantile(once, {3, 1, 1}, p), Quantile(rep, p)) << p;
  }
  EXPECT_EQ(WeightedQuantile({}, {}, 0.5), 0);
}

TEST(StatsTest, MedianIsTheSampleMedian) {
  EXPECT_EQ(Median(std::vector<double>{50, 10, 40, 20, 30}), 30);
  // An even count: the mean of the two middle values (unlike Quantile's lower middle).
  EXPECT_EQ(Median(std::vector<double>{4, 1, 3, 2}), 2.5);
  EXPECT_EQ(Median(std::vector<float>{4, 1, 3, 2}), 2.5f);
  EXPECT_EQ(Median(std::vector<double>{-7}), -7);
  EXPECT_EQ(Median(std::vector<double>{}), 0);
}

TEST(StatsTest, Mean) {
  EXPECT_DOUBLE_EQ(Mean({1, 2, 3, 6}), 3.0);
  EXPECT_EQ(Mean({}), 0.0);
}

}  // namespace
}  // namespace rouen
