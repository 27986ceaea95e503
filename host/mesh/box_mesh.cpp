#include "host/mesh/box_mesh.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <map>
#include <stdexcept>

namespace arnav::host {

TetMesh make_box_tet_mesh(int nx, int ny, int nz, const Eigen::Vector3d& size_mm) {
  if (nx < 1 || ny < 1 || nz < 1) throw std::invalid_argument("make_box_tet_mesh: need at least one cell per axis");
  TetMesh mesh;
  const int nv = (nx + 1) * (ny + 1) * (nz + 1);
  mesh.rest_positions_World_mm.resize(3, nv);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        mesh.rest_positions_World_mm.col(box_vertex_index(nx, ny, i, j, k)) =
            Eigen::Vector3d(size_mm.x() * i / nx, size_mm.y() * j / ny, size_mm.z() * k / nz);
  // Kuhn split: the 6 monotone paths from corner 000 to corner 111 of the unit cube.
  static const int kPaths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& path : kPaths) {
          std::array<int, 3> c{i, j, k};
          std::array<int, 4> tet{};
          tet[0] = box_vertex_index(nx, ny, c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[path[s]];
            tet[s + 1] = box_vertex_index(nx, ny, c[0], c[1], c[2]);
          }
          const Eigen::Vector3d x0 = mesh.rest_positions_World_mm.col(tet[0]);
          Eigen::Matrix3d D;
          for (int s = 0; s < 3; ++s) D.col(s) = mesh.rest_positions_World_mm.col(tet[s + 1]) - x0;
          if (D.determinant() < 0) std::swap(tet[2], tet[3]);
          mesh.tets.push_back(tet);
        }
  mesh.tet_region.assign(mesh.tets.size(), 0);
  mesh.region_names = {"default"};
  mesh.surface_tris = boundary_faces(mesh);
  return mesh;
}

std::vector<std::array<int, 3>> boundary_faces(const TetMesh& mesh) {
  // Faces of a positively oriented tet (v0,v1,v2,v3) with outward normals.
  const auto& kFaces = kTetFaces;
  std::map<std::array<int, 3>, std::pair<int, std::array<int, 3>>> count;
  for (const auto& tet : mesh.tets)
    for (const auto& f : kFaces) {
      std::array<int, 3> face{tet[f[0]], tet[f[1]], tet[f[2]]};
      std::array<int, 3> key = face;
      std::sort(key.begin(), key.end());
      auto& entry = count[key];
      ++entry.first;
      entry.second = face;
    }
  std::vector<std::array<int, 3>> out;
  for (const auto& [key, entry] : count)
    if (entry.first == 1) out.push_back(entry.second);
  return out;
}

}  // namespace arnav::host
