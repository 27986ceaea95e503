#include "host/sim/beams/beam_element.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace arnav::host {

BeamSection tube_section(double outer_radius_mm, double wall_thickness_mm) {
  if (!(outer_radius_mm > 0.0) || !(wall_thickness_mm > 0.0)) {
    throw std::invalid_argument("tube_section: radius and wall thickness must be positive (got r=" +
                                std::to_string(outer_radius_mm) + " mm, t=" + std::to_string(wall_thickness_mm) +
                                " mm)");
  }
  const double ro = outer_radius_mm;
  const double ri = wall_thickness_mm >= ro ? 0.0 : ro - wall_thickness_mm;
  BeamSection s;
  s.area_mm2 = std::numbers::pi * (ro * ro - ri * ri);
  s.I_y_mm4 = s.I_z_mm4 = std::numbers::pi / 4.0 * (std::pow(ro, 4) - std::pow(ri, 4));
  s.J_torsion_mm4 = 2.0 * s.I_y_mm4;
  // Shear correction: ~0.5 for a thin tube, 0.9 for a solid circle; interpolate on ri/ro.
  s.shear_factor = 0.9 - 0.4 * (ri / ro);
  return s;
}

BeamSection rectangle_section(double width_y_mm, double height_z_mm) {
  BeamSection s;
  const double b = width_y_mm, h = height_z_mm;
  s.area_mm2 = b * h;
  s.I_y_mm4 = b * h * h * h / 12.0;
  s.I_z_mm4 = h * b * b * b / 12.0;
  // Saint-Venant torsion constant of a rectangle (series approximation, a >= c).
  const double a = std::max(b, h), c = std::min(b, h);
  s.J_torsion_mm4 = a * c * c * c * (1.0 / 3.0 - 0.21 * c / a * (1.0 - std::pow(c / a, 4) / 12.0));
  s.shear_factor = 5.0 / 6.0;
  return s;
}

Eigen::Matrix<double, 12, 12> beam_local_stiffness(double L, const BeamSection& s, double E, double nu) {
  if (!(L > 0.0)) throw std::invalid_argument("beam_local_stiffness: non-positive length " + std::to_string(L));
  const double G = E / (2.0 * (1.0 + nu));
  Eigen::Matrix<double, 12, 12> K = Eigen::Matrix<double, 12, 12>::Zero();
  // Axial (u_x) and torsion (theta_x).
  const double ka = E * s.area_mm2 / L, kt = G * s.J_torsion_mm4 / L;
  K(0, 0) = K(6, 6) = ka;
  K(0, 6) = K(6, 0) = -ka;
  K(3, 3) = K(9, 9) = kt;
  K(3, 9) = K(9, 3) = -kt;
  // Bending: (w, theta) pairs; sign = +1 for (u_y, theta_z), -1 for (u_z, theta_y)
  // because theta_z = +dv/dx while theta_y = -dw/dx.
  auto bending = [&](int w, int th, double I, double sign) {
    const double phi = 12.0 * E * I / (s.shear_factor * G * s.area_mm2 * L * L);
    const double c = E * I / ((1.0 + phi) * L * L * L);
    const int d[4] = {w, th, w + 6, th + 6};
    const double m[4][4] = {{12, 6 * L, -12, 6 * L},
                            {6 * L, (4 + phi) * L * L, -6 * L, (2 - phi) * L * L},
                            {-12, -6 * L, 12, -6 * L},
                            {6 * L, (2 - phi) * L * L, -6 * L, (4 + phi) * L * L}};
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        const bool flip = ((i % 2) != (j % 2)) && sign < 0;  // translation-rotation couplings
        K(d[i], d[j]) = c * (flip ? -m[i][j] : m[i][j]);
      }
  };
  bending(1, 5, s.I_z_mm4, +1.0);
  bending(2, 4, s.I_y_mm4, -1.0);
  return K;
}

Eigen::Matrix<double, 12, 12> beam_world_stiffness(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                                    const BeamSection& s, double E, double nu) {
  const Eigen::Vector3d axis = b - a;
  const double L = axis.norm();
  if (!(L > 0.0)) throw std::invalid_argument("beam_world_stiffness: zero-length beam element");
  const Eigen::Vector3d e1 = axis / L;
  // Reference direction: the World axis least aligned with the beam.
  Eigen::Vector3d ref = Eigen::Vector3d::Zero();
  Eigen::Index k;
  e1.cwiseAbs().minCoeff(&k);
  ref[k] = 1.0;
  const Eigen::Vector3d e2 = (ref - ref.dot(e1) * e1).normalized();
  const Eigen::Vector3d e3 = e1.cross(e2);
  Eigen::Matrix3d Lambda;  // rows: local axes in World, maps World -> local
  Lambda.row(0) = e1.transpose();
  Lambda.row(1) = e2.transpose();
  Lambda.row(2) = e3.transpose();
  Eigen::Matrix<double, 12, 12> T = Eigen::Matrix<double, 12, 12>::Zero();
  for (int i = 0; i < 4; ++i) T.block<3, 3>(3 * i, 3 * i) = Lambda;
  return T.transpose() * beam_local_stiffness(L, s, E, nu) * T;
}

}  // namespace arnav::host
