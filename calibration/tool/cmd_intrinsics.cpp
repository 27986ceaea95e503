// arnav-calib intrinsics: camera intrinsics from an image folder or a live camera.
#include <memory>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/intrinsics_calibration.hpp"
#include "calibration/lib/plot.hpp"
#include "calibration/tool/commands.hpp"
#include "calibration/tool/image_views.hpp"
#include "calibration/tool/report.hpp"

namespace arnav::calib::tool {

namespace {
struct IntrinsicsArgs {
  std::string board, images, out = ".", name = "camera";
  int camera = -1, views = 20, max_frames = 2000, every = 15, min_views = 5;
  bool fix_k3 = false;
  double outlier_factor = 3.0;
};

void write_coverage_png(const std::filesystem::path& path, cv::Size size, const std::vector<CalibrationView>& views,
                        const IntrinsicsResult& res) {
  cv::Mat img(size, CV_8UC3, cv::Scalar(255, 255, 255));
  const int rows = res.coverage_cells.rows, cols = res.coverage_cells.cols;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const cv::Rect cell(c * size.width / cols, r * size.height / rows, size.width / cols, size.height / rows);
      if (res.coverage_cells.at<int>(r, c) == 0) cv::rectangle(img, cell, cv::Scalar(200, 200, 255), cv::FILLED);
      cv::rectangle(img, cell, cv::Scalar(180, 180, 180), 1);
    }
  }
  for (std::size_t i = 0; i < views.size(); ++i) {
    const bool used = res.views[i].used;
    for (const auto& p : views[i].image_px) {
      cv::circle(img, p, 2, used ? cv::Scalar(160, 80, 0) : cv::Scalar(0, 0, 220), cv::FILLED);
    }
  }
  cv::putText(img, "coverage " + std::to_string(static_cast<int>(100 * res.coverage)) + "% (red cells: no corner)",
              cv::Point(10, 25), cv::FONT_HERSHEY_SIMPLEX, 0.7, cv::Scalar(0, 0, 0), 2);
  if (!cv::imwrite(path.string(), img)) throw CalibError(path.string() + ": cannot write");
}
}  // namespace

Run add_intrinsics_command(CLI::App& app) {
  auto a = std::make_shared<IntrinsicsArgs>();
  CLI::App* c = app.add_subcommand("intrinsics", "Camera intrinsics from a chessboard or AprilTag grid (image folder or live camera)");
  c->add_option("--board", a->board, "board layout YAML (from arnav-calib board)")->required();
  auto* img = c->add_option("--images", a->images, "folder of images of the board");
  auto* cam = c->add_option("--camera", a->camera, "live camera index (cv::VideoCapture)");
  img->excludes(cam);
  c->add_option("--views", a->views, "live camera: views to collect")->capture_default_str();
  c->add_option("--every", a->every, "live camera: keep one frame in N")->capture_default_str();
  c->add_option("--max-frames", a->max_frames, "live camera: give up after N frames")->capture_default_str();
  c->add_option("--min-views", a->min_views, "fewest usable views accepted")->capture_default_str();
  c->add_option("--outlier-factor", a->outlier_factor, "reject views with RMS > factor x median")->capture_default_str();
  c->add_flag("--fix-k3", a->fix_k3, "keep k3 = 0 (few or flat views)");
  c->add_option("--name", a->name, "camera name stored in the file")->capture_default_str();
  c->add_option("--out", a->out, "output folder")->capture_default_str();
  return [a] {
    if (a->images.empty() && a->camera < 0) throw CalibError("intrinsics: give --images FOLDER or --camera INDEX");
    const BoardLayout layout = read_board_layout(a->board);
    cv::Size size;
    const std::vector<ImageView> observed = a->images.empty()
        ? observe_camera(a->camera, layout, a->views, a->max_frames, a->every, size)
        : observe_images(list_images(a->images), layout, size);
    const auto dir = prepare_out_dir(a->out);
    Report r(dir, "intrinsics");
    r.kv("board", a->board, " (", layout.name, ")");
    std::vector<CalibrationView> views;
    std::string skipped;
    for (const auto& v : observed) {
      if (v.observation.found) {
        views.push_back({v.name, v.observation.image_px, v.observation.board_mm});
      } else {
        r.line("  skipped " + v.name + ": " + v.observation.reason);
        skipped += "\n  " + v.name + ": " + v.observation.reason;
      }
    }
    IntrinsicsOptions o;
    o.fix_k3 = a->fix_k3;
    o.min_views = a->min_views;
    o.outlier_factor = a->outlier_factor;
    IntrinsicsResult res;
    try {
      if (size.empty()) throw DegenerateInput("intrinsics: no readable image");
      res = calibrate_intrinsics(views, size, o);
    } catch (const DegenerateInput& e) {
      throw DegenerateInput(std::string(e.what()) + (skipped.empty() ? "" : "\n skipped before calibration:" + skipped));
    }
    res.intrinsics.camera_name = a->name;
    const auto& K = res.intrinsics.camera_matrix;
    r.kv("image size", size.width, " x ", size.height, " px");
    r.kv("views", res.intrinsics.views_used, " used of ", observed.size());
    r.kv("RMS reprojection error", res.intrinsics.rms_reprojection_error_px, " px");
    r.kv("fx fy cx cy", K(0, 0), " ", K(1, 1), " ", K(0, 2), " ", K(1, 2), " px");
    std::ostringstream d;
    for (double x : res.intrinsics.distortion) d << x << " ";
    r.kv("distortion (k1 k2 p1 p2 k3)", d.str());
    r.kv("coverage", 100.0 * res.coverage, " % of ", o.coverage_cols, "x", o.coverage_rows, " image cells hold a corner");
    if (res.coverage < 0.5) r.line("  WARNING: less than half the image covered: add views with the board near the image corners.");
    for (const auto& v : res.views) {
      r.line("  view " + v.name + ": " + (v.used ? "used" : "REJECTED (" + v.reason + ")") + ", " +
             std::to_string(v.points) + " corners, RMS " + std::to_string(v.rms_px) + " px");
    }
    r.kv("solver", res.summary.termination, ", ", res.summary.wall_time_s, " s");
    const auto yaml = dir / "camera.yaml";
    write_intrinsics(yaml, res.intrinsics);
    r.file(yaml, "intrinsics, OpenCV FileStorage YAML");
    Chart chart;
    chart.title = "Reprojection error per view";
    chart.x_label = "view";
    chart.y_label = "RMS px";
    PlotSeries used{"used", {}, {}, {}, SeriesStyle::Bars, cv::Scalar(200, 90, 20)};
    PlotSeries rejected{"rejected", {}, {}, {}, SeriesStyle::Bars, cv::Scalar(40, 40, 220)};
    for (std::size_t i = 0; i < res.views.size(); ++i) {
      (res.views[i].used ? used : rejected).x.push_back(static_cast<double>(i));
      (res.views[i].used ? used : rejected).y.push_back(res.views[i].rms_px);
      chart.x_tick_labels.push_back(std::to_string(i));
    }
    chart.series = {used, rejected};
    chart.reference_y = res.intrinsics.rms_reprojection_error_px;
    chart.reference_label = "overall RMS";
    write_chart(dir / "per_view_error.png", chart);
    r.file(dir / "per_view_error.png", "per-view error plot");
    write_coverage_png(dir / "coverage.png", size, views, res);
    r.file(dir / "coverage.png", "corner coverage of the image");
    r.save();
  };
}

}  // namespace arnav::calib::tool
