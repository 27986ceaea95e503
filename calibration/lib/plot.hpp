#pragma once
// Small PNG charts for calibration reports (OpenCV drawing): line, scatter and bar
// series with axes, ticks, labels and an optional horizontal reference line.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace arnav::calib {

enum class SeriesStyle { Line, Points, Bars };

struct PlotSeries {
  std::string name;
  std::vector<double> x;
  std::vector<double> y;
  std::vector<double> y_err;        // optional +- bars (same length as y)
  SeriesStyle style = SeriesStyle::Line;
  cv::Scalar color = cv::Scalar(200, 90, 20);  // BGR
};

struct Chart {
  std::string title;
  std::string x_label;
  std::string y_label;
  std::vector<PlotSeries> series;
  std::optional<double> reference_y;  // e.g. a target or threshold
  std::string reference_label;
  std::vector<std::string> x_tick_labels;  // bars: one label per x = 0, 1, 2, ...
  int width = 900;
  int height = 520;
};

cv::Mat render_chart(const Chart& chart);

// A per-sample residual chart (x = sample index, points) with the RMS as reference line:
// the residual plot every calibration report carries.
Chart residual_chart(std::string title, std::string x_label, std::string y_label,
                     const std::vector<double>& residuals, double rms);
// Throws CalibError when the file cannot be written.
void write_chart(const std::filesystem::path& png, const Chart& chart);

}  // namespace arnav::calib
