#include "host/sim/embedded_elements.hpp"

#include "host/mesh/mesh_quality.hpp"
#include "host/sim/tissue_model.hpp"

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <unordered_set>

namespace arnav::host {

double tet_min_dihedral_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  return tet_dihedral_range_deg(a, b, c, d).first;
}

double tet_min_dihedral_deg(const Eigen::Matrix3Xd& x, const std::array<int, 4>& tet) {
  return tet_min_dihedral_deg(x.col(tet[0]), x.col(tet[1]), x.col(tet[2]), x.col(tet[3]));
}

namespace {
double edge_volume(const Eigen::Matrix3Xd& X, const std::array<int, 4>& q) {
  return (X.col(q[1]) - X.col(q[0])).dot((X.col(q[2]) - X.col(q[0])).cross(X.col(q[3]) - X.col(q[0]))) / 6.0;
}
}  // namespace

int EmbeddedElements::passive_count() const {
  return static_cast<int>(std::count_if(passive.begin(), passive.end(), [](std::uint8_t p) { return p != 0; }));
}

EmbeddedElementTracker::EmbeddedElementTracker(double min_dihedral_deg, double min_relative_volume)
    : min_deg_(min_dihedral_deg), min_relative_volume_(min_relative_volume) {
  if (!(min_dihedral_deg >= 0.0 && min_dihedral_deg < 70.5))
    throw std::invalid_argument("min_dihedral_deg must be in [0, 70.5) (got " + std::to_string(min_dihedral_deg) + ")");
  if (!(min_relative_volume >= 0.0 && min_relative_volume < 1.0))
    throw std::invalid_argument("min_relative_volume must be in [0, 1) (got " + std::to_string(min_relative_volume) + ")");
}

void EmbeddedElementTracker::build(const TetMesh& mesh, const std::vector<int>& fixed_vertices, EmbeddedElements& out) {
  const int n = mesh.num_vertices(), nt = mesh.num_tets();
  out = EmbeddedElements{};
  out.min_dihedral_deg = min_deg_;
  passive_added_.clear();
  tets_ = mesh.tets;
  vertex_tets_.assign(static_cast<std::size_t>(n), {});
  fixed_.assign(static_cast<std::size_t>(n), 0);
  for (int f : fixed_vertices)
    if (f >= 0 && f < n) fixed_[static_cast<std::size_t>(f)] = 1;
  if (min_deg_ <= 0.0) return;  // off: every tet elastic, nothing kept
  out.passive.assign(static_cast<std::size_t>(nt), 0);
  below_.assign(static_cast<std::size_t>(nt), 0);
  volume_.assign(static_cast<std::size_t>(nt), 0.0);
  flat_.assign(static_cast<std::size_t>(nt), 0);
  for (int t = 0; t < nt; ++t) {
    for (int w : tets_[static_cast<std::size_t>(t)]) vertex_tets_[static_cast<std::size_t>(w)].push_back(t);
    volume_[static_cast<std::size_t>(t)] = edge_volume(mesh.rest_positions_World_mm, tets_[static_cast<std::size_t>(t)]);
    flat_[static_cast<std::size_t>(t)] = tet_min_dihedral_deg(mesh.rest_positions_World_mm, tets_[static_cast<std::size_t>(t)]) < min_deg_ ? 1 : 0;
  }
  for (int t = 0; t < nt; ++t) {
    below_[static_cast<std::size_t>(t)] = flat_[static_cast<std::size_t>(t)] || tiny(t) ? 1 : 0;
    out.passive[static_cast<std::size_t>(t)] = below_[static_cast<std::size_t>(t)];
  }
  std::vector<int> candidates;
  {
    std::vector<int> seeds;
    for (int t = 0; t < nt; ++t)
      if (!below_[static_cast<std::size_t>(t)]) seeds.push_back(t);
    settle_islands(seeds, out, candidates);
  }
  for (int t = 0; t < nt; ++t)
    if (out.passive[static_cast<std::size_t>(t)])
      for (int w : tets_[static_cast<std::size_t>(t)]) candidates.push_back(w);
  resolve(mesh, std::move(candidates), out);
  share_passive_mass(mesh, out);
}

void EmbeddedElementTracker::update(const TetMesh& mesh, const std::vector<int>& changed_tets, const std::vector<int>& fixed_vertices,
                                    EmbeddedElements& out) {
  if (min_deg_ <= 0.0) return;
  const int n = mesh.num_vertices(), nt = mesh.num_tets();
  const int n_old = static_cast<int>(vertex_tets_.size());
  vertex_tets_.resize(static_cast<std::size_t>(n));
  fixed_.resize(static_cast<std::size_t>(n), 0);
  for (auto it = fixed_vertices.rbegin(); it != fixed_vertices.rend() && *it >= n_old; ++it)
    if (*it < n) fixed_[static_cast<std::size_t>(*it)] = 1;
  out.passive.resize(static_cast<std::size_t>(nt), 0);
  below_.resize(static_cast<std::size_t>(nt), 0);
  flat_.resize(static_cast<std::size_t>(nt), 0);
  volume_.resize(static_cast<std::size_t>(nt), 0.0);
  passive_added_.clear();
  std::vector<int> candidates;
  const std::size_t nt_old = tets_.size();
  tets_.resize(static_cast<std::size_t>(nt), {{-1, -1, -1, -1}});
  for (int t : changed_tets) {
    auto& tet = tets_[static_cast<std::size_t>(t)];
    if (static_cast<std::size_t>(t) < nt_old)
      for (int w : tet) {
        auto& list = vertex_tets_[static_cast<std::size_t>(w)];
        list.erase(std::remove(list.begin(), list.end(), t), list.end());
        candidates.push_back(w);
      }
    tet = mesh.tets[static_cast<std::size_t>(t)];
    for (int w : tet) {
      vertex_tets_[static_cast<std::size_t>(w)].push_back(t);
      candidates.push_back(w);
    }
    flat_[static_cast<std::size_t>(t)] = tet_min_dihedral_deg(mesh.rest_positions_World_mm, tet) < min_deg_ ? 1 : 0;
    volume_[static_cast<std::size_t>(t)] = edge_volume(mesh.rest_positions_World_mm, tet);
  }
  // The size bound of every tet at a vertex of a changed tet (the largest volume at those
  // vertices changed): the changed tets' and their vertex neighbours' flags.
  std::vector<int> flipped;
  {
    std::vector<int> near;
    for (int w : candidates) near.insert(near.end(), vertex_tets_[static_cast<std::size_t>(w)].begin(), vertex_tets_[static_cast<std::size_t>(w)].end());
    std::sort(near.begin(), near.end());
    near.erase(std::unique(near.begin(), near.end()), near.end());
    for (int t : changed_tets) {
      below_[static_cast<std::size_t>(t)] = flat_[static_cast<std::size_t>(t)] || tiny(t) ? 1 : 0;
      out.passive[static_cast<std::size_t>(t)] = below_[static_cast<std::size_t>(t)];
      passive_added_.push_back(t);  // checked against the flag when shared
    }
    for (int t : near) {
      const char b = flat_[static_cast<std::size_t>(t)] || tiny(t) ? 1 : 0;
      if (b == below_[static_cast<std::size_t>(t)]) continue;
      below_[static_cast<std::size_t>(t)] = b;
      flipped.push_back(t);
      if (b) {
        out.passive[static_cast<std::size_t>(t)] = 1;
        passive_added_.push_back(t);
      }
      for (int w : tets_[static_cast<std::size_t>(t)]) candidates.push_back(w);
    }
  }
  {  // islands among the changed tets, the tets whose size flag flipped, and their face neighbours
    std::vector<int> seeds, nb;
    for (const std::vector<int>* list : std::initializer_list<const std::vector<int>*>{&changed_tets, &flipped})
      for (int t : *list) {
        seeds.push_back(t);
        face_neighbours(t, nb);
        seeds.insert(seeds.end(), nb.begin(), nb.end());
      }
    std::erase_if(seeds, [&](int t) { return below_[static_cast<std::size_t>(t)] != 0; });
    settle_islands(seeds, out, candidates);
  }
  // Driven vertices and rigid groups near the change are looked at again (a cut may have
  // separated a driven vertex from its driver's piece without touching the driver tet, but
  // not without changing tets around the two): those with a changed vertex in the driver
  // tet or among the vertices of their own tets; every rigid group (few).
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  auto changed_vertex = [&](int w) { return std::binary_search(candidates.begin(), candidates.end(), w); };
  auto touches_change = [&](int w) {
    if (changed_vertex(w)) return true;
    for (int t : vertex_tets_[static_cast<std::size_t>(w)])
      for (int k = 0; k < 4; ++k)
        if (changed_vertex(tets_[static_cast<std::size_t>(t)][static_cast<std::size_t>(k)])) return true;
    return false;
  };
  std::vector<int> again;
  for (const DrivenVertex& d : out.driven) {
    bool near = static_cast<std::size_t>(d.driver_tet) >= tets_.size() || tets_[static_cast<std::size_t>(d.driver_tet)] != d.drivers;
    for (int k = 0; k < 4 && !near; ++k) near = changed_vertex(d.drivers[static_cast<std::size_t>(k)]);
    if (near || touches_change(d.vertex)) again.push_back(d.vertex);
  }
  // A rigid group is a region of passive tets with no active tet in reach: a change that
  // touches none of its vertices' tets leaves it as it is (pieces share no vertex); the
  // others are resolved again with the candidates.
  std::erase_if(out.rigid_groups, [&](const RigidGroup& g) {
    const bool near = std::any_of(g.vertices.begin(), g.vertices.end(), touches_change);
    if (near) again.insert(again.end(), g.vertices.begin(), g.vertices.end());
    return near;
  });
  candidates.insert(candidates.end(), again.begin(), again.end());
  resolve(mesh, std::move(candidates), out);
  share_passive_mass(mesh, out);
}

void EmbeddedElementTracker::share_passive_mass(const TetMesh& mesh, EmbeddedElements& out) const {
  // O(passive tets x their vertices' degree): the passive tets are the cut's, not the mesh.
  auto volume = [&](int t) { return volume_[static_cast<std::size_t>(t)]; };
  std::unordered_map<int, double> support_of;
  std::vector<int> passive_tets;
  if (out.passive_mass.empty()) {  // build: scan once
    for (std::size_t t = 0; t < out.passive.size(); ++t)
      if (out.passive[t]) passive_tets.push_back(static_cast<int>(t));
  } else {
    for (const PassiveMass& p : out.passive_mass) passive_tets.push_back(p.tet);
  }
  // Tets made passive since: found from the vertices of the driven set and the flags near
  // them is not enough, so update() records them (passive_added_).
  passive_tets.insert(passive_tets.end(), passive_added_.begin(), passive_added_.end());
  std::sort(passive_tets.begin(), passive_tets.end());
  passive_tets.erase(std::unique(passive_tets.begin(), passive_tets.end()), passive_tets.end());
  out.passive_mass.clear();
  for (int t : passive_tets) {
    if (!out.is_passive(t)) continue;
    PassiveMass p;
    p.tet = t;
    p.region = mesh.tet_region.empty() ? 0 : mesh.tet_region[static_cast<std::size_t>(t)];
    p.volume_mm3 = volume(t);
    p.v = tets_[static_cast<std::size_t>(t)];
    double sum = 0.0;
    for (int k = 0; k < 4; ++k) {
      const int w = p.v[static_cast<std::size_t>(k)];
      auto [it, fresh] = support_of.emplace(w, 0.0);
      if (fresh)
        for (int u : vertex_tets_[static_cast<std::size_t>(w)])
          if (!out.is_passive(u)) it->second += 0.25 * volume(u);
      const double support = it->second;
      p.share[static_cast<std::size_t>(k)] = support;
      sum += support;
    }
    for (double& sh : p.share) sh = sum > 0.0 ? sh / sum : 0.25;
    out.passive_mass.push_back(p);
  }
}

bool EmbeddedElementTracker::tiny(int t) const {
  if (!(min_relative_volume_ > 0.0)) return false;
  double largest = 0.0;
  for (int w : tets_[static_cast<std::size_t>(t)])
    for (int u : vertex_tets_[static_cast<std::size_t>(w)]) largest = std::max(largest, volume_[static_cast<std::size_t>(u)]);
  return volume_[static_cast<std::size_t>(t)] < min_relative_volume_ * largest;
}

void EmbeddedElementTracker::face_neighbours(int t, std::vector<int>& out) const {
  out.clear();
  const auto& tet = tets_[static_cast<std::size_t>(t)];
  for (int skip = 0; skip < 4; ++skip) {
    const int a = tet[static_cast<std::size_t>((skip + 1) % 4)], b = tet[static_cast<std::size_t>((skip + 2) % 4)],
              c = tet[static_cast<std::size_t>((skip + 3) % 4)];
    for (int u : vertex_tets_[static_cast<std::size_t>(a)]) {
      if (u == t) continue;
      const auto& o = tets_[static_cast<std::size_t>(u)];
      const bool has_b = std::find(o.begin(), o.end(), b) != o.end(), has_c = std::find(o.begin(), o.end(), c) != o.end();
      if (has_b && has_c) out.push_back(u);
    }
  }
}

void EmbeddedElementTracker::settle_islands(const std::vector<int>& seeds, EmbeddedElements& out, std::vector<int>& candidates) {
  std::unordered_set<int> settled;
  std::vector<int> component, nb;
  for (int seed : seeds) {
    if (settled.count(seed)) continue;
    // Breadth-first through face neighbours that are not below the bound, up to one more
    // than an island may hold.
    component.assign(1, seed);
    std::unordered_set<int> seen{seed};
    for (std::size_t k = 0; k < component.size() && static_cast<int>(component.size()) <= kMaxIslandTets; ++k) {
      face_neighbours(component[k], nb);
      for (int u : nb)
        if (!below_[static_cast<std::size_t>(u)] && seen.insert(u).second) component.push_back(u);
    }
    const bool island = static_cast<int>(component.size()) <= kMaxIslandTets;
    for (int t : component) {
      settled.insert(t);  // all in one component: an island, or part of one larger than an island
      const std::uint8_t flag = island || below_[static_cast<std::size_t>(t)] ? 1 : 0;
      if (out.passive[static_cast<std::size_t>(t)] != flag) {
        out.passive[static_cast<std::size_t>(t)] = flag;
        if (flag) passive_added_.push_back(t);
        for (int w : tets_[static_cast<std::size_t>(t)]) candidates.push_back(w);
      }
    }
  }
}

void EmbeddedElementTracker::resolve(const TetMesh& mesh, std::vector<int> candidates, EmbeddedElements& out) {
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  // Keep the entries of vertices that are not candidates (build: none; update: cleared).
  auto is_candidate = [&](int w) { return std::binary_search(candidates.begin(), candidates.end(), w); };
  std::erase_if(out.driven, [&](const DrivenVertex& d) { return is_candidate(d.vertex); });
  const auto& X = mesh.rest_positions_World_mm;
  auto passive = [&](int t) { return out.passive[static_cast<std::size_t>(t)] != 0; };
  auto has_active = [&](int w) {
    for (int t : vertex_tets_[static_cast<std::size_t>(w)])
      if (!passive(t)) return true;
    return false;
  };
  std::unordered_set<int> grouped;
  for (const RigidGroup& g : out.rigid_groups) grouped.insert(g.vertices.begin(), g.vertices.end());  // kept by an update
  // Tets visited by the current search: a stamp per tet (no clearing between searches).
  visit_stamp_.resize(tets_.size(), 0);
  std::vector<int> visited, frontier, next, found;
  auto visit = [&](int t) {
    unsigned& stamp = visit_stamp_[static_cast<std::size_t>(t)];
    if (stamp == visit_epoch_) return false;
    stamp = visit_epoch_;
    visited.push_back(t);
    return true;
  };
  for (int v : candidates) {
    if (fixed_[static_cast<std::size_t>(v)] || grouped.count(v) || vertex_tets_[static_cast<std::size_t>(v)].empty() || has_active(v)) continue;
    // Breadth-first over tets sharing a vertex (pieces share no vertex: a cut duplicates
    // them), so the driver is always in the vertex's piece.
    if (++visit_epoch_ == 0) {  // wrapped: every stamp is stale
      std::fill(visit_stamp_.begin(), visit_stamp_.end(), 0u);
      visit_epoch_ = 1;
    }
    visited.clear();
    frontier = vertex_tets_[static_cast<std::size_t>(v)];
    for (int t : frontier) visit(t);
    found.clear();
    // The driver: among the active tets near the vertex (from the first layer that reaches
    // active tets on, one layer further through active tets too), those that hold it with
    // little extrapolation (every barycentric weight >= kAcceptableWeight: a driver much
    // smaller than its distance would amplify its motion) and of them the largest (it takes
    // the vertex's mass: a tiny tet would carry far more than its own). None acceptable:
    // up to kMoreLayers further layers, then the least extrapolating one.
    constexpr double kAcceptableWeight = -0.25;
    constexpr int kMoreLayers = 3;
    DrivenVertex best, best_any;
    double best_volume = -1.0, best_score = -1e300;
    int layers = -1;
    while (!frontier.empty() && static_cast<int>(visited.size()) <= kMaxEmbeddingSearch) {
      next.clear();
      found.clear();
      for (int t : frontier)
        for (int u : tets_[static_cast<std::size_t>(t)])
          for (int t2 : vertex_tets_[static_cast<std::size_t>(u)]) {
            if (!visit(t2)) continue;
            (passive(t2) ? next : found).push_back(t2);
          }
      for (int t : found) {
        const auto& tet = tets_[static_cast<std::size_t>(t)];
        Eigen::Matrix3d M;
        for (int k = 0; k < 3; ++k) M.col(k) = X.col(tet[static_cast<std::size_t>(k + 1)]) - X.col(tet[0]);
        const Eigen::Vector3d w123 = M.inverse() * (X.col(v) - X.col(tet[0]));
        const std::array<double, 4> w{{1.0 - w123.sum(), w123[0], w123[1], w123[2]}};
        const double score = *std::min_element(w.begin(), w.end());
        if (!std::isfinite(score)) continue;
        const DrivenVertex candidate{v, t, tet, w};
        if (score > best_score) {
          best_score = score;
          best_any = candidate;
        }
        const double volume = M.determinant() / 6.0;
        if (score >= kAcceptableWeight && volume > best_volume) {
          best_volume = volume;
          best = candidate;
        }
      }
      if (best_any.vertex >= 0) ++layers;
      if ((best.vertex >= 0 && layers >= 1) || layers >= kMoreLayers) break;
      if (best_any.vertex >= 0) next.insert(next.end(), found.begin(), found.end());  // on through the active tets
      frontier.swap(next);
    }
    if (best.vertex < 0) best = best_any;
    if (best.vertex >= 0) {
      out.driven.push_back(best);
      continue;
    }
    // No active tet in reach: the passive region moves as one rigid body.
    RigidGroup g;
    for (int t : visited)
      for (int u : tets_[static_cast<std::size_t>(t)])
        if (!has_active(u)) g.vertices.push_back(u);
    std::sort(g.vertices.begin(), g.vertices.end());
    g.vertices.erase(std::unique(g.vertices.begin(), g.vertices.end()), g.vertices.end());
    for (int u : g.vertices) {
      grouped.insert(u);
      g.held = g.held || fixed_[static_cast<std::size_t>(u)] != 0;
    }
    out.driven.erase(std::remove_if(out.driven.begin(), out.driven.end(), [&](const DrivenVertex& d) { return grouped.count(d.vertex) > 0; }),
                     out.driven.end());
    out.rigid_groups.push_back(std::move(g));
  }
  std::sort(out.driven.begin(), out.driven.end(), [](const DrivenVertex& a, const DrivenVertex& b) { return a.vertex < b.vertex; });
}

// --- EmbeddedMotion ---

void EmbeddedMotion::reset(const EmbeddedElements& embedded, const Eigen::Matrix3Xd& rest, const Eigen::Matrix3Xd& x,
                           const Eigen::Matrix3Xd& v) {
  const int n = static_cast<int>(rest.cols());
  active_ = !embedded.driven.empty() || !embedded.rigid_groups.empty() || !embedded.passive_mass.empty();
  if (!active_ && held_.empty()) return;
  held_.assign(static_cast<std::size_t>(n), 0);
  driven_ = embedded.driven;
  passive_mass_ = embedded.passive_mass;
  for (const DrivenVertex& d : driven_) held_[static_cast<std::size_t>(d.vertex)] = 1;
  std::vector<Body> bodies;
  for (const RigidGroup& g : embedded.rigid_groups) {
    Body b;
    auto old = std::find_if(bodies_.begin(), bodies_.end(), [&](const Body& o) { return o.group.vertices == g.vertices; });
    if (old != bodies_.end()) b = *old;
    b.group = g;
    for (int u : g.vertices) held_[static_cast<std::size_t>(u)] = 1;
    b.r.assign(g.vertices.size(), Eigen::Vector3d::Zero());
    for (std::size_t k = 0; k < g.vertices.size(); ++k) b.r[k] = rest.col(g.vertices[k]);  // rest positions until prepare()
    if (old == bodies_.end()) {
      b.x_start.resize(g.vertices.size());
      b.v_start.resize(g.vertices.size());
      for (std::size_t k = 0; k < g.vertices.size(); ++k) {
        b.x_start[k] = x.col(g.vertices[k]);
        b.v_start[k] = v.cols() == x.cols() ? Eigen::Vector3d(v.col(g.vertices[k])) : Eigen::Vector3d::Zero();
      }
      b.started = false;
    }
    bodies.push_back(std::move(b));
  }
  bodies_ = std::move(bodies);
}

void EmbeddedMotion::move_mass(std::initializer_list<Eigen::VectorXd*> arrays, std::vector<int>& touched,
                               const std::vector<Material>* materials) {
  moved_.assign(arrays.size(), {});
  moved_driven_.clear();
  moved_groups_.clear();
  shared_v_.clear();
  shared_.assign(arrays.size(), {});
  if (!active_) return;
  if (materials) {  // passive tets' mass re-shared by support (PassiveMass)
    for (const PassiveMass& p : passive_mass_) {
      const Material& mat = (*materials)[static_cast<std::size_t>(p.region)];
      shared_v_.push_back(p.v);
      std::size_t a = 0;
      for (Eigen::VectorXd* arr : arrays) {
        const double m = (a == 0 ? 1.0 : mat.damping_mass_per_s) * mat.density_kg_per_mm3 * p.volume_mm3;
        std::array<double, 4> amounts{};
        for (int k = 0; k < 4; ++k) {
          amounts[static_cast<std::size_t>(k)] = (p.share[static_cast<std::size_t>(k)] - 0.25) * m;
          (*arr)[p.v[static_cast<std::size_t>(k)]] += amounts[static_cast<std::size_t>(k)];
        }
        shared_[a++].push_back(amounts);
      }
      touched.insert(touched.end(), p.v.begin(), p.v.end());
    }
  }
  const Eigen::VectorXd& mass = **arrays.begin();
  // Weights that move the mass: the driving weights when the vertex lies in its driver tet
  // (then mass, momentum and gravity are exactly those of the vertex moving with it); for a
  // vertex outside it (a negative weight) the clamped, renormalised ones, so that no driver
  // loses mass (total mass and gravity kept; momentum to the extrapolation's first order).
  for (const DrivenVertex& d : driven_) {
    DrivenVertex m = d;
    bool ok = true;
    for (int k = 0; k < 4; ++k) ok = ok && d.weights[static_cast<std::size_t>(k)] >= 0.0;
    (void)mass;
    if (!ok) {
      double sum = 0.0;
      for (double& w : m.weights) sum += (w = std::max(w, 0.0));
      for (double& w : m.weights) w /= sum;
    }
    moved_driven_.push_back(m);
  }
  std::size_t a = 0;
  for (Eigen::VectorXd* arr : arrays) {
    auto& out = moved_[a++];
    for (const DrivenVertex& d : moved_driven_) {
      const double m = (*arr)[d.vertex];
      out.push_back(m);
      (*arr)[d.vertex] = 0.0;
      for (int k = 0; k < 4; ++k) (*arr)[d.drivers[static_cast<std::size_t>(k)]] += d.weights[static_cast<std::size_t>(k)] * m;
    }
    for (const Body& b : bodies_)
      for (int u : b.group.vertices) {
        out.push_back((*arr)[u]);
        (*arr)[u] = 0.0;
      }
  }
  for (Body& b : bodies_) {
    b.m.clear();
    moved_groups_.push_back(b.group.vertices);
  }
  {
    std::size_t k = moved_driven_.size();
    for (Body& b : bodies_)
      for (std::size_t i = 0; i < b.group.vertices.size(); ++i) b.m.push_back(moved_[0][k++]);
  }
  for (Body& b : bodies_) prepare(b);
  for (const DrivenVertex& d : moved_driven_) {
    touched.push_back(d.vertex);
    touched.insert(touched.end(), d.drivers.begin(), d.drivers.end());
  }
  for (const auto& g : moved_groups_) touched.insert(touched.end(), g.begin(), g.end());
}

void EmbeddedMotion::restore_mass(std::initializer_list<Eigen::VectorXd*> arrays, std::vector<int>& touched) {
  if (moved_.size() != arrays.size()) return;  // nothing moved
  if (shared_.size() == arrays.size()) {
    std::size_t a = 0;
    for (Eigen::VectorXd* arr : arrays) {
      const auto& amounts = shared_[a++];
      for (std::size_t i = 0; i < amounts.size(); ++i)
        for (int k = 0; k < 4; ++k) (*arr)[shared_v_[i][static_cast<std::size_t>(k)]] -= amounts[i][static_cast<std::size_t>(k)];
    }
    for (const auto& v : shared_v_) touched.insert(touched.end(), v.begin(), v.end());
  }
  shared_.clear();
  shared_v_.clear();
  std::size_t a = 0;
  for (Eigen::VectorXd* arr : arrays) {
    const auto& in = moved_[a++];
    std::size_t k = 0;
    for (const DrivenVertex& d : moved_driven_) {
      const double m = in[k++];
      (*arr)[d.vertex] += m;
      for (int j = 0; j < 4; ++j) (*arr)[d.drivers[static_cast<std::size_t>(j)]] -= d.weights[static_cast<std::size_t>(j)] * m;
    }
    for (const auto& g : moved_groups_)
      for (int u : g) (*arr)[u] += in[k++];
  }
  for (const DrivenVertex& d : moved_driven_) {
    touched.push_back(d.vertex);
    touched.insert(touched.end(), d.drivers.begin(), d.drivers.end());
  }
  for (const auto& g : moved_groups_) touched.insert(touched.end(), g.begin(), g.end());
  moved_.clear();
  moved_driven_.clear();
  moved_groups_.clear();
}

void EmbeddedMotion::moved_vertices(std::vector<int>& out) const {
  for (const auto& v : shared_v_) out.insert(out.end(), v.begin(), v.end());
  for (const DrivenVertex& d : moved_driven_) {
    out.push_back(d.vertex);
    out.insert(out.end(), d.drivers.begin(), d.drivers.end());
  }
  for (const auto& g : moved_groups_) out.insert(out.end(), g.begin(), g.end());
}

void EmbeddedMotion::current_vertices(std::vector<int>& out) const {
  for (const PassiveMass& p : passive_mass_) out.insert(out.end(), p.v.begin(), p.v.end());
  for (const DrivenVertex& d : driven_) {
    out.push_back(d.vertex);
    out.insert(out.end(), d.drivers.begin(), d.drivers.end());
  }
  for (const Body& b : bodies_) out.insert(out.end(), b.group.vertices.begin(), b.group.vertices.end());
}

void EmbeddedMotion::prepare(Body& b) const {
  b.mass = 0.0;
  Eigen::Vector3d C = Eigen::Vector3d::Zero();
  const std::size_t n = b.group.vertices.size();
  // b.r holds rest positions (reset) or offsets (an earlier prepare): rebuild from the rest
  // positions kept in x_start's place is not possible, so offsets are re-centred in place.
  for (std::size_t k = 0; k < n; ++k) {
    b.mass += b.m[k];
    C += b.m[k] * b.r[k];
  }
  if (!(b.mass > 0.0)) return;
  C /= b.mass;
  b.I0.setZero();
  for (std::size_t k = 0; k < n; ++k) {
    b.r[k] -= C;
    b.I0 += b.m[k] * (b.r[k].squaredNorm() * Eigen::Matrix3d::Identity() - b.r[k] * b.r[k].transpose());
  }
  b.I0 += 1e-9 * (b.I0.trace() + 1e-30) * Eigen::Matrix3d::Identity();  // points on a line: no spin about it
}

void EmbeddedMotion::start(Body& b) const {
  const std::size_t n = b.group.vertices.size();
  b.c.setZero();
  b.V.setZero();
  for (std::size_t k = 0; k < n; ++k) {
    b.c += b.m[k] * b.x_start[k];
    b.V += b.m[k] * b.v_start[k];
  }
  b.c /= b.mass;
  b.V /= b.mass;
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  b.L.setZero();
  for (std::size_t k = 0; k < n; ++k) {
    A += b.m[k] * (b.x_start[k] - b.c) * b.r[k].transpose();
    b.L += b.m[k] * (b.x_start[k] - b.c).cross(b.v_start[k] - b.V);
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1.0;
  b.R = U * svd.matrixV().transpose();
  b.started = true;
}

void EmbeddedMotion::drive(Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, double dt_s, const Eigen::Vector3d& g) {
  if (!active_) return;
  for (const DrivenVertex& d : driven_) {
    Eigen::Vector3d xp = Eigen::Vector3d::Zero(), vp = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) {
      xp += d.weights[static_cast<std::size_t>(k)] * x.col(d.drivers[static_cast<std::size_t>(k)]);
      vp += d.weights[static_cast<std::size_t>(k)] * v.col(d.drivers[static_cast<std::size_t>(k)]);
    }
    x.col(d.vertex) = xp;
    v.col(d.vertex) = vp;
  }
  for (Body& b : bodies_) {
    const std::size_t n = b.group.vertices.size();
    if (b.group.held || !(b.mass > 0.0)) {
      for (int u : b.group.vertices) v.col(u).setZero();
      continue;
    }
    if (!b.started) start(b);
    // Rigid body: gravity moves the centre; no torque about it, so the angular momentum
    // stays and the rotation follows omega = I^-1 L (explicit, first order in dt).
    b.V += dt_s * g;
    b.c += dt_s * b.V;
    const Eigen::Matrix3d I = b.R * b.I0 * b.R.transpose();
    const Eigen::Vector3d omega = I.ldlt().solve(b.L);
    const double angle = omega.norm() * dt_s;
    if (angle > 0.0 && std::isfinite(angle)) b.R = Eigen::AngleAxisd(angle, omega.normalized()).toRotationMatrix() * b.R;
    // Velocities from the angular velocity of the new pose: their angular momentum is L.
    const Eigen::Vector3d omega_new = (b.R * b.I0 * b.R.transpose()).ldlt().solve(b.L);
    for (std::size_t k = 0; k < n; ++k) {
      const Eigen::Vector3d arm = b.R * b.r[k];
      x.col(b.group.vertices[k]) = b.c + arm;
      v.col(b.group.vertices[k]) = b.V + omega_new.cross(arm);
    }
  }
}

void EmbeddedMotion::restart(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  for (Body& b : bodies_) {
    const std::size_t n = b.group.vertices.size();
    b.x_start.resize(n);
    b.v_start.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      b.x_start[k] = x.col(b.group.vertices[k]);
      b.v_start[k] = v.col(b.group.vertices[k]);
    }
    b.started = false;
  }
}

}  // namespace arnav::host
