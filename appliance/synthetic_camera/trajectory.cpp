#include "appliance/synthetic_camera/trajectory.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace arnav::camera_sim {

Eigen::Isometry3d Trajectory::X_CamBoard(double t_s, const Eigen::Vector2d& board_centre_mm, int front_side) const {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  constexpr double kDeg = std::numbers::pi / 180.0;
  const double w = kTwoPi * (t_s + phase_s) / period_s;
  // Lissajous path: x once and y twice per period, depth out of phase with x.
  const Eigen::Vector3d p_CamCentre(image_offset_mm.x() + amplitude_mm.x() * std::sin(w),
                                    image_offset_mm.y() + amplitude_mm.y() * std::sin(2.0 * w),
                                    distance_mm + amplitude_mm.z() * std::cos(w));
  // Printed side facing the camera, then tilted about a turning axis.
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(front_side > 0 ? std::numbers::pi : 0.0, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(tilt_deg * kDeg * std::sin(w), Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(tilt_deg * kDeg * std::cos(1.5 * w), Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(spin_deg * kDeg * std::sin(0.5 * w), Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = R;
  X.translation() = p_CamCentre - R * Eigen::Vector3d(board_centre_mm.x(), board_centre_mm.y(), 0.0);
  return X;
}

void validate(const Trajectory& t) {
  if (!(t.distance_mm > 0.0)) throw std::invalid_argument("trajectory: distance_mm must be > 0");
  if (!(t.period_s > 0.0)) throw std::invalid_argument("trajectory: period_s must be > 0");
  if (!(std::abs(t.amplitude_mm.z()) < t.distance_mm)) {
    throw std::invalid_argument("trajectory: amplitude along z must be smaller than distance_mm (board behind the camera)");
  }
}

}  // namespace arnav::camera_sim
