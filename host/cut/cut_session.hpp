#pragma once
// A tissue model that the tracked scalpel cuts while it keeps deforming (docs/cut.md).
// Per frame: the blade (tip, heel in World) and whether cutting is enabled (foot pedal).
//  - cutting enabled: the surface the blade sweeps since the last frame cuts the volume
//    (TetCutter). The sweep starts from the previous blade carried along with the tissue
//    during the last step (its points move with the tets holding them), so each frame's
//    strip starts on the material where the last one ended even when the tissue moves
//    (a real blade holds the crack tip); after a topology change the tissue model is rebuilt on the new mesh and its
//    state (positions, velocities) carried over, embedded structures are re-embedded in the
//    pieces of the tets that changed, fixed vertices stay fixed in every copy;
//  - cutting disabled: the blade pushes the tissue: while its tip is inside the organ, the
//    surface point where it entered is pulled to the tip (a stiff attachment: contact
//    constraint as a penalty spring), released when the tip leaves.
// Events: the blade edge inside the organ entering a tumour's safety margin, the swept
// surface crossing a vessel centerline.
// Frame World, units mm, s, mN.
#include <Eigen/Core>

#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "host/cut/blade.hpp"
#include "host/cut/bvh.hpp"
#include "host/cut/structure_split.hpp"
#include "host/cut/surface_tracker.hpp"
#include "host/cut/tet_cutter.hpp"
#include "host/scene/embedding.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_config.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host::cut {

struct CutSessionSettings {
  CutSettings cut;
  int sweep_strips = 8;                    // strips of the swept surface (and blade points carried with the tissue)
  double tumour_margin_mm = 10.0;          // safety margin around each tumour
  double push_stiffness_mN_per_mm = 50.0;  // contact spring when cutting is disabled
  double min_sweep_mm = 0.01;              // a blade moving less than this across itself cuts nothing this frame
  // Rebuild the model on a worker thread after a topology change; the previous model keeps
  // stepping (the cut shows at once, the pieces separate mechanically when the new model is
  // swapped in a few frames later). false: rebuild inline, deterministic.
  bool rebuild_in_background = false;
  // Update the model in place after a cut (TissueModel::apply_mesh_change: work in the tets
  // the cut changed) where the model can; the others are rebuilt (above).
  bool local_updates = true;
  // Quality bound (docs/cut.md "Element quality"): tets whose smallest dihedral angle is
  // below it carry no elastic term; their lone vertices are driven by a well-shaped tet of
  // their piece, pieces of such tets only move rigidly (SimProblem::embedded). 0: off.
  double min_dihedral_deg = 5.0;
};

// A closed surface or a polyline carried by the volume (tumour, vessel centerlines), in its
// rest shape; the session keeps its embedding valid across cuts.
struct CarriedPoints {
  std::string name;
  Eigen::Matrix3Xd rest_World_mm;
  Embedding embedding;
};

struct CutEvent {
  int frame = 0;
  std::string kind;        // "margin_entered", "tumour_cut", "vessel_crossed"
  std::string structure;   // tumour or vessel name
  double distance_mm = 0;  // blade to tumour surface (margin), 0 when crossing
  Eigen::Vector3d location_World_mm = Eigen::Vector3d::Zero();
};

struct CutFrameReport {
  CutStepReport cut;              // what the cutter did (topology_changed, update_ms, ...)
  double rebuild_ms = 0.0;        // model rebuilt or updated on the new mesh (0 without topology change)
  bool local_update = false;      // the model was updated in place (not rebuilt)
  MeshChangeStats local;          // what that update touched
  double reembed_ms = 0.0;        // re-embedding and splitting the tumours and vessels
  int structure_edges_cut = 0;    // tumour edges and vessel segments crossing the cut (all cuts so far)
  Contact contact;                // blade against the organ surface
  bool pushing = false;           // contact attachment active (cutting disabled)
  std::vector<CutEvent> events;   // raised this frame
};

class CutSession {
 public:
  // problem.mesh is the mesh to cut; carried structures are embedded in it (their
  // embeddings must refer to problem.mesh). Throws std::invalid_argument like
  // make_tissue_model, or for bad settings.
  CutSession(const SimProblem& problem, const ModelConfig& config, const CutSessionSettings& settings,
             std::vector<CarriedPoints> tumours = {}, std::vector<std::vector<std::array<int, 3>>> tumour_tris = {},
             std::optional<CarriedPoints> vessels = std::nullopt, std::vector<std::array<int, 2>> vessel_segments = {});

  // Applies the blade for this frame (before the model steps). The first call only places
  // the blade (nothing swept yet).
  CutFrameReport apply_blade(const BladeSegment& blade, bool cutting_enabled);
  StepSummary step(double dt_s) { return model_->step(dt_s); }

  // Attachments (grasp, lobe pull) that survive cuts: re-added to every rebuilt model (their
  // material points keep their vertex ids: a cut only appends vertices). An id stays valid
  // until remove_attachment (the grasper releasing); a removed attachment is gone from the
  // current model and from every model rebuilt later. Throws std::out_of_range for an id
  // that was never added or is removed already.
  int add_attachment(const AttachmentSpec& spec);
  void set_attachment_target(int id, const Eigen::Vector3d& target_World_mm);
  void remove_attachment(int id);
  int attachments_active() const;

  TissueModel& model() { return *model_; }
  // Positions and velocities of every vertex of the current (cut) mesh: the model's, plus
  // vertices made since the model was built (background rebuild), interpolated or copied.
  Eigen::Matrix3Xd positions_World_mm() const { return extended(model_->positions_World_mm()); }
  Eigen::Matrix3Xd velocities_World_mm_s() const { return extended(model_->velocities_World_mm_s()); }
  const TetMesh& mesh() const { return cutter_.mesh(); }
  TetCutter& cutter() { return cutter_; }
  const std::vector<int>& fixed_vertices() const { return problem_.fixed_vertices; }
  // Organ surface: boundary faces of the cut volume (closed, outward), cut faces included;
  // kept up to date from the tets each cut changed (SurfaceTracker: O(changed tets)).
  const std::vector<std::array<int, 3>>& surface_tris() { return surface_.tris(); }
  // The same faces by slot, with their hierarchy (contact); surface_version() changes
  // whenever the boundary does.
  const SurfaceTracker& surface() const { return surface_; }
  int surface_version() const { return surface_version_; }
  // Tumours and vessels split along the cut (structure_split.hpp): points (the input ones
  // first, then the crossings' copies and cap centres) with their embedding in mesh(), and
  // the split triangles (closed, outward) / segments. Unchanged until the cut crosses them.
  const std::vector<CarriedPoints>& tumours() const { return tumours_; }
  const std::vector<std::vector<std::array<int, 3>>>& tumour_tris() const { return tumour_tris_; }
  const std::optional<CarriedPoints>& vessels() const { return vessels_; }
  const std::vector<std::array<int, 2>>& vessel_segments() const { return vessel_segments_; }
  // The split made again from the uncut structure against the cut mesh as it is now: what
  // tumours()[k] / tumour_tris()[k] and vessels() / vessel_segments() hold (they are kept
  // across steps whose cut cannot change them; tests compare the two).
  SplitStructure tumour_split_from_input(int k) const;
  SplitStructure vessel_split_from_input() const;
  // Per vessel point: the input node it was made from (its radius, ...); itself for input nodes.
  const std::vector<int>& vessel_node_source() const { return vessel_node_source_; }
  int frame() const { return frame_; }
  // The surface the blade swept in the last apply_blade that cut (its start carried with the
  // tissue, as the cutter used it), in the configuration of that instant; nullopt when the
  // last frame swept nothing.
  const std::optional<SweptSurface>& last_sweep() const { return last_sweep_; }
  int rebuilds() const { return rebuilds_; }
  int local_updates() const { return local_updates_; }
  // Tets below the quality bound and what moves their lone vertices (what the model got).
  const EmbeddedElements& embedded() const { return problem_.embedded; }

 private:
  void rebuild_model(const CutStepReport& step, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, CutFrameReport& report);
  Eigen::Matrix3Xd extended(const Eigen::Matrix3Xd& m) const;
  void launch_build();
  double poll_build();  // swaps a finished background model in; returns the ms it took
  void absorb(CutFrameReport& report, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v);
  void reembed(CarriedPoints& points, const CutStepReport& step, const std::vector<int>& region);
  void split_structures(const CutStepReport& step, CutFrameReport& report);
  std::vector<int> region_tets(const std::vector<int>& input_tets) const;
  std::vector<Triangle> new_cut_faces(const CutStepReport& step, const std::vector<int>& region) const;
  bool split_still_holds(const CarriedPoints& split, int input_points, const CutStepReport& step, const StructureEdges& edges,
                         const std::vector<int>& region) const;
  void check_events(const BladeSegment& blade, const SweptSurface* sweep, CutFrameReport& report);

  SimProblem problem_;
  ModelConfig config_;
  CutSessionSettings settings_;
  TetCutter cutter_;
  std::unique_ptr<TissueModel> model_;
  std::vector<char> fixed_;
  // As given (re-embedded after each cut) and split along the cut (what the accessors show).
  std::vector<CarriedPoints> tumour_input_;
  std::vector<std::vector<std::array<int, 3>>> tumour_input_tris_;
  std::optional<CarriedPoints> vessel_input_;
  std::vector<std::array<int, 2>> vessel_input_segments_;
  std::vector<std::vector<int>> tumour_region_;   // per tumour: input tets whose rest box meets its box
  std::vector<int> vessel_region_;
  std::vector<CarriedPoints> tumours_;
  std::vector<std::vector<std::array<int, 3>>> tumour_tris_;
  std::optional<CarriedPoints> vessels_;
  std::vector<std::array<int, 2>> vessel_segments_;
  std::vector<int> vessel_node_source_;
  std::vector<int> tumour_edges_cut_;
  int vessel_segments_cut_ = 0;
  // The uncut structures' edges (rest): a step whose new cut faces none of them passes
  // through leaves the split as it is (only the embeddings follow the new tets).
  std::vector<StructureEdges> tumour_edges_;
  StructureEdges vessel_edges_;
  std::vector<int> tumour_caps_;  // loops the last split closed (their centres lie on lips)
  std::vector<char> in_margin_, tumour_cut_;
  std::vector<char> vessel_segment_crossed_;
  std::optional<BladeSegment> previous_blade_;
  std::optional<SweptSurface> last_sweep_;
  Eigen::Matrix3Xd x_at_blade_;  // positions when the previous blade was applied
  bool previous_cutting_ = false;
  SurfaceTracker surface_;
  int surface_version_ = 0;
  std::optional<AttachmentId> push_;
  AttachmentSpec push_spec_;
  std::vector<std::optional<AttachmentSpec>> attachments_;  // session attachments (nullopt: removed)
  std::vector<AttachmentId> attachment_ids_;                 // their ids in the current model
  void readd_attachments();
  std::vector<VertexOrigin> origins_;  // of vertices n0_, n0_ + 1, ... (made by cuts)
  int n0_ = 0;
  std::future<std::unique_ptr<TissueModel>> build_;
  bool rebuild_wanted_ = false;
  int frame_ = 0;
  int rebuilds_ = 0;
  int local_updates_ = 0;
  bool sync_mesh(const CutStepReport& step);  // problem_.mesh follows the cutter's in O(changed tets)
  EmbeddedElementTracker quality_;             // problem_.embedded, updated from the changed tets
};

// A cut session on a loaded scene: its tumours and vessels carried through the cuts (one
// place for arnav-sim --scalpel and arnav-bench cut).
std::unique_ptr<CutSession> make_cut_session(const Scene& scene, const ModelConfig& config, const CutSessionSettings& settings);

// The settings a scene's 'cutting:' section gives (the rest at their defaults).
CutSessionSettings cut_settings_from(const CuttingSpec& spec);

}  // namespace arnav::host::cut
