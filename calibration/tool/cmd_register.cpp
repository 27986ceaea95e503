// arnav-calib register: paired-point rigid registration with FRE and predicted TRE.
#include <memory>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/plot.hpp"
#include "calibration/lib/point_registration.hpp"
#include "calibration/lib/pose_file.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "calibration/tool/commands.hpp"
#include "calibration/tool/report.hpp"

namespace arnav::calib::tool {

namespace {
struct RegisterArgs {
  std::string fixed, moving, fixed_frame = "Ref", moving_frame = "Model", out = ".";
  std::vector<double> target;
};
}  // namespace

Run add_register_command(CLI::App& app) {
  auto a = std::make_shared<RegisterArgs>();
  CLI::App* c = app.add_subcommand("register", "Paired-point rigid registration X_FixedMoving (Umeyama + reflection guard, FRE, TRE)");
  c->add_option("--fixed", a->fixed, "fiducials in the fixed frame: x y z per line, mm")->required();
  c->add_option("--moving", a->moving, "the same fiducials, same order, in the moving frame")->required();
  c->add_option("--fixed-frame", a->fixed_frame, "fixed frame name")->capture_default_str();
  c->add_option("--moving-frame", a->moving_frame, "moving frame name")->capture_default_str();
  c->add_option("--target", a->target, "target point in the moving frame (x y z, mm) for the TRE prediction")->expected(3);
  c->add_option("--out", a->out, "output folder")->capture_default_str();
  return [a] {
    for (const auto& f : {a->fixed_frame, a->moving_frame}) {
      if (!valid_frame_name(f)) throw CalibError("frame name '" + f + "': letters/digits starting upper-case (Ref, Model)");
    }
    const auto p_fixed = read_point_list(a->fixed);
    const auto p_moving = read_point_list(a->moving);
    if (p_fixed.size() != p_moving.size()) {
      throw CalibError(a->fixed + " has " + std::to_string(p_fixed.size()) + " points but " + a->moving + " has " +
                       std::to_string(p_moving.size()) + ": list the same fiducials in the same order");
    }
    const auto res = register_paired_points(p_fixed, p_moving);
    const auto dir = prepare_out_dir(a->out);
    const std::string name = "X_" + a->fixed_frame + a->moving_frame;
    Report r(dir, "register");
    r.kv("fiducials", p_fixed.size(), " (", a->fixed, " <- ", a->moving, ")");
    r.kv("method", res.summary.method);
    r.kv("FRE (RMS)", res.fre_rms_mm, " mm");
    r.kv("FLE estimate", res.fle_rms_mm, " mm (FRE * sqrt(N/(N-2)))");
    if (res.reflection_guarded) {
      r.line("  WARNING: the best orthogonal fit was a reflection; the guard kept a rotation. Check that the");
      r.line("  fiducials are listed in the same order in both files and not mirrored.");
    }
    for (std::size_t i = 0; i < res.residual_mm.size(); ++i) {
      r.kv("fiducial " + std::to_string(i + 1) + " residual", res.residual_mm[i], " mm");
    }
    if (a->target.size() == 3) {
      const Eigen::Vector3d t_moving(a->target[0], a->target[1], a->target[2]);
      r.kv("predicted TRE at target (Fitzpatrick 1998)", predicted_tre_mm(res, res.X_AB * t_moving), " mm RMS");
    }
    r.kv("predicted TRE at the fiducial centroid", predicted_tre_mm(res, res.centroid_A), " mm RMS");
    RigidTransformRecord rec;
    rec.parent_frame = a->fixed_frame;
    rec.child_frame = a->moving_frame;
    rec.X_ParentChild = res.X_AB;
    rec.method = res.summary.method;
    rec.date = utc_now_iso8601();
    rec.samples = static_cast<int>(p_fixed.size());
    rec.residuals = {{"fre_rms_mm", res.fre_rms_mm}, {"fle_estimate_mm", res.fle_rms_mm}};
    const auto path = dir / (name + ".yaml");
    write_transform(path, rec);
    r.file(path, name);
    Chart chart;
    chart.title = "Registration residual per fiducial";
    chart.x_label = "fiducial";
    chart.y_label = "residual mm";
    PlotSeries s{"residual", {}, res.residual_mm, {}, SeriesStyle::Bars, cv::Scalar(200, 90, 20)};
    for (std::size_t i = 0; i < res.residual_mm.size(); ++i) {
      s.x.push_back(static_cast<double>(i));
      chart.x_tick_labels.push_back(std::to_string(i + 1));
    }
    chart.series.push_back(s);
    chart.reference_y = res.fre_rms_mm;
    chart.reference_label = "FRE";
    write_chart(dir / "registration_residuals.png", chart);
    r.file(dir / "registration_residuals.png", "residual plot");
    r.save();
  };
}

}  // namespace arnav::calib::tool
