#pragma once
// AR error of a navigation session on the bench: the tumour centroid the host drew
// (overlay.csv, per camera frame) against where the synthetic camera's ground truth puts
// it (ground_truth.csv: X_CamBoard of the reference board per frame, through the session's
// registration X_RefModel, the scene's tumour centroid and the camera's intrinsics, with
// cv::projectPoints). In pixels, and in mm at the organ (px x depth / focal length).
// Also: which frames showed the overlay, which showed a tracking banner, and whether any
// frame whose board was clearly visible had no overlay.
//
// With a deforming phantom (the ground truth is version 2 with target:tumour_centroid
// rows, appliance/synthetic_camera/phantom_recording.hpp) the truth is the deformed
// tumour centroid of that frame, and the report also gives what a rigid overlay (the
// rest-shape centroid through the registration, i.e. no deformation model) would score
// against it on the same frames, plus how far the tumour moved: the deformation's effect.
//
// Honest metrics (issue 21 item 3): when overlay.csv carries the drawn centroid in the
// camera frame (tumour_x/y/z_cam_mm), the 3-D error is |drawn - true| in Cam (mm), split
// into its part along the viewing ray (depth) and across it; the 2-D figure above
// (px x depth / f) cannot see a depth error. Availability: every frame the camera made
// after the registration (the first overlay.csv row not flagged 'unregistered') whose
// board was clearly visible is eligible; one without an overlay (not drawn, or not in
// overlay.csv at all) is a failure, counted and kept in the statistics as a missing value
// (quantiles "counting missing" treat it as an infinite error), never dropped.
//
// Tumour surface distance (with the host's tumour_Cam.bin, the drawn tumour surface in Cam
// per frame): against the true tumour surface of the frame, which the phantom recording
// does not hold: it is approximated by the affine map that best takes the phantom's interior
// targets (tumour centroid +- 15 mm along x, y, z) at rest (Model, from the first frame
// through the true registration) to the same targets in that frame (Cam), applied to the
// scene's rest tumour surface. A non-affine deformation of the tumour itself (stiff,
// 40 kPa, in the phantom) is not in this truth.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace arnav::hil {

struct ArFrame {
  std::int64_t sequence = 0;
  bool drawn = false;           // the host drew the tumour
  bool board_visible = false;   // ground truth: every tag of the board clear
  double error_px = 0.0;        // when drawn
  double error_mm = 0.0;
  bool deformed_truth = false;  // truth from the phantom's deformed centroid
  double rigid_error_px = 0.0;  // a rigid overlay's error against the same truth (phantom only)
  double rigid_error_mm = 0.0;
  double tumour_displacement_mm = 0.0;  // deformed vs rest centroid (phantom only)
  double latency_ms = 0.0;
  bool own_pose = false;        // drawn with the board pose of this very frame (never an older one)
  std::string flags;
  bool registered = false;      // the host had registered (no 'unregistered' flag)
  bool has_3d = false;          // drawn and overlay.csv has the drawn centroid in Cam
  double error_3d_mm = 0.0;     // |drawn - true| tumour centroid in Cam
  double error_depth_mm = 0.0;  // its component along the true centroid's viewing ray (signed: + drawn too far)
  double error_lateral_mm = 0.0;  // across the ray
  bool has_surface = false;     // drawn surface and true (affine-approximated) surface both known
  double surface_mean_mm = 0.0; // mean distance between drawn and true tumour surfaces (both ways)
  double surface_max_mm = 0.0;  // largest (Hausdorff at the vertices)
};

// Availability over the frames the camera made (ground truth), in sequence order.
struct Availability {
  std::int64_t eligible = 0;   // board clearly visible, at or after the first registered frame
  std::int64_t with_overlay = 0;
  std::int64_t not_drawn = 0;  // displayed without the tumour
  std::int64_t not_displayed = 0;  // missing from overlay.csv (dropped by the host)
  double percent() const { return eligible ? 100.0 * static_cast<double>(with_overlay) / static_cast<double>(eligible) : 0.0; }
};

// The q-quantile (nearest rank) of `values` plus `missing` values counted as +infinity;
// nullopt when it falls on a missing one.
std::optional<double> quantile_counting_missing(std::vector<double> values, std::int64_t missing, double q);

struct ArErrorReport {
  std::vector<ArFrame> frames;  // frames present in both files
  std::int64_t truth_frames = 0, csv_rows = 0, missing_in_csv = 0;
  std::int64_t visible_without_overlay = 0;  // board clear, no tumour drawn
  std::int64_t invisible_with_overlay = 0;   // board gone, overlay still drawn (a frozen overlay)
  bool phantom = false;                      // the truth is a deforming phantom
  bool has_3d = false;                       // overlay.csv carried the drawn centroid in Cam
  bool has_surface = false;                  // tumour surfaces evaluated
  Availability availability;
  nlohmann::json summary() const;            // mean/p95/max px and mm, latency p50/p99, counts
  // One row per camera frame (ground truth): sequence, eligible, displayed, drawn, errors.
  std::string frames_csv() const;
  std::vector<std::int64_t> truth_sequences;          // every frame the camera made
  std::vector<std::int64_t> eligible_not_displayed;   // eligible frames missing from overlay.csv
};

// session_path: the host's session file (scene, registration, camera intrinsics, reference
// tool = the board's name in the ground truth). Throws std::runtime_error naming the file.
// tumour_surfaces: the host's tumour_Cam.bin (empty: no surface distance).
ArErrorReport evaluate_ar_error(const std::string& session_path, const std::string& ground_truth_csv,
                                const std::string& overlay_csv, const std::string& tumour_surfaces = {});

}  // namespace arnav::hil
