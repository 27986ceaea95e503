#pragma once
// Receive-to-publish latency over a window (the health period): p50, p99, max in
// microseconds. Fixed capacity, no allocation per sample.
#include <cstddef>
#include <vector>

namespace arnav::app {

struct LatencySummary {
  float p50_us = 0.0f;
  float p99_us = 0.0f;
  float max_us = 0.0f;
  std::size_t samples = 0;
};

class LatencyWindow {
 public:
  explicit LatencyWindow(std::size_t capacity = 8192);
  void add(float latency_us);  // beyond capacity, samples replace old ones round-robin
  // Summary of the samples since the last take(); clears the window.
  LatencySummary take();

 private:
  std::vector<float> samples_, scratch_;
  std::size_t count_ = 0, next_ = 0;
  float max_ = 0.0f;
};

}  // namespace arnav::app
