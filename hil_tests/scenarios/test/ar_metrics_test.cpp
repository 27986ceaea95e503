// The honest AR metrics (issue 21 item 3): the 3-D centroid error split along / across the
// viewing ray, the surface distance on analytic shapes, the quantile that counts missing
// frames, and arnav-ar-error's availability and 3-D error on hand-made files.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <unistd.h>

#include <opencv2/calib3d.hpp>

#include "appliance/synthetic_camera/ground_truth.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/scenarios/ar_error.hpp"
#include "hil_tests/scenarios/surface_error.hpp"
#include "host/app/tumour_surface_file.hpp"
#include "host/scene/scene.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::hil {
namespace {

TEST(ArMetrics, CentroidErrorAlongAndAcrossTheRay) {
  const Eigen::Vector3d truth(0, 0, 500);
  CentroidError3d e = centroid_error_3d(Eigen::Vector3d(3, 4, 500), truth);
  EXPECT_NEAR(e.distance_mm, 5.0, 1e-12);
  EXPECT_NEAR(e.along_ray_mm, 0.0, 1e-12);
  EXPECT_NEAR(e.across_ray_mm, 5.0, 1e-12);
  // A pure depth error: invisible in the image, 2 mm in 3-D.
  e = centroid_error_3d(Eigen::Vector3d(0, 0, 498), truth);
  EXPECT_NEAR(e.distance_mm, 2.0, 1e-12);
  EXPECT_NEAR(e.along_ray_mm, -2.0, 1e-12);
  EXPECT_NEAR(e.across_ray_mm, 0.0, 1e-12);
  EXPECT_THROW(centroid_error_3d(truth, Eigen::Vector3d::Zero()), std::invalid_argument);
}

TEST(ArMetrics, PointTriangleDistanceByRegion) {
  const Eigen::Vector3d a(0, 0, 0), b(10, 0, 0), c(0, 10, 0);
  EXPECT_NEAR(point_triangle_distance_mm({2, 2, 3}, a, b, c), 3.0, 1e-12);               // above the face
  EXPECT_NEAR(point_triangle_distance_mm({-3, -4, 0}, a, b, c), 5.0, 1e-12);             // vertex a
  EXPECT_NEAR(point_triangle_distance_mm({5, -2, 0}, a, b, c), 2.0, 1e-12);              // edge ab
  EXPECT_NEAR(point_triangle_distance_mm({8, 8, 0}, a, b, c), 6.0 / std::sqrt(2.0), 1e-12);  // edge bc
  EXPECT_NEAR(point_triangle_distance_mm({13, -4, 0}, a, b, c), 5.0, 1e-12);             // vertex b
}

// An axis-aligned cube of half side h centred at the origin (8 vertices, 12 triangles).
TriSurface cube(double h) {
  TriSurface s;
  for (int i = 0; i < 8; ++i) s.vertices_mm.emplace_back(i & 1 ? h : -h, i & 2 ? h : -h, i & 4 ? h : -h);
  s.triangles = {{0, 1, 3}, {0, 3, 2}, {4, 6, 7}, {4, 7, 5}, {0, 4, 5}, {0, 5, 1},
                 {2, 3, 7}, {2, 7, 6}, {0, 2, 6}, {0, 6, 4}, {1, 5, 7}, {1, 7, 3}};
  return s;
}

TEST(ArMetrics, SurfaceDistanceOfNestedCubes) {
  // Cubes of half sides a < b: an outer corner is sqrt(3) (b - a) from the inner cube (its
  // corner), an inner corner b - a from the outer cube (a face): mean (1 + sqrt 3)(b - a) / 2,
  // max sqrt(3) (b - a).
  const double a = 10.0, b = 12.0;
  const SurfaceDistance d = surface_distance(cube(a), cube(b));
  EXPECT_NEAR(d.mean_mm, (1.0 + std::sqrt(3.0)) * (b - a) / 2.0, 1e-9);
  EXPECT_NEAR(d.max_mm, std::sqrt(3.0) * (b - a), 1e-9);
  const SurfaceDistance same = surface_distance(cube(a), cube(a));
  EXPECT_NEAR(same.mean_mm, 0.0, 1e-12);
  EXPECT_NEAR(same.max_mm, 0.0, 1e-12);
  TriSurface bad = cube(a);
  bad.triangles[0][2] = 8;
  EXPECT_THROW(surface_distance(bad, cube(a)), std::invalid_argument);
  EXPECT_THROW(surface_distance(TriSurface{}, cube(a)), std::invalid_argument);
}

TEST(ArMetrics, QuantileCountsMissingFramesAsFailures) {
  EXPECT_EQ(quantile_counting_missing({1, 2, 3}, 0, 0.95), 3.0);
  EXPECT_EQ(quantile_counting_missing({3, 1, 2}, 1, 0.5), 3.0);           // rank 2 of 4
  EXPECT_FALSE(quantile_counting_missing({1, 2, 3}, 1, 0.95).has_value());  // falls on the missing one
  EXPECT_FALSE(quantile_counting_missing({}, 0, 0.5).has_value());
}

// arnav-ar-error on hand-made files: frame 0 unregistered; 1 drawn 2 mm too deep; 2 board
// visible but nothing drawn; 3 never displayed; 4 board hidden, nothing drawn (not
// eligible); 5 drawn where the truth is. Eligible 1, 2, 3, 5: availability 50 %.
TEST(ArMetrics, AvailabilityAndThreeDimensionalError) {
  const std::filesystem::path src = arnav::testing::source_dir() + "/hil_tests/scenarios/ar_demo";
  const std::string data = arnav::testing::data_dir();
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_armetrics_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  for (const char* f : {"camera.yaml", "X_RefModel_phantom.yaml", "session_phantom.yaml"})
    std::filesystem::copy_file(src / f, dir / f, std::filesystem::copy_options::overwrite_existing);
  std::ofstream(dir / "liver_navigation.scene.yaml")
      << std::regex_replace(arnav::testing::read_text(src / "liver_navigation.scene.yaml"), std::regex("\\.\\./\\.\\./\\.\\./data/"), data + "/");
  const calib::CameraIntrinsics cam = calib::read_intrinsics(dir / "camera.yaml");
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
  X_CamBoard.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  X_CamBoard.translation() = Eigen::Vector3d(37, 68, 450);
  const Eigen::Vector3d truth_Cam(20, 10, 480);
  std::vector<cv::Point2d> px;
  cv::projectPoints(std::vector<cv::Point3d>{{truth_Cam.x(), truth_Cam.y(), truth_Cam.z()}}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                    cv::Mat(cam.camera_matrix), cv::Mat(cam.distortion), px);
  {
    camera_sim::GroundTruthWriter w(dir / "gt.csv", 2);
    for (int k = 0; k < 6; ++k) {
      w.write({k, k / 15.0, "liver_marker", X_CamBoard, k == 4 ? 0 : 4, ""});
      camera_sim::GroundTruthRow t;
      t.sequence = k;
      t.time_s = k / 15.0;
      t.board = "target:tumour_centroid";
      t.X_CamBoard.translation() = truth_Cam;
      t.tags_visible = 1;
      t.has_px = true;
      t.u_px = px[0].x;
      t.v_px = px[0].y;
      w.write(t);
    }
  }
  {
    std::ofstream csv(dir / "overlay.csv");
    csv << "camera_sequence,capture_time_mono_us,pose_time_mono_us,model_step_time_mono_us,render_done_mono_us,"
           "motion_to_photon_ms,tumour_u_px,tumour_v_px,blade_to_margin_mm,flags,tumour_x_cam_mm,tumour_y_cam_mm,tumour_z_cam_mm\n";
    const Eigen::Vector3d deep = truth_Cam + 2.0 * truth_Cam.normalized();  // same pixel, 2 mm deeper
    csv << "0,100,100,110,120,20.0,,,,unregistered,,,\n";
    csv << "1,200,200,210,220,20.0," << px[0].x << "," << px[0].y << ",,," << deep.x() << "," << deep.y() << "," << deep.z() << "\n";
    csv << "2,300,300,310,320,20.0,,,,reference_lost,,,\n";
    csv << "4,500,500,510,520,20.0,,,,reference_lost,,,\n";
    csv << "5,600,600,610,620,20.0," << px[0].x << "," << px[0].y << ",,," << truth_Cam.x() << "," << truth_Cam.y() << "," << truth_Cam.z()
        << "\n";
  }
  const ArErrorReport rep = evaluate_ar_error((dir / "session_phantom.yaml").string(), (dir / "gt.csv").string(),
                                              (dir / "overlay.csv").string());
  ASSERT_TRUE(rep.has_3d);
  EXPECT_EQ(rep.availability.eligible, 4);
  EXPECT_EQ(rep.availability.with_overlay, 2);
  EXPECT_EQ(rep.availability.not_drawn, 1);
  EXPECT_EQ(rep.availability.not_displayed, 1);
  EXPECT_DOUBLE_EQ(rep.availability.percent(), 50.0);
  const nlohmann::json j = rep.summary();
  // The 2-D figure cannot see the depth error; the 3-D one does.
  EXPECT_NEAR(j["ar_error_mm"]["max"].get<double>(), 0.0, 1e-3);
  EXPECT_NEAR(j["ar_error_3d_mm"]["max"].get<double>(), 2.0, 1e-3);
  EXPECT_NEAR(j["ar_error_3d_mm"]["mean"].get<double>(), 1.0, 1e-3);
  EXPECT_NEAR(j["ar_error_3d_mm"]["along_ray_abs"]["max"].get<double>(), 2.0, 1e-3);
  EXPECT_EQ(j["ar_error_3d_mm"]["counting_missing"]["missing"].get<int>(), 2);
  EXPECT_TRUE(j["ar_error_3d_mm"]["counting_missing"]["p95"].is_null());
  EXPECT_DOUBLE_EQ(j["availability"]["percent"].get<double>(), 50.0);
  // Per frame: every frame the camera made, the undisplayed one included.
  const std::string frames = rep.frames_csv();
  EXPECT_NE(frames.find("\n3,0,,,0,"), std::string::npos) << frames;
  EXPECT_EQ(std::count(frames.begin(), frames.end(), '\n'), 7) << frames;
  std::filesystem::remove_all(dir);
}

TEST(ArMetrics, TumourSurfaceFileRoundTripAndErrors) {
  const auto path = std::filesystem::temp_directory_path() / ("arnav_tumour_bin_" + std::to_string(::getpid()));
  host::TriMesh m;
  m.positions_World_mm = Eigen::Matrix3Xd::Random(3, 4) * 50.0;
  m.tris = {{0, 1, 2}, {0, 2, 3}, {0, 3, 1}, {1, 3, 2}};
  {
    std::ofstream out(path, std::ios::binary);
    host::write_tumour_surface_header(out);
    host::write_tumour_surface(out, 7, m, true);
    host::write_tumour_surface(out, 8, m, false);  // same triangles
  }
  const auto read = host::read_tumour_surfaces(path.string());
  ASSERT_EQ(read.size(), 2u);
  EXPECT_TRUE(read.at(8).positions_World_mm.isApprox(m.positions_World_mm, 1e-6));
  EXPECT_EQ(read.at(8).tris, m.tris);
  // Truncated: the error names the file and the record.
  const std::string text = arnav::testing::read_text(path);
  std::ofstream(path, std::ios::binary) << text.substr(0, text.size() - 5);
  try {
    host::read_tumour_surfaces(path.string());
    ADD_FAILURE() << "accepted a truncated file";
  } catch (const host::TumourSurfaceFileError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string() + ": record 2: truncated"), std::string::npos) << e.what();
  }
  std::ofstream(path, std::ios::binary) << "not a tumour file\n";
  EXPECT_THROW(host::read_tumour_surfaces(path.string()), host::TumourSurfaceFileError);
  std::filesystem::remove(path);
}

// The tumour surface distance on hand-made files: the phantom at rest (its interior targets
// where the true registration puts them); frame 0 draws the true tumour, frame 1 the same
// moved 2 mm along the camera's z.
TEST(ArMetrics, TumourSurfaceDistanceAgainstTheTargetsTruth) {
  const std::filesystem::path src = arnav::testing::source_dir() + "/hil_tests/scenarios/ar_demo";
  const std::string data = arnav::testing::data_dir();
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_arsurf_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  for (const char* f : {"camera.yaml", "X_RefModel_phantom.yaml", "session_phantom.yaml"})
    std::filesystem::copy_file(src / f, dir / f, std::filesystem::copy_options::overwrite_existing);
  std::ofstream(dir / "liver_navigation.scene.yaml")
      << std::regex_replace(arnav::testing::read_text(src / "liver_navigation.scene.yaml"), std::regex("\\.\\./\\.\\./\\.\\./data/"), data + "/");
  const host::Scene scene = host::load_scene((dir / "liver_navigation.scene.yaml").string());
  const Eigen::Isometry3d X_RefModel = calib::read_transform(dir / "X_RefModel_phantom.yaml").X_ParentChild;
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
  X_CamBoard.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  X_CamBoard.translation() = Eigen::Vector3d(37, 68, 450);
  const Eigen::Isometry3d X_CamModel = X_CamBoard * X_RefModel;
  const Eigen::Vector3d c = scene.tumours[0].rest_centroid_World_mm;
  {
    camera_sim::GroundTruthWriter w(dir / "gt.csv", 2);
    for (int k = 0; k < 2; ++k) {
      w.write({k, k / 15.0, "liver_marker", X_CamBoard, 4, ""});
      std::vector<std::pair<std::string, Eigen::Vector3d>> targets{{"tumour_centroid", c}};
      for (int a = 0; a < 3; ++a)
        for (int sgn : {-1, 1}) targets.emplace_back("tumour_" + std::to_string(a) + (sgn < 0 ? "m" : "p"), c + sgn * 15.0 * Eigen::Vector3d::Unit(a));
      for (const auto& [name, p] : targets) {
        camera_sim::GroundTruthRow t;
        t.sequence = k;
        t.time_s = k / 15.0;
        t.board = "target:" + name;
        t.X_CamBoard.translation() = X_CamModel * p;
        t.tags_visible = 1;
        t.has_px = true;  // the pixel is not used by the surface distance
        w.write(t);
      }
    }
  }
  {
    std::ofstream csv(dir / "overlay.csv");
    csv << "camera_sequence,capture_time_mono_us,pose_time_mono_us,model_step_time_mono_us,render_done_mono_us,"
           "motion_to_photon_ms,tumour_u_px,tumour_v_px,blade_to_margin_mm,flags\n";
    csv << "0,100,100,110,120,20.0,600,300,,\n1,200,200,210,220,20.0,600,300,,\n";
    std::ofstream bin(dir / "tumour_Cam.bin", std::ios::binary);
    host::write_tumour_surface_header(bin);
    host::TriMesh drawn = scene.tumours[0].rest;
    drawn.positions_World_mm = X_CamModel * drawn.positions_World_mm;
    host::write_tumour_surface(bin, 0, drawn, true);
    drawn.positions_World_mm.row(2).array() += 2.0;
    host::write_tumour_surface(bin, 1, drawn, false);
  }
  const ArErrorReport rep = evaluate_ar_error((dir / "session_phantom.yaml").string(), (dir / "gt.csv").string(),
                                              (dir / "overlay.csv").string(), (dir / "tumour_Cam.bin").string());
  ASSERT_TRUE(rep.has_surface);
  ASSERT_EQ(rep.frames.size(), 2u);
  EXPECT_LT(rep.frames[0].surface_max_mm, 1e-3);
  EXPECT_LE(rep.frames[1].surface_max_mm, 2.0 + 1e-3);
  EXPECT_GT(rep.frames[1].surface_max_mm, 1.5);
  EXPECT_GT(rep.frames[1].surface_mean_mm, 0.3);
  EXPECT_LT(rep.frames[1].surface_mean_mm, 2.0);
  EXPECT_EQ(rep.summary()["tumour_surface_mm"]["frames"].get<int>(), 2);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace arnav::hil
