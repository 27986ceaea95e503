#include "host/sim/mass_spring/spring_network.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "host/sim/tet_geometry.hpp"

namespace arnav::host {

SpringNetwork build_spring_network(const TetMesh& mesh, const std::vector<Material>& region_materials,
                                   const std::vector<std::uint8_t>& passive) {
  const auto& kEdges = kTetEdges;
  std::unordered_map<std::uint64_t, int> index;
  index.reserve(mesh.tets.size() * 2);
  SpringNetwork net;
  const auto& X = mesh.rest_positions_World_mm;
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& tet = mesh.tets[t];
    const double volume = signed_volume_mm3(X, tet);
    if (!(volume > 0.0)) throw std::invalid_argument("tet " + std::to_string(t) + " has non-positive rest volume");
    const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[t];
    if (region < 0 || region >= static_cast<int>(region_materials.size())) {
      throw std::invalid_argument("tet " + std::to_string(t) + " refers to region " + std::to_string(region) +
                                  " which has no material");
    }
    const Material& mat = region_materials[region];
    lame_from(mat);  // validates E and nu
    for (const auto& e : kEdges) {
      int a = tet[e[0]], b = tet[e[1]];
      if (a > b) std::swap(a, b);
      const std::uint64_t key = edge_key(a, b);
      auto [it, inserted] = index.emplace(key, net.size());
      if (inserted) {
        const double length = (X.col(b) - X.col(a)).norm();
        if (!(length > 0.0)) {
          throw std::invalid_argument("edge " + std::to_string(a) + "-" + std::to_string(b) + " has zero rest length");
        }
        net.ends.push_back({a, b});
        net.rest_length_mm.push_back(length);
        net.stiffness_mN_per_mm.push_back(0.0);
        net.damping_mN_s_per_mm.push_back(0.0);
      }
      const int s = it->second;
      const double L = net.rest_length_mm[s];
      const bool elastic = static_cast<std::size_t>(t) >= passive.size() || passive[static_cast<std::size_t>(t)] == 0;
      const double k = elastic ? mat.youngs_modulus_kPa * volume / (L * L) : 0.0;  // kPa*mm^3/mm^2 = mN/mm
      net.stiffness_mN_per_mm[s] += k;
      net.damping_mN_s_per_mm[s] += mat.damping_stiffness_s * k;
    }
  }
  return net;
}

}  // namespace arnav::host
