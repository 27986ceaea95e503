#pragma once
// Synthetic camera of the bench: renders AprilTag boards at known poses X_CamBoard through
// a pinhole + OpenCV-distortion camera, with lighting changes, partial occlusion, blur and
// sensor noise, and returns the ground truth (projected corners, visibility) of each tag.
//
// How: every output pixel is traced back through the lens (distorted pixel -> normalised
// ray, computed once per camera) and intersected with the board plane; the tag cell under
// the ray comes from the AprilTag family's code word (TagFamily::cells). Pixels straddling
// an edge are supersampled, so edges are anti-aliased like a real sensor's.
//
// Frames and units: X_CamBoard in mm (Cam: OpenCV camera frame, x right, y down, z forward;
// Board: see appliance/markers/tag_board.hpp). Gray levels 0..255. Planar boards only.
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "appliance/markers/camera_model.hpp"
#include "appliance/markers/tag_board.hpp"

namespace arnav::camera_sim {

struct Lighting {
  double gain = 1.0;          // multiplies the whole image (exposure / light level)
  double offset = 0.0;        // added gray level (ambient light, black level)
  Eigen::Vector2d gradient_per_px = Eigen::Vector2d::Zero();  // relative illumination change per pixel from the centre
  double vignetting = 0.0;    // relative darkening at the image corners (0..1)
};

// A foreground object (instrument, hand) drawn over the scene: polygon in image pixels.
struct Occluder {
  std::vector<cv::Point2d> polygon_px;
  double reflectance = 0.15;
};

struct RenderOptions {
  double background_reflectance = 0.35;
  double paper_reflectance = 0.90;
  double black_reflectance = 0.05;
  double paper_margin_mm = 10.0;  // white paper around the tags when the board has no outline
  Lighting lighting;
  std::vector<Occluder> occluders;
  double blur_sigma_px = 0.0;     // Gaussian optical/defocus blur
  double noise_sigma = 0.0;       // Gaussian sensor noise, gray levels
  std::uint64_t noise_seed = 1;
  int supersample = 4;            // samples per axis for pixels on an edge
  bool keep_radiance = false;     // also return the image before the sensor's noise (RenderResult::radiance)
};

struct BoardInScene {
  const markers::TagBoard* board = nullptr;
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
};

// A shaded closed triangle surface (the bench's deforming organ phantom): drawn with OpenCV
// polygon fill, back faces culled, far-to-near (painter's order), Lambert shading under a
// light at the camera; boards are drawn over it only where they are nearer (per pixel), and
// tag pixels it hides count as occluded. Vertices in Cam (mm); faces outward-oriented.
struct SurfaceInScene {
  const Eigen::Matrix3Xd* vertices_Cam_mm = nullptr;
  const std::vector<Eigen::Vector3i>* faces = nullptr;
  double reflectance = 0.6;   // albedo; shade = reflectance * (0.3 + 0.7 |cos(view, normal)|)
};

struct TagTruth {
  std::string board;
  int id = 0;
  std::array<cv::Point2d, 4> corners_px{};  // distorted pixels, AprilTag corner order
  bool in_front = false;        // all corners in front of the camera
  bool in_image = false;        // all corners inside the image
  bool facing = false;          // front side towards the camera
  double occluded_fraction = 0.0;  // of the tag's pixels, covered by occluders
  double area_px = 0.0;         // rendered pixels of the tag
};

struct RenderResult {
  cv::Mat image;                // CV_8UC1, camera.height x camera.width
  std::vector<TagTruth> tags;
  cv::Mat surface_mask;         // CV_8UC1: 255 where a surface is the nearest thing drawn (empty: no surface)
  cv::Mat radiance;             // CV_32F, after lighting and blur, before noise (keep_radiance only)
};

// The sensor's last step: Gaussian noise (noise_sigma, seeded by noise_seed) added to a
// radiance image, rounded and saturated to 8 bits. render() ends with it, so re-exposing a
// kept radiance with another seed gives exactly the image render() would have given for the
// same scene (the synthetic camera reuses a static scene's radiance this way).
cv::Mat expose_radiance(const cv::Mat& radiance, const RenderOptions& options);

class SyntheticRenderer {
 public:
  // Precomputes the per-pixel rays of the camera (a few hundred ms at 1280x720).
  explicit SyntheticRenderer(markers::CameraModel camera);
  ~SyntheticRenderer();
  SyntheticRenderer(const SyntheticRenderer&) = delete;
  SyntheticRenderer& operator=(const SyntheticRenderer&) = delete;

  const markers::CameraModel& camera() const { return camera_; }
  // Throws std::invalid_argument for a non-planar board, an unknown family or tag id.
  RenderResult render(const std::vector<BoardInScene>& scene, const RenderOptions& options) const;
  // Boards and shaded surfaces (surfaces first, boards where nearer). Throws
  // std::invalid_argument for a face index out of range as well.
  RenderResult render(const std::vector<BoardInScene>& scene, const std::vector<SurfaceInScene>& surfaces,
                      const RenderOptions& options) const;

 private:
  struct BitmapCache;
  markers::CameraModel camera_;
  cv::Mat rays_;  // (height+1) x (width+1) CV_64FC2: normalised ray at pixel corners
  std::unique_ptr<BitmapCache> bitmaps_;
};

}  // namespace arnav::camera_sim
