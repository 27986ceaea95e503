#include "host/mesh/mesh_validation.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <unordered_map>

#include "host/mesh/box_mesh.hpp"
#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {


int line_of(std::size_t index, const ElementLines& lines) { return index < lines.size() ? lines[index] : 0; }

void check_finite(const Eigen::Matrix3Xd& p, const std::string& source) {
  for (int i = 0; i < p.cols(); ++i)
    if (!p.col(i).allFinite())
      throw_load_error(source, 0, "vertex " + std::to_string(i) + " has a NaN or infinite coordinate",
                       "repair or re-export the mesh");
}

// Drops vertices no element uses and renumbers the elements.
template <std::size_t N>
int compact_vertices(Eigen::Matrix3Xd& p, std::vector<std::array<int, N>>& elements) {
  std::vector<int> map(p.cols(), -1);
  int next = 0;
  for (auto& e : elements)
    for (int& v : e)
      if (map[v] < 0) map[v] = next++;
  const int removed = static_cast<int>(p.cols()) - next;
  if (removed == 0) return 0;
  Eigen::Matrix3Xd q(3, next);
  for (int i = 0; i < p.cols(); ++i)
    if (map[i] >= 0) q.col(map[i]) = p.col(i);
  for (auto& e : elements)
    for (int& v : e) v = map[v];
  p = std::move(q);
  return removed;
}

template <std::size_t N>
void check_indices(const std::vector<std::array<int, N>>& elements, int nv, const std::string& kind,
                   const std::string& source, const ElementLines& lines) {
  for (std::size_t e = 0; e < elements.size(); ++e) {
    for (int v : elements[e])
      if (v < 0 || v >= nv)
        throw_load_error(source, line_of(e, lines),
                         kind + " " + std::to_string(e) + " refers to vertex " + std::to_string(v) + " but the file has " +
                             std::to_string(nv) + " vertices (valid 0.." + std::to_string(nv - 1) + " after renumbering)",
                         "fix the index or the vertex count in the file");
    for (std::size_t a = 0; a < N; ++a)
      for (std::size_t b = a + 1; b < N; ++b)
        if (elements[e][a] == elements[e][b])
          throw_load_error(source, line_of(e, lines), kind + " " + std::to_string(e) + " uses vertex " +
                                                          std::to_string(elements[e][a]) + " twice (degenerate)",
                           "remove the element or repair the mesh");
  }
}

}  // namespace

SurfaceCheck validate_closed_surface(TriMesh& s, const std::string& source, const ElementLines& lines) {
  SurfaceCheck out;
  const int nv = static_cast<int>(s.positions_World_mm.cols());
  if (s.tris.empty()) throw_load_error(source, 0, "the surface has no triangles", "give a closed triangle surface");
  check_indices(s.tris, nv, "triangle", source, lines);
  check_finite(s.positions_World_mm, source);
  // Degenerate triangles: area tiny against the squared bounding-box size.
  const Eigen::Vector3d extent = s.positions_World_mm.rowwise().maxCoeff() - s.positions_World_mm.rowwise().minCoeff();
  const double scale2 = std::max(extent.squaredNorm(), 1e-300);
  for (std::size_t t = 0; t < s.tris.size(); ++t) {
    const auto& f = s.tris[t];
    const Eigen::Vector3d a = s.positions_World_mm.col(f[0]);
    const double area2 = (s.positions_World_mm.col(f[1]) - a).cross(s.positions_World_mm.col(f[2]) - a).norm();
    if (!(area2 > 1e-14 * scale2))
      throw_load_error(source, line_of(t, lines),
                       "triangle " + std::to_string(t) + " is degenerate (zero area: its vertices are collinear or coincide)",
                       "remove it or repair the surface (e.g. merge close vertices and remesh)");
  }
  // Edges: each undirected edge twice, once in each direction.
  std::map<std::pair<int, int>, std::pair<int, int>> directed;  // (a,b) -> (count, first tri)
  for (std::size_t t = 0; t < s.tris.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      auto& e = directed[{s.tris[t][k], s.tris[t][(k + 1) % 3]}];
      if (e.first++ == 0) e.second = static_cast<int>(t);
    }
  for (const auto& [edge, entry] : directed) {
    const auto reverse = directed.find({edge.second, edge.first});
    const int back = reverse == directed.end() ? 0 : reverse->second.first;
    const int t = entry.second;
    const std::string e = "edge " + std::to_string(edge.first) + "-" + std::to_string(edge.second);
    if (entry.first + back > 2)
      throw_load_error(source, line_of(t, lines),
                       "non-manifold " + e + ": used by " + std::to_string(entry.first + back) + " triangles (first: triangle " +
                           std::to_string(t) + ")",
                       "split the surface into separate closed parts or repair it so each edge joins two triangles");
    if (back == 0)
      throw_load_error(source, line_of(t, lines),
                       entry.first == 1 ? "open surface: " + e + " of triangle " + std::to_string(t) + " is on a hole (used once)"
                                        : "inconsistent orientation: " + e + " is used twice in the same direction (triangle " +
                                              std::to_string(t) + ")",
                       entry.first == 1 ? "close the hole (the organ surface must be watertight)"
                                        : "orient all triangles consistently (e.g. recompute normals)");
  }
  // Non-manifold vertices (two fans meeting at a point) are caught by TetGen later; here
  // the orientation and volume.
  double volume = 0;
  for (const auto& f : s.tris) {
    volume += s.positions_World_mm.col(f[0]).dot(s.positions_World_mm.col(f[1]).cross(s.positions_World_mm.col(f[2]))) / 6.0;
  }
  if (volume < 0) {
    for (auto& f : s.tris) std::swap(f[1], f[2]);
    volume = -volume;
    out.flipped = true;
  }
  if (!(volume > 0))
    throw_load_error(source, 0, "the surface encloses no volume", "give a closed organ surface");
  out.volume_mm3 = volume;
  out.removed_unused_vertices = compact_vertices(s.positions_World_mm, s.tris);
  std::vector<int> component;
  out.components = surface_components(s, component);
  return out;
}

int surface_components(const TriMesh& s, std::vector<int>& component_of_triangle) {
  std::vector<int> parent(s.positions_World_mm.cols());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
  auto find = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : s.tris) {
    parent[find(t[0])] = find(t[1]);
    parent[find(t[1])] = find(t[2]);
  }
  std::unordered_map<int, int> size;
  for (const auto& t : s.tris) ++size[find(t[0])];
  std::vector<std::pair<int, int>> order(size.begin(), size.end());  // (root, triangles)
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
  std::unordered_map<int, int> id;
  for (std::size_t i = 0; i < order.size(); ++i) id[order[i].first] = static_cast<int>(i);
  component_of_triangle.resize(s.tris.size());
  for (std::size_t t = 0; t < s.tris.size(); ++t) component_of_triangle[t] = id[find(s.tris[t][0])];
  return static_cast<int>(order.size());
}

int keep_largest_component(TriMesh& s) {
  std::vector<int> component;
  if (surface_components(s, component) <= 1) return 0;
  std::vector<std::array<int, 3>> kept;
  for (std::size_t t = 0; t < s.tris.size(); ++t)
    if (component[t] == 0) kept.push_back(s.tris[t]);
  s.tris = std::move(kept);
  return compact_vertices(s.positions_World_mm, s.tris);
}

TetMeshCheck validate_tet_mesh(TetMesh& m, const std::string& source, const ElementLines& lines) {
  TetMeshCheck out;
  const int nv = m.num_vertices();
  if (m.tets.empty()) throw_load_error(source, 0, "the volume mesh has no tetrahedra", "give a tetrahedral mesh");
  check_indices(m.tets, nv, "tetrahedron", source, lines);
  check_finite(m.rest_positions_World_mm, source);
  out.min_quality = 1.0;
  for (std::size_t t = 0; t < m.tets.size(); ++t) {
    const auto& tet = m.tets[t];
    Eigen::Matrix3d D;
    for (int k = 0; k < 3; ++k) D.col(k) = m.rest_positions_World_mm.col(tet[k + 1]) - m.rest_positions_World_mm.col(tet[0]);
    const double volume = D.determinant() / 6.0;
    double l2 = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        l2 += (m.rest_positions_World_mm.col(tet[a]) - m.rest_positions_World_mm.col(tet[b])).squaredNorm();
    const double lrms = std::sqrt(l2 / 6.0);
    const double quality = 6.0 * std::sqrt(2.0) * volume / (lrms * lrms * lrms);
    std::ostringstream v;
    v << volume;
    if (quality < -1e-9)
      throw_load_error(source, line_of(t, lines),
                       "tetrahedron " + std::to_string(t) + " (vertices " + std::to_string(tet[0]) + " " + std::to_string(tet[1]) +
                           " " + std::to_string(tet[2]) + " " + std::to_string(tet[3]) + ") is inverted: signed volume " +
                           v.str() + " mm^3",
                       "swap two of its vertices (or re-export with consistent orientation)");
    if (!(quality > 1e-9))
      throw_load_error(source, line_of(t, lines),
                       "tetrahedron " + std::to_string(t) + " is degenerate: volume " + v.str() +
                           " mm^3 is zero for its size (flat or sliver element)",
                       "remesh with a quality bound (TetGen -q) or remove the element");
    out.min_quality = std::min(out.min_quality, quality);
    out.volume_mm3 += volume;
  }
  // Faces shared by more than two tets mean overlapping elements.
  std::map<std::array<int, 3>, int> faces;
  for (std::size_t t = 0; t < m.tets.size(); ++t) {
    const auto& kFaces = kTetFaces;
    for (const auto& f : kFaces) {
      std::array<int, 3> key{m.tets[t][f[0]], m.tets[t][f[1]], m.tets[t][f[2]]};
      std::sort(key.begin(), key.end());
      if (++faces[key] > 2)
        throw_load_error(source, line_of(t, lines),
                         "tetrahedron " + std::to_string(t) + " shares a face with two other tetrahedra (overlapping elements)",
                         "remove duplicated or overlapping elements");
    }
  }
  out.removed_unused_vertices = compact_vertices(m.rest_positions_World_mm, m.tets);
  if (m.tet_region.empty()) {
    m.tet_region.assign(m.tets.size(), 0);
    if (m.region_names.empty()) m.region_names = {"default"};
  }
  m.surface_tris = boundary_faces(m);
  return out;
}

}  // namespace arnav::host
