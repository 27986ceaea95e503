// arnav-calib pivot: tip of an NDI pointer from poses recorded while pivoting in a divot.
#include <fstream>
#include <memory>

#include <nlohmann/json.hpp>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/pivot_calibration.hpp"
#include "calibration/lib/plot.hpp"
#include "calibration/lib/pose_file.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "calibration/tool/commands.hpp"
#include "calibration/tool/report.hpp"

namespace arnav::calib::tool {

namespace {
struct PivotArgs {
  std::string poses, method = "algebraic", tool = "Tool", out = ".";
  double min_spread_deg = 15.0, ransac_mm = 1.0;
};
}  // namespace

Run add_pivot_command(CLI::App& app) {
  auto a = std::make_shared<PivotArgs>();
  CLI::App* c = app.add_subcommand("pivot", "Pivot calibration of a tool tip (poses X_NdiTool, one row-major 4x4 per line, mm)");
  c->add_option("--poses", a->poses, "pose file: 16 numbers per line (row-major X_NdiTool, mm)")->required();
  c->add_option("--method", a->method, "algebraic, sphere or ransac")->check(CLI::IsMember({"algebraic", "sphere", "ransac"}))->capture_default_str();
  c->add_option("--tool", a->tool, "tool frame name written into X_<tool>Tip.yaml")->capture_default_str();
  c->add_option("--min-spread-deg", a->min_spread_deg, "reject pose sets with less rotation spread")->capture_default_str();
  c->add_option("--ransac-inlier-mm", a->ransac_mm, "RANSAC inlier threshold")->capture_default_str();
  c->add_option("--out", a->out, "output folder")->capture_default_str();
  return [a] {
    if (!valid_frame_name(a->tool)) throw CalibError("--tool '" + a->tool + "': use a frame name like Tool, Pointer, Probe2");
    const auto samples = read_pose_list(a->poses);
    std::vector<Eigen::Isometry3d> poses;
    for (const auto& s : samples) poses.push_back(s.X_ParentChild);
    PivotOptions o;
    o.method = parse_pivot_method(a->method);
    o.min_rotation_spread_deg = a->min_spread_deg;
    o.ransac_inlier_mm = a->ransac_mm;
    const PivotResult res = calibrate_pivot(poses, o);
    const auto dir = prepare_out_dir(a->out);
    Report r(dir, "pivot");
    r.kv("input", a->poses, " (", poses.size(), " poses)");
    r.kv("method", res.summary.method);
    r.kv("p_" + a->tool + "Tip_mm (tip in the tool frame)", res.p_ToolTip_mm.transpose());
    r.kv("p_NdiPivot_mm (divot in the tracker frame)", res.p_NdiPivot_mm.transpose());
    r.kv("rms residual", res.rms_mm, " mm, max ", res.max_mm, " mm");
    r.kv("rotation spread", res.rotation_spread_deg, " deg; rank ", res.rank, "; condition ", res.condition_number);
    r.kv("solver", res.summary.termination, ", ", res.summary.iterations, " iterations, ", res.summary.wall_time_s * 1e3, " ms");
    int outliers = 0;
    for (std::size_t i = 0; i < res.inlier.size(); ++i) {
      if (!res.inlier[i]) {
        ++outliers;
        r.line("  outlier: " + a->poses + ":" + std::to_string(samples[i].line) + " residual " +
               std::to_string(res.residual_mm[i]) + " mm");
      }
    }
    if (outliers > 0) r.kv("outliers", outliers, " of ", poses.size());

    nlohmann::json j;
    j["tool"] = a->tool;
    j["p_ToolTip_mm"] = {res.p_ToolTip_mm.x(), res.p_ToolTip_mm.y(), res.p_ToolTip_mm.z()};
    j["p_NdiPivot_mm"] = {res.p_NdiPivot_mm.x(), res.p_NdiPivot_mm.y(), res.p_NdiPivot_mm.z()};
    j["rms_residual_mm"] = res.rms_mm;
    j["max_residual_mm"] = res.max_mm;
    j["method"] = to_string(o.method);
    j["method_detail"] = res.summary.method;
    j["poses"] = poses.size();
    j["inliers"] = static_cast<int>(poses.size()) - outliers;
    j["rotation_spread_deg"] = res.rotation_spread_deg;
    j["date"] = utc_now_iso8601();
    j["units"] = "mm";
    const auto json_path = dir / "pivot.json";
    std::ofstream(json_path) << j.dump(2) << "\n";
    r.file(json_path, "pivot result");

    RigidTransformRecord tip;
    tip.parent_frame = a->tool;
    tip.child_frame = "Tip";
    tip.X_ParentChild.translation() = res.p_ToolTip_mm;
    tip.method = res.summary.method;
    tip.date = utc_now_iso8601();
    tip.samples = static_cast<int>(poses.size()) - outliers;
    tip.residuals = {{"rms_mm", res.rms_mm}, {"max_mm", res.max_mm}, {"rotation_spread_deg", res.rotation_spread_deg}};
    const auto tip_path = dir / ("X_" + a->tool + "Tip.yaml");
    write_transform(tip_path, tip);
    r.file(tip_path, "X_" + a->tool + "Tip: tip point, axes parallel to the tool frame");

    const Chart chart = residual_chart("Pivot residual per pose (" + to_string(o.method) + ")", "pose (file order)",
                                       "|R p_tip + t - p_pivot| mm", res.residual_mm, res.rms_mm);
    write_chart(dir / "pivot_residuals.png", chart);
    r.file(dir / "pivot_residuals.png", "residual plot");
    r.save();
  };
}

}  // namespace arnav::calib::tool
