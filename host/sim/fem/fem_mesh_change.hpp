#pragma once
// The parts of an FEM model's in-place update after a cut (TissueModel::apply_mesh_change)
// that do not depend on the element formulation, shared by CorotationalFem and
// StableNeoHookeanFem (docs/sim-fem.md "After a cut"): checking the change, the vertices it
// touches, lumped masses and state of those vertices (the embedding's mass moves undone
// and redone), the vertex-pair counts that say which pattern entries a cut uncoupled, the
// pattern grown by one merge pass with the element maps remapped, and the assembly
// partition. Frame World; units mm, kg, s.
#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "host/sim/embedded_elements.hpp"
#include "host/sim/fem/symmetric_pattern.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host::fem {

// A tet's rest data from the problem, common to both FEM materials: vertices, Dm^-1 and the
// shape-function gradients, rest volume, Lame parameters and Rayleigh beta of its region,
// whether it is passive (below the quality bound), and its lumped quarters of mass and alpha
// mass. Throws std::invalid_argument (`who` names the model) for a region without material
// or a non-positive rest volume.
struct RestTet {
  std::array<int, 4> v{};
  Eigen::Matrix3d Dm_inv;
  std::array<Eigen::Vector3d, 4> g;
  double volume = 0, mu = 0, lambda = 0, beta = 0;
  bool passive = false;
  double quarter_mass = 0, quarter_alpha = 0;
};
RestTet rest_tet(const SimProblem& problem, int mesh_tet, const std::string& who);

// True when `changed` (mesh tets) is a change the models can take in place: sorted, unique,
// in the cut mesh, listing every appended tet; the mesh did not shrink; x (and v unless
// empty) have the cut mesh's vertex count.
bool mesh_change_fits(const SimProblem& problem, const std::vector<int>& changed, int old_vertices, int old_tets,
                      const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v);

// One changed tet: its vertices and lumped quarters (mass, alpha * mass) before the cut
// (none for an appended tet) and after.
struct TetChange {
  bool existed = false;
  std::array<int, 4> before{}, after{};
  double mass_before = 0, alpha_before = 0, mass_after = 0, alpha_after = 0;
};

// A model's per-vertex arrays (all sized to the vertex count before the cut).
struct VertexArrays {
  Eigen::Matrix3Xd& X;            // rest positions
  Eigen::Matrix3Xd& x;            // positions
  Eigen::Matrix3Xd& v;            // velocities
  Eigen::VectorXd& mass;          // lumped m (after the embedding's moves)
  Eigen::VectorXd& mass_alpha;    // lumped alpha m
  std::vector<char>& fixed;       // user_fixed or held by the embedding
  std::vector<char>& user_fixed;  // the problem's fixed vertices
};

// Vertices whose records change: those of the changed tets before and after, and the
// appended ones (old_vertices .. new_vertices - 1). Sorted, unique.
std::vector<int> touched_vertices(const std::vector<TetChange>& changes, int old_vertices, int new_vertices);

// Vertex records after a cut, in this order: checks that no touched vertex is left without
// mass (std::invalid_argument naming it, before anything changes; `who` names the model),
// undoes the embedding's mass moves, grows the arrays to the cut mesh (appended fixed
// vertices, at the end of problem.fixed_vertices, set), writes the touched vertices' rest
// position, masses (the removed quarters out, the new ones in) and state (v = 0 for fixed
// ones), resets the embedding to problem.embedded and moves the masses again, and merges
// the held vertices into `fixed` (held velocities zeroed). Returns the vertex records written.
int update_vertex_records(const SimProblem& problem, const std::vector<TetChange>& changes, const std::vector<int>& touched,
                          const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s, EmbeddedMotion& embedded,
                          VertexArrays arrays, const std::string& who);

// Which vertex pairs the tets couple (a count per pair, made at the first cut in O(tets),
// then kept from the changed tets): the pairs no tet couples any more after a cut leave
// the pattern, as in a model built on the cut mesh.
class TetPairCounts {
 public:
  bool empty() const { return count_.empty(); }
  // Once, before the first update: every tet as it is before the cut.
  void add(const std::array<int, 4>& tet);
  // The changed tets' pairs out (before) and in (after). Returns the pairs ({b, a}, a > b,
  // sorted) no tet couples any more and no group of `kept` (attachments, beams) holds.
  std::vector<std::pair<int, int>> update(const std::vector<TetChange>& changes, const std::vector<std::vector<int>>& kept);

 private:
  static std::uint64_t key(int a, int b) { return directed_edge_key(a, b); }  // a > b
  std::unordered_map<std::uint64_t, int> count_;
};

// The pattern grown to num_vertices with the pairs of `groups` (the changed tets after the
// cut) added and `drop` removed (SymmetricPattern::extended: one merge pass); the entries
// of every map in `maps` (element -> nonzero index maps, -1 entries kept) are remapped.
// Returns false (nothing changed) when the pattern stays the same.
bool grow_pattern(std::unique_ptr<SymmetricPattern>& pattern, int num_vertices, const std::vector<std::vector<int>>& groups,
                  const std::vector<std::pair<int, int>>& drop, const std::vector<std::vector<int>*>& maps);

// Assembly partition after a cut: element ids are tets [0, T), then other elements
// (beams); appended tets (ids old_tets .. ) move those up. One part: appended tets join it;
// several parts: the changed and appended tets go to the serial interface set (the parts
// stay vertex-disjoint whatever vertices the cut made).
void update_partition(ElementPartition& partition, const std::vector<int>& changed_ids, int old_tets, int new_tets);

}  // namespace arnav::host::fem
