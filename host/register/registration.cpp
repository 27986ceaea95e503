#include "host/register/registration.hpp"

#include <chrono>

namespace arnav::host {

RegistrationResult register_patient(const Scene& scene, const RegistrationRequest& rq) {
  const auto t0 = std::chrono::steady_clock::now();
  RegistrationResult r;
  r.x_Model_mm = scene.problem.mesh.rest_positions_World_mm;
  Eigen::Isometry3d start = Eigen::Isometry3d::Identity();
  r.initialisation = "identity";
  if (!rq.landmarks.empty()) {
    r.landmarks = register_landmarks(rq.landmarks);
    start = r.landmarks->X_IntraopModel;
    r.initialisation = "landmarks";
  }
  if (rq.X_IntraopModel_initial) {
    start = *rq.X_IntraopModel_initial;
    r.initialisation = "initial pose";
  }
  r.X_IntraopModel = start;
  r.icp = icp_point_to_plane(scene.organ_surface.positions_World_mm, scene.organ_surface.tris, rq.points_Intraop_mm, rq.normals_Intraop,
                             start, rq.icp);
  if (r.icp.summary.termination == "no data") {
    r.notes.push_back("no surface points: the rigid result is the " + r.initialisation + " pose");
  } else if (r.icp.summary.termination.rfind("too few inliers", 0) == 0 || r.icp.summary.termination == "numerical failure") {
    r.notes.push_back("surface ICP failed (" + r.icp.summary.termination + "): the rigid result is the " + r.initialisation + " pose");
  } else {
    r.X_IntraopModel = r.icp.X_IntraopModel;
  }
  if (!rq.rigid_only) {
    const Eigen::Matrix3Xd data_Model = r.X_IntraopModel.inverse() * rq.points_Intraop_mm;
    std::vector<LandmarkPair> lm;
    for (const auto& l : rq.landmarks) lm.push_back({l.p_Model_mm, r.X_IntraopModel.inverse() * l.p_Intraop_mm});
    r.nonrigid = register_nonrigid(scene, data_Model, lm, rq.nonrigid);
    r.notes.push_back("non-rigid: " + r.nonrigid->message);
    if (r.nonrigid->accepted) {
      r.x_Model_mm = r.nonrigid->x_Model_mm;
      r.deformed = true;
    }
  }
  r.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

Eigen::Matrix3Xd carry_to_intraop(const Scene& scene, const Embedding& embedding, const RegistrationResult& result) {
  return result.X_IntraopModel * embedding.apply(scene.problem.mesh, result.x_Model_mm);
}

}  // namespace arnav::host
