#include "host/app/grasp_coupling.hpp"

#include <algorithm>
#include <cstdio>

namespace arnav::host {

GraspCoupling::GraspCoupling(const GrasperRole& role, const Scene& scene) : role_(role), scene_(scene) {}

void GraspCoupling::release(GraspBody& model, const std::string& why) {
  if (!status_.grasping) return;
  for (const int id : ids_) model.remove_attachment(id);
  char text[240];
  std::snprintf(text, sizeof text, "grasper '%s' released %d vertices (%s; tip moved %.1f mm while grasping)", role_.name.c_str(),
                status_.attached_vertices, why.c_str(), status_.tip_travel_mm);
  status_.messages.emplace_back(text);
  ids_.clear();
  grasped_.clear();
  start_Model_mm.clear();
  status_.grasping = false;
  status_.attached_vertices = 0;
  status_.tip_travel_mm = 0.0;
}

void GraspCoupling::apply(GraspBody& model, const GraspCommand& cmd, std::int64_t now_us) {
  const bool fresh = cmd.X_ModelTool && cmd.pose_time_us >= 0 &&
                     static_cast<double>(now_us - cmd.pose_time_us) <= role_.stale_after_ms * 1000.0;
  status_.stale = !fresh;
  if (status_.grasping && !fresh) {
    char why[160];
    if (cmd.X_ModelTool)
      std::snprintf(why, sizeof why, "grasper pose %.0f ms old, limit %.0f ms", static_cast<double>(now_us - cmd.pose_time_us) * 1e-3,
                    role_.stale_after_ms);
    else
      std::snprintf(why, sizeof why, "grasper pose lost");
    release(model, std::string("STALE: ") + why);
    ++status_.stale_releases;
  }
  if (status_.grasping && !cmd.requested) {
    release(model, cmd.why_not.empty() ? std::string("grasp released") : cmd.why_not);
    ++status_.releases;
  }
  if (!cmd.requested) refused_episode_ = false;
  if (!fresh || !cmd.requested) return;

  const Eigen::Vector3d tip_Model_mm = *cmd.X_ModelTool * role_.tip_Tool_mm;
  if (!status_.grasping) {
    // Grasp start: the organ surface vertices within radius of the tip, where the model has them now.
    const TetMesh& mesh = scene_.problem.mesh;
    const Eigen::Matrix3Xd surface = scene_.organ_embedding.apply(mesh, model.positions_World_mm());
    std::vector<int> picked;
    double nearest = 1e300;
    for (Eigen::Index i = 0; i < surface.cols(); ++i) {
      const double d = (surface.col(i) - tip_Model_mm).norm();
      nearest = std::min(nearest, d);
      if (d <= role_.radius_mm) picked.push_back(static_cast<int>(i));
    }
    if (picked.empty()) {
      if (!refused_episode_) {
        ++status_.refused;
        refused_episode_ = true;
        char text[200];
        std::snprintf(text, sizeof text, "grasper '%s': no grasp, the tip is %.1f mm from the organ surface (radius %.1f mm)", role_.name.c_str(),
                      nearest, role_.radius_mm);
        status_.messages.emplace_back(text);
      }
      return;
    }
    refused_episode_ = false;
    grasped_ = std::move(picked);
    X_ModelToolStart_ = *cmd.X_ModelTool;
    for (const int v : grasped_) {
      AttachmentSpec spec;
      spec.point = scene_.organ_embedding.material_point(mesh, v);
      spec.target_World_mm = surface.col(v);
      spec.stiffness_mN_per_mm = role_.stiffness_mN_per_mm;
      start_Model_mm.push_back(surface.col(v));
      ids_.push_back(model.add_attachment(spec));
    }
    status_.grasping = true;
    status_.attached_vertices = static_cast<int>(grasped_.size());
    ++status_.grasps;
    char text[200];
    std::snprintf(text, sizeof text, "grasper '%s' grasped %d surface vertices within %.1f mm of the tip at [%.1f, %.1f, %.1f] mm in Model",
                  role_.name.c_str(), status_.attached_vertices, role_.radius_mm, tip_Model_mm.x(), tip_Model_mm.y(), tip_Model_mm.z());
    status_.messages.emplace_back(text);
  }
  // Follow: the grasped points move rigidly with the tool since grasp start.
  const Eigen::Isometry3d motion = *cmd.X_ModelTool * X_ModelToolStart_.inverse();
  for (std::size_t i = 0; i < ids_.size(); ++i) model.set_attachment_target(ids_[i], motion * start_Model_mm[i]);
  status_.tip_travel_mm = (tip_Model_mm - X_ModelToolStart_ * role_.tip_Tool_mm).norm();
  status_.max_tip_travel_mm = std::max(status_.max_tip_travel_mm, status_.tip_travel_mm);
  ++status_.steps_grasping;
}

}  // namespace arnav::host
