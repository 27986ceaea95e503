#pragma once
// Scripted board motion for the synthetic camera: the board's centre moves on a smooth
// closed path in front of the camera while the board tilts and spins, so a run covers
// distances and viewing angles. Deterministic in time: X_CamBoard(t) is the ground truth.
#include <Eigen/Geometry>

namespace arnav::camera_sim {

struct Trajectory {
  double distance_mm = 500.0;                            // mean depth of the board centre
  Eigen::Vector3d amplitude_mm = Eigen::Vector3d(80, 50, 60);  // excursion along Cam x, y, z
  Eigen::Vector2d image_offset_mm = Eigen::Vector2d::Zero();   // shifts the path sideways
  double period_s = 10.0;                                // one loop of the path
  double tilt_deg = 25.0;                                // peak tilt of the board normal
  double spin_deg = 20.0;                                // peak in-plane rotation
  double phase_s = 0.0;                                  // time offset (several boards)

  // Pose of the board at time t. board_centre_mm: the point of the board (in Board) that
  // follows the path, usually the centre of its printed sheet. front_side: +1 when the
  // printed side is the board's +z, -1 when it is -z (markers::front_side).
  Eigen::Isometry3d X_CamBoard(double t_s, const Eigen::Vector2d& board_centre_mm, int front_side = 1) const;
};

// Throws std::invalid_argument for a non-positive distance or period.
void validate(const Trajectory& trajectory);

}  // namespace arnav::camera_sim
