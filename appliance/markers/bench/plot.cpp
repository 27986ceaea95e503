#include "plot.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace arnav::bench {

cv::Scalar series_color(size_t k) {
  static const cv::Scalar c[] = {{200, 80, 30}, {30, 120, 230}, {40, 170, 40}, {30, 30, 200},
                                 {160, 60, 160}, {20, 160, 200}, {90, 90, 90}, {0, 200, 120}};
  return c[k % 8];
}

namespace {

std::string fmt(double v) {
  char buf[32];
  if (std::abs(v) >= 100 || v == 0) std::snprintf(buf, sizeof buf, "%.0f", v);
  else if (std::abs(v) >= 10) std::snprintf(buf, sizeof buf, "%.1f", v);
  else std::snprintf(buf, sizeof buf, "%.2g", v);
  return buf;
}

void draw_panel(cv::Mat& img, const Panel& p, cv::Rect area) {
  const int left = area.x + 70, right = area.x + area.width - 20, top = area.y + 40, bottom = area.y + area.height - 55;
  double x0 = 1e300, x1 = -1e300, y0 = 0, y1 = -1e300;
  auto tx = [&](double x) { return p.log_x ? std::log10(std::max(x, 1e-12)) : x; };
  for (const auto& s : p.series) {
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      x0 = std::min(x0, tx(s.x[i]));
      x1 = std::max(x1, tx(s.x[i]));
      y1 = std::max(y1, s.y[i]);
    }
  }
  if (x0 > x1) return;
  if (x1 == x0) x1 = x0 + 1;
  if (y1 <= y0) y1 = y0 + 1;
  y1 *= 1.08;
  auto px = [&](double x, double y) {
    return cv::Point(static_cast<int>(left + (tx(x) - x0) / (x1 - x0) * (right - left)),
                     static_cast<int>(bottom - (y - y0) / (y1 - y0) * (bottom - top)));
  };
  cv::putText(img, p.title, {area.x + 70, area.y + 25}, cv::FONT_HERSHEY_SIMPLEX, 0.55, {0, 0, 0}, 1, cv::LINE_AA);
  cv::rectangle(img, {left, top}, {right, bottom}, {0, 0, 0}, 1);
  for (int k = 0; k <= 4; ++k) {
    const double yv = y0 + (y1 - y0) * k / 4.0;
    const int yy = bottom - (bottom - top) * k / 4;
    cv::line(img, {left, yy}, {right, yy}, {225, 225, 225}, 1);
    cv::putText(img, fmt(yv), {area.x + 8, yy + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0}, 1, cv::LINE_AA);
    const double xv = x0 + (x1 - x0) * k / 4.0;
    const int xx = left + (right - left) * k / 4;
    cv::putText(img, fmt(p.log_x ? std::pow(10.0, xv) : xv), {xx - 10, bottom + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                {0, 0, 0}, 1, cv::LINE_AA);
  }
  cv::putText(img, p.x_label, {left + (right - left) / 2 - 60, bottom + 38}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1,
              cv::LINE_AA);
  cv::putText(img, p.y_label, {area.x + 8, top - 8}, cv::FONT_HERSHEY_SIMPLEX, 0.42, {0, 0, 0}, 1, cv::LINE_AA);
  int legend_y = top + 14;
  for (const auto& s : p.series) {
    cv::Point prev(-1, -1);
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.y[i])) {
        prev = {-1, -1};
        continue;
      }
      const cv::Point q = px(s.x[i], s.y[i]);
      cv::circle(img, q, 3, s.color, cv::FILLED, cv::LINE_AA);
      if (s.lines && prev.x >= 0) cv::line(img, prev, q, s.color, 2, cv::LINE_AA);
      prev = q;
    }
    cv::line(img, {right - 150, legend_y - 4}, {right - 130, legend_y - 4}, s.color, 2);
    cv::putText(img, s.label, {right - 125, legend_y}, cv::FONT_HERSHEY_SIMPLEX, 0.38, {0, 0, 0}, 1, cv::LINE_AA);
    legend_y += 15;
  }
}

}  // namespace

cv::Mat draw_panels(const std::vector<Panel>& panels, int cols, cv::Size size) {
  const int rows = static_cast<int>((panels.size() + static_cast<size_t>(cols) - 1) / static_cast<size_t>(cols));
  cv::Mat img(rows * size.height, cols * size.width, CV_8UC3, cv::Scalar(255, 255, 255));
  for (size_t i = 0; i < panels.size(); ++i) {
    const int r = static_cast<int>(i) / cols, c = static_cast<int>(i) % cols;
    draw_panel(img, panels[i], cv::Rect(c * size.width, r * size.height, size.width, size.height));
  }
  return img;
}

}  // namespace arnav::bench
