#pragma once
// Springs on the unique edges of a tetrahedral mesh (the Voigt elements of the
// mass-spring model). Units: mm, mN/mm, mN*s/mm.
#include <array>
#include <cstdint>
#include <vector>

#include "host/mesh/tet_mesh.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct SpringNetwork {
  std::vector<std::array<int, 2>> ends;
  std::vector<double> rest_length_mm;
  std::vector<double> stiffness_mN_per_mm;
  std::vector<double> damping_mN_s_per_mm;  // Voigt dashpot along the spring
  int size() const { return static_cast<int>(ends.size()); }
};

// Stiffness after Van Gelder (1998): k_e = sum over tets t containing edge e of
// E_t V_t / L_e^2. For an isotropic network this reproduces Young's modulus with an
// effective Poisson ratio of 1/4 (a spring network cannot represent another ratio).
// Damping: Rayleigh stiffness-proportional beta of each region, eta_e = beta * k_e.
// Throws std::invalid_argument for degenerate edges or tets.
// Tets flagged in `passive` (embedded_elements.hpp) add no stiffness (their edges still get
// a spring, of zero stiffness when no active tet shares it).
SpringNetwork build_spring_network(const TetMesh& mesh, const std::vector<Material>& region_materials,
                                   const std::vector<std::uint8_t>& passive = {});

}  // namespace arnav::host
