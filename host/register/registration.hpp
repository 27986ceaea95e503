#pragma once
// The registration pipeline shared by arnav-register and arnav-bench register:
// landmarks (paired points) -> surface rigid (ICP) -> non-rigid (tissue model), each stage
// optional, with the summaries every report needs. Frames: Model (the scene frame World)
// and Intraop (the frame of the intraoperative data). X_IntraopModel maps Model into
// Intraop. Units: mm.
#include <Eigen/Geometry>

#include <optional>
#include <string>
#include <vector>

#include "host/register/nonrigid_registration.hpp"
#include "host/register/point_files.hpp"
#include "host/register/rigid_registration.hpp"
#include "host/scene/embedding.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {

struct RegistrationRequest {
  Eigen::Matrix3Xd points_Intraop_mm;                 // the intraoperative surface points
  Eigen::Matrix3Xd normals_Intraop;                   // unit normals, or 0 columns
  std::vector<Landmark> landmarks;                    // empty, or >= 3
  std::optional<Eigen::Isometry3d> X_IntraopModel_initial;  // wins over the landmark fit as ICP start
  bool rigid_only = false;
  IcpOptions icp;
  NonrigidOptions nonrigid;
};

struct RegistrationResult {
  std::string initialisation;                         // "landmarks", "initial pose", "identity"
  std::optional<LandmarkFit> landmarks;
  IcpResult icp;                                      // termination "no data" when skipped
  Eigen::Isometry3d X_IntraopModel = Eigen::Isometry3d::Identity();  // the rigid part
  std::optional<NonrigidResult> nonrigid;             // absent with rigid_only
  Eigen::Matrix3Xd x_Model_mm;                        // volume positions in Model (rest when rigid)
  bool deformed = false;                              // the non-rigid result was accepted
  double wall_time_s = 0.0;
  std::vector<std::string> notes;                     // what was decided and why
};

RegistrationResult register_patient(const Scene& scene, const RegistrationRequest& request);

// Points given in Model at rest, embedded in the scene's volume, carried through the
// registration into Intraop.
Eigen::Matrix3Xd carry_to_intraop(const Scene& scene, const Embedding& embedding, const RegistrationResult& result);

}  // namespace arnav::host
