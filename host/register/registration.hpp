#pragma once
// The registration pipeline shared by arnav-register and arnav-bench register:
// landmarks (paired points) -> surface rigid (ICP) -> non-rigid (tissue model), each stage
// optional, with the summaries every report needs. Frames: Model (the scene frame World)
// and Intraop (the frame of the intraoperative data). X_IntraopModel maps Model into
// Intraop. Units: mm.
#include <Eigen/Geometry>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "host/register/load_basis.hpp"
#include "host/register/nonrigid_registration.hpp"
#include "host/register/point_files.hpp"
#include "host/register/rigid_registration.hpp"
#include "host/scene/embedding.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {

// The start's uncertainty (docs/register.md, "Pose prior"). With `enabled`, every start
// carries a Gaussian prior that the surface fits use: a given pose
// (X_IntraopModel_initial: a file, or the identity for data already aligned) with the
// isotropic rotation_deg / translation_mm; the landmark fit with its covariance
// (landmark_error_mm, at least the FRE's estimate). Without a landmark fit or a given pose
// there is no prior (the identity is then only where ICP starts).
struct PosePriorOptions {
  bool enabled = false;
  double rotation_deg = 3.0;       // 1 sigma about each axis (given pose / identity)
  double translation_mm = 5.0;     // 1 sigma along each axis at the organ's centre
  double landmark_error_mm = 3.0;  // RMS 3-D landmark error for the landmark fit's covariance
  // Held supports: with a given pose (the data's frame is one where the scene's fixed
  // vertices are known: aligned data, a tracked reference) and fixed vertices in the scene,
  // the load fit's support modes get a prior of support_sigma_mm (0: not held).
  double support_sigma_mm = 2.0;
};

struct RegistrationRequest {
  Eigen::Matrix3Xd points_Intraop_mm;                 // the intraoperative surface points
  Eigen::Matrix3Xd normals_Intraop;                   // unit normals, or 0 columns
  std::vector<Landmark> landmarks;                    // empty, or >= 3
  std::optional<Eigen::Isometry3d> X_IntraopModel_initial;  // wins over the landmark fit as ICP start
  std::string initial_pose_name;                      // how the initial pose is reported ("identity", a file); empty: "initial pose"
  bool rigid_only = false;
  IcpOptions icp;
  // Non-rigid method: "loads" (load basis estimated jointly with the pose, load_basis.hpp)
  // or "energy" (paper 002's energy minimisation with the scene's tissue model,
  // nonrigid_registration.hpp). nonrigid.noise_mm, keep_fraction and max_distance_mm
  // apply to both.
  std::string nonrigid_method = "loads";
  NonrigidOptions nonrigid;
  LoadBasisOptions basis;
  // A basis built beforehand for this scene (build_load_basis: it depends only on the
  // scene, so it can be made before surgery); null: built here (timed in basis_time_s).
  std::shared_ptr<const LoadBasis> prebuilt_basis;
  LoadFitOptions loads;                               // its noise/trimming are taken from nonrigid
  PosePriorOptions prior;
  // true: nonrigid.noise_mm is replaced by the noise estimated from the points themselves
  // (estimate_point_noise_mm, floored at min_estimated_noise_mm).
  bool estimate_noise = false;
  double min_estimated_noise_mm = 0.3;
};

struct RegistrationResult {
  std::string initialisation;                         // "landmarks", "initial pose", "identity"
  std::optional<LandmarkFit> landmarks;
  IcpResult icp;                                      // termination "no data" when skipped
  Eigen::Isometry3d X_IntraopModel = Eigen::Isometry3d::Identity();  // the rigid part
  std::optional<NonrigidResult> nonrigid;             // absent with rigid_only (with "loads": the fit in its terms)
  std::optional<LoadFitResult> loads;                 // the "loads" method's own result
  int basis_modes = 0;                                // "loads": modes of the basis
  double basis_time_s = 0.0;                          // "loads": time to build the basis (in nonrigid->wall_time_s; 0 when prebuilt)
  Eigen::Matrix3Xd x_Model_mm;                        // volume positions in Model (rest when rigid)
  bool deformed = false;                              // the non-rigid result was accepted
  double wall_time_s = 0.0;
  std::vector<std::string> notes;                     // what was decided and why
  std::optional<PosePrior> prior;                     // the start's uncertainty, when enabled and known
  PosePosterior posterior;                            // of the kept pose (the stage kept)
  bool supports_held = false;                         // the load fit held the support modes
  double noise_mm = 0.0;                              // the point noise used
  bool noise_estimated = false;                       // ... estimated from the data
  std::string kept_stage = "start";                   // start | surface_rigid | nonrigid
  std::string kept_reason;                            // why that stage is the result
};

// Throws std::invalid_argument for an unknown method or model kind, or a basis that cannot be built.
RegistrationResult register_patient(const Scene& scene, const RegistrationRequest& request);

// Points given in Model at rest, embedded in the scene's volume, carried through the
// registration into Intraop.
Eigen::Matrix3Xd carry_to_intraop(const Scene& scene, const Embedding& embedding, const RegistrationResult& result);

}  // namespace arnav::host
