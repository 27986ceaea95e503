// arnav-camera-bench: speed and accuracy of the camera path on synthetic frames.
//   latency  detection + pose per frame, 1280x720, the 2x2-tag marker board, one core
//            (AprilTag nthreads = 1): p50/p99/max, wall and process CPU time, as JSON.
//   sweep    translation and rotation error against ground truth, and run time, over
//            distance, viewing angle, noise and blur, for decimation 1/2/4 and 1/2
//            threads: CSV (one row per setting) + PNG chart.
// Frames come from the synthetic camera (appliance/synthetic_camera); the board layout from the
// calibration library's marker-board generator (what arnav-calib prints).
#include <CLI/CLI.hpp>
#include <opencv2/imgcodecs.hpp>

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>

#include "appliance/markers/board_pose.hpp"
#include "appliance/markers/calibration_files.hpp"
#include "appliance/markers/tag_detector.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"
#include "appliance/synthetic_camera/trajectory.hpp"
#include "plot.hpp"
#include "protocol/guarded_main.hpp"

namespace {

using namespace arnav;
constexpr double kDeg = std::numbers::pi / 180.0;

double now_s(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto i = static_cast<size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

markers::CameraModel bench_camera() {
  markers::CameraModel cam = markers::pinhole_camera(1280, 720, 70.0);
  cam.distortion = {-0.12, 0.03, 0.0004, -0.0003, 0.0};  // a typical HD webcam lens
  return cam;
}

markers::TagBoard bench_board() {
  // Paper 000's marker: four tags around a free centre; 40 mm tags, 30 mm gap.
  return markers::board_from_layout(calib::make_marker_board("tag36h11", 40.0, 30.0, 0, 10.0), "marker", "generated");
}

Eigen::Vector2d board_centre(const markers::TagBoard& b) { return markers::paper_outline(b, 0).center(); }

struct Timed {
  double wall_ms, cpu_ms;
  markers::PoseOutcome outcome;
};

Timed detect_and_solve(markers::TagDetector& det, const markers::BoardPoseEstimator& est, const cv::Mat& img) {
  // Process CPU time: includes AprilTag's worker threads (threads = 2), and unlike wall
  // time it is not inflated by the other builds sharing the machine.
  const double w0 = now_s(CLOCK_MONOTONIC), c0 = now_s(CLOCK_PROCESS_CPUTIME_ID);
  const auto dets = det.detect(img);
  markers::PoseOutcome out = est.estimate(dets);
  return {1e3 * (now_s(CLOCK_MONOTONIC) - w0), 1e3 * (now_s(CLOCK_PROCESS_CPUTIME_ID) - c0), std::move(out)};
}

int run_latency(int frames, double noise, double blur, double quad_sigma) {
  const auto cam = bench_camera();
  const auto board = bench_board();
  camera_sim::SyntheticRenderer renderer(cam);
  camera_sim::Trajectory tr;
  tr.distance_mm = 550;
  tr.amplitude_mm = Eigen::Vector3d(150, 80, 150);
  tr.period_s = frames / 30.0;
  std::vector<cv::Mat> images;
  camera_sim::RenderOptions opt;
  opt.noise_sigma = noise;
  opt.blur_sigma_px = blur;
  for (int k = 0; k < frames; ++k) {
    opt.noise_seed = static_cast<std::uint64_t>(k + 1);
    images.push_back(renderer.render({{&board, tr.X_CamBoard(k / 30.0, board_centre(board), markers::front_side(board))}}, opt).image);
  }
  const markers::BoardPoseEstimator est(board, cam);
  std::cout << "{\n  \"benchmark\": \"camera detection + pose\",\n  \"image\": \"1280x720\",\n  \"tags\": 4,\n"
            << "  \"frames\": " << frames << ",\n  \"noise_sigma\": " << noise << ",\n  \"blur_sigma_px\": " << blur
            << ",\n  \"quad_sigma\": " << quad_sigma << ",\n  \"results\": [\n";
  const double decimations[] = {1.0, 2.0, 4.0};
  for (size_t d = 0; d < 3; ++d) {
    markers::DetectorSettings s;
    s.decimate = decimations[d];
    s.threads = 1;
    s.sigma = quad_sigma;
    markers::TagDetector det(s);
    detect_and_solve(det, est, images[0]);  // warm-up (allocations)
    std::vector<double> wall, cpu;
    int found = 0;
    for (const auto& img : images) {
      const Timed t = detect_and_solve(det, est, img);
      wall.push_back(t.wall_ms);
      cpu.push_back(t.cpu_ms);
      found += t.outcome.pose && t.outcome.pose->tags_used == 4;
    }
    std::printf("    {\"decimate\": %.0f, \"threads\": 1, \"all_4_tags_rate\": %.3f, \"wall_ms\": {\"p50\": %.2f, \"p99\": %.2f, "
                "\"max\": %.2f}, \"cpu_ms\": {\"p50\": %.2f, \"p99\": %.2f, \"max\": %.2f}, \"target_p99_ms\": 6.0, "
                "\"target_met_cpu\": %s, \"target_met_wall\": %s}%s\n",
                s.decimate, static_cast<double>(found) / frames, percentile(wall, 0.5), percentile(wall, 0.99),
                *std::max_element(wall.begin(), wall.end()), percentile(cpu, 0.5), percentile(cpu, 0.99),
                *std::max_element(cpu.begin(), cpu.end()), percentile(cpu, 0.99) <= 6.0 ? "true" : "false",
                percentile(wall, 0.99) <= 6.0 ? "true" : "false", d + 1 < 3 ? "," : "");
  }
  std::cout << "  ]\n}\n";
  return 0;
}

struct Setting {
  std::string factor;
  double distance_mm, angle_deg, noise, blur;
};

struct Row {
  Setting s;
  double decimate;
  int threads;
  int frames, detected;
  double t_med, t_p90, r_med, r_p90, time_med, time_p99, cpu_med;
};

int run_sweep(int frames_per_point, const std::string& csv_path, const std::string& png_path) {
  const auto cam = bench_camera();
  const auto board = bench_board();
  const Eigen::Vector2d c = board_centre(board);
  const int side = markers::front_side(board);
  camera_sim::SyntheticRenderer renderer(cam);
  const markers::BoardPoseEstimator est(board, cam);
  const Setting nominal{"nominal", 600, 30, 2, 0.5};
  std::vector<Setting> settings;
  for (double d : {300.0, 450.0, 600.0, 900.0, 1200.0, 1600.0}) settings.push_back({"distance", d, nominal.angle_deg, nominal.noise, nominal.blur});
  for (double a : {0.0, 15.0, 30.0, 45.0, 60.0, 70.0}) settings.push_back({"angle", nominal.distance_mm, a, nominal.noise, nominal.blur});
  for (double n : {0.0, 2.0, 5.0, 10.0, 20.0}) settings.push_back({"noise", nominal.distance_mm, nominal.angle_deg, n, nominal.blur});
  for (double b : {0.0, 0.5, 1.0, 2.0, 3.0}) settings.push_back({"blur", nominal.distance_mm, nominal.angle_deg, nominal.noise, b});

  std::vector<Row> rows;
  std::mt19937 rng(42);
  for (const auto& s : settings) {
    // Frames of this setting: the board centre on the optical axis region, tilted by the
    // angle about a random in-plane axis, random spin.
    std::vector<cv::Mat> images;
    std::vector<Eigen::Isometry3d> truths;
    std::uniform_real_distribution<double> u(0, 2 * std::numbers::pi), off(-60, 60);
    for (int k = 0; k < frames_per_point; ++k) {
      const double axis = u(rng);
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.linear() = (Eigen::AngleAxisd(side > 0 ? std::numbers::pi : 0.0, Eigen::Vector3d::UnitX()) *
                    Eigen::AngleAxisd(s.angle_deg * kDeg, Eigen::Vector3d(std::cos(axis), std::sin(axis), 0)) *
                    Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitZ()))
                       .toRotationMatrix();
      const Eigen::Vector3d p_CamCentre(off(rng) * s.distance_mm / 600, off(rng) * s.distance_mm / 1200, s.distance_mm);
      X.translation() = p_CamCentre - X.linear() * Eigen::Vector3d(c.x(), c.y(), 0);
      camera_sim::RenderOptions opt;
      opt.noise_sigma = s.noise;
      opt.blur_sigma_px = s.blur;
      opt.noise_seed = static_cast<std::uint64_t>(rng());
      images.push_back(renderer.render({{&board, X}}, opt).image);
      truths.push_back(X);
    }
    for (double decimate : {1.0, 2.0, 4.0}) {
      for (int threads : {1, 2}) {
        markers::DetectorSettings ds;
        ds.decimate = decimate;
        ds.threads = threads;
        markers::TagDetector det(ds);
        std::vector<double> t_err, r_err, wall, cpu;
        int detected = 0;
        for (size_t k = 0; k < images.size(); ++k) {
          const Timed t = detect_and_solve(det, est, images[k]);
          wall.push_back(t.wall_ms);
          cpu.push_back(t.cpu_ms);
          if (!t.outcome.pose) continue;
          ++detected;
          const Eigen::Isometry3d& X = t.outcome.pose->X_CamBoard;
          const Eigen::Vector3d centre(c.x(), c.y(), 0);
          t_err.push_back((X * centre - truths[k] * centre).norm());
          r_err.push_back(Eigen::AngleAxisd(X.linear().transpose() * truths[k].linear()).angle() / kDeg);
        }
        rows.push_back({s, decimate, threads, frames_per_point, detected, percentile(t_err, 0.5), percentile(t_err, 0.9),
                        percentile(r_err, 0.5), percentile(r_err, 0.9), percentile(wall, 0.5), percentile(wall, 0.99),
                        percentile(cpu, 0.5)});
      }
    }
    std::cerr << "sweep: " << s.factor << " done (" << rows.size() << " rows)\n";
  }

  std::ofstream csv(csv_path);
  if (!csv) {
    std::cerr << "arnav-camera-bench: cannot write " << csv_path << "\n";
    return 1;
  }
  csv << "factor,distance_mm,angle_deg,noise_sigma,blur_sigma_px,decimate,threads,frames,detected,"
         "t_err_median_mm,t_err_p90_mm,r_err_median_deg,r_err_p90_deg,time_median_ms,time_p99_ms,cpu_median_ms\n";
  for (const auto& r : rows) {
    char line[512];
    std::snprintf(line, sizeof line, "%s,%.0f,%.0f,%.1f,%.1f,%.0f,%d,%d,%d,%.3f,%.3f,%.3f,%.3f,%.2f,%.2f,%.2f\n",
                  r.s.factor.c_str(), r.s.distance_mm, r.s.angle_deg, r.s.noise, r.s.blur, r.decimate, r.threads, r.frames,
                  r.detected, r.t_med, r.t_p90, r.r_med, r.r_p90, r.time_med, r.time_p99, r.cpu_med);
    csv << line;
  }

  // Chart: error against each factor (threads = 1, one line per decimation), and error
  // against run time over all settings.
  std::vector<bench::Panel> panels;
  const struct {
    const char* factor;
    const char* x_label;
    double Setting::*member;
  } factors[] = {{"distance", "distance to the board (mm)", &Setting::distance_mm},
                 {"angle", "viewing angle (deg)", &Setting::angle_deg},
                 {"noise", "noise sigma (gray levels)", &Setting::noise},
                 {"blur", "blur sigma (px)", &Setting::blur}};
  for (const auto& f : factors) {
    bench::Panel p{std::string("translation error vs ") + f.factor + " (1 thread)", f.x_label, "median mm", {}, false};
    size_t k = 0;
    for (double dec : {1.0, 2.0, 4.0}) {
      bench::Series s{"decimate " + std::to_string(static_cast<int>(dec)), {}, {}, bench::series_color(k++), true};
      for (const auto& r : rows) {
        if (r.s.factor == f.factor && r.decimate == dec && r.threads == 1) {
          s.x.push_back(r.s.*f.member);
          s.y.push_back(r.t_med);
        }
      }
      p.series.push_back(s);
    }
    panels.push_back(p);
  }
  {
    bench::Panel p{"rotation error vs distance (1 thread)", "distance to the board (mm)", "median deg", {}, false};
    size_t k = 0;
    for (double dec : {1.0, 2.0, 4.0}) {
      bench::Series s{"decimate " + std::to_string(static_cast<int>(dec)), {}, {}, bench::series_color(k++), true};
      for (const auto& r : rows) {
        if (r.s.factor == "distance" && r.decimate == dec && r.threads == 1) {
          s.x.push_back(r.s.distance_mm);
          s.y.push_back(r.r_med);
        }
      }
      p.series.push_back(s);
    }
    panels.push_back(p);
  }
  {
    bench::Panel p{"error against run time (all settings but noise)", "median CPU time per frame (ms, log)",
                   "median translation error mm", {}, true};
    size_t k = 0;
    for (double dec : {1.0, 2.0, 4.0}) {
      for (int th : {1, 2}) {
        bench::Series s{"dec " + std::to_string(static_cast<int>(dec)) + ", " + std::to_string(th) + " thr", {}, {},
                        bench::series_color(k++), false};
        for (const auto& r : rows) {
          if (r.decimate == dec && r.threads == th && r.s.factor != "noise") {  // noise 20 dominates the scale
            s.x.push_back(r.cpu_med);
            s.y.push_back(r.t_med);
          }
        }
        p.series.push_back(s);
      }
    }
    panels.push_back(p);
  }
  const cv::Mat chart = bench::draw_panels(panels, 3, cv::Size(520, 380));
  if (!cv::imwrite(png_path, chart)) {
    std::cerr << "arnav-camera-bench: cannot write " << png_path << "\n";
    return 1;
  }
  std::cout << "{\"rows\": " << rows.size() << ", \"csv\": \"" << csv_path << "\", \"png\": \"" << png_path << "\"}\n";
  return 0;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-camera-bench: camera path speed (latency) and accuracy against run time (sweep) on synthetic frames"};
  app.require_subcommand(1);
  int frames = 200;
  double noise = 2.0, blur = 0.5;
  auto* lat = app.add_subcommand("latency", "detection + pose per frame, 1280x720, 4 tags, one core: JSON p50/p99");
  lat->add_option("--frames", frames, "frames to time")->check(CLI::Range(10, 100000));
  lat->add_option("--noise", noise, "sensor noise sigma (gray levels)")->check(CLI::Range(0.0, 100.0));
  lat->add_option("--blur", blur, "blur sigma (px)")->check(CLI::Range(0.0, 20.0));
  double quad_sigma = 0.0;
  lat->add_option("--quad-sigma", quad_sigma, "detector sigma (Gaussian blur before segmentation; 0.8 for noisy images)")
      ->check(CLI::Range(0.0, 10.0));
  int per_point = 12;
  std::string csv = "camera_sweep.csv", png = "camera_sweep.png";
  auto* sweep = app.add_subcommand("sweep", "error vs distance/angle/noise/blur for decimation 1/2/4, threads 1/2: CSV + PNG");
  sweep->add_option("--frames-per-point", per_point, "frames per setting")->check(CLI::Range(1, 1000));
  sweep->add_option("--csv", csv, "CSV output");
  sweep->add_option("--png", png, "chart output");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  if (*lat) return run_latency(frames, noise, blur, quad_sigma);
  return run_sweep(per_point, csv, png);
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-camera-bench", [&] { return main_body(argc, argv); });
}
