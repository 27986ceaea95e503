#pragma once
// Embedded treatment of elements below a quality bound (issue 11, docs/cut.md "Element
// quality"). A cut that keeps the path exact leaves slivers (tets whose smallest dihedral
// angle is a fraction of a degree); their elastic terms are ill-conditioned and invert.
// Such tets stay in the mesh with their geometry and mass (exact volume, exact cut) but
// carry no elastic term in the tissue models ("passive"). A vertex that belongs to no
// well-shaped ("active") tet has nothing elastic to move it: it is driven by an active tet
// of the same piece (barycentric coordinates of its rest position; its mass moves to the
// driving vertices with the same weights, so total mass, momentum and gravity are kept).
// A piece made only of passive tets (a tiny piece cut off) moves as one rigid body.
// Frame World; units mm, kg, s, degrees.
#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <initializer_list>
#include <vector>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

// Smallest dihedral angle (degrees) of the tet (a, b, c, d); 0 for a degenerate one. The
// quality measure: it goes to 0 for every flat shape (sliver, wedge, cap) whose linear
// elastic stiffness becomes singular, and is scale-free.
double tet_min_dihedral_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d);
double tet_min_dihedral_deg(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet);

// A vertex moved by an active tet: x = sum_k weights[k] x[drivers[k]] (rest barycentric
// coordinates; they sum to 1 and may be slightly negative when the vertex lies outside).
struct DrivenVertex {
  int vertex = -1;
  int driver_tet = -1;
  std::array<int, 4> drivers{};
  std::array<double, 4> weights{};
};

// A piece (or, beyond kMaxEmbeddingSearch tets, a region) made only of passive tets.
struct RigidGroup {
  std::vector<int> vertices;  // sorted
  bool held = false;          // contains a fixed vertex: the whole group stays where it is
};

// Where a passive tet's mass goes: shared among its vertices in proportion to each one's
// elastic support (the rest volume of its active tets), not a quarter each: a vertex held
// only by tiny active tets must not carry the mass of a large sliver next to it (it would
// sag and invert them). A tet none of whose vertices has support keeps quarters.
struct PassiveMass {
  int tet = -1;
  int region = 0;
  double volume_mm3 = 0.0;
  std::array<int, 4> v{};
  std::array<double, 4> share{};  // sums to 1
};

struct Material;

// What SimProblem carries (empty: every tet elastic, the models as before).
struct EmbeddedElements {
  double min_dihedral_deg = 0.0;       // the bound these flags were made with (0: off)
  std::vector<std::uint8_t> passive;   // per tet: 1 = below the bound, no elastic term (empty: none)
  std::vector<DrivenVertex> driven;    // sorted by vertex
  std::vector<RigidGroup> rigid_groups;
  std::vector<PassiveMass> passive_mass;  // one per passive tet, sorted by tet
  bool is_passive(int tet) const { return static_cast<std::size_t>(tet) < passive.size() && passive[static_cast<std::size_t>(tet)] != 0; }
  bool any() const { return !driven.empty() || !rigid_groups.empty() || passive_count() > 0; }
  int passive_count() const;
};

// Tets searched from a vertex for an active tet of its piece before the search gives up
// (the region searched then moves rigidly; docs/cut.md).
constexpr int kMaxEmbeddingSearch = 4096;
// Well-shaped tets face-connected to at most this many others through well-shaped tets (an
// "island" that the slivers around it cut off from the elastic body of its piece) are
// embedded too: elastically they would float free inside their piece (docs/cut.md).
constexpr int kMaxIslandTets = 64;
// Size bound: a tet whose rest volume is below kMinRelativeVolume times that of the largest
// tet at one of its vertices is passive too, however well shaped (docs/cut.md). A cut leaves
// such tets where its sweeps cross (0.01-1 mm^3 next to 100-2,000 mm^3 on the coarse liver):
// they move by their own size in a frame, their springs carry 1e-5 of their neighbours'
// masses, and the mass-spring ring runs stopped on them. Scale-free; an evenly refined
// region is not touched (only a jump of 1,000 in volume between tets at one vertex).
constexpr double kMinRelativeVolume = 1e-3;

// Keeps EmbeddedElements for a mesh that cuts change: build() once (O(mesh)), update()
// after each topology change (O(changed tets + driven vertices and rigid groups, each with
// a local search)).
class EmbeddedElementTracker {
 public:
  // min_dihedral_deg in [0, 70.5): tets below it are passive (0: none); min_relative_volume
  // in [0, 1): the size bound above (0: none; only with min_dihedral_deg > 0).
  explicit EmbeddedElementTracker(double min_dihedral_deg = 0.0, double min_relative_volume = kMinRelativeVolume);
  double min_dihedral_deg() const { return min_deg_; }
  // fixed_vertices: Dirichlet vertices (never driven; a rigid group holding one is held).
  void build(const TetMesh& mesh, const std::vector<int>& fixed_vertices, EmbeddedElements& out);
  // mesh: the mesh after the change (vertices appended, changed_tets changed or appended;
  // the vertices appended by the change that are fixed are in fixed_vertices).
  void update(const TetMesh& mesh, const std::vector<int>& changed_tets, const std::vector<int>& fixed_vertices, EmbeddedElements& out);

 private:
  void resolve(const TetMesh& mesh, std::vector<int> candidates, EmbeddedElements& out);
  // Islands: well-shaped tets reached from `seeds` through face neighbours that are not
  // below the bound; components of at most kMaxIslandTets become passive, larger ones
  // elastic. Appends the vertices of tets whose flag changed to candidates.
  void settle_islands(const std::vector<int>& seeds, EmbeddedElements& out, std::vector<int>& candidates);
  void face_neighbours(int t, std::vector<int>& out) const;
  bool tiny(int t) const;  // rest volume below min_relative_volume_ x the largest tet at one of its vertices
  void share_passive_mass(const TetMesh& mesh, EmbeddedElements& out) const;
  double min_deg_ = 0.0;
  double min_relative_volume_ = 0.0;
  std::vector<char> flat_;   // per tet: smallest dihedral angle below min_deg_
  std::vector<char> below_;  // per tet: below the quality bound (passive = below_ or in an island)
  std::vector<int> passive_added_;  // tets made passive by the current build/update
  std::vector<double> volume_;      // rest volume per tet
  std::vector<std::array<int, 4>> tets_;
  std::vector<std::vector<int>> vertex_tets_;
  std::vector<char> fixed_;
  std::vector<unsigned> visit_stamp_;  // resolve(): per tet, the search that last visited it
  unsigned visit_epoch_ = 0;
};

// What a model does with EmbeddedElements at run time: which vertices its solver holds
// (driven vertices and rigid groups: Dirichlet during the step, written afterwards), the
// mass moved off them, and their motion after every step.
class EmbeddedMotion {
 public:
  bool active() const { return active_; }
  // Takes the problem's embedding (rest positions for the rigid groups' shape). Rigid groups
  // whose vertex set is unchanged keep their state; new ones start from x, v.
  void reset(const EmbeddedElements& embedded, const Eigen::Matrix3Xd& rest_World_mm, const Eigen::Matrix3Xd& x,
             const Eigen::Matrix3Xd& v);
  // Vertex held by the solver (driven or in a rigid group).
  bool held(int vertex) const { return static_cast<std::size_t>(vertex) < held_.size() && held_[static_cast<std::size_t>(vertex)] != 0; }
  const std::vector<char>& held_flags() const { return held_; }
  // Moves the mass-like per-vertex arrays (lumped mass first, then e.g. alpha * mass): a
  // driven vertex's entry goes to its drivers by its weights, a rigid group's entries to
  // the group (array 0 is its mass). Appends the vertices whose entries changed to touched.
  // With materials (the problem's region materials), each passive tet's lumped quarters are
  // first re-shared (PassiveMass): array 0 takes density * volume, array 1 (if any) also
  // alpha * density * volume.
  void move_mass(std::initializer_list<Eigen::VectorXd*> arrays, std::vector<int>& touched,
                 const std::vector<Material>* materials = nullptr);
  // Undoes the last move_mass exactly (before the lumped masses change).
  void restore_mass(std::initializer_list<Eigen::VectorXd*> arrays, std::vector<int>& touched);
  // After a step of dt_s: driven vertices follow their drivers (positions and velocities),
  // rigid groups move as rigid bodies under gravity (momentum and angular momentum kept).
  void drive(Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, double dt_s, const Eigen::Vector3d& gravity_World_mm_s2);
  // Rigid groups restart from this state (set_state).
  void restart(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v);
  const std::vector<DrivenVertex>& driven() const { return driven_; }
  // Vertices whose entries the last move_mass changed / the current embedding's move would.
  void moved_vertices(std::vector<int>& out) const;
  void current_vertices(std::vector<int>& out) const;

 private:
  struct Body {
    RigidGroup group;
    std::vector<Eigen::Vector3d> r;  // rest offsets from the rest centre of mass
    std::vector<double> m;           // masses (set by move_mass)
    double mass = 0.0;
    Eigen::Matrix3d I0 = Eigen::Matrix3d::Zero();  // rest inertia about the centre
    Eigen::Vector3d c = Eigen::Vector3d::Zero(), V = Eigen::Vector3d::Zero(), L = Eigen::Vector3d::Zero();
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    bool started = false;
    std::vector<Eigen::Vector3d> x_start, v_start;  // state given to reset (the model may zero held velocities)
  };
  void prepare(Body& b) const;  // rest centre, offsets and inertia from the masses
  void start(Body& b) const;    // centre, velocity, rotation, angular momentum from x_start, v_start
  bool active_ = false;
  std::vector<char> held_;
  std::vector<DrivenVertex> driven_;
  std::vector<PassiveMass> passive_mass_;
  std::vector<Body> bodies_;
  std::vector<std::array<int, 4>> shared_v_;            // what move_mass re-shared: vertices
  std::vector<std::vector<std::array<double, 4>>> shared_;  // per array, per passive tet: amounts added
  Eigen::Matrix3Xd rest_;
  // What move_mass moved (per array: per driven vertex, then per rigid vertex).
  std::vector<std::vector<double>> moved_;
  std::vector<DrivenVertex> moved_driven_;
  std::vector<std::vector<int>> moved_groups_;
};

}  // namespace arnav::host
