#pragma once
// For the cut tests' diagnosis: per tet, the tets sharing a face with it (a cut face
// belongs to one tet only, so pieces are the components of this graph).
#include <algorithm>
#include <array>
#include <map>
#include <vector>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut::test {

inline std::vector<std::vector<int>> tet_face_neighbours(const TetMesh& mesh) {
  std::map<std::array<int, 3>, std::vector<int>> by_face;
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& q = mesh.tets[static_cast<std::size_t>(t)];
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> f{q[static_cast<std::size_t>(k)], q[static_cast<std::size_t>((k + 1) % 4)], q[static_cast<std::size_t>((k + 2) % 4)]};
      std::sort(f.begin(), f.end());
      by_face[f].push_back(t);
    }
  }
  std::vector<std::vector<int>> adj(static_cast<std::size_t>(mesh.num_tets()));
  for (const auto& [f, ts] : by_face)
    if (ts.size() == 2) {
      adj[static_cast<std::size_t>(ts[0])].push_back(ts[1]);
      adj[static_cast<std::size_t>(ts[1])].push_back(ts[0]);
    }
  return adj;
}

}  // namespace arnav::host::cut::test
