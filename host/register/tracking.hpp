#pragma once
// Per-frame tracking after the initial registration (after paper 001): surface points
// with stable IDs (features of a stereo/depth camera, or pointer samples) pull the tissue
// model through attachments and the volume - tumour, vessels, targets - follows. A new ID
// is bound to the material point of the model surface nearest to it when first seen; a
// known ID moves its attachment's target; an ID missing from a frame lets go (its spring
// goes idle) until it comes back. One model step per frame, with the scene's own
// (real-time) model settings and damping, and no gravity change.
// Frames: points arrive in Intraop; the model lives in Model (X_IntraopModel fixed from the
// initial registration). Units: mm, s.
#include <Eigen/Geometry>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "host/scene/scene.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct TrackingOptions {
  double stiffness_per_point_mN_per_mm = 2.0;  // spring per tracked point
  double bind_distance_mm = 10.0;              // a new ID further from the surface is ignored (outlier)
  bool scene_boundary = false;                 // as NonrigidOptions::scene_boundary
  // Model settings: true (default) runs the scene's model kind with its recommended
  // real-time configuration (recommended_model_config: for the FEM, 3 PCG iterations on a
  // lagged factor refactorised in the background, applied in float), so that the update
  // fits a 60 Hz frame; false keeps the scene's own model settings as they are.
  bool realtime_model = true;
};

struct TrackingFrame {
  int tracked = 0;         // IDs pulling this frame
  int bound = 0;           // new IDs bound this frame
  int rejected = 0;        // new IDs too far from the surface
  double frame_ms = 0.0;   // whole update (binding, targets, model step)
  double model_ms = 0.0;   // of which the model step
  double bind_ms = 0.0;    // of which binding new IDs and setting targets
  bool healthy = true;
  std::string warning;
};

class SurfaceTracker {
 public:
  // x_Model_mm: the registered volume positions (Model); X_IntraopModel: the rigid part.
  SurfaceTracker(const Scene& scene, const Eigen::Matrix3Xd& x_Model_mm, const Eigen::Isometry3d& X_IntraopModel,
                 const TrackingOptions& options = {});
  // points_Intraop_mm (3 x n) with one id per column; dt_s the frame period.
  TrackingFrame update(const Eigen::Matrix3Xd& points_Intraop_mm, const std::vector<long long>& ids, double dt_s);
  const Eigen::Matrix3Xd& positions_Model_mm() const { return model_->positions_World_mm(); }
  const Eigen::Isometry3d& X_IntraopModel() const { return X_IntraopModel_; }
  std::string model_name() const { return model_->name(); }

 private:
  const Scene& scene_;
  Eigen::Isometry3d X_IntraopModel_;
  TrackingOptions options_;
  std::unique_ptr<TissueModel> model_;
  std::map<long long, AttachmentId> bound_;   // id -> attachment
  std::map<long long, bool> rejected_;        // ids refused (too far when first seen)
};

}  // namespace arnav::host
