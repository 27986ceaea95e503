#pragma once
// XPBD tissue model (Macklin et al. 2016) with tetrahedral strain-energy constraints,
// substeps (small steps, Macklin et al. 2019) and Gauss-Seidel over the tets. Two energies
// (ModelConfig::energy):
//  - "neo_hookean": stable Neo-Hookean (Macklin & Mueller 2021), constraints |F| and
//    det F - gamma solved per tet as one coupled 2x2 block, no polar decomposition. One
//    sweep per substep only (small steps): see the constructor;
//  - "corotated" (default): fixed-corotated Psi(F) = mu |F - R|_F^2 + lambda/2 (det F - 1)^2
//    (Stomakhin et al. 2012), two blocks per tet solved in turn: deviatoric C = F - R
//    (R the polar rotation, frozen during the local solve, as in co-rotational FEM; the
//    9x9 block is I3 (x) B with B = sum_a w_a b_a b_a^T, one 3x3 solve) and hydrostatic
//    C_H = det F - 1. R comes from a warm-started rotation extraction (Mueller et al. 2016),
//    re-initialised by SVD whenever the state is set from outside.
// Both equal linear elasticity with the region's E and nu at small strain, are invariant
// to rigid motion and push inverted tets back. Lagrange multipliers per constraint, reset
// every substep. Both run on the SIMD batches of tet_batches.hpp, in groups that let two
// threads sweep without colours (build_batches). Attachments: compliant vector
// constraints (compliance 1/stiffness).
// Damping: Rayleigh beta as XPBD constraint damping, Rayleigh alpha on vertex velocities.
// Frame World; units mm, kg, s, mN, kPa.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <unordered_map>
#include <vector>

#include "host/sim/attachment_set.hpp"
#include "host/sim/model_config.hpp"
#include "host/sim/step_control.hpp"
#include "host/sim/step_health.hpp"
#include "host/sim/tissue_model.hpp"
#include "host/sim/xpbd/tet_batches.hpp"

namespace arnav::host {

class XpbdModel final : public TissueModel {
 public:
  // ModelConfig: energy ("corotated" when empty, or "neo_hookean"), iterations per
  // substep, substeps per step, tolerance (early stop on the sweep residual, see
  // step(); 0 = always run all iterations), threads.
  XpbdModel(const SimProblem& problem, const ModelConfig& config);

  // The label of its variant in model_variants(): "xpbd" (corotated) or "xpbd/neo_hookean".
  std::string name() const override { return neo_hookean_ ? "xpbd/neo_hookean" : "xpbd"; }
  StepSummary step(double dt_s) override;

  AttachmentId add_attachment(const AttachmentSpec& spec) override;
  void set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) override;
  void set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) override;
  void remove_attachment(AttachmentId id) override;
  void set_fixed_vertices(const std::vector<int>& vertices) override;

  const Eigen::Matrix3Xd& positions_World_mm() const override { return x_; }
  const Eigen::Matrix3Xd& velocities_World_mm_s() const override { return v_; }
  void set_state(const Eigen::Matrix3Xd& positions_World_mm, const Eigen::Matrix3Xd& velocities_World_mm_s) override;
  std::vector<ElementMeasure> element_measures() const override;
  // In place after a cut: the changed tets leave their batches (the batch's last lane
  // takes the freed one; an emptied batch leaves its group) and each joins the group it
  // can run in (the same rules as build_batches: a half when all its vertices are that
  // half's, else a side of the interface, else the seam) in the first batch of that group
  // with a free lane and none of its vertices (first fit over the group's open batches,
  // found through the lanes of its four vertices), else a new or reused empty batch;
  // lumped masses change by the removed and added tets' quarters, mass blocks are
  // refreshed for the tets around the vertices whose mass changed. A new vertex belongs
  // to a half when every old vertex of the changed tets around it does. O(changed tets
  // and their neighbours), no recolouring of the mesh.
  std::optional<MeshChangeStats> apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                   const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s) override;

  // Lumped vertex masses (kg) as the solver uses them: an embedded vertex's moved to its
  // drivers (0 there), a rigid group's to the group.
  const Eigen::VectorXd& masses_kg() const { return mass_; }
  // Stored elastic energy of tets and attachments at the current state (mN*mm).
  double elastic_energy() const;
  // Tets per group of the parallel sweep (tet_batches.hpp): the two halves (swept by two
  // threads at once), the two sides of their interface (likewise), the seam (one thread).
  std::array<int, 5> group_tets() const;
  // Checks the batches against problem (the mesh this model was built on or last updated
  // to): every elastic tet in exactly one lane with its vertices and rest shape, no
  // passive tet in a lane, the lanes of a batch on distinct vertices, groups 0 and 1 on
  // disjoint vertices and likewise 2 and 3, group 1 only on the vertices thread 1 owns and
  // group 0 on none of them. Empty when valid, else the first violation found.
  std::string check_batches(const SimProblem& problem) const;
  // Batches holding tets and the mean of their used lanes (SIMD occupancy, kLanes at most).
  int active_batches() const;
  double mean_lanes() const;
  // The energy in use: "neo_hookean" or "corotated".
  std::string energy() const { return neo_hookean_ ? "neo_hookean" : "corotated"; }
  // Step control (step_control.hpp): redone steps, steps at each factor of the substeps.
  const SubstepControl& step_control() const { return control_; }

 private:
  void build_batches(const SimProblem& problem);
  // Writes tet t of problem.mesh (rest shape, material) into lane l of batch b.
  void fill_lane(xpbd::TetBatch& b, int l, const SimProblem& problem, int t);
  void refresh_mass_block(std::size_t bi, int l);
  void fill_unused_lanes(std::size_t bi);
  void remove_lane(int lane);
  int add_lane(const SimProblem& problem, int t);
  int choose_group(const std::array<int, 4>& tet) const;
  int find_batch(int group, const std::array<int, 4>& tet);
  void free_batch(int batch);
  void build_local_maps();
  void set_owner(int vertex, unsigned char owner);
  void update_tet_mass_blocks();
  // One step (substeps, sweeps, attachments) in one parallel region; returns the elastic
  // energy of the tets and attachments and the inverted tets at its end.
  void step_batches(double h, int substeps, StepSummary& summary, bool& converged, double& energy, int& inverted);
  // One step of dt_s in `substeps` substeps with its health checks (step() redoes it).
  StepSummary step_once(double dt_s, int substeps);
  void reset_rotations();
  void reset_ledger();
  double total_energy() const;  // kinetic + elastic (attachments included) + gravity potential, mN*mm
  int count_inverted() const;
  double tet_energy(int* inverted) const;
  void solve_attachments(double h);

  ModelConfig config_;
  bool neo_hookean_ = false;
  int num_tets_ = 0;
  Eigen::Matrix3Xd x_, v_, x_prev_;
  Eigen::VectorXd mass_, inv_mass_, mass_damping_per_s_;
  std::vector<unsigned char> fixed_;       // held by the solver: user_fixed_ or embedded (below)
  std::vector<unsigned char> user_fixed_;  // set_fixed_vertices / the problem's
  // Tets below the quality bound (problem.embedded) are in no batch (no constraint); their
  // vertices and rest volumes, for the masses a later cut takes out again.
  struct PassiveTet {
    std::array<int, 4> v;
    double volume_mm3;
  };
  std::unordered_map<int, PassiveTet> passive_tets_;
  EmbeddedMotion embedded_;  // driven vertices, rigid groups
  void merge_fixed();
  Eigen::Vector3d gravity_;
  bool vessels_ignored_ = false;  // the problem declares vessels this model cannot couple
  xpbd::TetBatches batches_;      // tets in SIMD batches: two halves + interface
  std::array<std::vector<int>, 3> group_vertices_;  // vertices touched only by half 0, only by half 1, by both
  bool damped_ = false;           // some region has Rayleigh beta > 0
  std::vector<double> rotation_;  // corotated: warm start of each tet's rotation (4 x kLanes per batch)
  std::vector<double> lambda_;    // corotated, iterations > 1: multipliers (10 x kLanes per batch)
  AttachmentSet attachments_;
  InversionMonitor inversions_;   // inverted tets: counted warning (step_health.hpp)
  int inverted_at_end_ = -1;      // inverted tets after the last step; -1: unknown
  EnergyLedger ledger_;
  SubstepControl control_;
  // The state an unhealthy step is redone from (members: no allocation per step).
  Eigen::Matrix3Xd x_saved_, v_saved_;
  std::vector<double> rotation_saved_;
  InversionMonitor inversions_saved_;
  int inverted_saved_ = -1;
  // Local updates (apply_mesh_change), built at the first one: lane (batch * kLanes + lane)
  // of each tet, lanes of each vertex, the thread that owns each vertex (the index of its
  // group_vertices_ list), tets of groups 0, 2 and 3 at each vertex, per group the batches
  // with a free lane (open; may hold stale entries, dropped when met), empty batches.
  std::vector<int> lane_of_tet_;
  std::vector<std::vector<int>> vertex_lanes_;
  std::vector<unsigned char> vertex_owner_;
  std::vector<int> owner_pos_;                 // index of each vertex in its group_vertices_ list
  std::vector<std::array<int, 3>> side_tets_;  // tets of groups 0, 2 and 3 at each vertex
  std::array<std::vector<int>, 5> open_;
  std::vector<unsigned char> in_open_;
  std::vector<int> free_batches_;
  std::vector<int> batch_group_;  // group of each batch, -1: empty (free)
  std::array<int, 5> group_count_{};  // tets per group
  std::vector<int> clash_;            // find_batch's scratch
};

}  // namespace arnav::host
