#include "host/bench/pareto_plot.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

namespace arnav::host {
namespace {

const cv::Scalar kBlack(0, 0, 0), kGrey(190, 190, 190), kRed(40, 40, 220);

cv::Scalar colour_of(const std::string& kind) {
  if (kind == "xpbd") return {200, 110, 20};               // blue
  if (kind == "mass_spring") return {40, 160, 40};         // green
  if (kind == "corotational_fem") return {20, 120, 230};   // orange
  return {120, 120, 120};
}

std::string tick_label(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

void text(cv::Mat& img, const std::string& s, cv::Point p, double scale = 0.45, const cv::Scalar& c = kBlack) {
  cv::putText(img, s, p, cv::FONT_HERSHEY_SIMPLEX, scale, c, 1, cv::LINE_AA);
}

}  // namespace

void write_pareto_png(const std::string& path, const DeformBenchResult& result, const ParetoLabels& labels) {
  std::vector<std::string> scenarios;
  for (const auto& r : result.rows)
    if (std::find(scenarios.begin(), scenarios.end(), r.scenario) == scenarios.end()) scenarios.push_back(r.scenario);
  if (scenarios.empty()) throw std::runtime_error("no benchmark rows to plot");
  const int panel_w = 520, panel_h = 460, margin_l = 70, margin_b = 60, margin_t = 55, margin_r = 20;
  cv::Mat img(panel_h + 70, panel_w * static_cast<int>(scenarios.size()), CV_8UC3, cv::Scalar(255, 255, 255));
  // Common axes: decades covering every healthy point and the budget lines.
  double tmin = 1.0, tmax = 20.0, emin = 0.5, emax = 2.0;
  for (const auto& r : result.rows) {
    if (r.median_frame_cpu_ms <= 0) continue;
    tmin = std::min(tmin, r.median_frame_cpu_ms);
    tmax = std::max(tmax, r.median_frame_cpu_ms);
    emin = std::min(emin, std::max(r.tumour_error_mm, 1e-3));
    emax = std::max(emax, r.tumour_error_mm);
  }
  const double lt0 = std::floor(std::log10(tmin)), lt1 = std::ceil(std::log10(tmax));
  const double le0 = std::floor(std::log10(emin)), le1 = std::ceil(std::log10(emax));
  for (std::size_t p = 0; p < scenarios.size(); ++p) {
    const int ox = static_cast<int>(p) * panel_w;
    const cv::Rect area(ox + margin_l, margin_t, panel_w - margin_l - margin_r, panel_h - margin_t - margin_b);
    auto X = [&](double ms) { return area.x + static_cast<int>((std::log10(ms) - lt0) / (lt1 - lt0) * area.width); };
    auto Y = [&](double mm) {
      return area.y + area.height - static_cast<int>((std::log10(std::max(mm, 1e-3)) - le0) / (le1 - le0) * area.height);
    };
    for (double d = lt0; d <= lt1; ++d) {
      const double v = std::pow(10.0, d);
      cv::line(img, {X(v), area.y}, {X(v), area.y + area.height}, kGrey);
      text(img, tick_label(v), {X(v) - 10, area.y + area.height + 18});
    }
    for (double d = le0; d <= le1; ++d) {
      const double v = std::pow(10.0, d);
      cv::line(img, {area.x, Y(v)}, {area.x + area.width, Y(v)}, kGrey);
      text(img, tick_label(v), {ox + 10, Y(v) + 5});
    }
    cv::rectangle(img, area, kBlack);
    // Budgets: 2 ms (500 Hz) and 16.7 ms (60 Hz); target: 1 mm tumour error.
    for (double budget : {2.0, 1000.0 / 60.0}) {
      cv::line(img, {X(budget), area.y}, {X(budget), area.y + area.height}, kRed, 1, cv::LINE_AA);
      text(img, budget < 5 ? "500 Hz" : "60 Hz", {X(budget) + 3, area.y + 14}, 0.4, kRed);
    }
    cv::line(img, {area.x, Y(1.0)}, {area.x + area.width, Y(1.0)}, kRed, 1, cv::LINE_AA);
    text(img, "1 mm", {area.x + area.width - 40, Y(1.0) - 4}, 0.4, kRed);
    text(img, scenarios[p], {ox + margin_l, 22}, 0.6);
    text(img, labels.x.empty() ? "median CPU time per 1/60 s frame (ms, 1 thread)" : labels.x, {ox + margin_l, panel_h - 20});
    text(img, labels.y.empty() ? "tumour-centroid error (mm)" : labels.y, {ox + 5, margin_t - 8}, 0.4);
    // Points: filled = fine mesh, hollow = coarse; unhealthy runs are not drawn.
    std::vector<std::pair<double, double>> pts;
    for (const auto& r : result.rows) {
      if (r.scenario != scenarios[p] || r.median_frame_cpu_ms <= 0) continue;
      const cv::Point c(X(r.median_frame_cpu_ms), Y(r.tumour_error_mm));
      if (!r.healthy) {  // reported unhealthy: a cross, and not on the front
        cv::line(img, c + cv::Point(-5, -5), c + cv::Point(5, 5), colour_of(r.config.kind), 2, cv::LINE_AA);
        cv::line(img, c + cv::Point(-5, 5), c + cv::Point(5, -5), colour_of(r.config.kind), 2, cv::LINE_AA);
        continue;
      }
      cv::circle(img, c, 5, colour_of(r.config.kind), r.mesh == "fine" ? cv::FILLED : 2, cv::LINE_AA);
      pts.emplace_back(r.median_frame_cpu_ms, r.tumour_error_mm);
    }
    // Pareto front: points no other point beats in both time and error.
    std::sort(pts.begin(), pts.end());
    std::vector<cv::Point> front;
    double best = INFINITY;
    for (const auto& [t, e] : pts)
      if (e < best) {
        best = e;
        front.emplace_back(X(t), Y(e));
      }
    if (front.size() > 1) cv::polylines(img, front, false, kBlack, 1, cv::LINE_AA);
  }
  // Legend.
  int lx = 20;
  const int ly = panel_h + 40;
  for (const char* kind : {"xpbd", "mass_spring", "corotational_fem"}) {
    cv::circle(img, {lx, ly - 5}, 5, colour_of(kind), cv::FILLED, cv::LINE_AA);
    text(img, kind, {lx + 10, ly});
    lx += 170;
  }
  int ref_tets = 0;
  for (const auto& r : result.rows) ref_tets = std::max(ref_tets, r.reference_tets);
  text(img, labels.note.empty() ? "filled: fine mesh, hollow: coarse, x: unhealthy run; line: Pareto front; error against the FEM static equilibrium on " +
                                      std::to_string(ref_tets) + " tets"
                                : labels.note,
       {lx, ly}, 0.4);
  if (!cv::imwrite(path, img)) throw std::runtime_error(path + ": cannot write the PNG");
}

}  // namespace arnav::host
