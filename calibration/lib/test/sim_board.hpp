#pragma once
// Test glue: an ARNav board layout as the synthetic camera's TagBoard (tag centre and
// axes from its corners), and board poses facing a camera.
#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include "appliance/markers/tag_board.hpp"
#include "calibration/lib/board_layout.hpp"

namespace arnav::calib::test {

inline markers::TagBoard to_tag_board(const BoardLayout& layout) {
  markers::TagBoard board;
  board.name = layout.name;
  board.family = layout.tag_family;
  board.paper_mm = Eigen::AlignedBox2d(Eigen::Vector2d(0, 0), Eigen::Vector2d(layout.board_width_mm, layout.board_height_mm));
  for (const auto& t : layout.tags) {
    const auto& p = t.p_BoardCorner_mm;
    markers::BoardTag bt;
    bt.id = t.id;
    bt.size_mm = layout.tag_size_mm;
    const Eigen::Vector3d ex = (p[1] - p[0]).normalized();
    const Eigen::Vector3d ey = (p[3] - p[0]).normalized();
    bt.X_BoardTag.linear().col(0) = ex;
    bt.X_BoardTag.linear().col(1) = ey;
    bt.X_BoardTag.linear().col(2) = ex.cross(ey);
    bt.X_BoardTag.translation() = 0.25 * (p[0] + p[1] + p[2] + p[3]);
    board.tags.push_back(bt);
  }
  return board;
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
