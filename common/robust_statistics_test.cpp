// The median by selection and the σ from the MAD: what they return, and that outliers do not
// move the σ.
#include "common/robust_statistics.h"

#include <gtest/gtest.h>

#include <random>

namespace flarekit {
namespace {

TEST(RobustStatistics, UpperMedianIsTheMiddleValue) {
  std::vector<double> odd = {5, 1, 4, 2, 3};
  EXPECT_EQ(upperMedian(odd), 3);
  std::vector<float> even = {4, 1, 3, 2};
  EXPECT_EQ(upperMedian(even), 3);
}

TEST(RobustStatistics, MadSigmaIsTheNormalSigmaWhateverTheOutliers) {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal(10.0, 2.0);
  std::vector<double> values(20000);
  for (double& v : values) v = normal(rng);
  // One value in twenty wild: the standard deviation becomes ~220, the MAD's σ stays ~2.
  for (size_t i = 0; i < values.size(); i += 20) values[i] = 1000;
  std::vector<double> copy = values;
  const double centre = upperMedian(copy);
  EXPECT_NEAR(centre, 10.0, 0.4);
  EXPECT_NEAR(madSigma(values, centre), 2.0, 2.0 * 0.15);
}

}  // namespace
}  // namespace flarekit
