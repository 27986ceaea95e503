#include "calibration/lib/ar_accuracy.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/numeric_lines.hpp"
#include "calibration/lib/plot.hpp"

namespace arnav::calib {
namespace {

ArAngleStats stats_of(double angle, const std::vector<const ArTrial*>& ts) {
  ArAngleStats s;
  s.view_angle_deg = angle;
  s.n = static_cast<int>(ts.size());
  s.min_mm = std::numeric_limits<double>::infinity();
  s.max_mm = -s.min_mm;
  double sum = 0.0, img = 0.0, lat = 0.0;
  int n_img = 0;
  for (const ArTrial* t : ts) {
    sum += t->error_mm;
    s.min_mm = std::min(s.min_mm, t->error_mm);
    s.max_mm = std::max(s.max_mm, t->error_mm);
    if (t->image_error_px >= 0) {
      img += t->image_error_px;
      lat += t->lateral_error_mm;
      ++n_img;
    }
  }
  s.mean_mm = sum / s.n;
  double var = 0.0;
  for (const ArTrial* t : ts) var += (t->error_mm - s.mean_mm) * (t->error_mm - s.mean_mm);
  s.sd_mm = s.n > 1 ? std::sqrt(var / (s.n - 1)) : 0.0;
  if (n_img > 0) {
    s.mean_image_px = img / n_img;
    s.mean_lateral_mm = lat / n_img;
  }
  return s;
}

}  // namespace

std::vector<ArAngleStats> summarize_ar_trials(const std::vector<ArTrial>& trials) {
  std::map<double, std::vector<const ArTrial*>> by_angle;
  std::vector<const ArTrial*> all;
  for (const auto& t : trials) {
    by_angle[t.view_angle_deg].push_back(&t);
    all.push_back(&t);
  }
  std::vector<ArAngleStats> out;
  if (trials.empty()) return out;
  for (const auto& [angle, ts] : by_angle) out.push_back(stats_of(angle, ts));
  out.push_back(stats_of(std::numeric_limits<double>::quiet_NaN(), all));
  return out;
}

std::vector<ArTrial> parse_ar_measurements(const std::string& text, const std::string& source) {
  std::vector<ArTrial> trials;
  const NumericLineOptions options{.semicolons = true, .header_line = true};
  for_each_numeric_line(text, source, [&](const std::vector<double>& v, int, const std::string& at) {
    if (v.size() != 7) {
      throw CalibError(at + "expected 7 columns (view_angle_deg, x/y/z of the virtual target, x/y/z of "
                            "the realigned ball, mm), found " + std::to_string(v.size()));
    }
    ArTrial t;
    t.view_angle_deg = v[0];
    t.error_mm = (Eigen::Vector3d(v[1], v[2], v[3]) - Eigen::Vector3d(v[4], v[5], v[6])).norm();
    trials.push_back(t);
  }, options);
  if (trials.empty()) throw CalibError(source + ": no measurements (7 numbers per line)");
  return trials;
}

std::vector<ArTrial> read_ar_measurements(const std::filesystem::path& path) {
  return parse_ar_measurements(read_text_file(path, "the AR measurement file"), path.string());
}

void write_ar_trials_csv(const std::filesystem::path& path, const std::vector<ArTrial>& trials) {
  std::ofstream out(path);
  if (!out) throw CalibError(path.string() + ": cannot write");
  out << "view_angle_deg,error_mm,image_error_px,lateral_error_mm\n";
  for (const auto& t : trials) {
    out << t.view_angle_deg << "," << t.error_mm << "," << t.image_error_px << "," << t.lateral_error_mm << "\n";
  }
}

void write_ar_stats_csv(const std::filesystem::path& path, const std::vector<ArAngleStats>& stats) {
  std::ofstream out(path);
  if (!out) throw CalibError(path.string() + ": cannot write");
  out << "view_angle_deg,n,mean_mm,sd_mm,min_mm,max_mm,mean_image_px,mean_lateral_mm\n";
  for (const auto& s : stats) {
    if (std::isnan(s.view_angle_deg)) {
      out << "all";
    } else {
      out << s.view_angle_deg;
    }
    out << "," << s.n << "," << s.mean_mm << "," << s.sd_mm << "," << s.min_mm << "," << s.max_mm << ","
        << s.mean_image_px << "," << s.mean_lateral_mm << "\n";
  }
}

void write_ar_chart(const std::filesystem::path& png, const std::vector<ArAngleStats>& stats, const std::string& title,
                    double reference_mm, const std::string& reference_label) {
  Chart c;
  c.title = title;
  c.x_label = "view angle of the marker";
  c.y_label = "AR error mm (mean +- sd)";
  PlotSeries s;
  s.name = "AR error";
  s.style = SeriesStyle::Bars;
  for (std::size_t i = 0; i < stats.size(); ++i) {
    s.x.push_back(static_cast<double>(i));
    s.y.push_back(stats[i].mean_mm);
    s.y_err.push_back(stats[i].sd_mm);
    std::ostringstream label;
    if (std::isnan(stats[i].view_angle_deg)) {
      label << "all";
    } else {
      label << stats[i].view_angle_deg << " deg";
    }
    c.x_tick_labels.push_back(label.str());
  }
  c.series.push_back(s);
  c.reference_y = reference_mm;
  c.reference_label = reference_label;
  write_chart(png, c);
}

}  // namespace arnav::calib
