// Robust statistics shared by the fitter's stages: the median by selection and the normal σ
// from the median absolute deviation (MAD), the scale used wherever outliers must not set it.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace flarekit {

// σ of a normal distribution per unit of its median absolute deviation (1 / Φ⁻¹(3/4)).
inline constexpr double kSigmaPerMad = 1.4826;

// The upper median of `values` (the middle value for an odd count, the upper of the two middle
// ones for an even count): a selection, linear in the count, not a sort. Reorders `values`,
// which must not be empty.
template <class T>
double upperMedian(std::vector<T>& values) {
  const auto middle = values.begin() + static_cast<long>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return static_cast<double>(*middle);
}

// kSigmaPerMad × the median of |value − centre|: the normal σ of `values` about `centre`, which
// a few outliers do not move. Overwrites `values` with the deviations; they must not be empty.
template <class T>
double madSigma(std::vector<T>& values, double centre = 0) {
  for (T& v : values) v = static_cast<T>(std::abs(v - centre));
  return kSigmaPerMad * upperMedian(values);
}

}  // namespace flarekit
