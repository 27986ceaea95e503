#pragma once
// Attachments of the implicit FEM models (co-rotational and stable Neo-Hookean): zero-rest-
// length springs from a material point to a target, each kept as given plus its block map into
// the sparse pattern. One set serves both models: the checks before accepting or changing an
// attachment, the pattern groups and maps, and the spring energy. Units: mm, mN/mm, mN*mm.
#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

#include "host/sim/fem/symmetric_pattern.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host::fem {

struct FemAttachment {
  AttachmentSpec spec;
  std::vector<int> map;  // block map into the symmetric pattern
};

class FemAttachmentSet {
 public:
  // `model` names the model in the messages of std::invalid_argument.
  explicit FemAttachmentSet(std::string model) : model_(std::move(model)) {}

  // Checks the spec (at least one vertex, one finite weight each, no vertex twice, indices in
  // the mesh, finite stiffness >= 0 (0: inactive spring), finite target) and adds it. When
  // `pattern` already couples its vertices its block map is filled and needs_new_pattern is
  // false; otherwise the caller builds a new pattern (append_groups, then map_into).
  AttachmentId add(const AttachmentSpec& spec, int num_vertices, const SymmetricPattern& pattern, bool& needs_new_pattern);
  void set_target(AttachmentId id, const Eigen::Vector3d& target_World_mm);
  void set_stiffness(AttachmentId id, double stiffness_mN_per_mm);
  void remove(AttachmentId id);  // the id is not reused; the pattern keeps its entries

  // The vertex groups the pattern must couple, and the block maps once it does.
  void append_groups(std::vector<std::vector<int>>& groups) const;
  void map_into(const SymmetricPattern& pattern);

  bool any() const;
  // Sum of 0.5 k |p - target|^2 over the live attachments at positions x (mN*mm).
  double energy(const Eigen::Matrix3Xd& x_World_mm) const;

  // Every slot, removed ones empty (std::nullopt).
  auto begin() const { return items_.begin(); }
  auto end() const { return items_.end(); }

 private:
  FemAttachment& checked(AttachmentId id);
  std::vector<std::optional<FemAttachment>> items_;
  std::string model_;
};

}  // namespace arnav::host::fem
