#pragma once
// The AR overlay: draws the model's structures (tumour, safety-margin shell, vessels, the
// cut so far, the organ outline) and the scalpel, as the calibrated camera sees them,
// with OpenGL ES 3 (EglContext: headless, Mesa's software rasteriser without a GPU),
// then warps the result through the lens distortion (DistortionWarp) and alpha-blends it
// over the camera image. Text (status banners, blade-to-margin distance) is drawn with
// OpenCV on the blended image.
//
// Depth-correct "seen through the organ": the structures are drawn with depth testing
// among themselves, then the organ's front surface is laid over them as a translucent
// veil (more opaque where it turns away from the eye), so what lies deeper inside looks
// deeper; the scalpel is depth-tested against the organ surface: the part in front is
// solid, the part inside the tissue is drawn dimmed.
//
// Frames and units: meshes are given in Model (mm) with X_CamModel; Cam is OpenCV's.
// Output images are BGR / BGRA (OpenCV order), premultiplied alpha for the overlay layer.
// A renderer owns a GL context: create and use it on one thread.
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "host/overlay/camera_projection.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::overlay {

struct Rgba {
  float r = 1, g = 1, b = 1, a = 1;
};

struct OverlayStyle {
  Rgba tumour{1.0f, 0.15f, 0.15f, 0.95f};
  Rgba margin{1.0f, 0.85f, 0.1f, 0.30f};
  Rgba vessels{0.25f, 0.45f, 1.0f, 0.90f};
  Rgba cut{0.1f, 1.0f, 0.3f, 0.95f};
  Rgba organ_veil{0.95f, 0.75f, 0.65f, 0.25f};  // alpha at normal incidence; rises toward the outline
  Rgba outline{1.0f, 1.0f, 1.0f, 0.85f};
  Rgba scalpel{0.9f, 0.95f, 1.0f, 1.0f};
  float scalpel_inside_alpha = 0.45f;           // the part of the blade inside the tissue
  float line_width_px = 2.0f;
  double scalpel_radius_mm = 1.0;
  int msaa_samples = 0;                         // anti-aliasing; 4x costs ~5x on llvmpipe (docs/benchmarks.md)
  double near_mm = 5.0;
  double far_mm = 5000.0;
};

// Which layers to draw (tests draw one alone).
enum Layer : unsigned {
  kTumour = 1u << 0,
  kMargin = 1u << 1,
  kVessels = 1u << 2,
  kCut = 1u << 3,
  kOrganVeil = 1u << 4,
  kOutline = 1u << 5,
  kScalpel = 1u << 6,
  kAllLayers = 0x7fu,
};

// What to draw for one frame. Pointers may be null (nothing of that kind). All in Model.
struct OverlayContent {
  Eigen::Isometry3d X_CamModel = Eigen::Isometry3d::Identity();
  const TriMesh* organ = nullptr;
  std::vector<const TriMesh*> tumours;
  std::vector<const TriMesh*> margins;           // safety-margin shells
  const VesselTree* vessels = nullptr;
  const TriMesh* cut_surface = nullptr;          // the cut made so far, as a surface (host/cut)
  std::vector<std::vector<Eigen::Vector3d>> cut_paths_mm;  // or as the paths the blade traced (polylines)
  std::optional<std::array<Eigen::Vector3d, 2>> scalpel_mm;  // blade tip and heel
  unsigned layers = kAllLayers;
};

struct RenderTiming {
  double geometry_ms = 0;   // transforms, normals, tubes, silhouette, uploads
  double gl_ms = 0;         // draw + read back (glReadPixels waits for the rasteriser)
  double warp_ms = 0;       // lens distortion
  double total_ms = 0;
  // The part of the returned layer that can be non-transparent (every pixel outside it is
  // zero): the drawn geometry's screen bounding box (padded for lines and the lens warp's
  // interpolation). Read-back, warp and compositing only touch it.
  cv::Rect drawn_px;
};

class OverlayRenderer {
 public:
  // Creates the GL context and the framebuffers for `camera`. Throws OverlayError.
  OverlayRenderer(const OverlayCamera& camera, const OverlayStyle& style = {});
  ~OverlayRenderer();
  OverlayRenderer(const OverlayRenderer&) = delete;
  OverlayRenderer& operator=(const OverlayRenderer&) = delete;

  const OverlayCamera& camera() const;
  std::string gl_description() const;

  // The overlay layer for one frame: CV_8UC4 BGRA, premultiplied alpha, camera size,
  // lens distortion applied.
  cv::Mat render(const OverlayContent& content, RenderTiming* timing = nullptr);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// image (CV_8UC3 BGR, in place) = overlay over image; sizes must match. With `roi` only
// that rectangle is blended (RenderTiming::drawn_px: the overlay is transparent elsewhere).
void composite(cv::Mat& image_bgr, const cv::Mat& overlay_bgra_premultiplied);
void composite(cv::Mat& image_bgr, const cv::Mat& overlay_bgra_premultiplied, const cv::Rect& roi);

// Text on the finished frame.
struct Banner {
  std::string text;
  cv::Scalar colour_bgr{0, 0, 255};
};
// Banners stacked at the top, full width (always visible); the distance, coloured
// (green > warn_mm, amber 0..warn_mm, red inside the margin), bottom left.
void draw_status(cv::Mat& image_bgr, const std::vector<Banner>& banners, std::optional<double> blade_to_margin_mm,
                 double warn_mm, const std::string& footer);

}  // namespace arnav::host::overlay
