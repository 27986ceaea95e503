#include "calibration/vision/ar_chain_sim.hpp"

#include <chrono>
#include <memory>
#include <cmath>
#include <random>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "appliance/markers/calibration_files.hpp"
#include "appliance/markers/camera_model.hpp"
#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/intrinsics_calibration.hpp"
#include "calibration/lib/pivot_calibration.hpp"
#include "calibration/lib/point_registration.hpp"
#include "calibration/vision/target_detection.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

namespace arnav::calib {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct Bench {
  markers::CameraModel camera;
  Eigen::Isometry3d X_CamNdi;
  Eigen::Isometry3d X_ToolBoard;        // hybrid target: marker board on the Ref tool
  Eigen::Vector3d p_ToolTip;            // pointer tip in the pointer's tool frame
  std::vector<Eigen::Vector3d> spheres_Ref;      // marker spheres of the Ref tool (mm)
  std::vector<Eigen::Vector3d> spheres_Pointer;  // marker spheres of the pointer
  BoardLayout grid;                     // intrinsics board
  BoardLayout marker;                   // hybrid target board
  Eigen::Vector3d p_CamWork;            // centre of the work volume
};

Bench make_bench() {
  Bench b;
  b.camera.width = 1280;
  b.camera.height = 720;
  b.camera.K = cv::Matx33d(1000, 0, 643, 0, 1000, 358, 0, 0, 1);
  b.camera.distortion = {-0.12, 0.04, 0.0005, -0.0003, 0.0};
  b.p_CamWork = Eigen::Vector3d(0, 0, 550);
  // Polaris ~1.2 m from the work volume, beside the camera, its -z towards the volume.
  const Eigen::Vector3d c_Ndi(700, -400, -300);
  const Eigen::Vector3d z = (c_Ndi - b.p_CamWork).normalized();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
  b.X_CamNdi.setIdentity();
  b.X_CamNdi.linear() << x, z.cross(x), z;
  b.X_CamNdi.translation() = c_Ndi;
  // Passive 4-sphere tools (planar, 50-130 mm spread, like NDI's reference geometries).
  b.spheres_Ref = {{0, 0, 0}, {0, 50, 0}, {-35, 95, 0}, {40, 120, 0}};
  b.spheres_Pointer = {{0, 0, 0}, {0, 45, 0}, {-30, 85, 0}, {35, 110, 0}};
  b.p_ToolTip = Eigen::Vector3d(1.5, -160.0, -4.0);
  b.grid = make_apriltag_grid("tag36h11", 7, 5, 30.0, 6.0, 0, 6.0);
  b.marker = make_marker_board("tag36h11", 40.0, 50.0, 100, 5.0);
  b.X_ToolBoard = Eigen::Translation3d(-70, -160, 12) * Eigen::AngleAxisd(0.15, Eigen::Vector3d(1, 1, 0).normalized());
  return b;
}

Eigen::Vector3d gauss3(std::mt19937_64& rng, double sigma) {
  std::normal_distribution<double> g(0.0, sigma);
  return {g(rng), g(rng), g(rng)};
}

// The tracker's view of a tool: noisy spheres, rigid fit to the tool geometry.
Eigen::Isometry3d ndi_measure(const Eigen::Isometry3d& X_NdiTool, const std::vector<Eigen::Vector3d>& spheres,
                              double rms_mm, std::mt19937_64& rng) {
  std::vector<Eigen::Vector3d> measured;
  for (const auto& s : spheres) measured.push_back(X_NdiTool * s + gauss3(rng, rms_mm / std::sqrt(3.0)));
  return register_paired_points(measured, spheres).X_AB;
}

// Board facing the camera at its centre p_CamCentre, tilted by the rotation R_tilt.
Eigen::Isometry3d board_pose(const BoardLayout& layout, const Eigen::Vector3d& p_CamCentre, const Eigen::Matrix3d& R_tilt) {
  const Eigen::Vector3d centre(0.5 * layout.board_width_mm, 0.5 * layout.board_height_mm, 0.0);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = R_tilt * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  X.translation() = p_CamCentre;
  return X * Eigen::Translation3d(-centre);
}

struct Corners {
  std::vector<cv::Point2f> px;
  std::vector<cv::Point3f> board;
};

// The camera side of the simulation: Gaussian-noise corners, or rendered images and the
// detector. Accumulates the corner error against the true projections.
class SimCamera {
 public:
  SimCamera(const Bench& bench, const ArSimOptions& o) : bench_(bench), o_(o) {
    if (o.render) {
      renderer_ = std::make_unique<camera_sim::SyntheticRenderer>(bench.camera);
      grid_ = markers::board_from_layout(bench.grid, "grid", "simulated grid");
      marker_ = markers::board_from_layout(bench.marker, "marker", "simulated marker");
    }
  }

  Corners observe(const BoardLayout& layout, const Eigen::Isometry3d& X_CamBoard, std::mt19937_64& rng) {
    return o_.render ? rendered(layout, X_CamBoard, rng) : projected(layout, X_CamBoard, rng);
  }
  double corner_error_rms_px() const { return n_ ? std::sqrt(sum_sq_ / (2.0 * n_)) : 0.0; }
  int views_rendered() const { return rendered_; }

 private:
  // True corner pixels of a tag, or false when the tag is not fully visible.
  bool true_corners(const BoardTag& t, const Eigen::Isometry3d& X_CamBoard, std::vector<cv::Point2d>& px) const {
    std::vector<Eigen::Vector3d> p_Cam;
    for (const auto& p : t.p_BoardCorner_mm) p_Cam.push_back(X_CamBoard * p);
    for (const auto& p : p_Cam) {
      if (p.z() <= 50.0) return false;
    }
    px = bench_.camera.project(p_Cam);
    for (const auto& q : px) {
      if (!(q.x > 5 && q.y > 5 && q.x < bench_.camera.width - 6 && q.y < bench_.camera.height - 6)) return false;
    }
    return true;
  }

  void add_error(const cv::Point2f& measured, const cv::Point2d& truth) {
    const double dx = static_cast<double>(measured.x) - truth.x, dy = static_cast<double>(measured.y) - truth.y;
    sum_sq_ += dx * dx + dy * dy;
    ++n_;
  }

  Corners projected(const BoardLayout& layout, const Eigen::Isometry3d& X_CamBoard, std::mt19937_64& rng) {
    Corners c;
    std::normal_distribution<double> g(0.0, o_.corner_noise_px);
    std::vector<cv::Point2d> px;
    for (const auto& t : layout.tags) {
      if (!true_corners(t, X_CamBoard, px)) continue;
      for (std::size_t k = 0; k < 4; ++k) {
        c.px.emplace_back(static_cast<float>(px[k].x + g(rng)), static_cast<float>(px[k].y + g(rng)));
        add_error(c.px.back(), px[k]);
        const auto& p = t.p_BoardCorner_mm[k];
        c.board.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
      }
    }
    return c;
  }

  Corners rendered(const BoardLayout& layout, const Eigen::Isometry3d& X_CamBoard, std::mt19937_64& rng) {
    camera_sim::RenderOptions ro;
    ro.noise_sigma = o_.render_noise_gray;
    ro.blur_sigma_px = o_.render_blur_px;
    ro.noise_seed = rng();
    const markers::TagBoard& board = &layout == &bench_.grid ? grid_ : marker_;
    const auto frame = renderer_->render({{&board, X_CamBoard}}, ro);
    ++rendered_;
    DetectionOptions d;
    d.min_tags = 1;
    const BoardObservation obs = detect_board(frame.image, layout, d);
    Corners c;
    if (!obs.found) return c;
    std::vector<cv::Point2d> px;
    for (std::size_t i = 0; i < obs.tag_ids.size(); ++i) {
      const BoardTag* t = layout.find_tag(obs.tag_ids[i]);
      // Only fully visible tags, as in the projected mode (partial tags are not detected
      // reliably and would bias the comparison).
      if (!t || !true_corners(*t, X_CamBoard, px)) continue;
      for (std::size_t k = 0; k < 4; ++k) {
        c.px.push_back(obs.image_px[4 * i + k]);
        c.board.push_back(obs.board_mm[4 * i + k]);
        add_error(c.px.back(), px[k]);
      }
    }
    return c;
  }

  const Bench& bench_;
  const ArSimOptions& o_;
  std::unique_ptr<camera_sim::SyntheticRenderer> renderer_;
  markers::TagBoard grid_, marker_;
  double sum_sq_ = 0.0;
  long n_ = 0;
  int rendered_ = 0;
};

Eigen::Isometry3d solve_pnp(const Corners& c, const CameraIntrinsics& in) {
  return board_pose_pnp(c.board, c.px, in, "AR simulation");
}

Eigen::Matrix3d random_tilt(std::mt19937_64& rng, double max_deg) {
  std::uniform_real_distribution<double> u(-max_deg * kDeg, max_deg * kDeg);
  return (Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(0.5 * u(rng), Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

CameraIntrinsics calibrate_camera(const Bench& b, SimCamera& camera, std::mt19937_64& rng, const ArSimOptions& o,
                                  ArSimRun& run) {
  std::vector<CalibrationView> views;
  std::uniform_real_distribution<double> off(-1.0, 1.0);
  int attempts = 0;
  while (static_cast<int>(views.size()) < o.intrinsics_views && attempts++ < 50 * o.intrinsics_views) {
    const Eigen::Vector3d centre(140 * off(rng), 80 * off(rng), 420 + 120 * (0.5 + 0.5 * off(rng)));
    const Eigen::Isometry3d X = board_pose(b.grid, centre, random_tilt(rng, 40));
    Corners c = camera.observe(b.grid, X, rng);
    if (c.px.size() < 4u * 12u) continue;  // at least 12 tags, as a usable real view
    views.push_back({"sim" + std::to_string(views.size()), c.px, c.board});
  }
  IntrinsicsResult r = calibrate_intrinsics(views, cv::Size(b.camera.width, b.camera.height));
  run.intrinsics_rms_px = r.intrinsics.rms_reprojection_error_px;
  run.focal_error_px = std::abs(r.intrinsics.camera_matrix(0, 0) - b.camera.K(0, 0));
  return r.intrinsics;
}

}  // namespace

ArSimResult simulate_ar_accuracy(const ArSimOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  if (o.runs < 1 || o.trials_per_angle < 1 || o.view_angles_deg.empty() || !(o.ndi_rms_mm >= 0) ||
      !(o.corner_noise_px >= 0) || (o.chain != "marker" && o.chain != "direct")) {
    throw CalibError("AR simulation: runs and trials >= 1, noise >= 0, chain 'marker' or 'direct'");
  }
  for (double a : o.view_angles_deg) {
    if (!(a >= 0.0 && a <= 70.0)) throw CalibError("AR simulation: view angles must be in 0..70 deg");
  }
  const Bench b = make_bench();
  const Eigen::Isometry3d X_NdiCam = b.X_CamNdi.inverse();
  ArSimResult result;
  std::mt19937_64 rng(o.seed);
  SimCamera camera(b, o);
  for (int run_i = 0; run_i < o.runs; ++run_i) {
    ArSimRun run;
    // 1. Intrinsics.
    const CameraIntrinsics intr = calibrate_camera(b, camera, rng, o, run);
    // 2. Pivot of the pointer in a divot in the work volume.
    const Eigen::Vector3d p_NdiPivot = X_NdiCam * (b.p_CamWork + Eigen::Vector3d(40, 30, 20));
    std::vector<Eigen::Isometry3d> pivot_poses;
    for (int i = 0; i < o.pivot_poses; ++i) {
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      // Pointer roughly along the tracker's line of sight, tilted up to 30 deg.
      X.linear() = random_tilt(rng, 30) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
      X.translation() = p_NdiPivot - X.linear() * b.p_ToolTip;
      pivot_poses.push_back(ndi_measure(X, b.spheres_Pointer, o.ndi_rms_mm, rng));
    }
    const PivotResult pivot = calibrate_pivot(pivot_poses);
    run.pivot_rms_mm = pivot.rms_mm;
    run.tip_error_mm = (pivot.p_ToolTip_mm - b.p_ToolTip).norm();
    // 3. Hand-eye with the hybrid target.
    std::vector<Eigen::Isometry3d> he_ndi, he_cam;
    std::uniform_real_distribution<double> off(-1.0, 1.0);
    while (static_cast<int>(he_ndi.size()) < o.hand_eye_poses) {
      const Eigen::Vector3d centre = b.p_CamWork + Eigen::Vector3d(80 * off(rng), 60 * off(rng), 80 * off(rng));
      const Eigen::Isometry3d X_CamBoard = board_pose(b.marker, centre, random_tilt(rng, 35));
      const Corners c = camera.observe(b.marker, X_CamBoard, rng);
      if (c.px.size() < 16u) continue;
      const Eigen::Isometry3d X_NdiTool = X_NdiCam * X_CamBoard * b.X_ToolBoard.inverse();
      he_ndi.push_back(ndi_measure(X_NdiTool, b.spheres_Ref, o.ndi_rms_mm, rng));
      he_cam.push_back(solve_pnp(c, intr));
    }
    HandEyeOptions ho;
    ho.method = o.hand_eye_method;
    const HandEyeResult he = calibrate_hand_eye(he_ndi, he_cam, ho);
    run.hand_eye_rms_mm = he.rms_mm;
    run.X_CamNdi_error_mm = (he.X_CamNdi.translation() - b.X_CamNdi.translation()).norm();
    run.X_CamNdi_error_deg = Eigen::AngleAxisd(he.X_CamNdi.linear().transpose() * b.X_CamNdi.linear()).angle() / kDeg;
    run.X_ToolBoard_error_mm = (he.X_ToolBoard.translation() - b.X_ToolBoard.translation()).norm();
    result.runs.push_back(run);

    // 4. AR evaluation (paper 000): marker at each view angle, test ball near it.
    for (double angle : o.view_angles_deg) {
      for (int t = 0; t < o.trials_per_angle; ++t) {
        std::uniform_real_distribution<double> dir(0.0, 2 * M_PI);
        const Eigen::Matrix3d R_tilt =
            Eigen::AngleAxisd(angle * kDeg, Eigen::Vector3d(std::cos(dir(rng)), std::sin(dir(rng)), 0).normalized())
                .toRotationMatrix();
        const Eigen::Vector3d centre = b.p_CamWork + Eigen::Vector3d(40 * off(rng), 30 * off(rng), 40 * off(rng));
        const Eigen::Isometry3d X_CamBoard = board_pose(b.marker, centre, R_tilt);
        const Corners c = camera.observe(b.marker, X_CamBoard, rng);
        if (c.px.size() < 8u) {
          --t;
          continue;
        }
        // Test ball: within 60 mm of the marker centre, up to 40 mm above the board.
        const Eigen::Vector3d p_BoardBall(0.5 * b.marker.board_width_mm + 60 * off(rng),
                                          0.5 * b.marker.board_height_mm + 60 * off(rng), 20 + 20 * off(rng));
        const Eigen::Vector3d p_CamBall = X_CamBoard * p_BoardBall;
        const Eigen::Vector3d p_NdiBall = X_NdiCam * p_CamBall;
        Eigen::Isometry3d X_NdiPointer = Eigen::Isometry3d::Identity();
        X_NdiPointer.linear() = random_tilt(rng, 30) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
        X_NdiPointer.translation() = p_NdiBall - X_NdiPointer.linear() * b.p_ToolTip;
        const Eigen::Isometry3d X_NdiRef = X_NdiCam * X_CamBoard * b.X_ToolBoard.inverse();
        // What the system measures and computes.
        const Eigen::Vector3d p_NdiTip = ndi_measure(X_NdiPointer, b.spheres_Pointer, o.ndi_rms_mm, rng) * pivot.p_ToolTip_mm;
        Eigen::Vector3d p_CamVirtual;
        if (o.chain == "marker") {
          const Eigen::Isometry3d X_NdiBoard = ndi_measure(X_NdiRef, b.spheres_Ref, o.ndi_rms_mm, rng) * he.X_ToolBoard;
          p_CamVirtual = solve_pnp(c, intr) * (X_NdiBoard.inverse() * p_NdiTip);
        } else {
          p_CamVirtual = he.X_CamNdi * p_NdiTip;
        }
        ArTrial trial;
        trial.view_angle_deg = angle;
        trial.error_mm = (p_CamVirtual - p_CamBall).norm();
        std::vector<cv::Point2d> drawn;
        cv::projectPoints(std::vector<cv::Point3d>{{p_CamVirtual.x(), p_CamVirtual.y(), p_CamVirtual.z()}}, cv::Vec3d(0, 0, 0),
                          cv::Vec3d(0, 0, 0), intr.camera_matrix, intr.distortion_mat(), drawn);
        const cv::Point2d seen = b.camera.project({p_CamBall})[0];
        trial.image_error_px = cv::norm(drawn[0] - seen);
        const Eigen::Vector3d ray = p_CamBall.normalized();
        const Eigen::Vector3d d = p_CamVirtual - p_CamBall;
        trial.lateral_error_mm = (d - d.dot(ray) * ray).norm();
        result.trials.push_back(trial);
      }
    }
  }
  result.stats = summarize_ar_trials(result.trials);
  result.corner_error_rms_px = camera.corner_error_rms_px();
  result.views_rendered = camera.views_rendered();
  result.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace arnav::calib
