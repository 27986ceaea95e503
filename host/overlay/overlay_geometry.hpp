#pragma once
// Geometry the overlay derives from the model's meshes each frame: vertex normals, the
// safety-margin shell around a tumour, tubes around vessel centerlines and tool segments,
// the organ's silhouette as seen from the camera, and the signed distance from the blade
// to the tumour margin. Frame: whatever frame the inputs are in (Model or Cam), mm.
#include <Eigen/Core>

#include <array>
#include <vector>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::overlay {

// Area-weighted vertex normals (unit; zero for an unused vertex).
Eigen::Matrix3Xd vertex_normals(const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris);

// The surface moved outward by margin_mm along its vertex normals (a closed surface with
// outward normals; exact for a sphere, close for smooth convex shapes like a tumour).
TriMesh offset_surface(const TriMesh& surface, double margin_mm);

// Closed tubes of `sides` sides around each segment (radius per node, capped ends).
TriMesh tubes(const Eigen::Matrix3Xd& nodes, const std::vector<double>& radius_mm,
              const std::vector<std::array<int, 2>>& segments, int sides = 8);

// Each edge of a triangle surface with its one or two faces (face2 = -1 on an open
// boundary). Depends on the topology only: build once per mesh.
struct EdgeFaces {
  int v0, v1, face1, face2;
};
std::vector<EdgeFaces> edge_faces(const std::vector<std::array<int, 3>>& tris);

// Edges of the surface where a face turned towards the eye meets one turned away, for an
// eye at eye_position (same frame as positions): the organ outline. Pairs of vertex ids.
std::vector<std::array<int, 2>> silhouette_edges(const Eigen::Matrix3Xd& positions,
                                                 const std::vector<std::array<int, 3>>& tris,
                                                 const std::vector<EdgeFaces>& edges, const Eigen::Vector3d& eye_position);
std::vector<std::array<int, 2>> silhouette_edges(const Eigen::Matrix3Xd& positions,
                                                 const std::vector<std::array<int, 3>>& tris,
                                                 const Eigen::Vector3d& eye_position);

// Unsigned distance from a point to a triangle mesh (brute force over triangles).
double point_mesh_distance(const Eigen::Vector3d& p, const Eigen::Matrix3Xd& positions,
                           const std::vector<std::array<int, 3>>& tris);

// Signed distance from the blade segment (sampled every step_mm) to the margin shell of a
// closed tumour surface: min over the samples of (distance to the tumour surface, negative
// inside it) minus margin_mm. Negative: the blade is inside the safety margin.
double blade_to_margin_mm(const Eigen::Vector3d& blade_a, const Eigen::Vector3d& blade_b, const TriMesh& tumour,
                          double margin_mm, double step_mm = 0.5);

}  // namespace arnav::host::overlay
