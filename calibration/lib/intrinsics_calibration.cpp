#include "calibration/lib/intrinsics_calibration.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include <opencv2/calib3d.hpp>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {
namespace {

double view_rms(const CalibrationView& v, const cv::Mat& rvec, const cv::Mat& tvec, const cv::Matx33d& K,
                const cv::Mat& dist) {
  std::vector<cv::Point2f> proj;
  cv::projectPoints(v.board_mm, rvec, tvec, K, dist, proj);
  double sum = 0.0;
  for (std::size_t i = 0; i < proj.size(); ++i) {
    const cv::Point2f d = proj[i] - v.image_px[i];
    sum += static_cast<double>(d.dot(d));
  }
  return std::sqrt(sum / static_cast<double>(proj.size()));
}

std::string list_rejected(const std::vector<ViewReport>& reports) {
  std::ostringstream out;
  for (const auto& r : reports) {
    if (!r.used) out << "\n  " << r.name << ": " << r.reason;
  }
  return out.str();
}

}  // namespace

IntrinsicsResult calibrate_intrinsics(const std::vector<CalibrationView>& views, cv::Size image_size,
                                      const IntrinsicsOptions& opt) {
  const auto start = std::chrono::steady_clock::now();
  if (image_size.width <= 0 || image_size.height <= 0) throw CalibError("intrinsics: image size unknown");
  IntrinsicsResult res;
  std::vector<std::size_t> active;
  for (std::size_t i = 0; i < views.size(); ++i) {
    ViewReport r;
    r.name = views[i].name;
    r.points = static_cast<int>(views[i].image_px.size());
    if (views[i].image_px.size() != views[i].board_mm.size()) {
      r.reason = "image and board point counts differ";
    } else if (r.points < opt.min_points_per_view) {
      r.reason = std::to_string(r.points) + " corners (" + std::to_string(opt.min_points_per_view) + " needed)";
    } else {
      r.used = true;
      active.push_back(i);
    }
    res.views.push_back(r);
  }
  auto too_few = [&](const std::string& when) {
    std::ostringstream msg;
    msg << "intrinsics: " << active.size() << " usable views " << when << ", at least " << opt.min_views
        << " needed: capture more views of the board (tilted 20-45 degrees, filling the image "
           "corners)."
        << list_rejected(res.views);
    throw DegenerateInput(msg.str());
  };
  if (static_cast<int>(active.size()) < opt.min_views) too_few("after detection");

  int flags = 0;
  if (opt.fix_k3) flags |= cv::CALIB_FIX_K3;
  cv::Matx33d K;
  cv::Mat dist;
  double rms = 0.0;
  int rounds = 0;
  // Solve, reject outlier views once, solve again.
  for (; rounds < 2; ++rounds) {
    std::vector<std::vector<cv::Point3f>> obj;
    std::vector<std::vector<cv::Point2f>> img;
    for (std::size_t i : active) {
      obj.push_back(views[i].board_mm);
      img.push_back(views[i].image_px);
    }
    cv::Mat Km;
    res.rvecs.clear();
    res.tvecs.clear();
    rms = cv::calibrateCamera(obj, img, image_size, Km, dist, res.rvecs, res.tvecs, flags,
                              cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
    K = cv::Matx33d(Km);
    std::vector<double> per_view;
    for (std::size_t k = 0; k < active.size(); ++k) {
      const double e = view_rms(views[active[k]], res.rvecs[k], res.tvecs[k], K, dist);
      res.views[active[k]].rms_px = e;
      per_view.push_back(e);
    }
    if (rounds == 0) res.summary.initial_cost = rms;
    if (rounds == 1) break;
    std::vector<double> sorted = per_view;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2), sorted.end());
    const double median = sorted[sorted.size() / 2];
    const double limit = std::max(opt.outlier_factor * median, opt.outlier_min_px);
    std::vector<std::size_t> kept;
    for (std::size_t k = 0; k < active.size(); ++k) {
      if (per_view[k] > limit) {
        std::ostringstream why;
        why.precision(3);
        why << "outlier: view RMS " << per_view[k] << " px > " << limit << " px (" << opt.outlier_factor
            << " x median " << median << " px): blurred, moving or mis-detected";
        res.views[active[k]].used = false;
        res.views[active[k]].reason = why.str();
      } else {
        kept.push_back(active[k]);
      }
    }
    if (kept.size() == active.size()) break;
    active = kept;
    if (static_cast<int>(active.size()) < opt.min_views) too_few("after outlier rejection");
  }

  // Coverage: which cells of a grid over the image hold at least one used corner.
  res.coverage_cells = cv::Mat::zeros(opt.coverage_rows, opt.coverage_cols, CV_32S);
  for (std::size_t i : active) {
    for (const auto& p : views[i].image_px) {
      const int cx = std::clamp(static_cast<int>(p.x / static_cast<float>(image_size.width) * static_cast<float>(opt.coverage_cols)), 0, opt.coverage_cols - 1);
      const int cy = std::clamp(static_cast<int>(p.y / static_cast<float>(image_size.height) * static_cast<float>(opt.coverage_rows)), 0, opt.coverage_rows - 1);
      res.coverage_cells.at<int>(cy, cx) += 1;
    }
  }
  res.coverage = static_cast<double>(cv::countNonZero(res.coverage_cells)) / (opt.coverage_rows * opt.coverage_cols);

  CameraIntrinsics& in = res.intrinsics;
  in.image_width = image_size.width;
  in.image_height = image_size.height;
  in.camera_matrix = K;
  in.distortion.assign(dist.begin<double>(), dist.end<double>());
  in.rms_reprojection_error_px = rms;
  in.views_used = static_cast<int>(active.size());
  in.calibration_date = utc_now_iso8601();
  res.summary.method = "intrinsics: cv::calibrateCamera (Zhang), pinhole + k1 k2 p1 p2 k3" +
                       std::string(opt.fix_k3 ? " (k3 fixed at 0)" : "");
  res.summary.iterations = rounds + 1;
  res.summary.final_cost = rms;
  res.summary.termination = "Levenberg-Marquardt (OpenCV); " + std::to_string(rounds + 1) + " solve(s)";
  res.summary.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

}  // namespace arnav::calib
