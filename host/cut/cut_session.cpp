#include "host/cut/cut_session.hpp"

#include "host/scene/scene.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <stdexcept>

#include "host/sim/model_factory.hpp"

namespace arnav::host::cut {

namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Closest points of segments p0-p1 and q0-q1 (Ericson 5.1.9); returns the distance.
double segment_segment_distance(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                                const Eigen::Vector3d& q1, Eigen::Vector3d* on_p) {
  const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0, t = 0;
  if (a <= 1e-300 && e <= 1e-300) {
    s = t = 0;
  } else if (a <= 1e-300) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-300) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denom = a * e - b * b;
      s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  const Eigen::Vector3d cp = p0 + s * d1, cq = q0 + t * d2;
  if (on_p) *on_p = cp;
  return (cp - cq).norm();
}

// Distance between a segment and a triangle, with the closest point on the segment.
double segment_triangle_distance(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Triangle& tri, Eigen::Vector3d* on_seg) {
  double s = 0;
  if (segment_triangle_intersection(p0, p1, tri, s)) {
    if (on_seg) *on_seg = p0 + s * (p1 - p0);
    return 0.0;
  }
  double best = point_triangle_distance(p0, tri);
  Eigen::Vector3d where = p0;
  const double d1 = point_triangle_distance(p1, tri);
  if (d1 < best) {
    best = d1;
    where = p1;
  }
  const Eigen::Vector3d corners[3] = {tri.a, tri.b, tri.c};
  for (int i = 0; i < 3; ++i) {
    Eigen::Vector3d cp;
    const double d = segment_segment_distance(p0, p1, corners[i], corners[(i + 1) % 3], &cp);
    if (d < best) {
      best = d;
      where = cp;
    }
  }
  if (on_seg) *on_seg = where;
  return best;
}

}  // namespace

CutSession::CutSession(const SimProblem& problem, const ModelConfig& config, const CutSessionSettings& settings,
                       std::vector<CarriedPoints> tumours, std::vector<std::vector<std::array<int, 3>>> tumour_tris,
                       std::optional<CarriedPoints> vessels, std::vector<std::array<int, 2>> vessel_segments)
    : problem_(problem),
      config_(config),
      settings_(settings),
      cutter_(problem.mesh, settings.cut),
      tumour_input_(std::move(tumours)),
      tumour_input_tris_(std::move(tumour_tris)),
      vessel_input_(std::move(vessels)),
      vessel_input_segments_(std::move(vessel_segments)),
      quality_(settings.min_dihedral_deg) {
  if (settings_.sweep_strips < 1) throw std::invalid_argument("cutting: sweep_strips must be >= 1");
  if (!(settings_.tumour_margin_mm >= 0.0)) throw std::invalid_argument("cutting: tumour_margin_mm must be >= 0");
  if (!(settings_.push_stiffness_mN_per_mm > 0.0)) throw std::invalid_argument("cutting: push_stiffness_mN_per_mm must be > 0");
  if (tumour_input_tris_.size() != tumour_input_.size()) throw std::invalid_argument("cut session: one triangle list per tumour");
  tumours_ = tumour_input_;
  tumour_tris_ = tumour_input_tris_;
  vessels_ = vessel_input_;
  vessel_segments_ = vessel_input_segments_;
  if (vessels_) {
    vessel_node_source_.resize(static_cast<std::size_t>(vessels_->rest_World_mm.cols()));
    for (std::size_t i = 0; i < vessel_node_source_.size(); ++i) vessel_node_source_[i] = static_cast<int>(i);
  }
  // Input tets near each structure (rest boxes, 1 mm around): the cut can split it only there.
  const auto near = [&](const Eigen::Matrix3Xd& points) {
    std::vector<int> out;
    if (points.cols() == 0) return out;
    Aabb box;
    for (int i = 0; i < points.cols(); ++i) box.extend(Eigen::Vector3d(points.col(i)));
    box = box.inflated(1.0);
    const auto& mesh = problem_.mesh;
    for (int t = 0; t < mesh.num_tets(); ++t) {
      Aabb b;
      for (int w : mesh.tets[static_cast<std::size_t>(t)]) b.extend(Eigen::Vector3d(mesh.rest_positions_World_mm.col(w)));
      if (b.overlaps(box)) out.push_back(t);
    }
    return out;
  };
  for (const auto& t : tumour_input_) tumour_region_.push_back(near(t.rest_World_mm));
  if (vessel_input_) vessel_region_ = near(vessel_input_->rest_World_mm);
  for (std::size_t k = 0; k < tumour_input_.size(); ++k)
    tumour_edges_.emplace_back(tumour_input_[k].rest_World_mm, surface_edges(tumour_input_tris_[k]));
  if (vessel_input_) vessel_edges_ = StructureEdges(vessel_input_->rest_World_mm, vessel_input_segments_);
  tumour_caps_.assign(tumour_input_.size(), 0);
  tumour_edges_cut_.assign(tumour_input_.size(), 0);
  quality_.build(problem_.mesh, problem_.fixed_vertices, problem_.embedded);  // tets below the quality bound
  model_ = make_tissue_model(problem_, config_);
  surface_ = SurfaceTracker(problem_.mesh);
  n0_ = problem_.mesh.num_vertices();
  fixed_.assign(static_cast<std::size_t>(problem_.mesh.num_vertices()), 0);
  for (int v : problem_.fixed_vertices) fixed_[static_cast<std::size_t>(v)] = 1;
  in_margin_.assign(tumours_.size(), 0);
  tumour_cut_.assign(tumours_.size(), 0);
  vessel_segment_crossed_.assign(vessel_input_segments_.size(), 0);
}

bool CutSession::sync_mesh(const CutStepReport& step) {
  TetMesh& mine = problem_.mesh;
  const TetMesh& cut = cutter_.mesh();
  if (mine.tets.size() > cut.tets.size() || mine.num_vertices() > cut.num_vertices()) return false;
  const int n_old = mine.num_vertices();
  mine.rest_positions_World_mm.conservativeResize(Eigen::NoChange, cut.num_vertices());
  for (int i = n_old; i < cut.num_vertices(); ++i) mine.rest_positions_World_mm.col(i) = cut.rest_positions_World_mm.col(i);
  mine.tets.resize(cut.tets.size());
  mine.tet_region.resize(cut.tets.size(), 0);
  for (int t : step.changed_tets) {
    mine.tets[static_cast<std::size_t>(t)] = cut.tets[static_cast<std::size_t>(t)];
    mine.tet_region[static_cast<std::size_t>(t)] = cut.tet_region[static_cast<std::size_t>(t)];
    for (int w : cut.tets[static_cast<std::size_t>(t)]) mine.rest_positions_World_mm.col(w) = cut.rest_positions_World_mm.col(w);  // moved vertices
  }
  return true;
}

void CutSession::rebuild_model(const CutStepReport& step, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, CutFrameReport& report) {
  const int old_vertices = static_cast<int>(fixed_.size());
  for (std::size_t i = 0; i < step.new_vertices.size(); ++i) {
    const VertexOrigin& o = step.new_vertices[i];
    const bool fixed = o.b < 0 ? fixed_[static_cast<std::size_t>(o.a)] != 0
                               : fixed_[static_cast<std::size_t>(o.a)] != 0 && fixed_[static_cast<std::size_t>(o.b)] != 0;
    fixed_.push_back(fixed ? 1 : 0);
    if (fixed) problem_.fixed_vertices.push_back(old_vertices + static_cast<int>(i));
    origins_.push_back(o);
  }
  // Tets below the quality bound among the changed ones, and what drives their vertices.
  // Islands of good tets cut off by slivers can change the flag of tets the cut did not
  // touch: the models re-make those too (their element data follow the flag).
  const std::vector<std::uint8_t> passive_before = problem_.embedded.passive;
  quality_.update(cutter_.mesh(), step.changed_tets, problem_.fixed_vertices, problem_.embedded);
  std::vector<int> model_changed = step.changed_tets;
  for (std::size_t t = 0; t < passive_before.size(); ++t)
    if (problem_.embedded.is_passive(static_cast<int>(t)) != (passive_before[t] != 0)) model_changed.push_back(static_cast<int>(t));
  if (model_changed.size() != step.changed_tets.size()) {
    std::sort(model_changed.begin(), model_changed.end());
    model_changed.erase(std::unique(model_changed.begin(), model_changed.end()), model_changed.end());
  }
  // In place where the model can (work in the changed tets), while no background build runs.
  if (settings_.local_updates && !build_.valid() && static_cast<int>(model_->positions_World_mm().cols()) == old_vertices && sync_mesh(step)) {
    if (const auto stats = model_->apply_mesh_change(problem_, model_changed, x, v)) {
      report.local_update = true;
      report.local = *stats;
      ++local_updates_;
      return;
    }
  }
  problem_.mesh = cutter_.mesh();
  if (settings_.rebuild_in_background) {
    if (build_.valid()) {
      rebuild_wanted_ = true;  // a build is running: another one follows it
    } else {
      launch_build();
    }
    return;
  }
  model_ = make_tissue_model(problem_, config_);
  readd_attachments();
  model_->set_state(x, v);
  ++rebuilds_;
}

int CutSession::add_attachment(const AttachmentSpec& spec) {
  attachments_.emplace_back(spec);
  attachment_ids_.push_back(model_->add_attachment(spec));
  return static_cast<int>(attachments_.size()) - 1;
}

namespace {
std::size_t active_index(const std::vector<std::optional<AttachmentSpec>>& a, int id) {
  if (id < 0 || static_cast<std::size_t>(id) >= a.size() || !a[static_cast<std::size_t>(id)])
    throw std::out_of_range("cut session: no attachment " + std::to_string(id) + " (never added, or removed)");
  return static_cast<std::size_t>(id);
}
}  // namespace

void CutSession::set_attachment_target(int id, const Eigen::Vector3d& target_World_mm) {
  const std::size_t i = active_index(attachments_, id);
  attachments_[i]->target_World_mm = target_World_mm;
  model_->set_attachment_target(attachment_ids_[i], target_World_mm);
}

void CutSession::remove_attachment(int id) {
  const std::size_t i = active_index(attachments_, id);
  model_->remove_attachment(attachment_ids_[i]);
  attachments_[i].reset();
  attachment_ids_[i] = -1;
}

int CutSession::attachments_active() const {
  return static_cast<int>(std::count_if(attachments_.begin(), attachments_.end(), [](const auto& a) { return a.has_value(); }));
}

void CutSession::readd_attachments() {
  for (std::size_t i = 0; i < attachments_.size(); ++i)
    attachment_ids_[i] = attachments_[i] ? model_->add_attachment(*attachments_[i]) : -1;
}

Eigen::Matrix3Xd CutSession::extended(const Eigen::Matrix3Xd& m) const {
  const int n = cutter_.mesh().num_vertices();
  if (m.cols() >= n) return m;
  Eigen::Matrix3Xd out(3, n);
  out.leftCols(m.cols()) = m;
  for (int i = static_cast<int>(m.cols()); i < n; ++i) {
    const VertexOrigin& o = origins_[static_cast<std::size_t>(i - n0_)];
    out.col(i) = o.b < 0 ? Eigen::Vector3d(out.col(o.a)) : Eigen::Vector3d((1 - o.t) * out.col(o.a) + o.t * out.col(o.b));
  }
  return out;
}

void CutSession::launch_build() {
  rebuild_wanted_ = false;
  build_ = std::async(std::launch::async, [problem = problem_, config = config_]() { return make_tissue_model(problem, config); });
}

double CutSession::poll_build() {
  if (!build_.valid() || build_.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return 0.0;
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<TissueModel> next = build_.get();  // rethrows a failed build
  const int n = next->positions_World_mm().cols();
  next->set_state(extended(model_->positions_World_mm()).leftCols(n), extended(model_->velocities_World_mm_s()).leftCols(n));
  model_ = std::move(next);
  readd_attachments();
  ++rebuilds_;
  if (push_) push_ = model_->add_attachment(push_spec_);
  if (rebuild_wanted_) launch_build();
  return ms_since(t0);
}

void CutSession::reembed(CarriedPoints& points, const CutStepReport& step, const std::vector<int>& region) {
  const auto& changed = step.changed_tets;
  const TetMesh& mesh = cutter_.mesh();
  const auto& rest = mesh.rest_positions_World_mm;
  for (int i = 0; i < points.embedding.size(); ++i) {
    const int t = points.embedding.tet[static_cast<std::size_t>(i)];
    if (!std::binary_search(changed.begin(), changed.end(), t)) continue;
    const Eigen::Vector3d p = points.rest_World_mm.col(i);
    double best = -1e300;
    int best_tet = t;
    Eigen::Vector4d best_w = points.embedding.weights.col(i);
    const auto consider = [&](int piece) {
      const auto& tet = mesh.tets[static_cast<std::size_t>(piece)];
      Eigen::Matrix3d D;
      for (int k = 0; k < 3; ++k) D.col(k) = rest.col(tet[static_cast<std::size_t>(k + 1)]) - rest.col(tet[0]);
      const Eigen::Vector3d l = D.partialPivLu().solve(p - rest.col(tet[0]));
      const Eigen::Vector4d w(1.0 - l.sum(), l[0], l[1], l[2]);
      if (w.allFinite() && w.minCoeff() > best) {
        best = w.minCoeff();
        best_tet = piece;
        best_w = w;
      }
    };
    for (int piece : cutter_.pieces_of(cutter_.origin_tet(t))) consider(piece);
    // A vertex moved onto the cut reshapes tets of several input tets: the point may now lie
    // in a piece of a neighbouring input tet (outside its own family; weights negative, and
    // possibly across the cut). Look through the structure's region.
    if (best < -1e-9)
      for (int input : region)
        for (int piece : cutter_.pieces_of(input)) {
          const auto& tet = mesh.tets[static_cast<std::size_t>(piece)];
          Aabb box;
          for (int w : tet) box.extend(Eigen::Vector3d(rest.col(w)));
          if (box.inflated(1e-9).overlaps(Aabb{p, p})) consider(piece);  // only tets whose box holds the point
        }
    points.embedding.tet[static_cast<std::size_t>(i)] = best_tet;
    points.embedding.weights.col(i) = best_w;
  }
}

std::vector<int> CutSession::region_tets(const std::vector<int>& input_tets) const {
  // Only tets with a face on a cut can hold a lip: three or more vertices on a cut.
  std::vector<int> out;
  const auto& tets = cutter_.mesh().tets;
  for (int t : input_tets)
    for (int piece : cutter_.pieces_of(t)) {
      int on = 0;
      for (int v : tets[static_cast<std::size_t>(piece)]) on += cutter_.on_cut(v) ? 1 : 0;
      if (on >= 3) out.push_back(piece);
    }
  return out;
}

std::vector<Triangle> CutSession::new_cut_faces(const CutStepReport& step, const std::vector<int>& region) const {
  const TetMesh& mesh = cutter_.mesh();
  const auto& rest = mesh.rest_positions_World_mm;
  std::vector<Triangle> out;
  for (int t : step.changed_tets) {
    if (!std::binary_search(region.begin(), region.end(), cutter_.origin_tet(t))) continue;
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    for (const auto& f : kTetFaces) {
      const int a = tet[static_cast<std::size_t>(f[0])], b = tet[static_cast<std::size_t>(f[1])], c = tet[static_cast<std::size_t>(f[2])];
      if (cutter_.on_cut(a) && cutter_.on_cut(b) && cutter_.on_cut(c)) out.push_back({rest.col(a), rest.col(b), rest.col(c)});
    }
  }
  return out;
}

bool CutSession::split_still_holds(const CarriedPoints& split, int input_points, const CutStepReport& step, const StructureEdges& edges,
                                   const std::vector<int>& region) const {
  // The points the split added sit on lips (crossings, cap centres); a step that changed
  // their tets may have moved the lips they were put on.
  for (int i = input_points; i < split.embedding.size(); ++i)
    if (std::binary_search(step.changed_tets.begin(), step.changed_tets.end(), split.embedding.tet[static_cast<std::size_t>(i)])) return false;
  for (const Triangle& face : new_cut_faces(step, region))
    if (edges.crossed_by(face)) return false;
  return true;
}

SplitStructure CutSession::tumour_split_from_input(int k) const {
  const auto i = static_cast<std::size_t>(k);
  const CutLips lips(cutter_.mesh(), region_tets(tumour_region_.at(i)));
  return split_surface(cutter_.mesh(), lips, tumour_input_[i].rest_World_mm, tumour_input_[i].embedding, tumour_input_tris_[i]);
}

SplitStructure CutSession::vessel_split_from_input() const {
  if (!vessel_input_) return {};
  const CutLips lips(cutter_.mesh(), region_tets(vessel_region_));
  return split_segments(cutter_.mesh(), lips, vessel_input_->rest_World_mm, vessel_input_->embedding, vessel_input_segments_);
}

void CutSession::split_structures(const CutStepReport& step, CutFrameReport& report) {
  // Each structure is split again from its uncut input only when this step's cut can have
  // changed the split: a new cut face an edge of it passes through, or a lip a point the
  // split added sits on. Otherwise (most steps of a cut round a tumour, every refinement
  // ahead of the blade) the split stands and its input points take the input's new
  // embedding (the split keeps the input points first, embedded as the input). Issue 20:
  // splitting again at every step that touched a structure's tets cost 2.8 ms a step
  // (p95 16 ms) of a refined ring cut, 0.03 ms now.
  const auto touched = [&](const std::vector<int>& region) {
    for (int t : step.changed_tets)
      if (std::binary_search(region.begin(), region.end(), cutter_.origin_tet(t))) return true;
    return false;
  };
  const auto keep_split = [](CarriedPoints& split, const CarriedPoints& input) {
    for (int i = 0; i < input.embedding.size(); ++i) {
      split.embedding.tet[static_cast<std::size_t>(i)] = input.embedding.tet[static_cast<std::size_t>(i)];
      split.embedding.weights.col(i) = input.embedding.weights.col(i);
    }
  };
  for (std::size_t k = 0; k < tumour_input_.size(); ++k) {
    if (!touched(tumour_region_[k])) continue;
    const int n_input = static_cast<int>(tumour_input_[k].rest_World_mm.cols());
    // A cap's centre sits on the lip nearest along its loop: any new lip may move it.
    if (tumour_caps_[k] == 0 && split_still_holds(tumours_[k], n_input, step, tumour_edges_[k], tumour_region_[k])) {
      keep_split(tumours_[k], tumour_input_[k]);
      continue;
    }
    SplitStructure s = tumour_split_from_input(static_cast<int>(k));
    tumours_[k].rest_World_mm = std::move(s.rest_World_mm);
    tumours_[k].embedding = std::move(s.embedding);
    tumour_tris_[k] = std::move(s.tris);
    tumour_edges_cut_[k] = s.crossed_edges;
    tumour_caps_[k] = s.caps;
  }
  if (vessel_input_ && touched(vessel_region_)) {
    const int n_input = static_cast<int>(vessel_input_->rest_World_mm.cols());
    if (split_still_holds(*vessels_, n_input, step, vessel_edges_, vessel_region_)) {
      keep_split(*vessels_, *vessel_input_);
    } else {
      SplitStructure s = vessel_split_from_input();
      vessels_->rest_World_mm = std::move(s.rest_World_mm);
      vessels_->embedding = std::move(s.embedding);
      vessel_segments_ = std::move(s.segments);
      vessel_node_source_ = std::move(s.source);
      vessel_segments_cut_ = s.crossed_edges;
    }
  }
  report.structure_edges_cut = vessel_segments_cut_;
  for (int n : tumour_edges_cut_) report.structure_edges_cut += n;
}

void CutSession::check_events(const BladeSegment& blade, const SweptSurface* sweep, CutFrameReport& report) {
  const TetMesh& mesh = cutter_.mesh();
  const Eigen::Matrix3Xd x = positions_World_mm();
  if (report.contact.touching) {
    for (std::size_t k = 0; k < tumours_.size(); ++k) {
      const Eigen::Matrix3Xd p = tumours_[k].embedding.apply(mesh, x);
      double best = 1e300;
      Eigen::Vector3d where = blade.tip_World_mm;
      for (const auto& t : tumour_tris_[k]) {
        Eigen::Vector3d on_blade;
        const double d = segment_triangle_distance(blade.tip_World_mm, blade.heel_World_mm, {p.col(t[0]), p.col(t[1]), p.col(t[2])}, &on_blade);
        if (d < best) {
          best = d;
          where = on_blade;
        }
      }
      if (best < settings_.tumour_margin_mm && !in_margin_[k]) {
        report.events.push_back({frame_, "margin_entered", tumours_[k].name, best, where});
      }
      in_margin_[k] = best < settings_.tumour_margin_mm;
      if (sweep && best == 0.0 && !tumour_cut_[k]) {
        report.events.push_back({frame_, "tumour_cut", tumours_[k].name, 0.0, where});
        tumour_cut_[k] = 1;
      }
    }
  }
  if (sweep && vessel_input_) {
    // The input segments (their end nodes stay embedded; a split segment's parts follow them).
    const Eigen::Matrix3Xd p = vessel_input_->embedding.apply(mesh, x);
    const auto tris = sweep->triangles();
    for (std::size_t s = 0; s < vessel_input_segments_.size(); ++s) {
      if (vessel_segment_crossed_[s]) continue;
      const auto [a, b] = vessel_input_segments_[s];
      for (const auto& t : tris) {
        double u = 0;
        if (segment_triangle_intersection(p.col(a), p.col(b), t, u)) {
          vessel_segment_crossed_[s] = 1;
          report.events.push_back({frame_, "vessel_crossed", vessels_->name + " segment " + std::to_string(s), 0.0,
                                   p.col(a) + u * (p.col(b) - p.col(a))});
          break;
        }
      }
    }
  }
}

void CutSession::absorb(CutFrameReport& report, const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  if (!report.cut.topology_changed) return;
  auto t0 = std::chrono::steady_clock::now();
  rebuild_model(report.cut, x, v, report);
  report.rebuild_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  for (std::size_t k = 0; k < tumour_input_.size(); ++k) reembed(tumour_input_[k], report.cut, tumour_region_[k]);
  if (vessel_input_) reembed(*vessel_input_, report.cut, vessel_region_);
  split_structures(report.cut, report);
  report.reembed_ms = ms_since(t0);
  surface_.update(cutter_.mesh(), report.cut.changed_tets);
  ++surface_version_;
}

CutFrameReport CutSession::apply_blade(const BladeSegment& blade, bool cutting_enabled) {
  ++frame_;
  CutFrameReport report;
  last_sweep_.reset();
  report.rebuild_ms = poll_build();
  const Eigen::Matrix3Xd x_now = positions_World_mm();
  surface_.refit(x_now);
  report.contact = surface_.contact(x_now, blade);
  const std::array<int, 3> entered = report.contact.triangle >= 0 ? surface_.slots()[static_cast<std::size_t>(report.contact.triangle)]
                                                                  : std::array<int, 3>{{-1, -1, -1}};
  if (cutting_enabled) {
    if (push_) {
      model_->remove_attachment(*push_);
      push_.reset();
    }
    if (!previous_cutting_) cutter_.begin_stroke();
    if (previous_blade_ && previous_cutting_) {
      SweptSurface sweep{*previous_blade_, blade, settings_.sweep_strips, {}};
      Eigen::Matrix3Xd x = positions_World_mm(), v = velocities_World_mm_s();
      if (x_at_blade_.cols() == x.cols()) {
        // Points of the blade inside the tissue move with their tet; points outside move with
        // the nearest point inside (no gap opens between the strips at the surface).
        const int n = settings_.sweep_strips;
        std::vector<Eigen::Vector3d> start(static_cast<std::size_t>(n) + 1), moved(static_cast<std::size_t>(n) + 1);
        std::vector<char> inside(static_cast<std::size_t>(n) + 1, 0);
        for (int i = 0; i <= n; ++i) {
          const double u = static_cast<double>(i) / n;
          start[static_cast<std::size_t>(i)] = (1 - u) * previous_blade_->tip_World_mm + u * previous_blade_->heel_World_mm;
          Eigen::Vector4d w;
          const int t = cutter_.locate(start[static_cast<std::size_t>(i)], x_at_blade_, w, i == 0);  // one refit for all points
          if (t >= 0 && w.minCoeff() >= -1e-9) {
            const auto& tet = cutter_.mesh().tets[static_cast<std::size_t>(t)];
            moved[static_cast<std::size_t>(i)].setZero();
            for (int k = 0; k < 4; ++k) moved[static_cast<std::size_t>(i)] += w[k] * x.col(tet[static_cast<std::size_t>(k)]);
            inside[static_cast<std::size_t>(i)] = 1;
          }
        }
        for (int i = 0; i <= n; ++i) {
          if (inside[static_cast<std::size_t>(i)]) continue;
          int nearest = -1;
          for (int j = 0; j <= n; ++j)
            if (inside[static_cast<std::size_t>(j)] && (nearest < 0 || std::abs(j - i) < std::abs(nearest - i))) nearest = j;
          moved[static_cast<std::size_t>(i)] = start[static_cast<std::size_t>(i)] +
              (nearest < 0 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(moved[static_cast<std::size_t>(nearest)] - start[static_cast<std::size_t>(nearest)]));
        }
        sweep.from_points = moved;
      }
      // A blade that moves along itself (plunging in, lifting out) sweeps no area: the strip
      // between its carried previous position and the new one would only be noise. So is a
      // plunge while the tissue moves a little across the blade: that strip's normal is set
      // by the tissue's motion, and the vertices around would take their side of the cut
      // from it (a vertex 13 mm outside the liver ring took the inside's side from the XPBD
      // organ swaying during the plunge: a hole in the ring). A sweep counts when the motion
      // across the blade exceeds min_sweep_mm and a quarter of the motion along it.
      double moved = 0.0, along = 0.0;
      const Eigen::Vector3d dir = (blade.heel_World_mm - blade.tip_World_mm).normalized();
      for (std::size_t i = 0; i < sweep.from_points.size(); ++i) {
        const double u = static_cast<double>(i) / settings_.sweep_strips;
        const Eigen::Vector3d d = sweep.from_points[i] - ((1 - u) * blade.tip_World_mm + u * blade.heel_World_mm);
        moved = std::max(moved, (d - d.dot(dir) * dir).norm());
        along = std::max(along, std::abs(d.dot(dir)));
      }
      if (sweep.from_points.empty()) {
        for (const auto& d : {Eigen::Vector3d(previous_blade_->tip_World_mm - blade.tip_World_mm), Eigen::Vector3d(previous_blade_->heel_World_mm - blade.heel_World_mm)}) {
          moved = std::max(moved, (d - d.dot(dir) * dir).norm());
          along = std::max(along, std::abs(d.dot(dir)));
        }
      }
      if (moved > settings_.min_sweep_mm && moved > 0.25 * along) {
        last_sweep_ = sweep;
        report.cut = cutter_.step(sweep, x, v);
        absorb(report, x, v);
      }
      check_events(blade, &sweep, report);
    } else {
      check_events(blade, nullptr, report);
    }
  } else {
    if (previous_cutting_) {  // the stroke ends: complete what the blade has left
      Eigen::Matrix3Xd x = positions_World_mm(), v = velocities_World_mm_s();
      report.cut = cutter_.finish_stroke(x, v);
      absorb(report, x, v);
    }
    // Contact: the blade pushes the surface point it entered towards its tip.
    bool pushable = false;  // the entered triangle's vertices exist in the model (a new one may still be building)
    if (entered[0] >= 0) pushable = std::max({entered[0], entered[1], entered[2]}) < static_cast<int>(model_->positions_World_mm().cols());
    if (report.contact.tip_inside && (push_ || pushable)) {
      if (!push_) {
        const auto& t = entered;
        const Eigen::Matrix3Xd& x = x_now;
        const Eigen::Vector3d a = x.col(t[0]), b = x.col(t[1]), c = x.col(t[2]), p = report.contact.point_World_mm;
        const Eigen::Vector3d n = (b - a).cross(c - a);
        const double area2 = n.squaredNorm();
        const double wa = n.dot((b - p).cross(c - p)) / area2, wb = n.dot((c - p).cross(a - p)) / area2;
        AttachmentSpec spec;
        spec.point.vertices = {t[0], t[1], t[2]};
        spec.point.weights = {wa, wb, 1.0 - wa - wb};
        spec.target_World_mm = blade.tip_World_mm;
        spec.stiffness_mN_per_mm = settings_.push_stiffness_mN_per_mm;
        push_spec_ = spec;
        push_ = model_->add_attachment(spec);
      } else {
        push_spec_.target_World_mm = blade.tip_World_mm;
        model_->set_attachment_target(*push_, blade.tip_World_mm);
      }
    } else if (push_) {
      model_->remove_attachment(*push_);
      push_.reset();
    }
    report.pushing = push_.has_value();
    check_events(blade, nullptr, report);
  }
  previous_blade_ = blade;
  previous_cutting_ = cutting_enabled;
  x_at_blade_ = positions_World_mm();
  return report;
}

std::unique_ptr<CutSession> make_cut_session(const Scene& scene, const ModelConfig& config, const CutSessionSettings& settings) {
  std::vector<CarriedPoints> tumours;
  std::vector<std::vector<std::array<int, 3>>> tumour_tris;
  for (const auto& t : scene.tumours) {
    tumours.push_back({t.name, t.rest.positions_World_mm, t.embedding});
    tumour_tris.push_back(t.rest.tris);
  }
  std::optional<CarriedPoints> vessels;
  std::vector<std::array<int, 2>> segments;
  if (scene.vessels) {
    vessels = CarriedPoints{"vessels", scene.vessels->rest.nodes_World_mm, scene.vessels->embedding};
    segments = scene.vessels->rest.segments;
  }
  return std::make_unique<CutSession>(scene.problem, config, settings, tumours, tumour_tris, vessels, segments);
}

CutSessionSettings cut_settings_from(const CuttingSpec& spec) {
  CutSessionSettings settings;
  settings.cut.snap_fraction = spec.snap_fraction;
  settings.cut.path_tolerance_mm = spec.path_tolerance_mm;
  settings.cut.chord_sagitta_mm = spec.chord_sagitta_mm;
  settings.cut.min_refined_edge_mm = spec.min_refined_edge_mm;
  settings.min_dihedral_deg = spec.min_dihedral_deg;
  settings.sweep_strips = spec.sweep_strips;
  settings.tumour_margin_mm = spec.tumour_margin_mm;
  settings.push_stiffness_mN_per_mm = spec.push_stiffness_mN_per_mm;
  return settings;
}

}  // namespace arnav::host::cut
