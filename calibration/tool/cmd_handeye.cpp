// arnav-calib handeye: X_CamNdi and X_<Tool>Board from the hybrid target (an AprilTag
// board fixed to an NDI tool), seen by the camera and the tracker in N positions.
#include <memory>

#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/hand_eye.hpp"
#include "calibration/lib/plot.hpp"
#include "calibration/lib/pose_file.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "calibration/tool/commands.hpp"
#include "calibration/tool/image_views.hpp"
#include "calibration/tool/report.hpp"

namespace arnav::calib::tool {

namespace {
struct HandEyeArgs {
  std::string ndi_poses, cam_poses, images, intrinsics, board, method = "axzb-shah", tool = "Tool", out = ".";
  double min_spread_deg = 10.0;
};

Eigen::Isometry3d board_pose(const BoardObservation& obs, const CameraIntrinsics& in) {
  return board_pose_pnp(obs.board_mm, obs.image_px, in, "hand-eye board pose");
}
}  // namespace

Run add_handeye_command(CLI::App& app) {
  auto a = std::make_shared<HandEyeArgs>();
  CLI::App* c = app.add_subcommand("handeye", "Hand-eye between camera and tracker with a hybrid target (AX=XB or AX=ZB)");
  c->add_option("--ndi-poses", a->ndi_poses, "X_NdiTool of the hybrid target, one row-major 4x4 per line (mm)")->required();
  auto* cp = c->add_option("--cam-poses", a->cam_poses, "X_CamBoard per line, paired line by line with --ndi-poses");
  auto* im = c->add_option("--images", a->images, "folder of images (name order = pose order); needs --intrinsics and --board");
  cp->excludes(im);
  c->add_option("--intrinsics", a->intrinsics, "camera.yaml (with --images)");
  c->add_option("--board", a->board, "board layout YAML of the hybrid target (with --images)");
  c->add_option("--method", a->method, "axzb-shah, axzb-li, axxb-tsai, axxb-park, axxb-horaud, axxb-andreff, axxb-daniilidis")
      ->capture_default_str();
  c->add_option("--tool", a->tool, "NDI tool frame name of the hybrid target")->capture_default_str();
  c->add_option("--min-spread-deg", a->min_spread_deg, "reject pose sets with less rotation spread")->capture_default_str();
  c->add_option("--out", a->out, "output folder")->capture_default_str();
  return [a] {
    if (!valid_frame_name(a->tool)) throw CalibError("--tool '" + a->tool + "': use a frame name like Tool or Ref");
    HandEyeOptions o;
    o.method = parse_hand_eye_method(a->method);
    o.min_rotation_spread_deg = a->min_spread_deg;
    const auto ndi = read_pose_list(a->ndi_poses);
    std::vector<Eigen::Isometry3d> X_NdiTool, X_CamBoard;
    std::vector<std::string> skipped;
    if (!a->cam_poses.empty()) {
      const auto cam = read_pose_list(a->cam_poses);
      if (cam.size() != ndi.size()) {
        throw CalibError(a->cam_poses + " has " + std::to_string(cam.size()) + " poses but " + a->ndi_poses + " has " +
                         std::to_string(ndi.size()) + ": they must be paired line by line");
      }
      for (std::size_t i = 0; i < ndi.size(); ++i) {
        X_NdiTool.push_back(ndi[i].X_ParentChild);
        X_CamBoard.push_back(cam[i].X_ParentChild);
      }
    } else {
      if (a->images.empty() || a->intrinsics.empty() || a->board.empty()) {
        throw CalibError("handeye: give --cam-poses FILE, or --images FOLDER with --intrinsics and --board");
      }
      const CameraIntrinsics in = read_intrinsics(a->intrinsics);
      const BoardLayout layout = read_board_layout(a->board);
      const auto files = list_images(a->images);
      if (files.size() != ndi.size()) {
        throw CalibError(a->images + " holds " + std::to_string(files.size()) + " images but " + a->ndi_poses + " has " +
                         std::to_string(ndi.size()) + " poses: one image per pose, in name order");
      }
      cv::Size size;
      const auto views = observe_images(files, layout, size);
      if (size.width != in.image_width || size.height != in.image_height) {
        throw CalibError(a->intrinsics + ": calibrated for " + std::to_string(in.image_width) + "x" +
                         std::to_string(in.image_height) + " but the images are " + std::to_string(size.width) + "x" +
                         std::to_string(size.height));
      }
      for (std::size_t i = 0; i < views.size(); ++i) {
        if (!views[i].observation.found) {
          skipped.push_back(views[i].name + ": " + views[i].observation.reason + " (pose " + a->ndi_poses + ":" +
                            std::to_string(ndi[i].line) + " skipped)");
          continue;
        }
        X_NdiTool.push_back(ndi[i].X_ParentChild);
        X_CamBoard.push_back(board_pose(views[i].observation, in));
      }
    }
    const HandEyeResult res = calibrate_hand_eye(X_NdiTool, X_CamBoard, o);
    const auto dir = prepare_out_dir(a->out);
    Report r(dir, "handeye");
    for (const auto& s : skipped) r.line("  skipped " + s);
    r.kv("pose pairs", X_NdiTool.size());
    r.kv("method", res.summary.method);
    r.kv("rotation spread of the target", res.rotation_spread_deg, " deg");
    r.kv("residual X_CamBoard (model vs camera)", "RMS ", res.rms_mm, " mm, max ", res.max_mm, " mm, RMS ", res.rms_deg, " deg");
    r.kv("X_CamNdi translation", res.X_CamNdi.translation().transpose(), " mm");
    r.kv("X_" + a->tool + "Board translation", res.X_ToolBoard.translation().transpose(), " mm");
    // Both formulations side by side: a large disagreement means inconsistent data.
    r.line("  all formulations on the same data (RMS mm / deg of X_CamBoard residuals):");
    for (auto m : {HandEyeMethod::AXZB_Shah, HandEyeMethod::AXZB_Li, HandEyeMethod::AXXB_Tsai, HandEyeMethod::AXXB_Park,
                   HandEyeMethod::AXXB_Horaud, HandEyeMethod::AXXB_Andreff, HandEyeMethod::AXXB_Daniilidis}) {
      HandEyeOptions other = o;
      other.method = m;
      try {
        const HandEyeResult h = calibrate_hand_eye(X_NdiTool, X_CamBoard, other);
        std::ostringstream s;
        s.precision(4);
        s << "    " << to_string(m) << ": " << h.rms_mm << " mm / " << h.rms_deg << " deg; |dt X_CamNdi| vs chosen "
          << (h.X_CamNdi.translation() - res.X_CamNdi.translation()).norm() << " mm";
        r.line(s.str());
      } catch (const CalibError& e) {
        r.line("    " + to_string(m) + ": failed (" + e.what() + ")");
      }
    }
    const std::string date = utc_now_iso8601();
    const std::map<std::string, double> residuals = {{"rms_mm", res.rms_mm}, {"max_mm", res.max_mm}, {"rms_deg", res.rms_deg}};
    RigidTransformRecord cam_ndi{"Cam", "Ndi", res.X_CamNdi, res.summary.method, date, residuals, static_cast<int>(X_NdiTool.size())};
    RigidTransformRecord tool_board{a->tool, "Board", res.X_ToolBoard, res.summary.method, date, residuals,
                                    static_cast<int>(X_NdiTool.size())};
    write_transform(dir / "X_CamNdi.yaml", cam_ndi);
    write_transform(dir / (tool_board.name() + ".yaml"), tool_board);
    r.file(dir / "X_CamNdi.yaml", "camera <- tracker");
    r.file(dir / (tool_board.name() + ".yaml"), "hybrid target: tool <- board");
    const Chart chart = residual_chart("Hand-eye residual per pose (" + to_string(o.method) + ")", "pose",
                                       "|t_pred - t_cam| mm", res.translation_residual_mm, res.rms_mm);
    write_chart(dir / "handeye_residuals.png", chart);
    r.file(dir / "handeye_residuals.png", "residual plot");
    r.save();
  };
}

}  // namespace arnav::calib::tool
