#pragma once
// AR accuracy evaluation after paper 000's protocol: a virtual target is placed where
// the tracker says the test ball is, the real ball is moved until it coincides with the
// virtual one in the AR view, and both positions are read in the tracker frame; the
// distance is the AR error. Reported as mean +- sd per view angle of the marker.
//
// Measurement file (CSV, one trial per line, '#' comments, a header line allowed):
//   view_angle_deg, x_virtual, y_virtual, z_virtual, x_real, y_real, z_real   (mm, Ndi)
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace arnav::calib {

struct ArTrial {
  double view_angle_deg = 0.0;
  double error_mm = 0.0;       // 3D distance (the paper's measure)
  double image_error_px = -1;  // simulation only (-1: not measured)
  double lateral_error_mm = -1;  // simulation only: error across the viewing ray
};

struct ArAngleStats {
  double view_angle_deg = 0.0;
  int n = 0;
  double mean_mm = 0.0;
  double sd_mm = 0.0;          // sample standard deviation (n - 1)
  double min_mm = 0.0;
  double max_mm = 0.0;
  double mean_image_px = -1;
  double mean_lateral_mm = -1;
};

// Per distinct view angle (sorted), plus the overall statistics as the last entry with
// view_angle_deg = NaN.
std::vector<ArAngleStats> summarize_ar_trials(const std::vector<ArTrial>& trials);

// Throws CalibError "FILE:LINE: ..." on a wrong column count or a non-number.
std::vector<ArTrial> parse_ar_measurements(const std::string& text, const std::string& source);
std::vector<ArTrial> read_ar_measurements(const std::filesystem::path& path);

void write_ar_trials_csv(const std::filesystem::path& path, const std::vector<ArTrial>& trials);
void write_ar_stats_csv(const std::filesystem::path& path, const std::vector<ArAngleStats>& stats);
// Bar chart: mean +- sd per view angle, with a reference line (e.g. the target).
void write_ar_chart(const std::filesystem::path& png, const std::vector<ArAngleStats>& stats,
                    const std::string& title, double reference_mm, const std::string& reference_label);

}  // namespace arnav::calib
