#include "host/sim/attachment_set.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace arnav::host {

namespace {
void check_stiffness(double k) {
  if (!(k > 0.0) || !std::isfinite(k)) {
    throw std::invalid_argument("attachment stiffness must be finite and > 0 mN/mm (got " + std::to_string(k) + ")");
  }
}
void check_target(const Eigen::Vector3d& t) {
  if (!t.allFinite()) throw std::invalid_argument("attachment target is not finite");
}
}  // namespace

AttachmentId AttachmentSet::add(const AttachmentSpec& spec, const Eigen::Matrix3Xd& x_World_mm, double& work) {
  const int num_vertices = static_cast<int>(x_World_mm.cols());
  const auto& p = spec.point;
  if (p.vertices.empty() || p.vertices.size() > 4 || p.vertices.size() != p.weights.size()) {
    throw std::invalid_argument("attachment material point needs 1 to 4 vertices with one weight each (got " +
                                std::to_string(p.vertices.size()) + " vertices, " + std::to_string(p.weights.size()) +
                                " weights)");
  }
  Attachment a;
  a.count = static_cast<int>(p.vertices.size());
  double sum = 0.0;
  for (int i = 0; i < a.count; ++i) {
    if (p.vertices[i] < 0 || p.vertices[i] >= num_vertices) {
      throw std::invalid_argument("attachment vertex " + std::to_string(p.vertices[i]) + " is outside the mesh (0.." +
                                  std::to_string(num_vertices - 1) + ")");
    }
    a.vertices[i] = p.vertices[i];
    a.weights[i] = p.weights[i];
    sum += p.weights[i];
  }
  if (!(std::abs(sum - 1.0) < 1e-6)) {
    throw std::invalid_argument("attachment barycentric weights must sum to 1 (got " + std::to_string(sum) + ")");
  }
  check_target(spec.target_World_mm);
  check_stiffness(spec.stiffness_mN_per_mm);
  a.target_World_mm = spec.target_World_mm;
  a.stiffness_mN_per_mm = spec.stiffness_mN_per_mm;
  items_.push_back(a);
  const int id = static_cast<int>(items_.size()) - 1;
  active_.push_back(id);
  work = spring_energy(id, x_World_mm);
  return id;
}

Attachment& AttachmentSet::checked(AttachmentId id, const char* what) {
  if (std::find(active_.begin(), active_.end(), id) == active_.end()) {
    throw std::invalid_argument(std::string(what) + ": no active attachment with id " + std::to_string(id));
  }
  return items_[static_cast<std::size_t>(id)];
}

double AttachmentSet::set_target(AttachmentId id, const Eigen::Vector3d& target_World_mm, const Eigen::Matrix3Xd& x_World_mm) {
  check_target(target_World_mm);
  checked(id, "set_attachment_target");
  const double before = spring_energy(id, x_World_mm);
  items_[static_cast<std::size_t>(id)].target_World_mm = target_World_mm;
  return spring_energy(id, x_World_mm) - before;
}

double AttachmentSet::set_stiffness(AttachmentId id, double stiffness_mN_per_mm, const Eigen::Matrix3Xd& x_World_mm) {
  check_stiffness(stiffness_mN_per_mm);
  checked(id, "set_attachment_stiffness");
  const double before = spring_energy(id, x_World_mm);
  items_[static_cast<std::size_t>(id)].stiffness_mN_per_mm = stiffness_mN_per_mm;
  return spring_energy(id, x_World_mm) - before;
}

double AttachmentSet::remove(AttachmentId id, const Eigen::Matrix3Xd& x_World_mm) {
  checked(id, "remove_attachment");
  active_.erase(std::find(active_.begin(), active_.end(), id));
  return -spring_energy(id, x_World_mm);
}

double AttachmentSet::spring_energy(AttachmentId id, const Eigen::Matrix3Xd& x_World_mm) const {
  const Attachment& a = items_[static_cast<std::size_t>(id)];
  return 0.5 * a.stiffness_mN_per_mm * (a.point(x_World_mm) - a.target_World_mm).squaredNorm();
}

double AttachmentSet::energy(const Eigen::Matrix3Xd& x_World_mm) const {
  double e = 0.0;
  for (int id : active_) {
    const Attachment& a = items_[static_cast<std::size_t>(id)];
    e += 0.5 * a.stiffness_mN_per_mm * (a.point(x_World_mm) - a.target_World_mm).squaredNorm();
  }
  return e;
}

}  // namespace arnav::host
