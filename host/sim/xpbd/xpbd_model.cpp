#include "host/sim/xpbd/xpbd_model.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <omp.h>
#include <stdexcept>
#include <string>

#include "host/sim/graph_coloring.hpp"
#include "host/sim/model_setup.hpp"
#include "host/sim/element_measure.hpp"
#include "host/sim/step_health.hpp"
#include "host/sim/tet_geometry.hpp"

namespace arnav::host {

namespace {

// cof(F) = d det(F) / dF: column k is the cross product of the other two columns.
inline Eigen::Matrix3d cofactor(const Eigen::Matrix3d& F) {
  Eigen::Matrix3d c;
  c.col(0) = F.col(1).cross(F.col(2));
  c.col(1) = F.col(2).cross(F.col(0));
  c.col(2) = F.col(0).cross(F.col(1));
  return c;
}

// RMS change of F made by the last sweep (strain units) above which the step is reported
// as not converged.
constexpr double kUnconvergedResidual = 0.01;

// Slot of group g in the per-vertex counts XpbdModel::side_tets_ (groups 0, 2, 3), -1: none.
int side_slot(int g) { return g == 0 ? 0 : (g == 2 ? 1 : (g == 3 ? 2 : -1)); }

std::vector<int> all_tets(int nt) {
  std::vector<int> out(static_cast<std::size_t>(nt));
  for (int t = 0; t < nt; ++t) out[static_cast<std::size_t>(t)] = t;
  return out;
}

// Cuts the tets `set` at the median centroid along the longest axis of their centroids:
// [0] and [1] the tets of each side that touch only vertices no tet of the other side
// touches (they share no vertex), [2] the rest (touching the cut). touched[v] receives
// bit 0 / bit 1 for vertices touched by a tet of side 0 / side 1 (0: not in the set).
std::array<std::vector<int>, 3> split_tets(const TetMesh& mesh, const std::vector<int>& set,
                                           std::vector<unsigned char>& touched) {
  std::array<std::vector<int>, 3> out;
  touched.assign(static_cast<std::size_t>(mesh.num_vertices()), 0);
  if (set.empty()) return out;
  std::vector<Eigen::Vector3d> centroid(set.size(), Eigen::Vector3d::Zero());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(HUGE_VAL), hi = -lo;
  for (std::size_t k = 0; k < set.size(); ++k) {
    for (int v : mesh.tets[static_cast<std::size_t>(set[k])]) centroid[k] += 0.25 * mesh.rest_positions_World_mm.col(v);
    lo = lo.cwiseMin(centroid[k]);
    hi = hi.cwiseMax(centroid[k]);
  }
  const Eigen::Vector3d extent = hi - lo;
  const int axis = extent.x() >= extent.y() && extent.x() >= extent.z() ? 0 : (extent.y() >= extent.z() ? 1 : 2);
  std::vector<double> key(set.size());
  for (std::size_t k = 0; k < set.size(); ++k) key[k] = centroid[k][axis];
  std::vector<double> sorted = key;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(set.size() / 2), sorted.end());
  const double cut = sorted[set.size() / 2];
  for (std::size_t k = 0; k < set.size(); ++k) {
    const unsigned bit = key[k] < cut ? 1u : 2u;
    for (int v : mesh.tets[static_cast<std::size_t>(set[k])]) touched[static_cast<std::size_t>(v)] |= static_cast<unsigned char>(bit);
  }
  for (std::size_t k = 0; k < set.size(); ++k) {
    std::size_t g = key[k] < cut ? 0 : 1;
    for (int v : mesh.tets[static_cast<std::size_t>(set[k])])
      if (touched[static_cast<std::size_t>(v)] == 3) g = 2;
    out[g].push_back(set[k]);
  }
  return out;
}

}  // namespace

XpbdModel::XpbdModel(const SimProblem& problem, const ModelConfig& config) : config_(config) {
  check_iterative_config(config, "xpbd");
  const TetMesh& mesh = problem.mesh;
  mass_ = checked_masses_kg(problem, "xpbd");
  const int n = mesh.num_vertices();
  num_tets_ = mesh.num_tets();
  gravity_ = problem.gravity_World_mm_s2;
  vessels_ignored_ = problem.vessels.has_value() && !problem.vessels->segments.empty();
  x_ = mesh.rest_positions_World_mm;
  v_ = Eigen::Matrix3Xd::Zero(3, n);
  x_prev_ = x_;

  if (config.energy == "neo_hookean") {
    neo_hookean_ = true;
    // Its shear stiffness at rest lives in the multiplier of C_D = |F| (a prestress that
    // the gradient's rotation turns into shear force). XPBD's later sweeps ignore how the
    // gradient of an already loaded constraint changes, so a second sweep per substep
    // finds no shear stiffness and round-off grows without bound (measured: a box at rest
    // drifted 5e-3 mm in 3 steps of 2 sweeps). One sweep per substep is stable.
    if (config.iterations != 1)
      throw std::invalid_argument("xpbd: energy neo_hookean needs iterations = 1 (got " + std::to_string(config.iterations) +
                                  "): raise substeps instead (small steps), or use energy corotated");
  } else if (!config.energy.empty() && config.energy != "corotated") {
    throw std::invalid_argument("xpbd: unknown energy '" + config.energy + "': use corotated or neo_hookean");
  }
  mass_damping_per_s_ = Eigen::VectorXd::Zero(n);
  build_batches(problem);
  for (int t = 0; t < num_tets_; ++t) {  // passive tets: in no batch, their mass stays
    if (!problem.embedded.is_passive(t)) continue;
    const Material& mat = problem.region_materials[mesh.tet_region.empty() ? 0 : static_cast<std::size_t>(mesh.tet_region[static_cast<std::size_t>(t)])];
    const double V = signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[static_cast<std::size_t>(t)]);
    passive_tets_[t] = {mesh.tets[static_cast<std::size_t>(t)], V};
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) mass_damping_per_s_[w] += 0.25 * V * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
  }
  {  // embedded vertices: mass to their drivers / rigid groups, held by the solver
    std::vector<int> touched;
    embedded_.reset(problem.embedded, mesh.rest_positions_World_mm, x_, v_);
    embedded_.move_mass({&mass_, &mass_damping_per_s_}, touched, &problem.region_materials);
  }
  for (int i = 0; i < n; ++i) mass_damping_per_s_[i] = mass_[i] > 0.0 ? mass_damping_per_s_[i] / mass_[i] : 0.0;
  const std::size_t lanes = batches_.batches.size() * static_cast<std::size_t>(xpbd::kLanes);
  if (!neo_hookean_) {
    rotation_.assign(4 * lanes, 0.0);
    if (config.iterations > 1) lambda_.assign(10 * lanes, 0.0);
    reset_rotations();
  }
  set_fixed_vertices(problem.fixed_vertices);
  ledger_.set_floor(energy_floor_mN_mm(problem));
  reset_ledger();
}

void XpbdModel::build_batches(const SimProblem& problem) {
  const TetMesh& mesh = problem.mesh;
  using xpbd::kLanes;
  const int n = mesh.num_vertices(), nt = mesh.num_tets();
  // The tets are cut at the median centroid along the longest axis into two halves
  // whose interiors (tets touching only vertices of their own half) share no vertex, so
  // two threads sweep them at the same time without colours or barriers. The interface
  // (tets touching the cut) is cut the same way once more: its two interiors run in
  // parallel too, and only what touches both (a thin seam) runs on one thread. The cuts
  // do not depend on the thread count, so 1 and 2 threads compute the same positions.
  std::vector<unsigned char> touched, unused;
  std::vector<int> elastic = all_tets(nt);
  std::erase_if(elastic, [&](int t) { return problem.embedded.is_passive(t); });  // below the quality bound: no constraint
  const std::array<std::vector<int>, 3> first = split_tets(mesh, elastic, touched);
  const std::array<std::vector<int>, 3> second = split_tets(mesh, first[2], unused);
  const std::array<const std::vector<int>*, 5> groups = {&first[0], &first[1], &second[0], &second[1], &second[2]};
  for (auto& list : group_vertices_) list.clear();
  for (int v = 0; v < n; ++v)  // a vertex of passive tets only: the seam's (thread 0)
    group_vertices_[touched[static_cast<std::size_t>(v)] == 0 ? 2 : static_cast<std::size_t>(touched[static_cast<std::size_t>(v)] - 1)].push_back(v);

  // Within a group, colours only make batches: the 8 tets of a batch touch distinct
  // vertices (one thread runs a group's batches in order, Gauss-Seidel between them).
  xpbd::TetBatches& nb = batches_;
  nb.batches.clear();
  nb.count.clear();
  nb.tet.clear();
  for (auto& list : nb.group) list.clear();
  for (std::size_t g = 0; g < groups.size(); ++g) {
    std::vector<std::array<int, 4>> group_tets;
    for (int t : *groups[g]) group_tets.push_back(mesh.tets[t]);
    const Coloring col = greedy_vertex_coloring(group_tets, n);
    for (int c = 0; c < col.num_colors(); ++c) {
      for (int k = col.color_offsets[c]; k < col.color_offsets[c + 1]; ++k) {
        const int slot = k - col.color_offsets[c], l = slot % kLanes;
        if (l == 0) {
          nb.group[g].push_back(static_cast<int>(nb.batches.size()));
          nb.batches.emplace_back();
          nb.count.push_back(0);
          nb.tet.insert(nb.tet.end(), kLanes, -1);
        }
        const std::size_t bi = nb.batches.size() - 1;
        const int t = (*groups[g])[static_cast<std::size_t>(col.order[static_cast<std::size_t>(k)])];
        nb.tet[bi * kLanes + static_cast<std::size_t>(l)] = t;
        nb.count[bi] = l + 1;
        fill_lane(nb.batches[bi], l, problem, t);
        const Material& mat = problem.region_materials[mesh.tet_region.empty() ? 0 : mesh.tet_region[t]];
        const double V = signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[t]);
        for (int v : mesh.tets[t]) mass_damping_per_s_[v] += 0.25 * V * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
      }
    }
  }
  batch_group_.assign(nb.batches.size(), -1);
  for (std::size_t g = 0; g < groups.size(); ++g) {
    for (int bi : nb.group[g]) batch_group_[static_cast<std::size_t>(bi)] = static_cast<int>(g);
    group_count_[g] = static_cast<int>(groups[g]->size());
  }
  // Unused lanes repeat lane 0 (finite arithmetic; never written back nor summed).
  for (std::size_t bi = 0; bi < nb.batches.size(); ++bi) fill_unused_lanes(bi);
}

void XpbdModel::fill_lane(xpbd::TetBatch& b, int l, const SimProblem& problem, int t) {
  const TetMesh& mesh = problem.mesh;
  const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[t];
  const Material& mat = problem.region_materials[region];
  const Lame lame = lame_from(mat);
  const double V = signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[t]);
  const Eigen::Matrix3d Dm_inv = edge_matrix(mesh.rest_positions_World_mm, mesh.tets[t]).inverse();
  for (int a = 0; a < 4; ++a) b.v[a][l] = mesh.tets[t][a];
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 3; ++j) b.b[a][j][l] = Dm_inv(a, j);
  const double mu = lame.mu_kPa;
  if (neo_hookean_) {
    // Stable Neo-Hookean linearises to Lame (mu, lambda - mu): shift lambda by mu
    // so that small strains see the region's E and nu.
    const double lambda = lame.lambda_kPa + lame.mu_kPa;
    b.inv_mu_V[l] = 1.0 / (mu * V);
    b.inv_lambda_V[l] = 1.0 / (lambda * V);
    b.gamma[l] = 1.0 + mu / lambda;
    b.lambda_V[l] = lambda * V;
  } else {
    // Fixed-corotated: deviatoric compliance 1/(2 mu V); no volume term for nu = 0.
    const double lambda = lame.lambda_kPa;
    b.inv_mu_V[l] = 1.0 / (2.0 * mu * V);
    b.inv_lambda_V[l] = lambda > 0.0 ? 1.0 / (lambda * V) : 1.0;
    b.gamma[l] = lambda > 0.0 ? 1.0 : 0.0;
    b.lambda_V[l] = std::max(lambda, 0.0) * V;
  }
  b.mu_V[l] = mu * V;
  b.beta_s[l] = mat.damping_stiffness_s;
  if (mat.damping_stiffness_s != 0.0) damped_ = true;
}

void XpbdModel::fill_unused_lanes(std::size_t bi) {
  using xpbd::kLanes;
  xpbd::TetBatch& b = batches_.batches[bi];
  for (int l = std::max(batches_.count[bi], 1); l < kLanes; ++l) {
    for (int a = 0; a < 4; ++a) b.v[a][l] = b.v[a][0];
    for (int a = 0; a < 3; ++a)
      for (int j = 0; j < 3; ++j) b.b[a][j][l] = b.b[a][j][0];
    for (int k = 0; k < 6; ++k) b.B[k][l] = b.B[k][0];
    b.inv_mu_V[l] = b.inv_mu_V[0];
    b.inv_lambda_V[l] = b.inv_lambda_V[0];
    b.gamma[l] = b.gamma[0];
    b.beta_s[l] = b.beta_s[0];
    b.mu_V[l] = b.mu_V[0];
    b.lambda_V[l] = b.lambda_V[0];
  }
}

std::array<int, 5> XpbdModel::group_tets() const {
  std::array<int, 5> out{};
  for (std::size_t g = 0; g < 5; ++g)
    for (int bi : batches_.group[g]) out[g] += batches_.count[static_cast<std::size_t>(bi)];
  return out;
}

int XpbdModel::active_batches() const {
  int n = 0;
  for (const auto& list : batches_.group) n += static_cast<int>(list.size());
  return n;
}

double XpbdModel::mean_lanes() const {
  const std::array<int, 5> tets = group_tets();
  const int batches = active_batches();
  return batches > 0 ? static_cast<double>(tets[0] + tets[1] + tets[2] + tets[3] + tets[4]) / batches : 0.0;
}

std::string XpbdModel::check_batches(const SimProblem& problem) const {
  using xpbd::kLanes;
  const TetMesh& mesh = problem.mesh;
  const int n = mesh.num_vertices(), nt = mesh.num_tets();
  if (x_.cols() != n || num_tets_ != nt) return "model and mesh differ in size";
  std::vector<int> seen(static_cast<std::size_t>(nt), 0);
  std::vector<unsigned char> owner(static_cast<std::size_t>(n), 255);
  for (std::size_t d = 0; d < 3; ++d)
    for (int w : group_vertices_[d]) {
      if (w < 0 || w >= n || owner[static_cast<std::size_t>(w)] != 255) return "vertex " + std::to_string(w) + " owned twice or out of range";
      owner[static_cast<std::size_t>(w)] = static_cast<unsigned char>(d);
    }
  for (int w = 0; w < n; ++w)
    if (owner[static_cast<std::size_t>(w)] == 255) return "vertex " + std::to_string(w) + " owned by no thread";
  std::vector<int> group_of_batch(batches_.batches.size(), -1);
  for (int g = 0; g < 5; ++g)
    for (int bi : batches_.group[static_cast<std::size_t>(g)]) {
      if (bi < 0 || static_cast<std::size_t>(bi) >= batches_.batches.size() || group_of_batch[static_cast<std::size_t>(bi)] >= 0)
        return "batch " + std::to_string(bi) + " listed twice or out of range";
      group_of_batch[static_cast<std::size_t>(bi)] = g;
    }
  // Vertex marks: bit g for a tet of group g at the vertex.
  std::vector<unsigned char> mark(static_cast<std::size_t>(n), 0);
  for (std::size_t bi = 0; bi < batches_.batches.size(); ++bi) {
    const xpbd::TetBatch& b = batches_.batches[bi];
    const int g = group_of_batch[bi], count = batches_.count[bi];
    if (count < 0 || count > kLanes) return "batch " + std::to_string(bi) + " holds " + std::to_string(count) + " lanes";
    if (g < 0 && count > 0) return "batch " + std::to_string(bi) + " holds tets but is in no group";
    std::vector<int> vertices;
    for (int l = 0; l < count; ++l) {
      const int t = batches_.tet[bi * kLanes + static_cast<std::size_t>(l)];
      const std::string where = "tet " + std::to_string(t) + " (batch " + std::to_string(bi) + ", lane " + std::to_string(l) + ")";
      if (t < 0 || t >= nt) return where + ": no mesh tet";
      if (problem.embedded.is_passive(t)) return where + ": passive (below the quality bound) but has a constraint";
      if (++seen[static_cast<std::size_t>(t)] > 1) return where + ": in two lanes";
      const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
      const Eigen::Matrix3d Dm_inv = edge_matrix(mesh.rest_positions_World_mm, tet).inverse();
      for (int a = 0; a < 4; ++a) {
        if (b.v[a][l] != tet[static_cast<std::size_t>(a)]) return where + ": vertices differ from the mesh";
        vertices.push_back(tet[static_cast<std::size_t>(a)]);
      }
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < 3; ++j)
          if (std::abs(b.b[a][j][l] - Dm_inv(a, j)) > 1e-9 * (1.0 + std::abs(Dm_inv(a, j)))) return where + ": rest shape differs from the mesh";
      for (int w : tet) {
        const unsigned char o = owner[static_cast<std::size_t>(w)];
        if (g == 1 && o != 1) return where + ": in group 1 but vertex " + std::to_string(w) + " is not thread 1's";
        if (g == 0 && o == 1) return where + ": in group 0 but vertex " + std::to_string(w) + " is thread 1's";
        mark[static_cast<std::size_t>(w)] |= static_cast<unsigned char>(1u << g);
      }
    }
    std::sort(vertices.begin(), vertices.end());
    if (std::adjacent_find(vertices.begin(), vertices.end()) != vertices.end())
      return "batch " + std::to_string(bi) + ": two lanes share a vertex";
  }
  for (int t = 0; t < nt; ++t)
    if (!problem.embedded.is_passive(t) && seen[static_cast<std::size_t>(t)] != 1) return "elastic tet " + std::to_string(t) + " in no lane";
  for (int w = 0; w < n; ++w) {
    const unsigned m = mark[static_cast<std::size_t>(w)];
    if ((m & 1u) && (m & 2u)) return "vertex " + std::to_string(w) + " in groups 0 and 1 (swept at the same time)";
    if ((m & 4u) && (m & 8u)) return "vertex " + std::to_string(w) + " in groups 2 and 3 (swept at the same time)";
  }
  return {};
}

void XpbdModel::update_tet_mass_blocks() {
  for (std::size_t bi = 0; bi < batches_.batches.size(); ++bi)
    for (int l = 0; l < xpbd::kLanes; ++l) refresh_mass_block(bi, l);
}

void XpbdModel::refresh_mass_block(std::size_t bi, int l) {
  xpbd::TetBatch& b = batches_.batches[bi];
  Eigen::Matrix3d B = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b0 = Eigen::Vector3d::Zero();
  for (int a = 1; a < 4; ++a) {
    const Eigen::Vector3d ba(b.b[a - 1][0][l], b.b[a - 1][1][l], b.b[a - 1][2][l]);
    B += inv_mass_[b.v[a][l]] * ba * ba.transpose();
    b0 -= ba;
  }
  B += inv_mass_[b.v[0][l]] * b0 * b0.transpose();
  b.B[0][l] = B(0, 0);
  b.B[1][l] = B(0, 1);
  b.B[2][l] = B(0, 2);
  b.B[3][l] = B(1, 1);
  b.B[4][l] = B(1, 2);
  b.B[5][l] = B(2, 2);
}

void XpbdModel::remove_lane(int lane) {
  using xpbd::kLanes;
  const std::size_t bi = static_cast<std::size_t>(lane / kLanes);
  const int l = lane % kLanes, last = batches_.count[bi] - 1;
  const int g = batch_group_[bi];
  xpbd::TetBatch& b = batches_.batches[bi];
  auto drop = [&](int v, int id) {
    auto& list = vertex_lanes_[static_cast<std::size_t>(v)];
    list.erase(std::remove(list.begin(), list.end(), id), list.end());
  };
  for (int a = 0; a < 4; ++a) {
    drop(b.v[a][l], lane);
    if (side_slot(g) >= 0) --side_tets_[static_cast<std::size_t>(b.v[a][l])][static_cast<std::size_t>(side_slot(g))];
  }
  --group_count_[static_cast<std::size_t>(g)];
  lane_of_tet_[static_cast<std::size_t>(batches_.tet[static_cast<std::size_t>(lane)])] = -1;
  if (l != last) {  // the batch's last lane takes the freed one
    const int from = static_cast<int>(bi) * kLanes + last;
    for (int a = 0; a < 4; ++a) {
      b.v[a][l] = b.v[a][last];
      for (int& id : vertex_lanes_[static_cast<std::size_t>(b.v[a][l])])
        if (id == from) id = lane;
    }
    for (int a = 0; a < 3; ++a)
      for (int j = 0; j < 3; ++j) b.b[a][j][l] = b.b[a][j][last];
    for (int k = 0; k < 6; ++k) b.B[k][l] = b.B[k][last];
    b.inv_mu_V[l] = b.inv_mu_V[last];
    b.inv_lambda_V[l] = b.inv_lambda_V[last];
    b.gamma[l] = b.gamma[last];
    b.beta_s[l] = b.beta_s[last];
    b.mu_V[l] = b.mu_V[last];
    b.lambda_V[l] = b.lambda_V[last];
    if (!rotation_.empty())
      for (int k = 0; k < 4; ++k) rotation_[4 * kLanes * bi + static_cast<std::size_t>(k * kLanes + l)] = rotation_[4 * kLanes * bi + static_cast<std::size_t>(k * kLanes + last)];
    const int moved = batches_.tet[static_cast<std::size_t>(from)];
    batches_.tet[static_cast<std::size_t>(lane)] = moved;
    lane_of_tet_[static_cast<std::size_t>(moved)] = lane;
  }
  batches_.tet[bi * kLanes + static_cast<std::size_t>(last)] = -1;
  --batches_.count[bi];
  if (batches_.count[bi] == 0) {
    free_batch(static_cast<int>(bi));
    return;
  }
  fill_unused_lanes(bi);
  if (!in_open_[bi]) {
    in_open_[bi] = 1;
    open_[static_cast<std::size_t>(g)].push_back(static_cast<int>(bi));
  }
}

void XpbdModel::free_batch(int batch) {
  const std::size_t bi = static_cast<std::size_t>(batch);
  const std::size_t g = static_cast<std::size_t>(batch_group_[bi]);
  auto& list = batches_.group[g];
  list.erase(std::find(list.begin(), list.end(), batch));  // keeps the sweep order of the others
  if (in_open_[bi]) {
    auto& open = open_[g];
    open.erase(std::find(open.begin(), open.end(), batch));
    in_open_[bi] = 0;
  }
  batch_group_[bi] = -1;
  free_batches_.push_back(batch);
}

int XpbdModel::choose_group(const std::array<int, 4>& tet) const {
  // The phases of step_batches: groups 0 and 1 run at once (thread 1 predicts its own
  // vertices and sweeps group 1 with no barrier in between: group 1 touches only thread
  // 1's vertices, group 0 none of them), then groups 2 and 3 (no vertex in common), then
  // the seam alone. Allowed: group 0 without a vertex of thread 1; group 1 without a
  // vertex of thread 0 and with no group-0 tet at its shared vertices (those become
  // thread 1's, add_lane); group 2 (3) with no tet of group 3 (2) at its vertices; the
  // seam always. Among those, the one that lengthens the step's critical path
  // max(n0, n1) + max(n2, n3) + n4 (tets) least, then the one with most slack.
  unsigned owners = 0;
  bool at0_shared = false, at2 = false, at3 = false;
  for (int w : tet) {
    const auto& at = side_tets_[static_cast<std::size_t>(w)];
    const unsigned char o = vertex_owner_[static_cast<std::size_t>(w)];
    owners |= 1u << o;
    at0_shared = at0_shared || (o == 2 && at[0] > 0);
    at2 = at2 || at[1] > 0;
    at3 = at3 || at[2] > 0;
  }
  const std::array<bool, 5> allowed = {(owners & 2u) == 0, (owners & 1u) == 0 && !at0_shared, !at3, !at2, true};
  const std::array<int, 5>& n = group_count_;
  int best = 4;
  long best_cost = 0, best_slack = 0;
  for (int g = 0; g < 5; ++g) {
    if (!allowed[static_cast<std::size_t>(g)]) continue;
    long cost = 1, slack = -(1L << 40);  // the seam: always one more on the path, last on ties
    if (g < 4) {
      const int partner = g ^ 1;
      const long mine = n[static_cast<std::size_t>(g)], other = n[static_cast<std::size_t>(partner)];
      cost = mine + 1 > other ? mine + 1 - std::max(mine, other) : 0;
      slack = other - mine;
    }
    if (g == 0 || cost < best_cost || (cost == best_cost && slack > best_slack)) {
      best = g;
      best_cost = cost;
      best_slack = slack;
    }
  }
  return best;
}

void XpbdModel::set_owner(int vertex, unsigned char owner) {
  const std::size_t w = static_cast<std::size_t>(vertex);
  auto& from = group_vertices_[vertex_owner_[w]];
  const int pos = owner_pos_[w];
  from[static_cast<std::size_t>(pos)] = from.back();
  owner_pos_[static_cast<std::size_t>(from.back())] = pos;
  from.pop_back();
  vertex_owner_[w] = owner;
  owner_pos_[w] = static_cast<int>(group_vertices_[owner].size());
  group_vertices_[owner].push_back(vertex);
}

int XpbdModel::find_batch(int group, const std::array<int, 4>& tet) {
  using xpbd::kLanes;
  // Batches already holding one of the tet's vertices (in any group); a member buffer,
  // so that no allocation is made per tet once it has grown.
  std::vector<int>& clash = clash_;
  clash.clear();
  for (int w : tet)
    for (int lane : vertex_lanes_[static_cast<std::size_t>(w)]) clash.push_back(lane / kLanes);
  std::sort(clash.begin(), clash.end());
  // First fit among the group's open batches, the most recent first; a bounded scan (the
  // work per tet stays constant), dropping stale entries (full, emptied) on the way.
  constexpr int kScan = 64;
  auto& open = open_[static_cast<std::size_t>(group)];
  int scanned = 0;
  for (std::size_t i = open.size(); i-- > 0 && scanned < kScan;) {
    const int bi = open[i];
    if (batch_group_[static_cast<std::size_t>(bi)] != group || batches_.count[static_cast<std::size_t>(bi)] >= kLanes) {
      in_open_[static_cast<std::size_t>(bi)] = 0;
      open[i] = open.back();
      open.pop_back();
      continue;
    }
    ++scanned;
    if (!std::binary_search(clash.begin(), clash.end(), bi)) return bi;
  }
  // A new batch at the end of the group's sweep: an emptied one again, else appended.
  int bi;
  if (!free_batches_.empty()) {
    bi = free_batches_.back();
    free_batches_.pop_back();
  } else {
    bi = static_cast<int>(batches_.batches.size());
    batches_.batches.emplace_back();
    batches_.count.push_back(0);
    batches_.tet.insert(batches_.tet.end(), kLanes, -1);
    batch_group_.push_back(-1);
    in_open_.push_back(0);
    if (!rotation_.empty()) rotation_.resize(rotation_.size() + 4 * kLanes, 0.0);
    if (!lambda_.empty()) lambda_.resize(lambda_.size() + 10 * kLanes, 0.0);
  }
  batch_group_[static_cast<std::size_t>(bi)] = group;
  batches_.group[static_cast<std::size_t>(group)].push_back(bi);
  in_open_[static_cast<std::size_t>(bi)] = 1;
  open.push_back(bi);
  return bi;
}

int XpbdModel::add_lane(const SimProblem& problem, int t) {
  using xpbd::kLanes;
  const auto& tet = problem.mesh.tets[static_cast<std::size_t>(t)];
  const int g = choose_group(tet);
  if (g == 1)  // its shared vertices (no group-0 tet there) become thread 1's
    for (int w : tet)
      if (vertex_owner_[static_cast<std::size_t>(w)] == 2) set_owner(w, 1);
  const int bi = find_batch(g, tet);
  const std::size_t b = static_cast<std::size_t>(bi);
  const int l = batches_.count[b]++;
  fill_lane(batches_.batches[b], l, problem, t);
  const int lane = bi * kLanes + l;
  batches_.tet[static_cast<std::size_t>(lane)] = t;
  if (lane_of_tet_.size() <= static_cast<std::size_t>(t)) lane_of_tet_.resize(static_cast<std::size_t>(t) + 1, -1);
  lane_of_tet_[static_cast<std::size_t>(t)] = lane;
  for (int w : tet) {
    vertex_lanes_[static_cast<std::size_t>(w)].push_back(lane);
    if (side_slot(g) >= 0) ++side_tets_[static_cast<std::size_t>(w)][static_cast<std::size_t>(side_slot(g))];
  }
  ++group_count_[static_cast<std::size_t>(g)];
  if (!rotation_.empty()) {
    Eigen::Matrix3d Dm_inv;
    for (int a = 0; a < 3; ++a)
      for (int j = 0; j < 3; ++j) Dm_inv(a, j) = batches_.batches[b].b[a][j][l];
    const Eigen::Matrix3d F = edge_matrix(x_, tet) * Dm_inv;
    const Eigen::Quaterniond q = F.allFinite() ? Eigen::Quaterniond(polar_rotation(F)) : Eigen::Quaterniond::Identity();
    double* r = rotation_.data() + 4 * kLanes * b;
    r[0 * kLanes + l] = q.w();
    r[1 * kLanes + l] = q.x();
    r[2 * kLanes + l] = q.y();
    r[3 * kLanes + l] = q.z();
  }
  return lane;
}

void XpbdModel::build_local_maps() {
  using xpbd::kLanes;
  const int n = static_cast<int>(x_.cols());
  lane_of_tet_.assign(static_cast<std::size_t>(num_tets_), -1);
  vertex_lanes_.assign(static_cast<std::size_t>(n), {});
  side_tets_.assign(static_cast<std::size_t>(n), {0, 0, 0});
  for (std::size_t bi = 0; bi < batches_.batches.size(); ++bi)
    for (int l = 0; l < batches_.count[bi]; ++l) {
      const int lane = static_cast<int>(bi) * kLanes + l;
      lane_of_tet_[static_cast<std::size_t>(batches_.tet[static_cast<std::size_t>(lane)])] = lane;
      const int g = batch_group_[bi];
      for (int a = 0; a < 4; ++a) {
        const int w = batches_.batches[bi].v[a][l];
        vertex_lanes_[static_cast<std::size_t>(w)].push_back(lane);
        if (side_slot(g) >= 0) ++side_tets_[static_cast<std::size_t>(w)][static_cast<std::size_t>(side_slot(g))];
      }
    }
  vertex_owner_.assign(static_cast<std::size_t>(n), 2);
  owner_pos_.assign(static_cast<std::size_t>(n), -1);
  for (std::size_t d = 0; d < 3; ++d)
    for (std::size_t i = 0; i < group_vertices_[d].size(); ++i) {
      vertex_owner_[static_cast<std::size_t>(group_vertices_[d][i])] = static_cast<unsigned char>(d);
      owner_pos_[static_cast<std::size_t>(group_vertices_[d][i])] = static_cast<int>(i);
    }
  in_open_.assign(batches_.batches.size(), 0);
  for (auto& open : open_) open.clear();
  free_batches_.clear();
  for (std::size_t bi = 0; bi < batches_.batches.size(); ++bi) {
    if (batch_group_[bi] < 0) {
      free_batches_.push_back(static_cast<int>(bi));
    } else if (batches_.count[bi] < kLanes) {
      in_open_[bi] = 1;
      open_[static_cast<std::size_t>(batch_group_[bi])].push_back(static_cast<int>(bi));
    }
  }
}

std::optional<MeshChangeStats> XpbdModel::apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                            const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  using xpbd::kLanes;
  const TetMesh& mesh = problem.mesh;
  const int n_old = static_cast<int>(x_.cols()), n = mesh.num_vertices(), nt = mesh.num_tets();
  if (n < n_old || nt < num_tets_ || x.cols() != n || (v.cols() != n && v.cols() != 0) || mesh.tet_region.size() != mesh.tets.size())
    return std::nullopt;
  MeshChangeStats stats;
  // The cut is an external agent: the energy it adds or takes (vertices moved onto the cut,
  // split tets with their own rest shapes, mass moved between vertices) is its work in the
  // ledger, as a grasp's is (docs/sim.md "Run-time health"). One energy pass before and after.
  const double energy_before = total_energy();
  if (lane_of_tet_.empty()) build_local_maps();  // once: the maps for local updates
  // Appended vertices.
  x_.conservativeResize(Eigen::NoChange, n);
  v_.conservativeResize(Eigen::NoChange, n);
  x_prev_.conservativeResize(Eigen::NoChange, n);
  mass_.conservativeResize(n);
  inv_mass_.conservativeResize(n);
  mass_damping_per_s_.conservativeResize(n);
  fixed_.resize(static_cast<std::size_t>(n), 0);
  vertex_lanes_.resize(static_cast<std::size_t>(n));
  side_tets_.resize(static_cast<std::size_t>(n), {0, 0, 0});
  for (int i = n_old; i < n; ++i) {
    mass_[i] = 0.0;
    mass_damping_per_s_[i] = 0.0;
  }
  {  // A new vertex is a half's (its thread predicts it) when every old vertex of the
     // changed tets around it is; else thread 0 owns it (the seam's list).
    std::vector<unsigned> owners(static_cast<std::size_t>(n - n_old), 0);
    for (int t : changed_tets) {
      unsigned old = 0;
      for (int w : mesh.tets[static_cast<std::size_t>(t)])
        if (w < n_old) old |= 1u << vertex_owner_[static_cast<std::size_t>(w)];
      for (int w : mesh.tets[static_cast<std::size_t>(t)])
        if (w >= n_old) owners[static_cast<std::size_t>(w - n_old)] |= old;
    }
    vertex_owner_.resize(static_cast<std::size_t>(n), 2);
    owner_pos_.resize(static_cast<std::size_t>(n), -1);
    for (int i = n_old; i < n; ++i) {
      const unsigned o = owners[static_cast<std::size_t>(i - n_old)];
      const unsigned char d = o == 1u ? 0 : (o == 2u ? 1 : 2);
      vertex_owner_[static_cast<std::size_t>(i)] = d;
      owner_pos_[static_cast<std::size_t>(i)] = static_cast<int>(group_vertices_[d].size());
      group_vertices_[d].push_back(i);
    }
  }
  // Masses: the changed tets' old quarters out, their new quarters in (raw damping mass
  // likewise); touched = vertices whose mass changed. The embedding's mass moves (driven
  // vertices, rigid groups) are undone first and made again for the new embedding.
  std::vector<int> touched;
  auto touch = [&](int w) { touched.push_back(w); };
  for (int w = n_old; w < n; ++w) touch(w);
  for (int t : changed_tets) {
    if (t < num_tets_ && lane_of_tet_[static_cast<std::size_t>(t)] >= 0) {
      const int lane = lane_of_tet_[static_cast<std::size_t>(t)];
      const xpbd::TetBatch& b = batches_.batches[static_cast<std::size_t>(lane / kLanes)];
      for (int a = 0; a < 4; ++a) touch(b.v[a][lane % kLanes]);
    }
    if (const auto it = passive_tets_.find(t); it != passive_tets_.end())
      for (int w : it->second.v) touch(w);
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) touch(w);
  }
  std::vector<int> embedded_vertices;
  embedded_.moved_vertices(embedded_vertices);
  embedded_.reset(problem.embedded, mesh.rest_positions_World_mm, x, v);
  embedded_.current_vertices(embedded_vertices);
  for (int w : embedded_vertices) touch(w);
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  for (int w : touched) mass_damping_per_s_[w] *= mass_[w];  // back to the raw sum
  {
    std::vector<int> unused;
    embedded_.restore_mass({&mass_, &mass_damping_per_s_}, unused);
  }
  for (int t : changed_tets) {
    const Material& mat = problem.region_materials[static_cast<std::size_t>(mesh.tet_region[static_cast<std::size_t>(t)])];
    if (t < num_tets_ && lane_of_tet_[static_cast<std::size_t>(t)] >= 0) {
      const int lane = lane_of_tet_[static_cast<std::size_t>(t)];
      const xpbd::TetBatch& b = batches_.batches[static_cast<std::size_t>(lane / kLanes)];
      const int l = lane % kLanes;
      Eigen::Matrix3d Dm_inv;
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < 3; ++j) Dm_inv(a, j) = b.b[a][j][l];
      const double V_old = 1.0 / (6.0 * Dm_inv.determinant());
      for (int a = 0; a < 4; ++a) {
        mass_[b.v[a][l]] -= 0.25 * V_old * mat.density_kg_per_mm3;
        mass_damping_per_s_[b.v[a][l]] -= 0.25 * V_old * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
      }
      remove_lane(lane);
      ++stats.elements_updated;
    } else if (const auto it = passive_tets_.find(t); it != passive_tets_.end()) {
      for (int w : it->second.v) {
        mass_[w] -= 0.25 * it->second.volume_mm3 * mat.density_kg_per_mm3;
        mass_damping_per_s_[w] -= 0.25 * it->second.volume_mm3 * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
      }
      passive_tets_.erase(it);
      ++stats.elements_updated;
    }
    const double V = signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[static_cast<std::size_t>(t)]);
    if (!(V > 0.0)) throw std::invalid_argument("xpbd: tet " + std::to_string(t) + " has non-positive rest volume after the cut");
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
      mass_[w] += 0.25 * V * mat.density_kg_per_mm3;
      mass_damping_per_s_[w] += 0.25 * V * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
    }
    if (problem.embedded.is_passive(t)) passive_tets_[t] = {mesh.tets[static_cast<std::size_t>(t)], V};
  }
  num_tets_ = nt;
  lane_of_tet_.resize(static_cast<std::size_t>(nt), -1);
  user_fixed_.resize(static_cast<std::size_t>(n), 0);
  for (auto it = problem.fixed_vertices.rbegin(); it != problem.fixed_vertices.rend() && *it >= n_old; ++it)
    user_fixed_[static_cast<std::size_t>(*it)] = 1;
  for (int w : touched)
    if (!(mass_[w] > 0.0)) throw std::invalid_argument("xpbd: vertex " + std::to_string(w) + " lost its mass in the cut");
  {
    std::vector<int> unused;
    embedded_.move_mass({&mass_, &mass_damping_per_s_}, unused, &problem.region_materials);
  }
  merge_fixed();
  // State of the touched vertices (new ones, moved ones: the cutter's), masses. The
  // embedding's mass moves were undone and made again for every driven vertex and rigid
  // group; most vertices get their inverse mass back to round-off: those keep it exactly
  // (the mass blocks around them stay valid), only real changes refresh blocks below.
  std::vector<int> reweighed;  // vertices whose inverse mass changed
  for (int w : touched) {
    mass_damping_per_s_[w] = mass_[w] > 0.0 ? mass_damping_per_s_[w] / mass_[w] : 0.0;
    x_.col(w) = x.col(w);
    x_prev_.col(w) = x.col(w);
    v_.col(w) = v.cols() == n && !fixed_[static_cast<std::size_t>(w)] ? Eigen::Vector3d(v.col(w)) : Eigen::Vector3d::Zero();
    const double inv = fixed_[static_cast<std::size_t>(w)] ? 0.0 : 1.0 / mass_[w];
    const double before = inv_mass_[w];
    if (w >= n_old || std::abs(inv - before) > 1e-12 * std::max(std::abs(inv), std::abs(before)) || (inv == 0.0) != (before == 0.0)) {
      inv_mass_[w] = inv;
      reweighed.push_back(w);
    }
    ++stats.vertices_updated;
  }
  // The changed tets join the seam (those below the quality bound: no constraint).
  for (int t : changed_tets) {
    if (problem.embedded.is_passive(t)) continue;
    add_lane(problem, t);
    ++stats.elements_updated;
  }
  // Mass blocks of the added tets and of every tet around a vertex whose inverse mass changed.
  std::vector<int> lanes;
  for (int t : changed_tets)
    if (lane_of_tet_[static_cast<std::size_t>(t)] >= 0) lanes.push_back(lane_of_tet_[static_cast<std::size_t>(t)]);
  for (int w : reweighed) lanes.insert(lanes.end(), vertex_lanes_[static_cast<std::size_t>(w)].begin(), vertex_lanes_[static_cast<std::size_t>(w)].end());
  std::sort(lanes.begin(), lanes.end());
  lanes.erase(std::unique(lanes.begin(), lanes.end()), lanes.end());
  for (int lane : lanes) {
    refresh_mass_block(static_cast<std::size_t>(lane / kLanes), lane % kLanes);
    ++stats.elements_updated;
  }
  std::vector<std::size_t> batches;
  for (int lane : lanes) batches.push_back(static_cast<std::size_t>(lane / kLanes));
  std::sort(batches.begin(), batches.end());
  batches.erase(std::unique(batches.begin(), batches.end()), batches.end());
  for (std::size_t bi : batches) fill_unused_lanes(bi);
  ledger_.add_work(total_energy() - energy_before);
  return stats;
}

void XpbdModel::reset_rotations() {
  // Polar rotation by SVD (reflection-safe), so that a state set from outside (e.g. turned
  // by 180 degrees) does not start the warm-started refinement at a saddle.
  if (neo_hookean_) return;
  for (std::size_t bi = 0; bi < batches_.batches.size(); ++bi) {
    const xpbd::TetBatch& b = batches_.batches[bi];
    for (int l = 0; l < xpbd::kLanes; ++l) {
      Eigen::Matrix3d Dm_inv;
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < 3; ++j) Dm_inv(a, j) = b.b[a][j][l];
      const Eigen::Matrix3d F = edge_matrix(x_, {b.v[0][l], b.v[1][l], b.v[2][l], b.v[3][l]}) * Dm_inv;
      const Eigen::Quaterniond q = F.allFinite() ? Eigen::Quaterniond(polar_rotation(F)) : Eigen::Quaterniond::Identity();
      double* r = rotation_.data() + 4 * xpbd::kLanes * bi;
      r[0 * xpbd::kLanes + l] = q.w();
      r[1 * xpbd::kLanes + l] = q.x();
      r[2 * xpbd::kLanes + l] = q.y();
      r[3 * xpbd::kLanes + l] = q.z();
    }
  }
}

void XpbdModel::set_fixed_vertices(const std::vector<int>& vertices) {
  check_vertex_indices(vertices, static_cast<int>(x_.cols()), "set_fixed_vertices");
  user_fixed_.assign(static_cast<std::size_t>(x_.cols()), 0);
  for (int v : vertices) user_fixed_[static_cast<std::size_t>(v)] = 1;
  merge_fixed();
  inv_mass_ = mass_.cwiseInverse();
  for (int v : vertices) v_.col(v).setZero();
  for (std::size_t i = 0; i < fixed_.size(); ++i)
    if (fixed_[i]) inv_mass_[static_cast<Eigen::Index>(i)] = 0.0;  // fixed, or held by the embedding (mass moved off)
  update_tet_mass_blocks();
}

void XpbdModel::merge_fixed() {
  fixed_.assign(user_fixed_.size(), 0);
  for (std::size_t i = 0; i < fixed_.size(); ++i) fixed_[i] = user_fixed_[i] || embedded_.held(static_cast<int>(i)) ? 1 : 0;
}

AttachmentId XpbdModel::add_attachment(const AttachmentSpec& spec) {
  double work = 0.0;
  const AttachmentId id = attachments_.add(spec, x_, work);
  ledger_.add_work(work);
  return id;
}
void XpbdModel::set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) {
  ledger_.add_work(attachments_.set_target(id, target_World_mm, x_));
}
void XpbdModel::set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) {
  ledger_.add_work(attachments_.set_stiffness(id, stiffness_mN_per_mm, x_));
}
void XpbdModel::remove_attachment(AttachmentId id) { ledger_.add_work(attachments_.remove(id, x_)); }

void XpbdModel::reset_ledger() {
  ledger_.reset(kinetic_energy(mass_, v_) + elastic_energy(), gravity_potential(mass_, x_, gravity_));
  control_.ledger_reset();
}

double XpbdModel::total_energy() const {
  return kinetic_energy(mass_, v_) + elastic_energy() + gravity_potential(mass_, x_, gravity_);
}

void XpbdModel::set_state(const Eigen::Matrix3Xd& positions_World_mm, const Eigen::Matrix3Xd& velocities_World_mm_s) {
  check_state_shape(positions_World_mm, velocities_World_mm_s, static_cast<int>(x_.cols()));
  x_ = positions_World_mm;
  v_ = velocities_World_mm_s;
  embedded_.restart(x_, v_);  // rigid groups start from the given state
  for (std::size_t i = 0; i < fixed_.size(); ++i)
    if (fixed_[i]) v_.col(static_cast<Eigen::Index>(i)).setZero();
  inversions_.reset_episode();
  inverted_at_end_ = -1;
  reset_rotations();
  reset_ledger();
}

void XpbdModel::step_batches(double h, int substeps, StepSummary& summary, bool& converged, double& energy, int& inverted) {
  // At most two threads: one per half of the mesh (build_batches).
  const int threads = std::min(config_.threads, 2);
  // Residual: RMS over the tets of |dF|, the change of F made by a sweep (strain units).
  // It measures convergence with several sweeps per substep and, with one, how much the
  // solve still corrects the inertial prediction. Computed where it is reported (first
  // and last sweep of the step) or tested (tolerance > 0).
  const double constraints = static_cast<double>(num_tets_);
  const std::array<std::vector<int>, 5>& group = batches_.group;
  xpbd::SweepParams params;
  params.h_s = h;
  params.damped = damped_;
  params.multipliers = !neo_hookean_ && config_.iterations > 1;
  double* rotation = rotation_.data();
  double* lambda = lambda_.data();
  constexpr long kLambdaPerBatch = 10L * xpbd::kLanes;
  double* X = x_.data();
  double* V = v_.data();
  double* XP = x_prev_.data();
  const double* W = inv_mass_.data();
  const double* mass_damping = mass_damping_per_s_.data();
  const xpbd::TetBatch* batches = batches_.batches.data();
  const int* count = batches_.count.data();
  auto solve = [&](std::size_t g, bool residual) {
    xpbd::SweepParams p = params;
    p.residual = residual;
    const int* index = group[g].data();
    const int num = static_cast<int>(group[g].size());
    return neo_hookean_ ? xpbd::solve_nh_batches(batches, count, index, num, X, XP, W, p)
                        : xpbd::solve_corotated_batches(batches, count, index, num, X, XP, W, rotation, lambda, p);
  };
  // Multipliers restart at zero every substep; each thread clears those of its groups.
  auto clear_multipliers = [&](std::size_t g) {
    if (params.multipliers)
      for (int bi : group[g]) std::fill(lambda + kLambdaPerBatch * bi, lambda + kLambdaPerBatch * (bi + 1), 0.0);
  };
  const Eigen::Vector3d g = gravity_;
  // Per-thread partial sums, a cache line apart.
  std::array<double, 16> partial{};
  std::array<int, 32> partial_inverted{};
  bool stop = false;
  // One parallel region for the whole step. Thread d owns half d: it predicts and updates
  // the velocities of the vertices only half d touches and sweeps the interior of half d
  // with no synchronisation; thread 0 also owns the vertices on the cut. After a barrier
  // the two threads sweep the two sides of the interface, after another thread 0 sweeps
  // the seam and the attachments while the other waits. Three barriers per sweep.
#pragma omp parallel num_threads(threads) if (threads > 1)
  {
    const int tid = omp_get_thread_num(), nt = omp_get_num_threads();
    auto predict = [&](const std::vector<int>& vertices) {
      for (int i : vertices) {
        for (int k = 0; k < 3; ++k) XP[3 * i + k] = X[3 * i + k];
        if (fixed_[static_cast<std::size_t>(i)]) continue;
        // Damp the carried velocity only: damping gravity's increment too would weaken
        // gravity at steady state by 1/(1 + h alpha).
        const double keep = 1.0 / (1.0 + h * mass_damping[i]);
        for (int k = 0; k < 3; ++k) {
          V[3 * i + k] = V[3 * i + k] * keep + h * g[k];
          X[3 * i + k] += h * V[3 * i + k];
        }
      }
    };
    auto update_velocity = [&](const std::vector<int>& vertices) {
      for (int i : vertices)
        for (int k = 0; k < 3; ++k) V[3 * i + k] = (X[3 * i + k] - XP[3 * i + k]) / h;
    };
    for (int s = 0; s < substeps && !stop; ++s) {
      for (int d = tid; d < 2; d += nt) {
        predict(group_vertices_[static_cast<std::size_t>(d)]);
        clear_multipliers(static_cast<std::size_t>(d));
      }
      if (tid == 0) {
        predict(group_vertices_[2]);
        for (std::size_t k = 2; k < 5; ++k) clear_multipliers(k);
      }
      for (int it = 0; it < config_.iterations; ++it) {
        // Phase 1: the two halves; phase 2: the two sides of the interface; phase 3:
        // the seam, the attachments and the residual on thread 0.
        const bool residual = config_.tolerance > 0.0 || (s == 0 && it == 0) ||
                              (s == substeps - 1 && it == config_.iterations - 1);
        double correction = 0.0;
        for (int d = tid; d < 2; d += nt)
          correction += solve(static_cast<std::size_t>(d), residual);
#pragma omp barrier
        for (int d = tid; d < 2; d += nt)
          correction += solve(static_cast<std::size_t>(d) + 2, residual);
        partial[static_cast<std::size_t>(8 * tid)] = correction;
#pragma omp barrier
        if (tid == 0) {
          double sum = solve(4, residual);
          if (it == 0)
            for (int id : attachments_.active()) attachments_[id].lambda.setZero();
          solve_attachments(h);
          for (int t = 0; t < nt; ++t) sum += partial[static_cast<std::size_t>(8 * t)];
          const double rms = std::sqrt(sum / constraints);
          ++summary.iterations;
          if (s == 0 && it == 0) summary.initial_residual = rms;
          summary.final_residual = rms;
          if (config_.tolerance > 0.0 && rms < config_.tolerance) {
            converged = true;
            stop = true;
          }
        }
#pragma omp barrier
        if (stop) break;
      }
      for (int d = tid; d < 2; d += nt) update_velocity(group_vertices_[static_cast<std::size_t>(d)]);
      if (tid == 0) update_velocity(group_vertices_[2]);
    }
#pragma omp barrier
    // Energy and inverted tets at the end of the step, in the same region.
    const int num_batches = static_cast<int>(batches_.batches.size());
    const int b0 = static_cast<int>(static_cast<long>(num_batches) * tid / nt);
    const int b1 = static_cast<int>(static_cast<long>(num_batches) * (tid + 1) / nt);
    int bad = 0;
    partial[static_cast<std::size_t>(8 * tid)] = neo_hookean_ ? xpbd::nh_energy(batches, count, b0, b1, X, &bad)
                                                              : xpbd::corotated_energy(batches, count, b0, b1, X, rotation, &bad);
    partial_inverted[static_cast<std::size_t>(16 * tid)] = bad;
  }
  energy = attachments_.energy(x_);
  inverted = 0;
  for (int t = 0; t < threads; ++t) {
    energy += partial[static_cast<std::size_t>(8 * t)];
    inverted += partial_inverted[static_cast<std::size_t>(16 * t)];
  }
}

void XpbdModel::solve_attachments(double h) {
  for (int id : attachments_.active()) {
    Attachment& a = attachments_[id];
    const double alpha = 1.0 / (a.stiffness_mN_per_mm * h * h);
    double denom = alpha;
    for (int k = 0; k < a.count; ++k) denom += a.weights[k] * a.weights[k] * inv_mass_[a.vertices[k]];
    const Eigen::Vector3d C = a.point(x_) - a.target_World_mm;
    const Eigen::Vector3d dl = -(C + alpha * a.lambda) / denom;
    a.lambda += dl;
    for (int k = 0; k < a.count; ++k) x_.col(a.vertices[k]) += inv_mass_[a.vertices[k]] * a.weights[k] * dl;
  }
}

StepSummary XpbdModel::step(double dt_s) {
  check_dt(dt_s);
  const auto start = std::chrono::steady_clock::now();
  // Step control (step_control.hpp): an unhealthy step is redone from the saved state with
  // 2-8x the substeps. Saved: positions, velocities, the rotations' warm start, the inversion
  // monitor (multipliers and x_prev_ restart every substep).
  StepSummary summary = control_.run(
      [&] {
        x_saved_ = x_;
        v_saved_ = v_;
        rotation_saved_ = rotation_;
        inversions_saved_ = inversions_;
        inverted_saved_ = inverted_at_end_;
      },
      [&] {
        x_ = x_saved_;
        v_ = v_saved_;
        rotation_ = rotation_saved_;
        inversions_ = inversions_saved_;
        inverted_at_end_ = inverted_saved_;
      },
      [&](int factor) { return step_once(dt_s, config_.substeps * factor); },
      SubstepControl::budget_factor(dt_s));
  // Embedded vertices (massless here) follow their drivers; rigid groups move as bodies.
  embedded_.drive(x_, v_, dt_s, gravity_);
  summary.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

StepSummary XpbdModel::step_once(double dt_s, int substeps) {
  StepSummary summary;
  summary.termination = "max_iterations";
  const double h = dt_s / substeps;
  // The count at the end of the last step still holds unless set_state moved the vertices.
  const int inverted_at_start = inverted_at_end_ >= 0 ? inverted_at_end_ : count_inverted();
  bool converged = false;
  double energy = 0.0;
  int inverted = 0;
  step_batches(h, substeps, summary, converged, energy, inverted);
  if (converged) summary.termination = "converged";
  if (vessels_ignored_) {
    report(summary, "vessel tree ignored: this model has no beam coupling (model vessels as a stiff tet region, or use corotational_fem)", false);
  }
  check_state(x_, v_, summary);
  inverted_at_end_ = inverted;
  // A counted warning; unhealthy only for a collapse (step_health.hpp, docs/sim.md).
  inversions_.update(inverted, num_tets_, dt_s, summary);
  if (inverted == 0 && inverted_at_start > 0 && summary.warning.find("recovered") == std::string::npos)
    report(summary, "inverted tets: " + std::to_string(inverted_at_start) + " at step start, recovered", false);
  if (summary.final_residual > kUnconvergedResidual) {
    report(summary,
           "not converged: RMS strain correction of the last sweep " + std::to_string(summary.final_residual) +
               " (raise iterations or substeps; the tissue behaves softer than its material)",
           false);
  }
  summary.kinetic_energy = kinetic_energy(mass_, v_);
  summary.elastic_energy = energy;
  ledger_.check(summary.kinetic_energy + summary.elastic_energy, gravity_potential(mass_, x_, gravity_), summary);
  return summary;
}

int XpbdModel::count_inverted() const {
  int inverted = 0;
  tet_energy(&inverted);
  return inverted;
}

double XpbdModel::tet_energy(int* inverted) const {
  const int end = static_cast<int>(batches_.batches.size());
  return neo_hookean_ ? xpbd::nh_energy(batches_.batches.data(), batches_.count.data(), 0, end, x_.data(), inverted)
                      : xpbd::corotated_energy(batches_.batches.data(), batches_.count.data(), 0, end, x_.data(),
                                               rotation_.data(), inverted);
}

double XpbdModel::elastic_energy() const {
  int inverted = 0;
  return tet_energy(&inverted) + attachments_.energy(x_);
}

std::vector<ElementMeasure> XpbdModel::element_measures() const {
  std::vector<ElementMeasure> out(static_cast<std::size_t>(num_tets_));
  for (std::size_t bi = 0; bi < batches_.batches.size(); ++bi) {
    const xpbd::TetBatch& b = batches_.batches[bi];
    for (int l = 0; l < batches_.count[bi]; ++l) {
      Eigen::Matrix3d Dm_inv;
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < 3; ++j) Dm_inv(a, j) = b.b[a][j][l];
      const Eigen::Matrix3d F = edge_matrix(x_, {b.v[0][l], b.v[1][l], b.v[2][l], b.v[3][l]}) * Dm_inv;
      const double J = F.determinant();
      const double V = 1.0 / (6.0 * Dm_inv.determinant());  // rest volume
      const double mu = b.mu_V[l] / V, lambda = b.lambda_V[l] / V;
      // First Piola-Kirchhoff stress of the model's energy: Neo-Hookean mu F + lambda
      // (J - gamma) cof F, corotated 2 mu (F - R) + lambda (J - 1) cof F. Cauchy stress
      // P F^T / J where the element is not (nearly) inverted, else P itself as the best
      // available measure.
      const Eigen::Matrix3d P = neo_hookean_ ? Eigen::Matrix3d(mu * F + lambda * (J - b.gamma[l]) * cofactor(F))
                                             : Eigen::Matrix3d(2.0 * mu * (F - polar_rotation(F)) + lambda * (J - 1.0) * cofactor(F));
      const Eigen::Matrix3d sigma = J > 1e-6 ? Eigen::Matrix3d(P * F.transpose() / J) : P;
      out[static_cast<std::size_t>(batches_.tet[bi * xpbd::kLanes + static_cast<std::size_t>(l)])] = element_measure_from(F, sigma);
    }
  }
  return out;
}

}  // namespace arnav::host
