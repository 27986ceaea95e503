#include "host/cut/surface_tracker.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace arnav::host::cut {

namespace {
// Faces of a positively oriented tet (v0, v1, v2, v3) with outward normals (as boundary_faces).
constexpr const auto& kFaces = kTetFaces;
constexpr int kVertexBits = 21;  // three ids in one 64-bit key
const std::array<int, 3> kEmpty{{-1, -1, -1}};
}  // namespace

std::uint64_t SurfaceTracker::key(std::array<int, 3> f) {
  std::sort(f.begin(), f.end());
  if (f[0] < 0 || f[2] >= (1 << kVertexBits))
    throw std::invalid_argument("surface tracker: vertex index " + std::to_string(f[2]) + " out of range (at most 2^21 vertices)");
  return (static_cast<std::uint64_t>(f[0]) << (2 * kVertexBits)) | (static_cast<std::uint64_t>(f[1]) << kVertexBits) |
         static_cast<std::uint64_t>(f[2]);
}

SurfaceTracker::SurfaceTracker(const TetMesh& mesh) {
  faces_.reserve(mesh.tets.size() * 2 + 16);
  std::vector<int> all(mesh.tets.size());
  for (std::size_t t = 0; t < all.size(); ++t) all[t] = static_cast<int>(t);
  update(mesh, all);
  added_.clear();
}

int SurfaceTracker::new_slot(const std::array<int, 3>& face) {
  slots_.push_back(face);
  ++live_;
  added_.push_back(static_cast<int>(slots_.size()) - 1);
  tris_dirty_ = true;
  return static_cast<int>(slots_.size()) - 1;
}

void SurfaceTracker::clear_slot(int slot) {
  slots_[static_cast<std::size_t>(slot)] = kEmpty;
  if (static_cast<std::size_t>(slot) < boxes_.size()) boxes_[static_cast<std::size_t>(slot)] = Aabb{};
  --live_;
  tris_dirty_ = true;
}

void SurfaceTracker::add_face(const std::array<int, 3>& oriented, int tet) {
  Entry& e = faces_[key(oriented)];
  if (e.count < 2) {
    e.owners[static_cast<std::size_t>(e.count)] = tet;
    e.oriented[static_cast<std::size_t>(e.count)] = oriented;
  }
  ++e.count;
  if (e.count == 1) {
    e.slot = new_slot(oriented);
  } else if (e.slot >= 0) {  // now interior
    clear_slot(e.slot);
    e.slot = -1;
  }
}

void SurfaceTracker::remove_face(const std::array<int, 3>& oriented, int tet) {
  const auto it = faces_.find(key(oriented));
  if (it == faces_.end()) throw std::logic_error("surface tracker: a changed tet's old face is unknown");
  Entry& e = it->second;
  if (e.owners[1] == tet) {
    e.owners[1] = -1;
  } else if (e.owners[0] == tet) {
    e.owners[0] = e.owners[1];
    e.oriented[0] = e.oriented[1];
    e.owners[1] = -1;
  }
  --e.count;
  if (e.count == 0) {
    if (e.slot >= 0) clear_slot(e.slot);
    faces_.erase(it);
  } else if (e.count == 1 && e.slot < 0) {  // the remaining tet's face is boundary now
    e.slot = new_slot(e.oriented[0]);
  }
}

void SurfaceTracker::update(const TetMesh& mesh, const std::vector<int>& changed_tets) {
  std::vector<int> changed = changed_tets;
  std::sort(changed.begin(), changed.end());
  changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
  for (int t : changed) {  // old faces out (all of them before any new one comes in)
    if (t < 0 || t >= mesh.num_tets()) throw std::invalid_argument("surface tracker: changed tet " + std::to_string(t) + " is not in the mesh");
    if (static_cast<std::size_t>(t) >= tets_.size() || tets_[static_cast<std::size_t>(t)][0] < 0) continue;
    const auto& tet = tets_[static_cast<std::size_t>(t)];
    for (const auto& f : kFaces) remove_face({tet[static_cast<std::size_t>(f[0])], tet[static_cast<std::size_t>(f[1])], tet[static_cast<std::size_t>(f[2])]}, t);
  }
  if (tets_.size() < mesh.tets.size()) tets_.resize(mesh.tets.size(), {{-1, -1, -1, -1}});
  for (int t : changed) {  // new faces in
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    tets_[static_cast<std::size_t>(t)] = tet;
    for (const auto& f : kFaces) add_face({tet[static_cast<std::size_t>(f[0])], tet[static_cast<std::size_t>(f[1])], tet[static_cast<std::size_t>(f[2])]}, t);
  }
}

const std::vector<std::array<int, 3>>& SurfaceTracker::tris() {
  if (tris_dirty_) {
    tris_.clear();
    tris_.reserve(static_cast<std::size_t>(live_));
    for (const auto& f : slots_)
      if (f[0] >= 0) tris_.push_back(f);
    tris_dirty_ = false;
  }
  return tris_;
}

std::vector<int> SurfaceTracker::take_added_slots() {
  std::vector<int> out;
  out.swap(added_);
  // Slots emptied again since they were added are not reported.
  out.erase(std::remove_if(out.begin(), out.end(), [&](int s) { return slots_[static_cast<std::size_t>(s)][0] < 0; }), out.end());
  return out;
}

void SurfaceTracker::rebuild(const Eigen::Matrix3Xd& x) {
  // Compact: live faces keep their order; the face entries and pending added slots follow.
  std::vector<int> new_index(slots_.size(), -1);
  std::vector<std::array<int, 3>> compact;
  compact.reserve(static_cast<std::size_t>(live_));
  for (std::size_t s = 0; s < slots_.size(); ++s)
    if (slots_[s][0] >= 0) {
      new_index[s] = static_cast<int>(compact.size());
      compact.push_back(slots_[s]);
    }
  for (auto& [k, e] : faces_)
    if (e.slot >= 0) e.slot = new_index[static_cast<std::size_t>(e.slot)];
  std::vector<int> added;
  for (int s : added_)
    if (new_index[static_cast<std::size_t>(s)] >= 0) added.push_back(new_index[static_cast<std::size_t>(s)]);
  added_ = std::move(added);
  slots_ = std::move(compact);
  boxes_ = triangle_boxes(slots_, x);
  bvh_.build(boxes_);
  built_ = static_cast<int>(slots_.size());
  ++rebuilds_;
}

void SurfaceTracker::refit(const Eigen::Matrix3Xd& x) {
  const int overflow = static_cast<int>(slots_.size()) - built_;
  const int empty = static_cast<int>(slots_.size()) - live_;
  if (built_ == 0 || overflow > std::max(64, built_ / 8) || 2 * empty > static_cast<int>(slots_.size())) {
    rebuild(x);
    return;
  }
  boxes_.resize(slots_.size());
  for (std::size_t s = 0; s < slots_.size(); ++s) {
    Aabb b;
    if (slots_[s][0] >= 0)
      for (int v : slots_[s]) b.extend(Eigen::Vector3d(x.col(v)));
    boxes_[s] = b;
  }
  bvh_.refit(std::vector<Aabb>(boxes_.begin(), boxes_.begin() + built_));
}

void SurfaceTracker::query(const Aabb& box, const std::function<void(int)>& visit) const {
  bvh_.query(box, [&](int s) {
    if (slots_[static_cast<std::size_t>(s)][0] >= 0) visit(s);
  });
  for (std::size_t s = static_cast<std::size_t>(built_); s < slots_.size() && s < boxes_.size(); ++s)
    if (slots_[s][0] >= 0 && boxes_[s].overlaps(box)) visit(static_cast<int>(s));
}

Contact SurfaceTracker::contact(const Eigen::Matrix3Xd& x, const BladeSegment& blade) const {
  return blade_contact([this](const Aabb& box, const std::function<void(int)>& visit) { query(box, visit); }, slots_, x, blade);
}

}  // namespace arnav::host::cut
