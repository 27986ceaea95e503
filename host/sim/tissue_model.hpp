#pragma once
// One interface for the tissue models (mass-spring, co-rotational FEM, XPBD).
// Frame: World (the scene frame). Units: mm, kg, s; forces in mN (kg*mm/s^2),
// stresses in kPa (mN/mm^2), stiffness of attachments in mN/mm.
#include <Eigen/Core>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "host/mesh/tet_mesh.hpp"
#include "host/sim/embedded_elements.hpp"

namespace arnav::host {

// Linear isotropic elastic material of one region, in model units.
struct Material {
  double youngs_modulus_kPa = 5.0;     // liver parenchyma ~ 2-10 kPa
  double poisson_ratio = 0.45;
  double density_kg_per_mm3 = 1.06e-6;  // 1060 kg/m^3
  double damping_mass_per_s = 0.0;     // Rayleigh alpha (mass-proportional), 1/s
  double damping_stiffness_s = 0.0;    // Rayleigh beta (stiffness-proportional), s
};

// What a tissue model is built from. Only what is declared is built: an empty vessel
// tree means no beam machinery, no attachments means none are allocated.
struct SimProblem {
  TetMesh mesh;
  std::vector<Material> region_materials;     // indexed by mesh.tet_region
  std::vector<int> fixed_vertices;            // Dirichlet: held at rest position
  Eigen::Vector3d gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  std::optional<VesselTree> vessels;          // beams coupled to the volume when present
  Material vessel_material{.youngs_modulus_kPa = 500.0, .poisson_ratio = 0.45};
  // Tets below a quality bound: no elastic term; vertices in no other tet driven by an
  // active tet of their piece or moved rigidly (embedded_elements.hpp). Empty: none.
  EmbeddedElements embedded;
};

// A material point: barycentric combination of mesh vertices (a vertex, or a point in a tet).
struct MaterialPoint {
  std::vector<int> vertices;
  std::vector<double> weights;  // sum to 1
};

// Zero-rest-length spring from a material point to a target in World: a grasp pulled
// by a tool, or a registration correspondence with its own weight (stiffness).
struct AttachmentSpec {
  MaterialPoint point;
  Eigen::Vector3d target_World_mm = Eigen::Vector3d::Zero();
  double stiffness_mN_per_mm = 1.0;
};
using AttachmentId = int;

// Per-step report (after Ceres' Summary): what the solver did and how well.
struct StepSummary {
  int iterations = 0;             // solver / constraint iterations in this step
  double initial_residual = 0.0;  // model-defined (relative residual for linear solves)
  double final_residual = 0.0;
  std::string termination;        // "converged", "max_iterations", "direct", ...
  double wall_time_ms = 0.0;
  double kinetic_energy = 0.0;    // mN*mm (= micro-joules)
  double elastic_energy = 0.0;
  bool healthy = true;            // false: real divergence (NaN/Inf, energy blow-up, a solver that
                                  // cannot reduce its residual, a collapsed mesh); docs/sim.md
  std::string warning;            // why not healthy, or a known limit hit (e.g. "inverted tets: 12")
  int inverted_elements = 0;      // elements with det F <= 0 at the end of the step (a counted
                                  // warning, not unhealthy by itself: InversionMonitor)
  // The energy ledger at the end of the step (EnergyLedger::check), for the models that keep
  // one (XPBD, mass-spring): energy created since the ledger's reset, and the most that may
  // be (budget + tolerance; 0: no ledger). Created beyond the allowance is unhealthy.
  double energy_created_mN_mm = 0.0;
  double energy_allowance_mN_mm = 0.0;
};

// Per-element measure for display and checks.
struct ElementMeasure {
  double von_mises_stress_kPa = 0.0;
  double max_principal_strain = 0.0;   // Green strain, largest eigenvalue
  double volume_ratio = 1.0;           // det(F)
};

// What a local mesh update did (TissueModel::apply_mesh_change): for checks that the work
// scales with the change, not with the mesh.
struct MeshChangeStats {
  int elements_updated = 0;  // element records removed, added or refreshed
  int vertices_updated = 0;  // vertex records (mass, state) written
};

class TissueModel {
 public:
  virtual ~TissueModel() = default;
  virtual std::string name() const = 0;

  // Advances the state by dt_s seconds (quasi-static models ignore inertia).
  virtual StepSummary step(double dt_s) = 0;

  virtual AttachmentId add_attachment(const AttachmentSpec& spec) = 0;
  virtual void set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) = 0;
  virtual void set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) = 0;
  virtual void remove_attachment(AttachmentId id) = 0;

  // Fixed vertices are held at their current position from now on.
  virtual void set_fixed_vertices(const std::vector<int>& vertices) = 0;

  virtual const Eigen::Matrix3Xd& positions_World_mm() const = 0;
  virtual const Eigen::Matrix3Xd& velocities_World_mm_s() const = 0;
  virtual void set_state(const Eigen::Matrix3Xd& positions_World_mm, const Eigen::Matrix3Xd& velocities_World_mm_s) = 0;
  virtual std::vector<ElementMeasure> element_measures() const = 0;

  // Local update after a cut (host/cut, docs/cut.md): problem.mesh is the model's mesh with
  // vertices appended and the tets `changed_tets` (sorted) changed or appended; every other
  // tet and vertex keeps its index and rest shape. x and v hold the state of every vertex of
  // the new mesh (read for the appended vertices and those of changed tets); fixed vertices
  // among the appended ones are at the end of problem.fixed_vertices. Returns what was
  // updated, or nothing when the model cannot update in place (the caller rebuilds it).
  virtual std::optional<MeshChangeStats> apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                           const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s) {
    (void)problem, (void)changed_tets, (void)x_World_mm, (void)v_World_mm_s;
    return std::nullopt;
  }
};

}  // namespace arnav::host
