#pragma once
// Attachments shared by the tissue models: zero-rest-length springs from a barycentric
// material point to a target in World (tool grasp, registration correspondence).
// Nothing is allocated until the first attachment is added. Units: mm, mN/mm.
#include <Eigen/Core>

#include <array>
#include <vector>

#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct Attachment {
  int count = 0;                         // vertices in use (1..4)
  std::array<int, 4> vertices{};
  std::array<double, 4> weights{};
  Eigen::Vector3d target_World_mm = Eigen::Vector3d::Zero();
  double stiffness_mN_per_mm = 0.0;
  Eigen::Vector3d lambda = Eigen::Vector3d::Zero();  // XPBD Lagrange multiplier (mN*s^2)

  Eigen::Vector3d point(const Eigen::Matrix3Xd& x_World_mm) const {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int i = 0; i < count; ++i) p += weights[i] * x_World_mm.col(vertices[i]);
    return p;
  }
};

class AttachmentSet {
 public:
  // Each mutator returns the external work it does: the change of spring energy at the
  // current positions x_World_mm (for the energy ledger).
  // add validates the spec (vertex indices in range, 1..4 vertices, weights summing to 1,
  // finite target, positive stiffness); all throw std::invalid_argument naming the problem.
  AttachmentId add(const AttachmentSpec& spec, const Eigen::Matrix3Xd& x_World_mm, double& work);
  double set_target(AttachmentId id, const Eigen::Vector3d& target_World_mm, const Eigen::Matrix3Xd& x_World_mm);
  double set_stiffness(AttachmentId id, double stiffness_mN_per_mm, const Eigen::Matrix3Xd& x_World_mm);
  double remove(AttachmentId id, const Eigen::Matrix3Xd& x_World_mm);

  // Active attachments (ids are not reused; removed ones are skipped).
  const std::vector<int>& active() const { return active_; }
  Attachment& operator[](int id) { return items_[static_cast<std::size_t>(id)]; }
  const Attachment& operator[](int id) const { return items_[static_cast<std::size_t>(id)]; }

  // 0.5 k |p - target|^2 of one attachment (mN*mm).
  double spring_energy(AttachmentId id, const Eigen::Matrix3Xd& x_World_mm) const;
  // Sum of 0.5 k |p - target|^2 over active attachments (mN*mm).
  double energy(const Eigen::Matrix3Xd& x_World_mm) const;

 private:
  Attachment& checked(AttachmentId id, const char* what);
  std::vector<Attachment> items_;
  std::vector<int> active_;
};

}  // namespace arnav::host
