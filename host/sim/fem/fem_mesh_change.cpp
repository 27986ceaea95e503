#include "host/sim/fem/fem_mesh_change.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <stdexcept>

#include "host/sim/tet_geometry.hpp"

namespace arnav::host::fem {

RestTet rest_tet(const SimProblem& problem, int t, const std::string& who) {
  const TetMesh& mesh = problem.mesh;
  const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[static_cast<std::size_t>(t)];
  if (region < 0 || region >= static_cast<int>(problem.region_materials.size()))
    throw std::invalid_argument(who + ": tet " + std::to_string(t) + " refers to region " + std::to_string(region) +
                                " which has no material");
  const Material& m = problem.region_materials[static_cast<std::size_t>(region)];
  RestTet e;
  e.v = mesh.tets[static_cast<std::size_t>(t)];
  const Lame lame = lame_from(m);
  e.mu = lame.mu_kPa;
  e.lambda = lame.lambda_kPa;
  e.beta = m.damping_stiffness_s;
  e.passive = problem.embedded.is_passive(t);
  e.volume = signed_volume_mm3(mesh.rest_positions_World_mm, e.v);
  if (!(e.volume > 0.0))
    throw std::invalid_argument(who + ": tet " + std::to_string(t) + " has non-positive rest volume " + std::to_string(e.volume) +
                                " mm^3");
  e.Dm_inv = edge_matrix(mesh.rest_positions_World_mm, e.v).inverse();
  for (int k = 0; k < 3; ++k) e.g[static_cast<std::size_t>(k) + 1] = e.Dm_inv.row(k).transpose();
  e.g[0] = -(e.g[1] + e.g[2] + e.g[3]);
  e.quarter_mass = 0.25 * e.volume * m.density_kg_per_mm3;
  e.quarter_alpha = e.quarter_mass * m.damping_mass_per_s;
  return e;
}

bool mesh_change_fits(const SimProblem& problem, const std::vector<int>& changed, int old_vertices, int old_tets,
                      const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  const TetMesh& mesh = problem.mesh;
  const int n = mesh.num_vertices(), nt = mesh.num_tets();
  if (n < old_vertices || nt < old_tets || x.cols() != n || (v.cols() != n && v.cols() != 0) ||
      (!mesh.tet_region.empty() && mesh.tet_region.size() != mesh.tets.size()))
    return false;
  int appended = 0;
  for (std::size_t i = 0; i < changed.size(); ++i) {
    if (changed[i] < 0 || changed[i] >= nt || (i > 0 && changed[i] <= changed[i - 1])) return false;
    appended += changed[i] >= old_tets;
  }
  return appended == nt - old_tets;
}

std::vector<int> touched_vertices(const std::vector<TetChange>& changes, int old_vertices, int new_vertices) {
  std::vector<int> touched;
  touched.reserve(8 * changes.size() + static_cast<std::size_t>(new_vertices - old_vertices));
  for (const TetChange& c : changes) {
    if (c.existed) touched.insert(touched.end(), c.before.begin(), c.before.end());
    touched.insert(touched.end(), c.after.begin(), c.after.end());
  }
  for (int i = old_vertices; i < new_vertices; ++i) touched.push_back(i);
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  return touched;
}

int update_vertex_records(const SimProblem& problem, const std::vector<TetChange>& changes, const std::vector<int>& touched,
                          const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, EmbeddedMotion& embedded, VertexArrays a,
                          const std::string& who) {
  const TetMesh& mesh = problem.mesh;
  const int n_old = static_cast<int>(a.X.cols()), n = mesh.num_vertices();
  Eigen::VectorXd dm = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(touched.size())), da = dm;
  const auto slot = [&](int w) { return std::lower_bound(touched.begin(), touched.end(), w) - touched.begin(); };
  for (const TetChange& c : changes) {
    if (c.existed)
      for (int w : c.before) {
        dm[slot(w)] -= c.mass_before;
        da[slot(w)] -= c.alpha_before;
      }
    for (int w : c.after) {
      dm[slot(w)] += c.mass_after;
      da[slot(w)] += c.alpha_after;
    }
  }
  // The embedding's mass moves undone first (the lumped quarters change below; the new
  // embedding moves them again at the end), then checked: a failed check redoes them.
  std::vector<int> embedding_touched;
  embedded.restore_mass({&a.mass, &a.mass_alpha}, embedding_touched);
  for (std::size_t k = 0; k < touched.size(); ++k) {
    const int w = touched[k];
    const double before = w < n_old ? a.mass[w] : 0.0;
    const double d = dm[static_cast<Eigen::Index>(k)];
    // A vertex whose tets all went away keeps round-off of its old mass at most.
    if (!(before + d > 1e-9 * std::max(before, std::abs(d)))) {
      embedded.move_mass({&a.mass, &a.mass_alpha}, embedding_touched, &problem.region_materials);
      throw std::invalid_argument(who + ": vertex " + std::to_string(w) + " belongs to no tetrahedron after the cut (zero mass)");
    }
  }
  for (auto it = problem.fixed_vertices.rbegin(); it != problem.fixed_vertices.rend() && *it >= n_old; ++it)
    if (*it >= n) throw std::invalid_argument(who + ": fixed vertex " + std::to_string(*it) + " is not in the cut mesh");

  a.X.conservativeResize(Eigen::NoChange, n);
  a.x.conservativeResize(Eigen::NoChange, n);
  a.v.conservativeResize(Eigen::NoChange, n);
  for (Eigen::VectorXd* m : {&a.mass, &a.mass_alpha}) {
    m->conservativeResize(n);
    m->tail(n - n_old).setZero();
  }
  a.fixed.resize(static_cast<std::size_t>(n), 0);
  a.user_fixed.resize(static_cast<std::size_t>(n), 0);
  for (auto it = problem.fixed_vertices.rbegin(); it != problem.fixed_vertices.rend() && *it >= n_old; ++it)
    a.user_fixed[static_cast<std::size_t>(*it)] = 1;
  int written = 0;
  for (std::size_t k = 0; k < touched.size(); ++k) {
    const int w = touched[k];
    a.X.col(w) = mesh.rest_positions_World_mm.col(w);
    a.mass[w] += dm[static_cast<Eigen::Index>(k)];
    a.mass_alpha[w] += da[static_cast<Eigen::Index>(k)];
    a.x.col(w) = x.col(w);
    a.v.col(w) = (v.cols() == n && !a.user_fixed[static_cast<std::size_t>(w)]) ? Eigen::Vector3d(v.col(w)) : Eigen::Vector3d::Zero();
    ++written;
  }
  // The new embedding: masses moved to the drivers and rigid groups, their vertices held
  // in the solve. O(vertices), scalar: the merged fixed flags and held velocities.
  embedded.reset(problem.embedded, a.X, a.x, a.v);
  embedded.move_mass({&a.mass, &a.mass_alpha}, embedding_touched, &problem.region_materials);
  for (int w = 0; w < n; ++w) {
    const bool f = a.user_fixed[static_cast<std::size_t>(w)] || embedded.held(w);
    a.fixed[static_cast<std::size_t>(w)] = f ? 1 : 0;
    if (f) a.v.col(w).setZero();
  }
  return written;
}

void TetPairCounts::add(const std::array<int, 4>& tet) {
  for (int a : tet)
    for (int b : tet)
      if (a > b) ++count_[key(a, b)];
}

std::vector<std::pair<int, int>> TetPairCounts::update(const std::vector<TetChange>& changes,
                                                       const std::vector<std::vector<int>>& kept) {
  std::vector<std::pair<int, int>> emptied, drop;
  for (const TetChange& c : changes) {
    if (!c.existed) continue;
    for (int a : c.before)
      for (int b : c.before)
        if (a > b) {
          auto it = count_.try_emplace(key(a, b), 0).first;
          if (--it->second == 0) emptied.emplace_back(b, a);
        }
  }
  for (const TetChange& c : changes) add(c.after);
  for (const auto& pair : emptied) {
    const int b = pair.first, a = pair.second;
    const auto it = count_.find(key(a, b));
    if (it == count_.end() || it->second != 0) continue;  // coupled again (or listed twice)
    count_.erase(it);
    const bool held = std::any_of(kept.begin(), kept.end(), [&](const std::vector<int>& g) {
      return std::find(g.begin(), g.end(), a) != g.end() && std::find(g.begin(), g.end(), b) != g.end();
    });
    if (!held) drop.emplace_back(b, a);
  }
  std::sort(drop.begin(), drop.end());
  return drop;
}

bool grow_pattern(std::unique_ptr<SymmetricPattern>& pattern, int num_vertices, const std::vector<std::vector<int>>& groups,
                  const std::vector<std::pair<int, int>>& drop, const std::vector<std::vector<int>*>& maps) {
  std::vector<int> remap;
  auto grown = std::make_unique<SymmetricPattern>(pattern->extended(num_vertices, groups, remap, drop));
  if (drop.empty() && grown->matrix().nonZeros() == pattern->matrix().nonZeros() &&
      grown->matrix().rows() == pattern->matrix().rows())
    return false;
  // Unchanged elements keep their entries, which only move (a vertex's three rows stay
  // consecutive, so compact run starts stay runs).
  for (std::vector<int>* map : maps)
    for (int& k : *map)
      if (k >= 0) k = remap[static_cast<std::size_t>(k)];
  pattern = std::move(grown);
  return true;
}

void update_partition(ElementPartition& partition, const std::vector<int>& changed_ids, int old_tets, int new_tets) {
  const int shift = new_tets - old_tets;
  const auto shift_others = [&](std::vector<int>& ids) {
    if (shift > 0)
      for (int& id : ids)
        if (id >= old_tets) id += shift;
  };
  for (auto& part : partition.parts) shift_others(part);
  shift_others(partition.shared);
  if (partition.parts.size() <= 1) {
    if (partition.parts.empty()) partition.parts.emplace_back();
    for (int s : changed_ids)
      if (s >= old_tets) partition.parts[0].push_back(s);
    return;
  }
  std::vector<char> moved(static_cast<std::size_t>(new_tets), 0);
  for (int s : changed_ids) moved[static_cast<std::size_t>(s)] = 1;
  const auto is_moved = [&](int id) { return id < new_tets && moved[static_cast<std::size_t>(id)]; };
  for (auto& part : partition.parts) part.erase(std::remove_if(part.begin(), part.end(), is_moved), part.end());
  partition.shared.erase(std::remove_if(partition.shared.begin(), partition.shared.end(), is_moved), partition.shared.end());
  partition.shared.insert(partition.shared.end(), changed_ids.begin(), changed_ids.end());
}

}  // namespace arnav::host::fem
