#pragma once
// Attachments of the implicit FEM models (co-rotational and stable Neo-Hookean): the spec
// kept as given plus its block map into the sparse pattern. The checks every FEM model
// applies before accepting or changing one; messages name the model and the problem.
// Units: mm, mN/mm.
#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "host/sim/step_health.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host::fem {

struct FemAttachment {
  AttachmentSpec spec;
  std::vector<int> map;  // block map into the symmetric pattern
};
using FemAttachments = std::vector<std::optional<FemAttachment>>;

// A new attachment: at least one vertex, one finite weight per vertex, no vertex twice,
// indices in the mesh, a finite stiffness >= 0 (0: inactive spring) and a finite target.
inline void check_new_attachment(const AttachmentSpec& spec, int num_vertices, const std::string& who) {
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
}

inline void check_attachment_target(const Eigen::Vector3d& target_World_mm, const char* model) {
  if (!target_World_mm.allFinite()) throw std::invalid_argument(std::string(model) + ": non-finite attachment target");
}

inline void check_attachment_stiffness(double stiffness_mN_per_mm, const char* model) {
  if (!(stiffness_mN_per_mm >= 0.0) || !std::isfinite(stiffness_mN_per_mm)) {
    throw std::invalid_argument(std::string(model) + ": attachment stiffness must be finite and >= 0 mN/mm");
  }
}

// The live attachment with this id, or std::invalid_argument naming the model.
inline FemAttachment& checked_attachment(FemAttachments& attachments, AttachmentId id, const char* model) {
  if (id < 0 || id >= static_cast<int>(attachments.size()) || !attachments[static_cast<std::size_t>(id)]) {
    throw std::invalid_argument(std::string(model) + ": no attachment with id " + std::to_string(id));
  }
  return *attachments[static_cast<std::size_t>(id)];
}

}  // namespace arnav::host::fem
