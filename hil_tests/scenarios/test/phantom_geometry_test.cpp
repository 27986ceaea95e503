// The deforming-phantom bench's three configs describe one world: the synthetic camera's
// phantom pose (appliance_phantom.yaml: board trajectory, X_BoardModel), the simulated
// Polaris' X_NdiModel (polaris_phantom.yaml) through the hand-eye X_CamNdi.yaml, and the
// host's registration (session_phantom.yaml). If one is edited alone, the tool the host
// sees no longer touches the organ the camera films: this test fails.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <unistd.h>

#include "appliance/camera/camera_config.hpp"
#include "appliance/synthetic_camera/phantom_recording.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"
#include "host/app/session_config.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::hil {
namespace {

std::string slurp(const std::filesystem::path& p) { return arnav::testing::read_text(p); }

TEST(PhantomBenchGeometry, CameraTrackerAndHostAgree) {
  const std::filesystem::path src = arnav::testing::source_dir() + "/hil_tests/scenarios/ar_demo";
  const std::string data = arnav::testing::data_dir();
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_phgeo_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  for (const char* f : {"camera.yaml", "marker_board.yaml", "X_RefModel_phantom.yaml", "X_CamNdi.yaml", "liver_navigation.scene.yaml"})
    std::filesystem::copy_file(src / f, dir / f, std::filesystem::copy_options::overwrite_existing);
  for (const char* f : {"appliance_phantom.yaml", "polaris_phantom.yaml", "session_phantom.yaml"}) {
    std::ofstream(dir / f) << std::regex_replace(slurp(src / f), std::regex("\\.\\./\\.\\./\\.\\./data/"), data + "/");
  }
  // A stand-in recording (the real one is generated): the grasper at two poses.
  camera_sim::PhantomRecording rec;
  rec.tool_names = {"grasper"};
  rec.target_names = {"tumour_centroid"};
  rec.vertex_count = 3;
  rec.faces = {{0, 1, 2}};
  for (int k = 0; k < 2; ++k) {
    camera_sim::PhantomFrame f;
    f.t_s = k;
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(0.3 * k, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
    X.translation() = Eigen::Vector3d(71, 161, 57) + k * Eigen::Vector3d(20, 10, -15);
    f.X_ModelTool = {X};
    f.targets_Model_mm = {Eigen::Vector3d(70, 160, 140)};
    f.vertices_Model_mm = Eigen::Matrix3Xd::Identity(3, 3);
    rec.frames.push_back(f);
  }
  camera_sim::write_phantom_recording(dir / "phantom.txt", rec);

  const auto cam = camera::parse_camera_config(slurp(dir / "appliance_phantom.yaml"), "appliance_phantom.yaml", dir);
  ASSERT_TRUE(cam && cam->synthetic && cam->synthetic->phantom);
  const auto& ph = *cam->synthetic->phantom;
  capture::SyntheticSource source(*cam->synthetic);
  const Eigen::Isometry3d X_CamModel = source.X_CamBoard(ph.board_index, 0) * ph.X_BoardModel;
  // The camera is static: the same pose at every frame.
  EXPECT_TRUE(source.X_CamBoard(ph.board_index, 100).isApprox(source.X_CamBoard(ph.board_index, 0), 1e-9));

  const Scenario sim = load_scenario(dir / "polaris_phantom.yaml");
  ASSERT_EQ(sim.tools.size(), 1u);
  ASSERT_TRUE(sim.tools[0].motion.phantom);
  const Eigen::Isometry3d X_CamNdi = calib::read_transform(dir / "X_CamNdi.yaml").X_ParentChild;
  const Eigen::Isometry3d X_CamModel_tracker = X_CamNdi * sim.tools[0].motion.phantom->X_NdiModel;
  EXPECT_TRUE(X_CamModel_tracker.isApprox(X_CamModel, 1e-9)) << X_CamModel_tracker.matrix() << "\nvs camera\n" << X_CamModel.matrix();
  // The tool in Cam as the tracker reports it = as the camera's world has it.
  const double t0 = sim.tools[0].motion.phantom->t0_s;
  for (double t : {0.0, 0.4, 1.0}) {
    const Eigen::Isometry3d via_tracker = X_CamNdi * sim.tools[0].motion.X_NdiTool(t0 + t);
    const Eigen::Isometry3d via_camera = X_CamModel * rec.tool_pose_at(t, 0);
    EXPECT_TRUE(via_tracker.isApprox(via_camera, 1e-9)) << "t = " << t;
  }

  // The host is registered to the same phantom-on-board pose.
  const host::SessionConfig session = host::load_session((dir / "session_phantom.yaml").string());
  ASSERT_TRUE(session.X_RefModel);
  EXPECT_TRUE(session.X_RefModel->isApprox(ph.X_BoardModel, 1e-9));
  ASSERT_TRUE(session.reference);
  EXPECT_EQ(session.reference->name, cam->tools[ph.board_index].board.name);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace arnav::hil
