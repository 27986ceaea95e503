#pragma once
// Minimal line/scatter charts drawn with OpenCV, for benchmark figures (no plotting
// library on the build machines). One Panel = one chart with axes, ticks and a legend.
#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace arnav::bench {

struct Series {
  std::string label;
  std::vector<double> x, y;
  cv::Scalar color;
  bool lines = true;  // false: markers only
};

struct Panel {
  std::string title, x_label, y_label;
  std::vector<Series> series;
  bool log_x = false;
};

// Draws the panels on a grid of `cols` columns into a white image.
cv::Mat draw_panels(const std::vector<Panel>& panels, int cols, cv::Size panel_size);
// Distinct colours for series k.
cv::Scalar series_color(size_t k);

}  // namespace arnav::bench
