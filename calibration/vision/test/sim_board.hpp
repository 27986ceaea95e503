#pragma once
// Test glue: an ARNav board layout as the synthetic camera's TagBoard, and board poses
// facing a camera.
#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include "appliance/markers/calibration_files.hpp"
#include "appliance/markers/tag_board.hpp"
#include "calibration/lib/board_layout.hpp"

namespace arnav::calib::test {

// The appliance's own conversion (appliance/markers/calibration_files.hpp).
inline markers::TagBoard to_tag_board(const BoardLayout& layout) {
  return markers::board_from_layout(layout, layout.name, "test layout " + layout.name);
}

// Board centre at distance z_mm on the optical axis (+ offset), facing the camera, then
// tilted by (rx, ry) degrees about the board centre's axes.
inline Eigen::Isometry3d board_facing_camera(const BoardLayout& layout, double z_mm, double rx_deg, double ry_deg,
                                             double rz_deg, const Eigen::Vector2d& offset_mm) {
  const double d = M_PI / 180.0;
  const Eigen::Vector3d centre(0.5 * layout.board_width_mm, 0.5 * layout.board_height_mm, 0.0);
  Eigen::Isometry3d X_CamCentre = Eigen::Isometry3d::Identity();
  // Board z (out of the paper) towards the camera: rotate pi about x.
  X_CamCentre.linear() = (Eigen::AngleAxisd(rx_deg * d, Eigen::Vector3d::UnitX()) *
                          Eigen::AngleAxisd(ry_deg * d, Eigen::Vector3d::UnitY()) *
                          Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) *
                          Eigen::AngleAxisd(rz_deg * d, Eigen::Vector3d::UnitZ()))
                             .toRotationMatrix();
  X_CamCentre.translation() = Eigen::Vector3d(offset_mm.x(), offset_mm.y(), z_mm);
  return X_CamCentre * Eigen::Translation3d(-centre);
}

}  // namespace arnav::calib::test
