// The overlay's projection conventions checked against OpenCV: the tumour's rendered
// pixels must lie where cv::projectPoints puts the tumour's triangles (with and without
// lens distortion, at the centre and in a corner where the lens bends most), the layers
// must compose as documented (veil over the structures, outline, scalpel dimmed inside the
// organ) and the geometry helpers must match analytic shapes.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "host/overlay/camera_projection.hpp"
#include "host/overlay/egl_context.hpp"
#include "host/overlay/overlay_geometry.hpp"
#include "host/overlay/overlay_renderer.hpp"
#include "host/mesh/surface_shapes.hpp"

namespace arnav::host::overlay {
namespace {

OverlayCamera bench_camera(bool distorted) {
  OverlayCamera c;
  c.width = 1280;
  c.height = 720;
  c.K = cv::Matx33d(900.0, 0.0, 652.3, 0.0, 905.0, 351.7, 0.0, 0.0, 1.0);
  if (distorted) c.distortion = {-0.28, 0.09, 0.0012, -0.0008, -0.01};
  return c;
}

// The reference: every triangle projected with cv::projectPoints and filled (subpixel).
cv::Mat reference_mask(const OverlayCamera& cam, const TriMesh& mesh, const Eigen::Isometry3d& X_CamModel) {
  std::vector<cv::Point3d> pts;
  for (Eigen::Index i = 0; i < mesh.positions_World_mm.cols(); ++i) {
    const Eigen::Vector3d p = mesh.positions_World_mm.col(i);
    pts.emplace_back(p.x(), p.y(), p.z());
  }
  cv::Mat R(3, 3, CV_64F), rvec, tvec = (cv::Mat_<double>(3, 1) << X_CamModel.translation().x(), X_CamModel.translation().y(),
                                         X_CamModel.translation().z());
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R.at<double>(r, c) = X_CamModel.linear()(r, c);
  cv::Rodrigues(R, rvec);
  std::vector<cv::Point2d> px;
  cv::projectPoints(pts, rvec, tvec, cv::Mat(cam.K), cv::Mat(cam.distortion), px);
  cv::Mat mask = cv::Mat::zeros(cam.height, cam.width, CV_8U);
  constexpr int kShift = 4;
  for (const auto& t : mesh.tris) {
    cv::Point poly[3];
    for (int k = 0; k < 3; ++k) {
      const auto& p = px[static_cast<std::size_t>(t[static_cast<std::size_t>(k)])];
      poly[k] = cv::Point(static_cast<int>(std::lround(p.x * (1 << kShift))), static_cast<int>(std::lround(p.y * (1 << kShift))));
    }
    cv::fillConvexPoly(mask, poly, 3, cv::Scalar(255), cv::LINE_8, kShift);
  }
  return mask;
}

cv::Point2d centroid(const cv::Mat& mask) {
  const cv::Moments m = cv::moments(mask, true);
  return {m.m10 / m.m00, m.m01 / m.m00};
}

// Pixels where the two masks disagree that are not on the reference's 1-px boundary band
// (OpenCV's polygon fill includes edge pixels, OpenGL's rule takes pixel centres).
int mismatches_off_boundary(const cv::Mat& rendered, const cv::Mat& reference) {
  cv::Mat diff, dil, ero, band, off;
  cv::bitwise_xor(rendered, reference, diff);
  cv::dilate(reference, dil, cv::Mat());
  cv::erode(reference, ero, cv::Mat());
  cv::subtract(dil, ero, band);
  cv::bitwise_and(diff, ~band, off);
  return cv::countNonZero(off);
}

double iou(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat i, u;
  cv::bitwise_and(a, b, i);
  cv::bitwise_or(a, b, u);
  return static_cast<double>(cv::countNonZero(i)) / cv::countNonZero(u);
}

cv::Mat alpha_mask(const cv::Mat& bgra) {
  cv::Mat alpha, mask;
  cv::extractChannel(bgra, alpha, 3);
  cv::threshold(alpha, mask, 127, 255, cv::THRESH_BINARY);
  return mask;
}

// Pose of the model seen from the camera: the tumour centre at `target_Cam`, tilted.
Eigen::Isometry3d pose_looking_at(const Eigen::Vector3d& centre_Model, const Eigen::Vector3d& target_Cam) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = (Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 0.5).normalized()) * Eigen::AngleAxisd(2.5, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  X.translation() = target_Cam - X.linear() * centre_Model;
  return X;
}

struct Case {
  bool distorted;
  Eigen::Vector3d target_Cam;
  const char* name;
};

class TumourProjection : public ::testing::TestWithParam<Case> {};

TEST_P(TumourProjection, PixelsLieWhereOpenCvProjectsTheTumour) {
  const Case c = GetParam();
  const OverlayCamera cam = bench_camera(c.distorted);
  OverlayStyle style;
  style.msaa_samples = 0;  // hard edges: compare with the filled reference exactly
  OverlayRenderer renderer(cam, style);
  const Eigen::Vector3d centre(70, 160, 140);
  const TriMesh tumour = make_ellipsoid_surface(centre, Eigen::Vector3d(13, 11, 10), 3);
  OverlayContent content;
  content.X_CamModel = pose_looking_at(centre, c.target_Cam);
  content.tumours = {&tumour};
  content.layers = kTumour;
  const cv::Mat overlay = renderer.render(content);
  ASSERT_EQ(overlay.type(), CV_8UC4);
  ASSERT_EQ(overlay.size(), cv::Size(cam.width, cam.height));
  const cv::Mat rendered = alpha_mask(overlay);
  const cv::Mat reference = reference_mask(cam, tumour, content.X_CamModel);
  ASSERT_GT(cv::countNonZero(reference), 1000) << c.name;
  const cv::Point2d dc = centroid(rendered) - centroid(reference);
  EXPECT_LT(std::hypot(dc.x, dc.y), 0.25) << c.name << ": centroid off by (" << dc.x << ", " << dc.y << ") px";
  EXPECT_GT(iou(rendered, reference), 0.94) << c.name;
  EXPECT_EQ(mismatches_off_boundary(rendered, reference), 0) << c.name << ": every differing pixel lies on the outline";
  if (c.distorted) {
    // The lens matters here: the pinhole projection lies far from the rendered tumour.
    OverlayCamera pinhole = cam;
    pinhole.distortion.clear();
    const cv::Point2d d0 = centroid(reference_mask(pinhole, tumour, content.X_CamModel)) - centroid(rendered);
    EXPECT_GT(std::hypot(d0.x, d0.y), std::string(c.name) == "distorted_corner" ? 20.0 : 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Cases, TumourProjection,
                         ::testing::Values(Case{false, {0, 0, 400}, "pinhole_centre"},
                                           Case{false, {-230, 120, 420}, "pinhole_corner"},
                                           Case{true, {0, 0, 400}, "distorted_centre"},
                                           Case{true, {-250, 125, 400}, "distorted_corner"}),
                         [](const ::testing::TestParamInfo<Case>& param_info) { return std::string(param_info.param.name); });

// Only the drawn region is cleared, read back, warped and composited: every visible pixel
// lies inside RenderTiming::drawn_px, nothing of the previous frame survives elsewhere
// (the same output as a fresh renderer), and geometry reaching the near plane falls back
// to the whole image.
TEST(DrawnRegion, HoldsEveryPixelAndLeavesNothingBehind) {
  const OverlayCamera cam = bench_camera(true);
  OverlayRenderer renderer(cam);
  const Eigen::Vector3d centre(70, 160, 140);
  const TriMesh tumour = make_ellipsoid_surface(centre, Eigen::Vector3d(13, 11, 10), 3);
  OverlayContent a;
  a.tumours = {&tumour};
  a.margins = {};
  a.X_CamModel = pose_looking_at(centre, {-280, -150, 520});  // top left, where the lens bends most
  OverlayContent b = a;
  b.X_CamModel = pose_looking_at(centre, {250, 130, 480});    // bottom right
  RenderTiming ta, tb;
  const cv::Mat out_a = renderer.render(a, &ta).clone();
  const cv::Mat out_b = renderer.render(b, &tb).clone();
  for (const auto& [out, t] : {std::pair{out_a, ta}, std::pair{out_b, tb}}) {
    const cv::Mat visible = alpha_mask(out);
    ASSERT_GT(cv::countNonZero(visible), 500);
    cv::Mat outside = visible.clone();
    outside(t.drawn_px).setTo(0);
    EXPECT_EQ(cv::countNonZero(outside), 0) << "pixels outside drawn_px " << t.drawn_px;
    EXPECT_LT(t.drawn_px.area(), cam.width * cam.height / 10) << t.drawn_px;
  }
  EXPECT_EQ((ta.drawn_px & tb.drawn_px).area(), 0);
  // Frame b after frame a equals frame b alone: nothing of a is left in the canvas.
  OverlayRenderer fresh(cam);
  const cv::Mat alone = fresh.render(b);
  EXPECT_EQ(cv::norm(out_b, alone, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::countNonZero(alpha_mask(out_b)(ta.drawn_px)), 0);
  // A scalpel reaching behind the near plane: the whole image.
  OverlayContent c = b;
  c.scalpel_mm = std::array<Eigen::Vector3d, 2>{centre, c.X_CamModel.inverse() * Eigen::Vector3d(0, 0, -10)};
  RenderTiming tc;
  renderer.render(c, &tc);
  EXPECT_EQ(tc.drawn_px, cv::Rect(0, 0, cam.width, cam.height));
  // In front of the camera but far outside the view: nothing drawn, an empty region.
  OverlayContent d = a;
  d.X_CamModel = pose_looking_at(centre, {3000, 0, 400});
  RenderTiming td;
  EXPECT_EQ(cv::countNonZero(alpha_mask(renderer.render(d, &td))), 0);
  EXPECT_EQ(td.drawn_px.area(), 0);
}

TEST(OverlayRenderer, ScaledCameraKeepsThePixelCentreConvention) {
  const OverlayCamera cam = bench_camera(false);
  const OverlayCamera half = cam.scaled_to(640, 360);
  EXPECT_DOUBLE_EQ(half.K(0, 0), 450.0);
  EXPECT_DOUBLE_EQ(half.K(0, 2), 0.5 * (652.3 + 0.5) - 0.5);
  OverlayStyle style;
  style.msaa_samples = 0;
  OverlayRenderer renderer(half, style);
  const TriMesh tumour = make_ellipsoid_surface({0, 0, 0}, {10, 10, 10}, 3);
  OverlayContent content;
  content.X_CamModel = pose_looking_at({0, 0, 0}, {20, -10, 300});
  content.tumours = {&tumour};
  content.layers = kTumour;
  const cv::Point2d d = centroid(alpha_mask(renderer.render(content))) - centroid(reference_mask(half, tumour, content.X_CamModel));
  EXPECT_LT(std::hypot(d.x, d.y), 0.25);
}

TEST(OverlayRenderer, OrganVeilOutlineAndScalpelCompose) {
  const OverlayCamera cam = bench_camera(true);
  OverlayRenderer renderer(cam);
  EXPECT_NE(renderer.gl_description().find("OpenGL ES"), std::string::npos) << renderer.gl_description();
  const TriMesh organ = make_ellipsoid_surface({0, 0, 0}, {80, 60, 50}, 4);
  const TriMesh tumour = make_ellipsoid_surface({0, 0, 0}, {12, 12, 12}, 3);
  const TriMesh margin = offset_surface(tumour, 5.0);
  OverlayContent content;
  content.X_CamModel = Eigen::Isometry3d(Eigen::Translation3d(0, 0, 500));  // Model axes = Cam axes
  content.organ = &organ;
  content.tumours = {&tumour};
  content.margins = {&margin};
  // Blade from in front of the organ (z < 0 faces the camera) into it, oblique to the view.
  content.scalpel_mm = std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(-20, 0, -20), Eigen::Vector3d(-80, 0, -100)};
  const cv::Mat overlay = renderer.render(content);
  const auto at = [&](cv::Point p) { return overlay.at<cv::Vec4b>(p); };
  // Image of the model origin: the principal point.
  const cv::Point centre(652, 352);
  const cv::Vec4b tumour_px = at(centre);
  EXPECT_GT(tumour_px[3], 240) << "tumour opaque under the veil";
  EXPECT_GT(tumour_px[2], 2 * tumour_px[1]) << "red dominates (BGRA)";
  // Tumour under the veil only is dimmer than the tumour drawn alone.
  OverlayContent alone = content;
  alone.layers = kTumour;
  EXPECT_LT(tumour_px[2], renderer.render(alone).at<cv::Vec4b>(centre)[2]);
  // Organ veil: translucent tissue between tumour and outline.
  const cv::Vec4b veil = at({652 + 90, 352});
  EXPECT_GT(veil[3], 30);
  EXPECT_LT(veil[3], 160);
  // Outline near the organ's silhouette (x = 80 mm at 500 mm: ~144 px right, ~ +distortion).
  int outline_hits = 0;
  for (int u = 652 + 100; u < 652 + 160; ++u) outline_hits += at({u, 352})[3] > 200 ? 1 : 0;
  EXPECT_GT(outline_hits, 0);
  // Scalpel: the part in front of the organ (z < -50 in Model) solid, inside dimmed.
  const auto project = [&](const Eigen::Vector3d& p_Model) {
    std::vector<cv::Point3d> in{{p_Model.x(), p_Model.y(), p_Model.z() + 500.0}};
    std::vector<cv::Point2d> out;
    cv::projectPoints(in, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(cam.K), cv::Mat(cam.distortion), out);
    return cv::Point(static_cast<int>(std::lround(out[0].x)), static_cast<int>(std::lround(out[0].y)));
  };
  // Blade points: t = 0.2 (x -68, z -84) lies in front of the surface (z -26 there),
  // t = 0.9 (x -26, z -28) behind it (surface at z -47).
  const cv::Point p_out = project({-68, 0, -84}), p_in = project({-26, 0, -28});
  const cv::Vec4b outside = at(p_out), inside = at(p_in);
  OverlayContent no_scalpel = content;
  no_scalpel.scalpel_mm.reset();
  const cv::Mat without = renderer.render(no_scalpel);
  EXPECT_GT(outside[3], 240);
  EXPECT_GT(outside[0], without.at<cv::Vec4b>(p_out)[0] + 60) << "blade in front of the organ is solid";
  EXPECT_GT(inside[0], without.at<cv::Vec4b>(p_in)[0] + 10) << "blade inside the tissue still shows";
  EXPECT_LT(inside[0], outside[0] - 30) << "blade inside the tissue is dimmed; inside " << inside << " outside " << outside << " without " << without.at<cv::Vec4b>(p_in) << " " << without.at<cv::Vec4b>(p_out);
}

TEST(OverlayRenderer, CompositeBlendsPremultipliedAlpha) {
  cv::Mat image(2, 2, CV_8UC3, cv::Scalar(100, 100, 100));
  cv::Mat overlay(2, 2, CV_8UC4, cv::Scalar(0, 0, 0, 0));
  overlay.at<cv::Vec4b>(0, 0) = {0, 0, 128, 128};  // half-transparent red
  overlay.at<cv::Vec4b>(1, 1) = {255, 0, 0, 255};
  composite(image, overlay);
  EXPECT_EQ(image.at<cv::Vec3b>(0, 0), cv::Vec3b(50, 50, 178));
  EXPECT_EQ(image.at<cv::Vec3b>(0, 1), cv::Vec3b(100, 100, 100));
  EXPECT_EQ(image.at<cv::Vec3b>(1, 1), cv::Vec3b(255, 0, 0));
  cv::Mat wrong(3, 3, CV_8UC4);
  EXPECT_THROW(composite(image, wrong), OverlayError);
}

TEST(OverlayRenderer, StatusTextIsDrawn) {
  cv::Mat image(720, 1280, CV_8UC3, cv::Scalar(0, 0, 0));
  draw_status(image, {{"TRACKING LOST: reference", cv::Scalar(0, 0, 200)}}, -1.5, 5.0, "seq 12");
  EXPECT_EQ(image.at<cv::Vec3b>(5, 1000), cv::Vec3b(0, 0, 200)) << "banner spans the width";
  cv::Mat red;
  cv::inRange(image(cv::Rect(0, 600, 500, 100)), cv::Scalar(0, 0, 200), cv::Scalar(50, 50, 255), red);
  EXPECT_GT(cv::countNonZero(red), 100) << "a negative margin is drawn in red";
}

TEST(OverlayCamera, InvalidCamerasAreRefused) {
  OverlayCamera c = bench_camera(false);
  c.width = 0;
  EXPECT_THROW(validate(c), OverlayError);
  c = bench_camera(false);
  c.distortion = {0.1, 0.2, 0.3};
  EXPECT_THROW(validate(c), OverlayError);
  EXPECT_TRUE(DistortionWarp::make(bench_camera(false)).identity);
  const DistortionWarp w = DistortionWarp::make(bench_camera(true));
  EXPECT_FALSE(w.identity);
  EXPECT_GT(w.canvas_width, 1280) << "a barrel lens sees more than the pinhole image";
}

TEST(OverlayGeometry, MarginShellAndBladeDistanceOnASphere) {
  const TriMesh sphere = make_ellipsoid_surface({0, 0, 0}, {10, 10, 10}, 4);
  const TriMesh shell = offset_surface(sphere, 5.0);
  for (Eigen::Index i = 0; i < shell.positions_World_mm.cols(); ++i) EXPECT_NEAR(shell.positions_World_mm.col(i).norm(), 15.0, 1e-4);
  // Blade from 30 to 20 mm on the x axis: 10 mm from the sphere (facets: within 0.1 mm), 5 from the margin.
  EXPECT_NEAR(blade_to_margin_mm({30, 0, 0}, {20, 0, 0}, sphere, 5.0), 5.0, 0.1);
  // Blade tip at 12 mm: 2 mm from the tumour, 3 mm inside the margin.
  EXPECT_NEAR(blade_to_margin_mm({30, 0, 0}, {12, 0, 0}, sphere, 5.0), -3.0, 0.1);
  // Tip inside the tumour (at 4 mm from the centre: 6 mm deep).
  EXPECT_NEAR(blade_to_margin_mm({4, 0, 30}, {4, 0, 0}, sphere, 5.0), -11.0, 0.15);
  // Oblique blade passing the sphere at 13 mm from its centre.
  EXPECT_NEAR(blade_to_margin_mm({-40, 13, 0}, {40, 13, 0}, sphere, 5.0), -2.0, 0.1);
}

TEST(OverlayGeometry, SilhouetteOfASphereIsItsTangentCone) {
  const TriMesh sphere = make_ellipsoid_surface({0, 0, 100}, {20, 20, 20}, 4);
  const auto edges = silhouette_edges(sphere.positions_World_mm, sphere.tris, Eigen::Vector3d::Zero());
  ASSERT_GT(edges.size(), 30u);
  // Tangent points from the eye: angle to the centre ray asin(r/d); vertices within a facet.
  const double expected = std::asin(20.0 / 100.0);
  for (const auto& e : edges) {
    const Eigen::Vector3d p = sphere.positions_World_mm.col(e[0]);
    EXPECT_NEAR(std::acos(p.normalized().z()), expected, 0.03);
  }
}

TEST(OverlayGeometry, TubesAreClosedAndOutward) {
  Eigen::Matrix3Xd nodes(3, 2);
  nodes << 0, 0, 0, 0, 0, 50;
  const TriMesh t = tubes(nodes, {3.0, 2.0}, {{0, 1}}, 12);
  EXPECT_NEAR(winding_number(t, Eigen::Vector3d(0, 0, 25)), 1.0, 1e-6);
  EXPECT_NEAR(winding_number(t, Eigen::Vector3d(10, 0, 25)), 0.0, 1e-6);
}

}  // namespace
}  // namespace arnav::host::overlay
