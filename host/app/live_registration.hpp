#pragma once
// Live paired-point registration of a navigation session (session key registration.live,
// docs/overlay.md): the model-frame landmarks of a file are touched one after the other
// with the tracked pointer; each press of the accept input takes the pointer tip in Ref,
// averaged over a short window before the press, refused when the pointer is stale or was
// moving. When every landmark is taken, host/register's paired-point fit (calibration's
// Umeyama) gives X_RefModel with its FRE and Fitzpatrick's predicted TRE at the target
// (the first tumour's centroid). Frames: Ref (the patient reference tool), Model (the
// scene frame); mm.
#include <Eigen/Geometry>

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "host/app/session_config.hpp"
#include "host/register/rigid_registration.hpp"

namespace arnav::host {

struct TipSample {
  std::int64_t arrival_us = 0;   // session clock
  Eigen::Vector3d p_Ref_mm = Eigen::Vector3d::Zero();
};

struct LandmarkTake {
  bool accepted = false;
  std::string message;  // what happened, for the console and the summary
};

class LiveRegistration {
 public:
  // target_Model_mm: where the predicted TRE is reported (the tumour centroid).
  LiveRegistration(const LiveRegistrationSettings& settings, const Eigen::Vector3d& target_Model_mm);

  // An accept press at now_us with the pointer tip samples (any order) around it.
  LandmarkTake take(const std::vector<TipSample>& tips, std::int64_t now_us);

  int taken() const { return static_cast<int>(taken_.size()); }
  int total() const { return static_cast<int>(settings_.landmarks_Model_mm.size()); }
  bool done() const { return fit_.has_value(); }
  const std::optional<LandmarkFit>& fit() const { return fit_; }
  // Valid once done().
  Eigen::Isometry3d X_RefModel() const { return fit_->X_IntraopModel; }
  double fre_mm() const { return fit_ ? fit_->fit.fre_rms_mm : 0.0; }
  double predicted_tre_mm() const { return tre_mm_; }
  // "registration: 2/4 landmarks - touch 'falciform' and press accept" / "... FRE ..".
  std::string status() const;
  int refused() const { return refused_; }
  const std::vector<std::pair<std::string, Eigen::Vector3d>>& taken_points_Ref() const { return taken_; }

 private:
  LiveRegistrationSettings settings_;
  Eigen::Vector3d target_Model_mm_;
  std::vector<std::pair<std::string, Eigen::Vector3d>> taken_;
  std::optional<LandmarkFit> fit_;
  double tre_mm_ = 0.0;
  int refused_ = 0;
  std::string last_error_;
};

}  // namespace arnav::host
