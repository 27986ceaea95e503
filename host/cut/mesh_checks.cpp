#include "host/cut/mesh_checks.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <sstream>

#include "host/mesh/mesh_quality.hpp"

namespace arnav::host::cut {

double min_dihedral_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  return tet_dihedral_range_deg(a, b, c, d).first;
}

CutMeshCheck check_cut_mesh(const TetMesh& mesh, const Eigen::Matrix3Xd& x_in) {
  const Eigen::Matrix3Xd& x = x_in.cols() == 0 ? mesh.rest_positions_World_mm : x_in;
  CutMeshCheck c;
  const int nt = mesh.num_tets();
  c.min_tet_volume_mm3 = nt > 0 ? 1e300 : 0.0;
  const auto& kFaces = kTetFaces;
  std::map<std::array<int, 3>, std::vector<std::pair<int, std::array<int, 3>>>> faces;
  for (int t = 0; t < nt; ++t) {
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    const Eigen::Vector3d a = x.col(tet[0]), b = x.col(tet[1]), cc = x.col(tet[2]), d = x.col(tet[3]);
    const double vol = (b - a).cross(cc - a).dot(d - a) / 6.0;
    c.total_volume_mm3 += vol;
    c.min_tet_volume_mm3 = std::min(c.min_tet_volume_mm3, vol);
    if (!(vol > 0)) ++c.nonpositive_tets;
    c.min_dihedral_deg = std::min(c.min_dihedral_deg, min_dihedral_deg(a, b, cc, d));
    for (const auto& f : kFaces) {
      std::array<int, 3> face{tet[static_cast<std::size_t>(f[0])], tet[static_cast<std::size_t>(f[1])], tet[static_cast<std::size_t>(f[2])]};
      std::array<int, 3> key = face;
      std::sort(key.begin(), key.end());
      faces[key].emplace_back(t, face);
    }
  }
  // Pieces: union of tets sharing a face.
  std::vector<int> parent(static_cast<std::size_t>(nt));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[static_cast<std::size_t>(i)] != i) i = parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
    return i;
  };
  std::map<std::pair<int, int>, int> directed;  // boundary edge (from, to) -> count
  for (const auto& [key, users] : faces) {
    if (users.size() > 2) ++c.overshared_faces;
    if (users.size() == 2) parent[static_cast<std::size_t>(find(users[0].first))] = find(users[1].first);
    if (users.size() == 1) {
      ++c.boundary_faces;
      const auto& f = users[0].second;
      for (int i = 0; i < 3; ++i) ++directed[{f[static_cast<std::size_t>(i)], f[static_cast<std::size_t>((i + 1) % 3)]}];
    }
  }
  for (const auto& [e, n] : directed) {
    const auto it = directed.find({e.second, e.first});
    const int back = it == directed.end() ? 0 : it->second;
    if (n > 1) ++c.misoriented_edges;
    if (back == 0) ++c.open_edges;
    else if (e.first < e.second && n + back > 2) ++c.nonmanifold_edges;
  }
  c.piece_of_tet.assign(static_cast<std::size_t>(nt), -1);
  std::map<int, int> root_piece;
  for (int t = 0; t < nt; ++t) {
    const int r = find(t);
    auto [it, inserted] = root_piece.emplace(r, static_cast<int>(root_piece.size()));
    if (inserted) c.piece_volume_mm3.push_back(0.0);
    c.piece_of_tet[static_cast<std::size_t>(t)] = it->second;
  }
  for (int t = 0; t < nt; ++t) {
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    const Eigen::Vector3d a = x.col(tet[0]);
    c.piece_volume_mm3[static_cast<std::size_t>(c.piece_of_tet[static_cast<std::size_t>(t)])] +=
        (Eigen::Vector3d(x.col(tet[1])) - a).cross(Eigen::Vector3d(x.col(tet[2])) - a).dot(Eigen::Vector3d(x.col(tet[3])) - a) / 6.0;
  }
  return c;
}

std::string CutMeshCheck::summary() const {
  std::ostringstream s;
  s << "volume " << total_volume_mm3 << " mm^3, pieces " << piece_volume_mm3.size() << ", min tet volume " << min_tet_volume_mm3
    << ", non-positive tets " << nonpositive_tets << ", min dihedral " << min_dihedral_deg << " deg, boundary faces " << boundary_faces
    << ", open edges " << open_edges << ", non-manifold edges " << nonmanifold_edges << ", misoriented edges " << misoriented_edges
    << ", faces in >2 tets " << overshared_faces;
  return s.str();
}

}  // namespace arnav::host::cut
