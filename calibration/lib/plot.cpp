#include "calibration/lib/plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {
namespace {

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

// A "nice" tick step (1, 2 or 5 x 10^k) for about n ticks over span.
double nice_step(double span, int n) {
  const double raw = span / n;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / mag;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * mag;
}

}  // namespace

cv::Mat render_chart(const Chart& c) {
  cv::Mat img(c.height, c.width, CV_8UC3, cv::Scalar(255, 255, 255));
  const int left = 80, right = 20, top = 56, bottom = 60;
  const cv::Rect area(left, top, c.width - left - right, c.height - top - bottom);
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = 0.0, ymax = -xmin;
  for (const auto& s : c.series) {
    for (std::size_t i = 0; i < s.y.size(); ++i) {
      const double x = i < s.x.size() ? s.x[i] : static_cast<double>(i);
      const double e = i < s.y_err.size() ? s.y_err[i] : 0.0;
      if (!std::isfinite(x) || !std::isfinite(s.y[i])) continue;
      xmin = std::min(xmin, x);
      xmax = std::max(xmax, x);
      ymin = std::min(ymin, s.y[i] - e);
      ymax = std::max(ymax, s.y[i] + e);
    }
  }
  if (c.reference_y) ymax = std::max(ymax, *c.reference_y);
  if (!std::isfinite(xmin)) { xmin = 0; xmax = 1; ymax = 1; }
  const bool bars = std::any_of(c.series.begin(), c.series.end(), [](const PlotSeries& s) { return s.style == SeriesStyle::Bars; });
  if (bars) { xmin -= 0.6; xmax += 0.6; }
  if (xmax - xmin < 1e-12) { xmin -= 1; xmax += 1; }
  if (ymax - ymin < 1e-12) ymax = ymin + 1;
  ymax += 0.08 * (ymax - ymin);
  auto X = [&](double x) { return area.x + (x - xmin) / (xmax - xmin) * area.width; };
  auto Y = [&](double y) { return area.y + area.height - (y - ymin) / (ymax - ymin) * area.height; };
  auto P = [&](double x, double y) { return cv::Point(static_cast<int>(std::lround(X(x))), static_cast<int>(std::lround(Y(y)))); };
  const cv::Scalar grid(225, 225, 225), ink(40, 40, 40);
  // Axes, grid and ticks.
  const double ys = nice_step(ymax - ymin, 6);
  for (double y = std::ceil(ymin / ys) * ys; y <= ymax + 1e-12; y += ys) {
    cv::line(img, P(xmin, y), P(xmax, y), grid, 1);
    cv::putText(img, fmt(y), cv::Point(8, P(xmin, y).y + 5), cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);
  }
  if (bars && !c.x_tick_labels.empty()) {
    for (std::size_t i = 0; i < c.x_tick_labels.size(); ++i) {
      const cv::Point p = P(static_cast<double>(i), ymin);
      cv::putText(img, c.x_tick_labels[i], cv::Point(p.x - 4 * static_cast<int>(c.x_tick_labels[i].size()), p.y + 18),
                  cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);
    }
  } else {
    const double xs = nice_step(xmax - xmin, 8);
    for (double x = std::ceil(xmin / xs) * xs; x <= xmax + 1e-12; x += xs) {
      const cv::Point p = P(x, ymin);
      cv::line(img, p, p + cv::Point(0, 5), ink, 1);
      cv::putText(img, fmt(x), cv::Point(p.x - 10, p.y + 20), cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);
    }
  }
  cv::rectangle(img, area, ink, 1);
  // Series.
  const int nbars = static_cast<int>(std::count_if(c.series.begin(), c.series.end(), [](const PlotSeries& s) { return s.style == SeriesStyle::Bars; }));
  int bar_index = 0;
  for (const auto& s : c.series) {
    std::vector<cv::Point> pts;
    const double bw = 0.7 / std::max(nbars, 1);
    for (std::size_t i = 0; i < s.y.size(); ++i) {
      double x = i < s.x.size() ? s.x[i] : static_cast<double>(i);
      if (!std::isfinite(x) || !std::isfinite(s.y[i])) continue;
      if (s.style == SeriesStyle::Bars) {
        x += -0.35 + bw * (bar_index + 0.5);
        cv::rectangle(img, P(x - 0.45 * bw, 0.0), P(x + 0.45 * bw, s.y[i]), s.color, cv::FILLED);
      } else if (s.style == SeriesStyle::Points) {
        cv::circle(img, P(x, s.y[i]), 3, s.color, cv::FILLED, cv::LINE_AA);
      }
      if (i < s.y_err.size()) {
        cv::line(img, P(x, s.y[i] - s.y_err[i]), P(x, s.y[i] + s.y_err[i]), ink, 1, cv::LINE_AA);
        cv::line(img, P(x, s.y[i] - s.y_err[i]) + cv::Point(-4, 0), P(x, s.y[i] - s.y_err[i]) + cv::Point(4, 0), ink, 1);
        cv::line(img, P(x, s.y[i] + s.y_err[i]) + cv::Point(-4, 0), P(x, s.y[i] + s.y_err[i]) + cv::Point(4, 0), ink, 1);
      }
      pts.push_back(P(x, s.y[i]));
    }
    if (s.style == SeriesStyle::Line && pts.size() > 1) cv::polylines(img, pts, false, s.color, 2, cv::LINE_AA);
    if (s.style == SeriesStyle::Bars) ++bar_index;
  }
  if (c.reference_y) {
    cv::line(img, P(xmin, *c.reference_y), P(xmax, *c.reference_y), cv::Scalar(30, 30, 220), 1, cv::LINE_AA);
    cv::putText(img, c.reference_label, P(xmin, *c.reference_y) + cv::Point(6, -6), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(30, 30, 220), 1, cv::LINE_AA);
  }
  // Legend, title, labels.
  int ly = top + 18;
  for (const auto& s : c.series) {
    if (s.name.empty()) continue;
    cv::rectangle(img, cv::Rect(area.x + area.width - 230, ly - 10, 12, 12), s.color, cv::FILLED);
    cv::putText(img, s.name, cv::Point(area.x + area.width - 212, ly), cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);
    ly += 18;
  }
  cv::putText(img, c.title, cv::Point(left, 22), cv::FONT_HERSHEY_SIMPLEX, 0.6, ink, 1, cv::LINE_AA);
  cv::putText(img, c.x_label, cv::Point(area.x + area.width / 2 - 60, c.height - 14), cv::FONT_HERSHEY_SIMPLEX, 0.5, ink, 1, cv::LINE_AA);
  cv::putText(img, c.y_label, cv::Point(8, top - 12), cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);
  return img;
}

void write_chart(const std::filesystem::path& png, const Chart& chart) {
  if (!cv::imwrite(png.string(), render_chart(chart))) {
    throw CalibError(png.string() + ": cannot write the plot");
  }
}

Chart residual_chart(std::string title, std::string x_label, std::string y_label,
                     const std::vector<double>& residuals, double rms) {
  Chart chart;
  chart.title = std::move(title);
  chart.x_label = std::move(x_label);
  chart.y_label = std::move(y_label);
  PlotSeries s{"residual", {}, residuals, {}, SeriesStyle::Points, cv::Scalar(200, 90, 20)};
  for (std::size_t i = 0; i < residuals.size(); ++i) s.x.push_back(static_cast<double>(i));
  chart.series.push_back(std::move(s));
  chart.reference_y = rms;
  chart.reference_label = "RMS";
  return chart;
}

}  // namespace arnav::calib
