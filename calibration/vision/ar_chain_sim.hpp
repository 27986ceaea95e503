#pragma once
// End-to-end simulation of the AR chain on the bench, for the AR accuracy benchmark:
// an NDI tracker and a camera fixed to each other, a hybrid target (AprilTag marker
// board on an NDI tool, the "identification" of paper 000) and a tracked pointer whose
// tip is the test ball. Every calibration is made from simulated data, then paper 000's
// AR error is measured per view angle of the marker.
//
// What is simulated (and nothing else):
//  - NDI: each tool's 4 marker spheres get isotropic Gaussian noise (ndi_rms_mm, 3D RMS)
//    and the tool pose is the rigid fit of the noisy spheres (Umeyama), as the tracker's
//    marker fit does; no volumetric bias, no latency.
//  - Camera, default: tag corners projected through the true camera (markers::CameraModel,
//    the synthetic camera's projection) plus Gaussian pixel noise (corner_noise_px per
//    axis); no blur, rolling shutter, or detector failures.
//  - Camera, render = true: every view is rendered by the synthetic camera
//    (appliance/synthetic_camera: anti-aliased tags, blur, sensor noise) and the corners come
//    from the appliance's AprilTag detector; corner_noise_px is then unused and the
//    detector's real corner error is measured against the renderer's ground truth.
//  - Calibrations from simulated data: intrinsics (AprilTag grid views, calibrateCamera),
//    pivot (algebraic), hand-eye (AX=ZB Shah or a chosen method), with the same noise.
//  - The AR error: the virtual ball is drawn where the chain puts it; the error is its
//    3D distance to the true ball (what the paper reads back with the NDI after a person
//    realigns the ball: human alignment error is NOT simulated), plus the image error
//    in pixels and the error across the viewing ray in mm.
#include <cstdint>
#include <string>
#include <vector>

#include "calibration/lib/ar_accuracy.hpp"
#include "calibration/lib/hand_eye.hpp"

namespace arnav::calib {

struct ArSimOptions {
  double ndi_rms_mm = 0.25;          // per sphere, 3D RMS
  double corner_noise_px = 0.2;      // per axis
  int runs = 10;                     // independent calibration sessions
  int trials_per_angle = 5;          // per run (paper 000: 5 people)
  std::vector<double> view_angles_deg = {0.0, 20.0, 40.0, 60.0};
  int intrinsics_views = 15;
  int pivot_poses = 100;
  int hand_eye_poses = 20;
  HandEyeMethod hand_eye_method = HandEyeMethod::AXZB_Shah;
  // "marker": virtual ball anchored to the camera-tracked marker (paper 000's chain);
  // "direct": drawn through the hand-eye X_CamNdi only.
  std::string chain = "marker";
  std::uint64_t seed = 1;
  bool render = false;
  double render_noise_gray = 2.0;    // sensor noise, gray levels (render = true)
  double render_blur_px = 0.5;       // Gaussian blur sigma (render = true)
};

struct ArSimRun {
  double intrinsics_rms_px = 0.0;
  double focal_error_px = 0.0;       // |fx_est - fx_true|
  double pivot_rms_mm = 0.0;
  double tip_error_mm = 0.0;         // |p_ToolTip_est - true|
  double hand_eye_rms_mm = 0.0;
  double X_CamNdi_error_mm = 0.0;    // translation error of the hand-eye result
  double X_CamNdi_error_deg = 0.0;
  double X_ToolBoard_error_mm = 0.0;
};

struct ArSimResult {
  std::vector<ArTrial> trials;
  std::vector<ArAngleStats> stats;
  std::vector<ArSimRun> runs;
  // Corner error of the camera observations against the true projections (px, RMS per
  // axis): the injected noise, or the detector's error on rendered images.
  double corner_error_rms_px = 0.0;
  int views_rendered = 0;
  double wall_time_s = 0.0;
};

// Throws CalibError for invalid options; DegenerateInput if a simulated calibration is
// rejected (it should not be with the defaults).
ArSimResult simulate_ar_accuracy(const ArSimOptions& options);

}  // namespace arnav::calib
