#include <gtest/gtest.h>

#include <cmath>

#include "appliance/frames/reference_frames.hpp"
#include "calibration/lib/rigid_transform_file.hpp"

namespace arnav::frames {
namespace {

Eigen::Isometry3d pose(double ax, double ay, double az, double angle, double x, double y, double z) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d(ax, ay, az).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(x, y, z);
  return X;
}

const Eigen::Isometry3d X_NdiCam = pose(0.2, 1, 0.1, 2.1, -350, 40, -1200);

TEST(ReferenceFrames, BoardFixedToTheReferenceStaysPutWhileEverythingMoves) {
  ReferenceFrames frames(Reference::Ref, X_NdiCam, "ref", 0.05);
  const Eigen::Isometry3d X_RefBoard = pose(1, 0, 0.3, 0.7, 30, -20, 15);
  for (int k = 0; k < 20; ++k) {
    const std::int64_t t = 1000000 + k * 16667;
    // The patient moves: the reference tool moves, the board moves with it.
    const Eigen::Isometry3d X_NdiRef = pose(0.1 * k, 1, 0.2, 0.05 * k, 5.0 * k, -200 + 2.0 * k, -1500);
    frames.update_reference(X_NdiRef, t);
    const Eigen::Isometry3d X_CamBoard = X_NdiCam.inverse() * X_NdiRef * X_RefBoard;
    const Converted c = frames.camera_pose(X_CamBoard, t + 3000);
    ASSERT_TRUE(c.X_ParentChild) << c.reason;
    EXPECT_EQ(c.frame_parent, "Ref");
    EXPECT_TRUE(c.X_ParentChild->isApprox(X_RefBoard, 1e-9));
    // An NDI tool on the same board: X_RefTool from the tracker agrees.
    const Eigen::Isometry3d X_BoardTool = pose(0, 0, 1, 0.3, 10, 0, 5);
    const Converted n = frames.ndi_pose(X_NdiRef * X_RefBoard * X_BoardTool, t);
    ASSERT_TRUE(n.X_ParentChild);
    EXPECT_TRUE(n.X_ParentChild->isApprox(X_RefBoard * X_BoardTool, 1e-9));
  }
}

TEST(ReferenceFrames, UsesTheReferenceSampleClosestInTimeAndRefusesStaleOnes) {
  ReferenceFrames frames(Reference::Ref, X_NdiCam, "ref", 0.02);
  const Eigen::Isometry3d A = pose(1, 0, 0, 0.1, 0, 0, -1000), B = pose(0, 1, 0, 0.4, 50, 0, -1000);
  frames.update_reference(A, 1000000);
  frames.update_reference(B, 1016667);
  const Eigen::Isometry3d X_CamBoard = pose(0, 0, 1, 0.2, 0, 0, 500);
  EXPECT_TRUE(frames.camera_pose(X_CamBoard, 1004000).X_ParentChild->isApprox(A.inverse() * X_NdiCam * X_CamBoard, 1e-9));
  EXPECT_TRUE(frames.camera_pose(X_CamBoard, 1012000).X_ParentChild->isApprox(B.inverse() * X_NdiCam * X_CamBoard, 1e-9));
  const Converted stale = frames.camera_pose(X_CamBoard, 1100000);
  EXPECT_FALSE(stale.X_ParentChild);
  EXPECT_NE(stale.reason.find("'ref'"), std::string::npos) << stale.reason;
  EXPECT_NE(stale.reason.find("ms from the frame"), std::string::npos) << stale.reason;
  frames.reference_missing(1120000);
  const Converted hidden = frames.camera_pose(X_CamBoard, 1121000);
  EXPECT_FALSE(hidden.X_ParentChild);
  EXPECT_NE(hidden.reason.find("not visible"), std::string::npos);
  ReferenceFrames empty(Reference::Ref, X_NdiCam, "ref", 0.02);
  EXPECT_NE(empty.ndi_pose(A, 0).reason.find("not seen yet"), std::string::npos);
}

TEST(ReferenceFrames, CamAndNdiReferences) {
  const Eigen::Isometry3d X_CamBoard = pose(0, 0, 1, 0.2, 10, 0, 500), X_NdiTool = pose(1, 1, 0, 0.5, 0, 100, -900);
  ReferenceFrames cam_only(Reference::Cam, std::nullopt, "", 0.05);
  EXPECT_EQ(cam_only.camera_pose(X_CamBoard, 0).frame_parent, "Cam");
  EXPECT_TRUE(cam_only.camera_pose(X_CamBoard, 0).X_ParentChild->isApprox(X_CamBoard));
  EXPECT_EQ(cam_only.ndi_pose(X_NdiTool, 0).frame_parent, "Ndi");
  ReferenceFrames cam(Reference::Cam, X_NdiCam, "", 0.05);
  EXPECT_TRUE(cam.ndi_pose(X_NdiTool, 0).X_ParentChild->isApprox(X_NdiCam.inverse() * X_NdiTool, 1e-9));
  ReferenceFrames ndi(Reference::Ndi, X_NdiCam, "", 0.05);
  EXPECT_EQ(ndi.camera_pose(X_CamBoard, 0).frame_parent, "Ndi");
  EXPECT_TRUE(ndi.camera_pose(X_CamBoard, 0).X_ParentChild->isApprox(X_NdiCam * X_CamBoard, 1e-9));
  // Without a hand-eye, Ndi serves NDI poses as measured and refuses camera poses with the reason.
  ReferenceFrames ndi_only(Reference::Ndi, std::nullopt, "", 0.05);
  EXPECT_TRUE(ndi_only.ndi_pose(X_NdiTool, 0).X_ParentChild->isApprox(X_NdiTool));
  EXPECT_EQ(ndi_only.ndi_pose(X_NdiTool, 0).frame_parent, "Ndi");
  const Converted refused = ndi_only.camera_pose(X_CamBoard, 0);
  EXPECT_FALSE(refused.X_ParentChild.has_value());
  EXPECT_NE(refused.reason.find("frames.hand_eye"), std::string::npos) << refused.reason;
  EXPECT_THROW(ReferenceFrames(Reference::Ref, X_NdiCam, "", 0.05), std::invalid_argument);
  EXPECT_THROW(parse_reference("World"), std::invalid_argument);
}

TEST(ReferenceFrames, LoadsEitherDirectionOfTheHandEyeFile) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_frames_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  calib::RigidTransformRecord rec;
  rec.parent_frame = "Cam";
  rec.child_frame = "Ndi";
  rec.X_ParentChild = X_NdiCam.inverse();
  rec.method = "test";
  rec.date = "2026-11-21T10:00:00Z";
  calib::write_transform(dir / "X_CamNdi.yaml", rec);
  const auto a = ReferenceFrames::load({Reference::Ndi, "", dir / "X_CamNdi.yaml", 0.05});
  const Eigen::Isometry3d X_CamBoard = pose(0, 0, 1, 0.2, 10, 0, 500);
  EXPECT_TRUE(a->camera_pose(X_CamBoard, 0).X_ParentChild->isApprox(X_NdiCam * X_CamBoard, 1e-6));
  rec.parent_frame = "Ndi";
  rec.child_frame = "Cam";
  rec.X_ParentChild = X_NdiCam;
  calib::write_transform(dir / "X_NdiCam.yaml", rec);
  const auto b = ReferenceFrames::load({Reference::Ndi, "", dir / "X_NdiCam.yaml", 0.05});
  EXPECT_TRUE(b->camera_pose(X_CamBoard, 0).X_ParentChild->isApprox(X_NdiCam * X_CamBoard, 1e-6));
  rec.parent_frame = "Tool";
  rec.child_frame = "Tip";
  calib::write_transform(dir / "X_ToolTip.yaml", rec);
  try {
    ReferenceFrames::load({Reference::Ndi, "", dir / "X_ToolTip.yaml", 0.05});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("X_ToolTip.yaml"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReferenceFrames::load({Reference::Ndi, "", dir / "missing.yaml", 0.05}), std::invalid_argument);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace arnav::frames
