// Per-frame tracking: features with IDs pull the model and the interior follows; lost and
// far IDs are handled; bad frames are refused.
#include <gtest/gtest.h>

#include <cstdlib>
#include <iostream>

#include "host/register/tracking.hpp"
#include "host/scene/embedding.hpp"

using namespace arnav::host;

namespace {
const Scene& coarse_scene() {
  static const Scene s = [] {
    const char* d = std::getenv("ARNAV_DATA_DIR");
    if (!d) throw std::runtime_error("ARNAV_DATA_DIR is not set");
    return load_scene(std::string(d) + "/liver/liver_coarse.scene.yaml");
  }();
  return s;
}
}  // namespace

// Features spread over the whole surface, first seen at the registered shape, then all
// moving 6 mm along x over half a second: the free model follows and an interior point
// (the tumour centre) moves with them.
TEST(Tracking, InteriorFollowsTrackedFeatures) {
  const Scene& s = coarse_scene();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(10, -20, 30);
  SurfaceTracker tracker(s, s.problem.mesh.rest_positions_World_mm, X);
  const Eigen::Matrix3Xd& sv = s.organ_surface.positions_World_mm;
  std::vector<long long> ids;
  Eigen::Matrix3Xd pts(3, 0);
  for (int v = 0; v < sv.cols(); v += sv.cols() / 80) {
    ids.push_back(v);
    pts.conservativeResize(3, pts.cols() + 1);
    pts.col(pts.cols() - 1) = X * sv.col(v);
  }
  const Eigen::Vector3d centre(70, 160, 140);
  const Embedding e = embed_points(s.problem.mesh, Eigen::Matrix3Xd(centre), 0.5, "centre");
  TrackingFrame f;
  for (int frame = 0; frame < 120; ++frame) {
    const double shift = 6.0 * std::min(1.0, frame / 30.0);
    Eigen::Matrix3Xd moved_pts = pts;
    moved_pts.colwise() += X.linear() * Eigen::Vector3d(shift, 0, 0);
    f = tracker.update(moved_pts, ids, s.time_step_s);
    ASSERT_TRUE(f.healthy) << f.warning;
    if (frame == 0) {
      EXPECT_EQ(f.bound, static_cast<int>(ids.size()));
    }
  }
  EXPECT_EQ(f.tracked, static_cast<int>(ids.size()));
  EXPECT_EQ(f.bound, 0);
  const Eigen::Vector3d moved = e.apply(s.problem.mesh, tracker.positions_Model_mm()).col(0);
  std::cout << "tumour centre moved by " << (moved - centre).transpose() << " mm\n";
  EXPECT_NEAR(moved.x() - centre.x(), 6.0, 1.0);
  EXPECT_LT((moved - centre - Eigen::Vector3d(6, 0, 0)).norm(), 1.5);
}

TEST(Tracking, LostFarAndBadInput) {
  const Scene& s = coarse_scene();
  SurfaceTracker tracker(s, s.problem.mesh.rest_positions_World_mm, Eigen::Isometry3d::Identity());
  Eigen::Matrix3Xd pts(3, 2);
  pts.col(0) = s.organ_surface.positions_World_mm.col(0);
  pts.col(1) = pts.col(0) + Eigen::Vector3d(500, 0, 0);  // far from the organ: an outlier
  TrackingFrame f = tracker.update(pts, {1, 2}, s.time_step_s);
  EXPECT_EQ(f.bound, 1);
  EXPECT_EQ(f.rejected, 1);
  f = tracker.update(Eigen::Matrix3Xd(3, 0), {}, s.time_step_s);  // everything lost this frame
  EXPECT_EQ(f.tracked, 0);
  EXPECT_TRUE(f.healthy);
  f = tracker.update(pts, {1, 2}, s.time_step_s);  // id 1 back, id 2 stays refused
  EXPECT_EQ(f.tracked, 1);
  EXPECT_EQ(f.bound, 0);
  EXPECT_THROW(tracker.update(pts, {1}, s.time_step_s), std::invalid_argument);
}
