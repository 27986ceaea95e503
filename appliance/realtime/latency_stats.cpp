#include "appliance/realtime/latency_stats.hpp"

#include <algorithm>
#include <cmath>

namespace arnav::app {

LatencyWindow::LatencyWindow(std::size_t capacity) : samples_(capacity), scratch_(capacity) {}

void LatencyWindow::add(float latency_us) {
  samples_[next_] = latency_us;
  next_ = (next_ + 1) % samples_.size();
  count_ = std::min(count_ + 1, samples_.size());
  max_ = std::max(max_, latency_us);  // the true max, even when samples were overwritten
}

LatencySummary LatencyWindow::take() {
  LatencySummary s;
  s.samples = count_;
  if (count_ == 0) return s;
  std::copy_n(samples_.begin(), count_, scratch_.begin());
  auto rank = [&](double q) {
    // Nearest-rank percentile.
    const auto k = static_cast<std::size_t>(std::ceil(q * static_cast<double>(count_))) - 1;
    std::nth_element(scratch_.begin(), scratch_.begin() + static_cast<std::ptrdiff_t>(k),
                     scratch_.begin() + static_cast<std::ptrdiff_t>(count_));
    return scratch_[k];
  };
  s.p50_us = rank(0.50);
  s.p99_us = rank(0.99);
  s.max_us = max_;
  count_ = next_ = 0;
  max_ = 0.0f;
  return s;
}

}  // namespace arnav::app
