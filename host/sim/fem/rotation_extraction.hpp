#pragma once
// Rotation part of a deformation gradient for the co-rotational FEM.
// Iterative maximisation of tr(R^T F) over SO(3) on a unit quaternion (after Mueller et
// al. 2016, "A robust method to extract the rotational part of deformations", with a
// Newton step where the local Hessian allows): warm started from the previous step's
// rotation it needs 1-2 iterations, and it always returns
// a proper rotation, also for degenerate or inverted elements (det F <= 0), where a plain
// polar decomposition would return a reflection. For det F > 0 the result is the polar
// rotation.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arnav::host {

struct RotationExtraction {
  int max_iterations = 20;
  double tolerance_rad = 1e-9;  // stop when the update rotation is smaller
};

// Returns the rotation; q_warm is the starting guess (previous rotation). iterations, if
// not null, receives the number of updates made.
Eigen::Quaterniond extract_rotation(const Eigen::Matrix3d& F, const Eigen::Quaterniond& q_warm,
                                    const RotationExtraction& options = {}, int* iterations = nullptr);

// Closed-form start for a cold element (after set_state): R = U diag(1, 1, det(U V^T)) V^T
// from the SVD of F, the rotation nearest to F (a proper rotation also when det F < 0).
Eigen::Quaterniond rotation_by_svd(const Eigen::Matrix3d& F);

}  // namespace arnav::host
