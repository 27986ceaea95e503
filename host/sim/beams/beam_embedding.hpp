#pragma once
// Vessel centrelines as Timoshenko beams embedded in the tetrahedral mesh (paper 001):
// every beam node is tied to the tet that holds it by barycentric coordinates, and its
// rotation is the infinitesimal rotation of that tet (half the curl of the P1
// displacement field). That gives a constant map J (6 beam DOF per node from the 12 DOF
// of its tet), so the coupled stiffness is K = Kp + J^T Kb J with no extra unknowns:
// the beams stiffen the tissue but the system keeps 3 DOF per mesh vertex.
// Each beam element therefore becomes a "super-element" over the (up to 8) vertices of
// its two embedding tets with a rest stiffness J^T Kb J, co-rotated like a tet by the
// FEM model. Frame: World, units mm, kPa, mN.
#include <Eigen/Core>

#include <array>
#include <vector>

#include "host/mesh/tet_mesh.hpp"
#include "host/sim/beams/beam_element.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct VesselBeamOptions {
  double wall_thickness_mm = 0.2;      // vessel wall (paper 001: 200 um); >= radius: solid rod
  double max_element_length_mm = 0.0;  // subdivide longer segments; 0 = one element per segment
  double outside_tolerance = 0.25;     // nodes outside the mesh: accepted barycentric overshoot
};

// A beam element pulled back onto the mesh vertices.
struct EmbeddedBeam {
  std::vector<int> vertices;   // distinct mesh vertices of both embedding tets (4..8)
  Eigen::MatrixXd K_rest;      // 3n x 3n, J^T Kb J in the rest configuration, mN/mm
  std::array<int, 2> tets{};   // embedding tet of each end node (source of the co-rotation)
};

struct VesselEmbedding {
  Eigen::Matrix3Xd node_rest_World_mm;        // beam nodes after subdivision
  std::vector<int> node_tet;                  // embedding tet per node
  std::vector<Eigen::Vector4d> node_barycentric;
  std::vector<std::array<int, 2>> segments;   // beam elements (node pairs)
  std::vector<EmbeddedBeam> beams;            // one per segment
};

// 6 x 12 map from the displacements of the 4 vertices of `tet` to the displacement and
// rotation vector of the material point with barycentric coordinates `bary`.
Eigen::Matrix<double, 6, 12> embedding_jacobian(const Eigen::Matrix3Xd& rest_World_mm, const std::array<int, 4>& tet,
                                                const Eigen::Vector4d& bary);

// Barycentric coordinates of p in tet (may be negative outside).
Eigen::Vector4d barycentric(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet, const Eigen::Vector3d& p);

// Builds the embedding. Throws std::invalid_argument naming the vessel node that lies
// outside the mesh (beyond options.outside_tolerance), a zero-length segment or bad radius.
VesselEmbedding embed_vessels(const TetMesh& mesh, const VesselTree& vessels, const Material& vessel_material,
                              const VesselBeamOptions& options = {});

// Current beam node positions from mesh vertex positions (for overlay and checks).
Eigen::Matrix3Xd beam_node_positions(const VesselEmbedding& embedding, const TetMesh& mesh,
                                     const Eigen::Matrix3Xd& x_World_mm);

}  // namespace arnav::host
