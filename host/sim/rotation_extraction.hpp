#pragma once
// Rotational part of a deformation gradient without an SVD: the proper rotation R that
// maximises tr(R^T F) (the polar rotation, reflection-safe for inverted F), found by the
// iteration of Mueller et al. 2016 ("A Robust Method to Extract the Rotational Part of
// Deformations"), warm-started from the previous result. A few iterations when warm.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arnav::host {

// (host/sim/fem has its own variant for the FEM.) Refines q in place (unit quaternion) and returns its rotation matrix. Stops when the
// correction angle is below tol_rad or after max_iterations.
Eigen::Matrix3d refine_rotation(const Eigen::Matrix3d& F, Eigen::Quaterniond& q, int max_iterations = 20,
                                 double tol_rad = 1e-12);

}  // namespace arnav::host
