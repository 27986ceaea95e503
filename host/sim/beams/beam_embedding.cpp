#include "host/sim/beams/beam_embedding.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

namespace arnav::host {
namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

Eigen::Matrix3d rest_edges(const Eigen::Matrix3Xd& x, const std::array<int, 4>& tet) {
  Eigen::Matrix3d D;
  for (int k = 0; k < 3; ++k) D.col(k) = x.col(tet[k + 1]) - x.col(tet[0]);
  return D;
}

}  // namespace

Eigen::Vector4d barycentric(const Eigen::Matrix3Xd& x, const std::array<int, 4>& tet, const Eigen::Vector3d& p) {
  const Eigen::Vector3d l = rest_edges(x, tet).inverse() * (p - x.col(tet[0]));
  return Eigen::Vector4d(1.0 - l.sum(), l.x(), l.y(), l.z());
}

Eigen::Matrix<double, 6, 12> embedding_jacobian(const Eigen::Matrix3Xd& rest, const std::array<int, 4>& tet,
                                                const Eigen::Vector4d& bary) {
  // Shape function gradients: rows of Dm^-1 for vertices 1..3, minus their sum for vertex 0.
  const Eigen::Matrix3d Dm_inv = rest_edges(rest, tet).inverse();
  std::array<Eigen::Vector3d, 4> g;
  for (int k = 0; k < 3; ++k) g[k + 1] = Dm_inv.row(k).transpose();
  g[0] = -(g[1] + g[2] + g[3]);
  Eigen::Matrix<double, 6, 12> J = Eigen::Matrix<double, 6, 12>::Zero();
  for (int i = 0; i < 4; ++i) {
    J.block<3, 3>(0, 3 * i) = bary[i] * Eigen::Matrix3d::Identity();
    // theta = curl(u)/2 = 1/2 sum_i g_i x u_i: the rotation of the affine displacement field.
    J.block<3, 3>(3, 3 * i) = 0.5 * skew(g[i]);
  }
  return J;
}

VesselEmbedding embed_vessels(const TetMesh& mesh, const VesselTree& vessels, const Material& material,
                              const VesselBeamOptions& options) {
  const int n_in = static_cast<int>(vessels.nodes_World_mm.cols());
  if (static_cast<int>(vessels.radius_mm.size()) != n_in) {
    throw std::invalid_argument("vessel tree: " + std::to_string(vessels.radius_mm.size()) + " radii for " +
                                std::to_string(n_in) + " nodes");
  }
  VesselEmbedding out;
  // Subdivide segments so that the beams couple to the tissue at more than the tree nodes.
  std::vector<Eigen::Vector3d> nodes;
  std::vector<double> radius;
  for (int i = 0; i < n_in; ++i) {
    nodes.push_back(vessels.nodes_World_mm.col(i));
    radius.push_back(vessels.radius_mm[i]);
  }
  for (std::size_t s = 0; s < vessels.segments.size(); ++s) {
    const auto [a, b] = vessels.segments[s];
    if (a < 0 || b < 0 || a >= n_in || b >= n_in || a == b) {
      throw std::invalid_argument("vessel segment " + std::to_string(s) + " has invalid node indices " +
                                  std::to_string(a) + ", " + std::to_string(b));
    }
    const double L = (nodes[b] - nodes[a]).norm();
    if (!(L > 1e-9)) throw std::invalid_argument("vessel segment " + std::to_string(s) + " has zero length");
    if (!(radius[a] > 0.0) || !(radius[b] > 0.0)) {
      throw std::invalid_argument("vessel segment " + std::to_string(s) + " has a non-positive radius");
    }
    int pieces = 1;
    if (options.max_element_length_mm > 0.0) pieces = std::max(1, static_cast<int>(std::ceil(L / options.max_element_length_mm)));
    int prev = a;
    for (int p = 1; p <= pieces; ++p) {
      int next = b;
      if (p < pieces) {
        const double t = static_cast<double>(p) / pieces;
        nodes.push_back((1 - t) * nodes[a] + t * nodes[b]);
        radius.push_back((1 - t) * radius[a] + t * radius[b]);
        next = static_cast<int>(nodes.size()) - 1;
      }
      out.segments.push_back({prev, next});
      prev = next;
    }
  }
  const int n = static_cast<int>(nodes.size());
  out.node_rest_World_mm.resize(3, n);
  for (int i = 0; i < n; ++i) out.node_rest_World_mm.col(i) = nodes[i];

  // Point location: the tet whose smallest barycentric coordinate is largest (brute force:
  // runs once at scene load, a few hundred nodes times the tets).
  const Eigen::Matrix3Xd& X = mesh.rest_positions_World_mm;
  std::vector<Eigen::Matrix3d> Dm_inv(mesh.tets.size());
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) Dm_inv[t] = rest_edges(X, mesh.tets[t]).inverse();
  out.node_tet.assign(n, -1);
  out.node_barycentric.resize(n);
  for (int i = 0; i < n; ++i) {
    double best = -std::numeric_limits<double>::infinity();
    for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
      const Eigen::Vector3d l = Dm_inv[t] * (nodes[i] - X.col(mesh.tets[t][0]));
      const double m = std::min(1.0 - l.sum(), l.minCoeff());
      if (m > best) {
        best = m;
        out.node_tet[i] = static_cast<int>(t);
        out.node_barycentric[i] = Eigen::Vector4d(1.0 - l.sum(), l.x(), l.y(), l.z());
      }
      if (best >= 0.0) break;  // inside: done
    }
    if (best < -options.outside_tolerance) {
      throw std::invalid_argument("vessel node " + std::to_string(i) + " at (" + std::to_string(nodes[i].x()) + ", " +
                                  std::to_string(nodes[i].y()) + ", " + std::to_string(nodes[i].z()) +
                                  ") mm lies outside the tissue mesh: fix the vessel centreline or the mesh");
    }
  }

  // Super-element stiffness J^T Kb J per beam element.
  for (const auto& [a, b] : out.segments) {
    const double r = 0.5 * (radius[a] + radius[b]);
    const BeamSection section = tube_section(r, options.wall_thickness_mm);
    const Eigen::Matrix<double, 12, 12> Kb =
        beam_world_stiffness(nodes[a], nodes[b], section, material.youngs_modulus_kPa, material.poisson_ratio);
    EmbeddedBeam beam;
    beam.tets = {out.node_tet[a], out.node_tet[b]};
    for (int t : beam.tets)
      for (int v : mesh.tets[t])
        if (std::find(beam.vertices.begin(), beam.vertices.end(), v) == beam.vertices.end()) beam.vertices.push_back(v);
    const int nv = static_cast<int>(beam.vertices.size());
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(12, 3 * nv);
    for (int end = 0; end < 2; ++end) {
      const int node = end == 0 ? a : b;
      const auto& tet = mesh.tets[out.node_tet[node]];
      const Eigen::Matrix<double, 6, 12> Jn = embedding_jacobian(X, tet, out.node_barycentric[node]);
      for (int k = 0; k < 4; ++k) {
        const int local = static_cast<int>(std::find(beam.vertices.begin(), beam.vertices.end(), tet[k]) -
                                           beam.vertices.begin());
        J.block<6, 3>(6 * end, 3 * local) += Jn.block<6, 3>(0, 3 * k);
      }
    }
    beam.K_rest = J.transpose() * Kb * J;
    out.beams.push_back(std::move(beam));
  }
  return out;
}

Eigen::Matrix3Xd beam_node_positions(const VesselEmbedding& e, const TetMesh& mesh, const Eigen::Matrix3Xd& x) {
  Eigen::Matrix3Xd p(3, e.node_rest_World_mm.cols());
  for (Eigen::Index i = 0; i < p.cols(); ++i) {
    const auto& tet = mesh.tets[e.node_tet[i]];
    p.col(i).setZero();
    for (int k = 0; k < 4; ++k) p.col(i) += e.node_barycentric[i][k] * x.col(tet[k]);
  }
  return p;
}

}  // namespace arnav::host
