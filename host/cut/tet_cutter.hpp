#pragma once
// Progressive volumetric cut of a tetrahedral mesh by the surface the blade sweeps, frame by
// frame (docs/cut.md). Method: element splitting with snapping, driven by the intersection
// state of each tet's edges (paper 003's edge/face intersection state):
//  - every frame, the edges of the tets near the swept surface are intersected with it (in
//    the current, deformed configuration); a crossing closer than snap_fraction of the edge
//    to an end snaps to that vertex (the vertex is "on the cut"), otherwise the crossing
//    parameter is recorded for the edge (material parameter: it survives deformation);
//  - a tet is cut when its recorded crossings separate it completely (the crossed edges are
//    exactly those between two non-empty vertex sides); its crossed edges are then split at
//    the recorded points. An edge split bisects every tet around the edge, so the mesh stays
//    conforming; a tet the cut reaches only partly (the crack tip) is bisected but stays
//    connected until the cut goes through it;
//  - faces whose three vertices lie on the cut and that lie on the swept surface are cut
//    faces; a vertex whose incident tets fall into several groups once cut faces no longer
//    connect them is duplicated, one copy per group (the pieces separate there).
// Volumes: every split partitions a tet exactly (sub-tets sum to the parent, in rest and
// current configuration), vertex duplication moves nothing: total volume is conserved to
// round-off, every tet keeps a positive volume (split parameters lie in (f, 1-f)).
// Frame World, units mm.
#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "host/cut/blade.hpp"
#include "host/cut/bvh.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut {

struct CutSettings {
  // Edge crossings closer than this fraction of the edge length to an end snap to that vertex
  // (no split, no sliver). Sub-tets of a split keep at least this fraction of their parent's
  // volume per split edge. In (0, 0.5).
  double snap_fraction = 0.1;
  // Vertices this close to the swept surface lie on it (exact hits, planes through vertices).
  double vertex_tolerance_mm = 1e-6;
  // A vertex near a crossing that is not moved onto the swept surface snaps to it (the cut
  // passes through the vertex) only when it lies within this distance of the crossing;
  // farther, the edge is split at the crossing (path fidelity over the volume-fraction
  // bound). 0: never snap such a vertex (only exact hits within vertex_tolerance_mm).
  double path_tolerance_mm = 0.1;
  // A snapped interior vertex not on an earlier cut is moved onto the swept surface (rest and
  // current position along its edge) when every tet around keeps a quarter of its volume:
  // the cut stays on the path and the star's total volume is unchanged.
  bool move_snapped_vertices = true;
  // While the blade passes, a vertex takes its side of the cut only from a part of the
  // surface swept so far within this distance (and within one edge of its tets); farther
  // vertices get it when a cut face needs it, or at the stroke's end from the complete
  // surface. On a curved cut a far vertex can lie across from a part swept early while the
  // part nearest to it is not swept yet (a vertex 7 mm outside a 21 mm ring took the
  // inside's side from the strip across the ring's diameter, 42 mm away). About the cut's
  // smallest radius of curvature; sensitive on the coarse liver (docs/cut.md): the bundled
  // 25 mm ring needs >= 30 in the running simulation, the 21 mm ring made from the scene
  // <= 20 (ring_path.hpp users set it so).
  double side_distance_mm = 30.0;
  // Refinement ahead of the blade, where the cut curves: before the sweep's crossings are
  // taken, every edge of a tet the sweep is about to enter (no vertex on a cut, no crossing
  // recorded yet) longer than L = sqrt(8 s R) at rest is bisected, longest first, with s this
  // setting and R the cut's radius of curvature in the material over its last few mm. A chord
  // of length L across the cut then lies at most s off it (unrefined, a 40 mm chord of the
  // demo's 21 mm ring lies 9.5 mm off it). A straight cut refines nothing. 0: off (the mesh as given). Volumes stay
  // exact (bisections partition their tets).
  double chord_sagitta_mm = 0.0;
  // L is never below this (a tight turn would otherwise refine without bound).
  double min_refined_edge_mm = 6.0;
  // At most this many bisections per frame (bounds a frame's cost; a tet the blade reaches
  // before its turn is cut as it is).
  int max_refinements_per_step = 200;
};

// Where a vertex created by a cut step came from: the edge point (1-t) a + t b, or a copy of
// a (t = 0, b = -1) when the cut separated the pieces at a.
struct VertexOrigin {
  int a = -1;
  int b = -1;
  double t = 0.0;
};

struct CutStepReport {
  int candidate_tets = 0;     // tets near the swept surface
  int edges_crossed = 0;      // new edge crossings recorded this step
  int vertices_snapped = 0;   // vertices newly on the cut
  int tets_cut = 0;           // tets separated by the cut this step
  int tets_completed = 0;     // of which completed from the vertex sides (tissue moved)
  int edges_split = 0;
  int tets_added = 0;         // new tets (splits)
  int vertices_added = 0;     // edge points + copies
  int vertices_moved = 0;     // snapped interior vertices moved onto the cut
  int edges_refined = 0;      // edges bisected ahead of the blade (chord_sagitta_mm; also in edges_split)
  int faces_separated = 0;    // cut faces that became boundary this step
  bool topology_changed = false;  // the mesh changed (new vertices or tets, moved vertices)
  double update_ms = 0.0;     // wall time of this step
  // Path fidelity: largest distance from this frame's swept surface (current configuration,
  // the instant the blade sweeps it) of a point put on the cut this step: split points
  // (round-off), vertices moved onto the surface (round-off), vertices snapped where they
  // stand (at most path_tolerance_mm). The cut faces are the polygons through these points.
  double max_path_deviation_mm = 0.0;
  // Tets completed after the blade left them (tets_completed): distance of the points added
  // from the plane fitted through their recorded points (which lie on the swept surface).
  double max_completion_deviation_mm = 0.0;
  int cut_points = 0;  // points put on the cut this step (crossings recorded, vertices snapped)
  std::vector<VertexOrigin> new_vertices;  // for vertex ids old_count .. old_count + n - 1
  // Tets whose vertex list changed or that were created (sorted); origin_tet() names the
  // input tet each came from. Used to re-embed points and to rebuild per-element data.
  std::vector<int> changed_tets;
};

class TetCutter {
 public:
  // The mesh must be valid (positive tets, conforming). Copies it.
  TetCutter(const TetMesh& mesh, const CutSettings& settings);

  // One frame: cuts along the surface swept by the blade. x and v (current positions and
  // velocities, one column per vertex; v may be empty) gain a column per new vertex
  // (interpolated or copied). mesh().surface_tris is not updated (update_surface()).
  CutStepReport step(const SweptSurface& sweep, Eigen::Matrix3Xd& x_World_mm, Eigen::Matrix3Xd& v_World_mm_s);

  // Ends the stroke (cutting switched off): tets with incomplete crossings that no blade end
  // passed through are completed from their vertex sides (as the blade leaving them does).
  CutStepReport finish_stroke(Eigen::Matrix3Xd& x_World_mm, Eigen::Matrix3Xd& v_World_mm_s);

  // Starts a new stroke (cutting switched on again, a second cut): crossings the previous
  // stroke recorded but did not complete are dropped (its crack tip stays where it is), and
  // vertices on earlier cuts no longer count as lying on the new one. The first stroke starts
  // at construction.
  void begin_stroke();

  // The tet containing p at positions x (or the nearest one of those whose box holds p, by
  // barycentric weights; of a refined or cut input tet's children only those whose own box
  // holds p), with its weights; tet -1 when no tet box holds p.
  // refit false: the hierarchy was refitted to x by an earlier call (several points, one refit).
  int locate(const Eigen::Vector3d& p_World_mm, const Eigen::Matrix3Xd& x_World_mm, Eigen::Vector4d& weights, bool refit = true);

  // The surface a sweep covered, pulled back into the rest configuration through the tets
  // holding it at positions x (the tissue as the blade passed): the material the blade went
  // through, whatever the tissue does afterwards. Each blade line is resampled every ~1 mm
  // (the pull-back is affine per tet only). Empty when the sweep missed the tissue.
  std::vector<Triangle> sweep_in_material(const SweptSurface& sweep, const Eigen::Matrix3Xd& x_World_mm, bool refit = true);

  // Tets with recorded crossings that do not (yet) separate them, as text (for diagnosis).
  std::string describe_pending() const;

  // Recomputes mesh().surface_tris (boundary faces, outward): O(tets log tets).
  void update_surface();

  const TetMesh& mesh() const { return mesh_; }
  const CutSettings& settings() const { return settings_; }
  // Side of this stroke's cut a vertex lies on (+1/-1; 0: not known yet or on the cut).
  int side(int vertex) const { return side_[static_cast<std::size_t>(vertex)]; }
  // The vertex lies on a cut (this stroke or an earlier one).
  bool on_cut(int vertex) const { return on_cut_[static_cast<std::size_t>(vertex)] != 0; }
  // Crossings recorded but not yet split (the crack front and tets the cut has entered).
  int pending_crossings() const { return static_cast<int>(pending_.size()); }
  // Index of the tet of the input mesh that tet t was cut from, and the current pieces of an
  // input tet (they tile it exactly in the rest configuration).
  int origin_tet(int t) const { return origin_[static_cast<std::size_t>(t)]; }
  const std::vector<int>& pieces_of(int input_tet) const { return family_[static_cast<std::size_t>(input_tet)]; }

 private:
  using EdgeKey = std::uint64_t;
  struct FaceHash {
    std::size_t operator()(const std::array<int, 3>& f) const {
      return std::hash<std::uint64_t>()((static_cast<std::uint64_t>(f[0]) * 73856093ULL) ^
                                        (static_cast<std::uint64_t>(f[1]) * 19349663ULL) ^
                                        (static_cast<std::uint64_t>(f[2]) * 83492791ULL));
    }
  };
  using FaceSet = std::unordered_set<std::array<int, 3>, FaceHash>;

  static EdgeKey edge_key(int a, int b);
  static std::pair<int, int> edge_ends(EdgeKey key);  // the smaller id first
  static std::array<int, 3> face_key(int a, int b, int c);
  std::vector<int> tets_with_edge(int a, int b) const;
  int tets_with_face(const std::array<int, 3>& f, int* tets = nullptr) const;
  // Crossed-edge bitmask of a complete separation of tet t, or 0 when incomplete.
  int complete_pattern(int t) const;
  // Crossed-edge bitmask implied by the sides of tet t's free vertices (0 when unknown).
  int side_pattern(int t) const;
  // Adds the crossings missing from the side pattern of tet t where its edges cross the
  // stroke's surface in the material (else as swept, else on the plane through the recorded
  // ones); false when the sides are unknown, nothing is missing, or (no crossing recorded)
  // the surface never passed near the tet.
  bool complete_from_sides(int t, const Eigen::Matrix3Xd& x, CutStepReport& r);
  // Side of free vertex w from the nearest point of this stroke's whole swept surface so far
  // (0: not across from it, or farther than an edge of its tets).
  int stroke_side(int w, const Eigen::Matrix3Xd& x, double cone, bool within_reach = true) const;
  // Distance of p from this stroke's whole swept surface (as swept).
  double stroke_distance(const Eigen::Vector3d& p) const;
  // The same in the rest configuration: p at rest against the stroke's surface in the material.
  double material_stroke_distance(const Eigen::Vector3d& p_rest, Eigen::Vector3d* closest = nullptr) const;
  // Where edge a-b crosses the stroke's surface in the material (the crossing nearest to
  // parameter near_s, from the smaller vertex id); false when it does not cross it.
  bool material_crossing(int a, int b, double near_s, double& s) const;
  // The parameter on edge a-b (from the smaller id, in [0.01, 0.99]) nearest in the material
  // to the stroke's surface there, starting from near_s: where a completion puts an edge's
  // missing crossing when the edge does not cross that surface.
  double nearest_on_material_stroke(int a, int b, double near_s) const;
  // The same for the surface as swept, at positions x (-1 when it does not cross it).
  double world_stroke_crossing(int a, int b, double near_s, const Eigen::Matrix3Xd& x) const;
  // A vertex inserted inside the cut (an edge split at its mid-point) and its copies, one per
  // side once separated, moved together towards the stroke's surface in the material, all the
  // way or as far as can_move_copies allows: one rest position for all (the lips coincide at
  // rest), each copy's position now from its own side's tissue (lips already opened stay open).
  void place_on_material_stroke(const std::vector<int>& copies, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v);
  // After the separation (docs/cut.md, step 8): every point this step put on the cut (split
  // points, with the copies the separation made of them) that lies farther than
  // path_tolerance_mm from the surface in the material (a completion's point nearest that
  // surface on an edge it does not cross) goes onto it as far as the tets around allow
  // (place_on_material_stroke). A separation mid-point that its first move left short is
  // tried again here (the star may have changed since).
  void place_new_cut_points(int first_new_vertex, const CutStepReport& r, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v);
  // The copies may move to rest_new (rest) and x_new[c] (now): every tet around each keeps a
  // quarter of its volume at rest and now, their boundary faces through it are this stroke's
  // lips, and their tets together keep their rest volume (the lips coincide at rest).
  bool can_move_copies(const std::vector<int>& copies, const Eigen::Vector3d& rest_new, const std::vector<Eigen::Vector3d>& x_new,
                       const Eigen::Matrix3Xd& x) const;
  // Adds tet t to the watch list when it has a vertex on this stroke's cut.
  void watch_tet(int t);
  // Interior vertex w may move to rest_new (rest) and x_new (now): every tet around keeps a
  // quarter of its volume at rest and now.
  bool can_move(int w, const Eigen::Vector3d& rest_new, const Eigen::Vector3d& x_new, const Eigen::Matrix3Xd& x) const;
  // Tet tt keeps at least a quarter of its volume, at rest and now, with its vertex w moved to
  // rest_new and x_new. With inverted_may_move, a tet inverted now may also get less inverted
  // (keeps_a_quarter_of_volume): points going onto the cut in the material do; snaps do not
  // (allowed there too, the bundled ring on mass_spring/local_global created energy at its end).
  bool keeps_a_quarter(int tt, int w, const Eigen::Vector3d& rest_new, const Eigen::Vector3d& x_new, const Eigen::Matrix3Xd& x,
                       bool inverted_may_move) const;
  bool move_vertex(int w, int o, double t, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  int add_vertex(const VertexOrigin& o, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  void split_edge(int a, int b, double t_ab, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r,
                  std::vector<int>& touched);
  void replace_vertex(int tet, int from, int to);
  // Curvature of this stroke's surface in the material over its last few mm (1/mm; 0 while
  // unknown or straight).
  double material_curvature_per_mm() const;
  // Refinement ahead of the blade (CutSettings::chord_sagitta_mm): bisects the long edges of the
  // candidates the sweep crosses that the cut has not touched yet; adds the new tets to
  // candidates.
  void refine_ahead(const std::vector<Triangle>& tris, std::vector<int>& candidates, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                    CutStepReport& r);
  // Marks the candidates a blade end (tip or heel path of this frame's sweep) passes through:
  // they hold the crack front.
  void mark_tip_tets(const SweptSurface& sweep, const std::vector<int>& candidates, const Eigen::Matrix3Xd& x);
  // Splits the tets among check whose recorded crossings separate them, while splits complete
  // more (step 4); marks the pieces in cut_piece.
  void split_completed(std::vector<int> check, std::vector<char>& cut_piece, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  // Completes and splits the tets the blade has left with crossings missing (step 4b).
  void complete_left_tets(const std::vector<int>& candidates, int old_tets, std::vector<char>& cut_piece, Eigen::Matrix3Xd& x,
                          Eigen::Matrix3Xd& v, CutStepReport& r);
  // Duplicates the vertices of cut faces whose tets fall apart into groups (step 5).
  void separate_along_cut(Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  // No vertex of tet t is on a cut and no edge of it has a crossing recorded.
  bool untouched(int t) const;
  // Tet t may be refined ahead of the blade: no vertex of it is on a cut (crossings already
  // recorded on its edges stay where they are, and its new edges take theirs from the
  // stroke's surface in the material: record_material_crossings).
  bool refinable(int t) const;
  // After an edge split at new vertex m: the new edges from m that cross the stroke's surface
  // in the material get that crossing recorded, as the sweep would have recorded it had the
  // edges been there when the blade passed (tets refined after the blade reached them).
  void record_material_crossings(int m);
  // True when the tets around edge p-q fall into several groups once cut faces no longer
  // connect them.
  bool ring_is_cut(int p, int q) const;
  int separate_vertex(int vertex, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  std::vector<Aabb> family_boxes(const Eigen::Matrix3Xd& x) const;

  // The phases of step(), in order (numbered as in tet_cutter.cpp).
  // An edge with one end on this stroke's cut that the sweep crosses again farther along.
  struct SecondCrossing {
    int on_cut, free;
    double s;  // from on_cut to free
    Triangle tri;
  };
  std::vector<int> sweep_candidates(const std::vector<Triangle>& tris, const Eigen::Matrix3Xd& x);
  void record_stroke_surface(const SweptSurface& sweep, const std::vector<Triangle>& tris, const Eigen::Matrix3Xd& x);
  // 1. Vertices within vertex_tolerance_mm of the sweep go onto the cut.
  void snap_vertices_on_sweep(const std::vector<Triangle>& tris, const std::vector<int>& candidates, const Eigen::Matrix3Xd& x,
                              std::unordered_set<int>& seen_vertices, CutStepReport& r);
  // 2. Edge crossings: snapped or recorded; the second crossings are returned for 2b.
  std::vector<SecondCrossing> record_edge_crossings(const std::vector<Triangle>& tris, const std::vector<int>& candidates,
                                                    Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  void record_crossing(int a, int b, double s, const Triangle& tri, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r);
  std::optional<SecondCrossing> second_crossing(int p, int o, const std::vector<Triangle>& tris, const Eigen::Matrix3Xd& x) const;
  // Vertex w, at fraction t_w of its edge (edge_mm long, other end o) from a crossing of
  // `tri`, goes onto the cut when within snap_fraction: moved onto the sweep, or snapped when
  // within path_tolerance_mm. False: the edge is to be split at the crossing.
  bool snap_to_crossing(int w, int o, double t_w, double edge_mm, const Triangle& tri, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                        CutStepReport& r);
  // 2b. Second crossings: the free end snapped, or the edge split there.
  void split_second_crossings(const std::vector<SecondCrossing>& crossings, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                              std::vector<int>& candidates, std::unordered_set<int>& seen_vertices, CutStepReport& r);
  // 3. Sides of the vertices right across from the sweep.
  void side_vertices_near_sweep(const std::vector<Triangle>& tris, const std::unordered_set<int>& seen_vertices, const Eigen::Matrix3Xd& x);
  // Cut faces of the pieces split_completed separated.
  std::vector<std::array<int, 3>> separated_piece_faces(const std::vector<char>& cut_piece);
  // Faces on the cut between tets on opposite sides (appended to new_cut_faces; those not
  // decidable yet wait in undecided_faces_).
  void decide_cut_faces(const std::vector<int>& candidates, const std::vector<int>& changed_tets, const Eigen::Matrix3Xd& x,
                        std::vector<std::array<int, 3>>& new_cut_faces);
  // Side of a tet from its free vertices (0 when it has none or they are not all known).
  int free_side(int t) const;
  // The side most of a tet's face neighbours are on (flat ones with the side they were given).
  int neighbours_side(int t) const;
  // Side of a tet: from its free vertices, sided from the stroke when needed; a flat tet (all
  // four vertices on the cut) by flat_tet_side.
  int tet_side(int t, const Eigen::Matrix3Xd& x);
  int flat_tet_side(int t, const Eigen::Matrix3Xd& x);
  bool all_on_stroke(int t) const;
  // 4c. Groups of flat tets the new cut faces would wall off join their neighbours' side.
  void join_walled_off_slivers(const std::vector<std::array<int, 3>>& new_cut_faces);
  void join_sliver_group(int seed, std::set<int>& done);

  TetMesh mesh_;
  CutSettings settings_;
  std::vector<std::vector<int>> vertex_tets_;
  bool on_stroke(int v) const { return on_cut_[static_cast<std::size_t>(v)] == stroke_; }
  int stroke_ = 1;
  bool finishing_ = false;
  std::vector<int> on_cut_;                      // per vertex: last stroke it was put on the cut by (0: none)
  std::unordered_map<EdgeKey, double> pending_;  // t from the smaller to the larger vertex id
  std::unordered_map<EdgeKey, Eigen::Vector3d> pending_normal_;  // unit normal of the sweep at each pending crossing
  std::vector<signed char> side_;                // per vertex: side of this stroke's sweep (+1/-1, 0 unknown)
  std::vector<Triangle> stroke_tris_;             // this stroke's swept triangles, as swept
  struct StrokeChunk {
    Aabb box;
    int begin = 0, end = 0;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  // area-weighted
    Eigen::Vector3d axis = Eigen::Vector3d::Zero();      // unit, its longest extent (the blade; 0: no area)
  };
  std::vector<StrokeChunk> stroke_chunks_;       // stroke_tris_ by frame, with their box
  // A stroke's surface (as swept, or in the material) queried by frame chunk: distance of p
  // (closest point optional), the crossing of segment p0-p1 nearest parameter near_s (-1 when
  // none), the side of vertex w at positions x (stroke_side), and a frame's triangles
  // appended as a new chunk.
  int surface_side(const std::vector<Triangle>& tris, const std::vector<StrokeChunk>& chunks, const Eigen::Matrix3Xd& x, int w, double cone,
                   bool within_reach) const;
  static double surface_distance(const std::vector<Triangle>& tris, const std::vector<StrokeChunk>& chunks, const Eigen::Vector3d& p,
                                 Eigen::Vector3d* closest);
  static double surface_crossing(const std::vector<Triangle>& tris, const std::vector<StrokeChunk>& chunks, const Eigen::Vector3d& p0,
                                 const Eigen::Vector3d& p1, double near_s);
  static void append_chunk(const std::vector<Triangle>& add, std::vector<Triangle>& tris, std::vector<StrokeChunk>& chunks);
  std::vector<Triangle> stroke_tris_rest_;        // this stroke's swept surface in the material (rest configuration)
  std::vector<StrokeChunk> stroke_chunks_rest_;  // stroke_tris_rest_ by frame, with their box
  std::vector<Eigen::Vector3d> cut_normal_;      // per vertex on this stroke's cut: the sweep's unit normal there (0: unknown)
  std::vector<int> sided_;                       // vertices with a side (reset at the next stroke)
  std::vector<std::array<int, 3>> undecided_faces_;  // on the cut, sides of their tets not known yet
  FaceSet cut_faces_;                            // interior faces to separate
  std::vector<signed char> flat_side_;           // per tet with all vertices on the cut: its side (this stroke)
  std::vector<char> tip_tet_;                    // per tet: a blade end passed through it this stroke
  std::vector<int> watch_;                       // tets with a vertex on this stroke's cut, until the blade has left them
  std::vector<char> watched_;                    // per tet: in watch_
  Eigen::Vector3d last_normal_ = Eigen::Vector3d::UnitZ();  // of the last sweep
  std::vector<int> origin_;                      // per tet: tet of the input mesh
  std::vector<std::vector<int>> family_;         // per input tet: its current pieces
  Bvh bvh_;                                      // over input tets (boxes of their families)
};

// Whether a tet whose (signed, 6x) volume goes from `volume6_before` to `volume6_after` by a
// vertex move stays usable: an upright tet keeps at least a quarter of its volume; a tet the
// load has turned inside out (a mass-spring or XPBD model lets that happen) may get less
// inverted, down to flat, but not more inverted nor flipped upright. Points the cutter moves
// onto the cut in the material use it; a "quarter" of a negative volume refused every move of
// an inverted tet's vertex (issue 20: a chord's mid-point left 3.06 mm off the cut).
bool keeps_a_quarter_of_volume(double volume6_before, double volume6_after);

}  // namespace arnav::host::cut
