#pragma once
// Linear 3D Timoshenko beam element (2 nodes, 6 DOF each: displacement then rotation
// vector). Used for vessel centrelines embedded in the tissue (beam_embedding.hpp) and
// verified alone against the cantilever formulas. Frame: World, units mm, kPa, mN.
#include <Eigen/Core>

namespace arnav::host {

// Cross-section of a beam. Bending about the local y and z axes; torsion about x (axis).
struct BeamSection {
  double area_mm2 = 0.0;
  double I_y_mm4 = 0.0;        // second moment about local y (bending in the x-z plane)
  double I_z_mm4 = 0.0;        // second moment about local z (bending in the x-y plane)
  double J_torsion_mm4 = 0.0;  // torsion constant
  double shear_factor = 0.5;   // Timoshenko k (thin tube ~0.5, solid circle ~0.9, rectangle 5/6)
};

// Thin-walled tube (vessel): outer radius r, wall thickness t (t >= r gives a solid rod).
BeamSection tube_section(double outer_radius_mm, double wall_thickness_mm);
// Solid b x h rectangle, h along local z (I_y = b h^3 / 12); for verification.
BeamSection rectangle_section(double width_y_mm, double height_z_mm);

// 12x12 stiffness in the element's local frame (x from node a to node b), DOF order
// [u_a, theta_a, u_b, theta_b]. Shear deformation included through Phi = 12EI/(kGAL^2)
// (Euler-Bernoulli when shear_factor -> infinity).
Eigen::Matrix<double, 12, 12> beam_local_stiffness(double length_mm, const BeamSection& section,
                                                    double E_kPa, double poisson_ratio);

// The same stiffness expressed in World: T^T K_local T with the local frame built from the
// axis a->b and a reference direction (any not parallel to the axis; picked if zero).
// Throws std::invalid_argument for a zero-length element.
Eigen::Matrix<double, 12, 12> beam_world_stiffness(const Eigen::Vector3d& a_World_mm, const Eigen::Vector3d& b_World_mm,
                                                    const BeamSection& section, double E_kPa, double poisson_ratio);

}  // namespace arnav::host
