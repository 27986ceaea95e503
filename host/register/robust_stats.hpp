#pragma once
// Order statistics shared by the registration methods (trimming thresholds, robust scale).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace arnav::host {

// The value below which `fraction` of `values` lie (the ceil(fraction * n)-th smallest);
// 0 for an empty set. Takes the vector by value (partially reordered).
inline double kth_value(std::vector<double> values, double fraction) {
  if (values.empty()) return 0.0;
  const auto k = std::clamp(static_cast<std::ptrdiff_t>(std::ceil(fraction * static_cast<double>(values.size()))) - 1, std::ptrdiff_t{0},
                            static_cast<std::ptrdiff_t>(values.size()) - 1);
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[static_cast<std::size_t>(k)];
}

}  // namespace arnav::host
