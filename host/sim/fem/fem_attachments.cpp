#include "host/sim/fem/fem_attachments.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "host/sim/step_health.hpp"

namespace arnav::host::fem {

namespace {
void check_target(const Eigen::Vector3d& target_World_mm, const std::string& model) {
  if (!target_World_mm.allFinite()) throw std::invalid_argument(model + ": non-finite attachment target");
}
void check_stiffness(double stiffness_mN_per_mm, const std::string& model) {
  if (!(stiffness_mN_per_mm >= 0.0) || !std::isfinite(stiffness_mN_per_mm)) {
    throw std::invalid_argument(model + ": attachment stiffness must be finite and >= 0 mN/mm");
  }
}
}  // namespace

AttachmentId FemAttachmentSet::add(const AttachmentSpec& spec, int num_vertices, const SymmetricPattern& pattern,
                                   bool& needs_new_pattern) {
  const std::string who = model_ + ": attachment " + std::to_string(items_.size());
  const auto& p = spec.point;
  if (p.vertices.empty() || p.vertices.size() != p.weights.size()) {
    throw std::invalid_argument(who + " needs as many weights as vertices (and at least one)");
  }
  check_vertex_indices(p.vertices, num_vertices, who.c_str());
  for (double w : p.weights) {
    if (!std::isfinite(w)) throw std::invalid_argument(who + " has a non-finite weight");
  }
  if (!(spec.stiffness_mN_per_mm >= 0.0) || !std::isfinite(spec.stiffness_mN_per_mm) || !spec.target_World_mm.allFinite()) {
    throw std::invalid_argument(who + " needs a finite stiffness >= 0 mN/mm and a finite target");
  }
  std::vector<int> sorted = p.vertices;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
    throw std::invalid_argument(who + " lists a vertex twice");
  }
  items_.push_back(FemAttachment{spec, {}});
  // New couplings need a new symbolic analysis (rare: an attachment spans one tet).
  needs_new_pattern = !pattern.covers(p.vertices);
  if (!needs_new_pattern) items_.back()->map = pattern.block_map(p.vertices);
  return static_cast<AttachmentId>(items_.size() - 1);
}

FemAttachment& FemAttachmentSet::checked(AttachmentId id) {
  if (id < 0 || id >= static_cast<int>(items_.size()) || !items_[static_cast<std::size_t>(id)]) {
    throw std::invalid_argument(model_ + ": no attachment with id " + std::to_string(id));
  }
  return *items_[static_cast<std::size_t>(id)];
}

void FemAttachmentSet::set_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) {
  check_target(target_World_mm, model_);
  checked(id).spec.target_World_mm = target_World_mm;
}

void FemAttachmentSet::set_stiffness(AttachmentId id, double stiffness_mN_per_mm) {
  check_stiffness(stiffness_mN_per_mm, model_);
  checked(id).spec.stiffness_mN_per_mm = stiffness_mN_per_mm;
}

void FemAttachmentSet::remove(AttachmentId id) {
  checked(id);
  items_[static_cast<std::size_t>(id)].reset();
}

void FemAttachmentSet::append_groups(std::vector<std::vector<int>>& groups) const {
  for (const auto& a : items_)
    if (a) groups.push_back(a->spec.point.vertices);
}

void FemAttachmentSet::map_into(const SymmetricPattern& pattern) {
  for (auto& a : items_)
    if (a) a->map = pattern.block_map(a->spec.point.vertices);
}

bool FemAttachmentSet::any() const {
  return std::any_of(items_.begin(), items_.end(), [](const auto& a) { return a.has_value(); });
}

double FemAttachmentSet::energy(const Eigen::Matrix3Xd& x_World_mm) const {
  double e = 0.0;
  for (const auto& a : items_) {
    if (!a) continue;
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < a->spec.point.vertices.size(); ++i)
      p += a->spec.point.weights[i] * x_World_mm.col(a->spec.point.vertices[i]);
    e += 0.5 * a->spec.stiffness_mN_per_mm * (a->spec.target_World_mm - p).squaredNorm();
  }
  return e;
}

}  // namespace arnav::host::fem
