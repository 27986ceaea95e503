#include "host/app/swab_registration.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "host/register/surface_index.hpp"

namespace arnav::host {
namespace {

constexpr double kKeepFraction = 0.9;      // as the ICP trims
constexpr double kMaxDistanceMm = 30.0;    // a point further from the organ is an outlier
constexpr double kMinImprovement = 0.02;   // host/register's "never worse than rigid" margin
constexpr double kMinImprovementMm = 0.02; // and at least this: a pose already on the surface is kept
constexpr double kLandmarkSlackMm = 5.0;   // landmarks may move this much (plus 3 FRE) under the refined pose

// Trimmed RMS distance of points (Model) to the surface: the closest kKeepFraction, none
// beyond kMaxDistanceMm. *within: how many lie within kMaxDistanceMm.
double trimmed_rms_mm(const SurfaceIndex& index, const Eigen::Matrix3Xd& p_Model_mm, int* within) {
  std::vector<double> d;
  d.reserve(static_cast<std::size_t>(p_Model_mm.cols()));
  for (Eigen::Index i = 0; i < p_Model_mm.cols(); ++i) {
    const SurfaceHit h = index.closest(p_Model_mm.col(i), kMaxDistanceMm);
    if (h.tri >= 0) d.push_back(h.distance_mm);
  }
  if (within) *within = static_cast<int>(d.size());
  if (d.empty()) return 0.0;
  std::sort(d.begin(), d.end());
  const auto keep = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(kKeepFraction * static_cast<double>(p_Model_mm.cols()))));
  double s = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < d.size() && i < keep; ++i, ++n) s += d[i] * d[i];
  return std::sqrt(s / static_cast<double>(n));
}

}  // namespace

SwabRegistration::SwabRegistration(const SwabRegistrationSettings& settings, Eigen::Matrix3Xd surface_Model_mm,
                                   std::vector<std::array<int, 3>> tris, const Eigen::Vector3d& target_Model_mm)
    : settings_(settings), surface_Model_mm_(std::move(surface_Model_mm)), tris_(std::move(tris)), target_Model_mm_(target_Model_mm) {
  model_extent_mm_ = bounding_extent_mm(surface_Model_mm_);
}

void SwabRegistration::begin(const Eigen::Isometry3d& X_RefModel, std::string origin,
                             std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> landmarks_Model_Ref, double landmark_fre_mm) {
  X_RefModel_start_ = X_RefModel;
  origin_ = std::move(origin);
  landmarks_ = std::move(landmarks_Model_Ref);
  landmark_fre_mm_ = landmark_fre_mm;
  started_ = true;
}

int SwabRegistration::add(const PointCloud& cloud_Ref) {
  if (!started_ || running_ || done_) {
    ignore_message(cloud_Ref.size());
    return 0;
  }
  return collector_.add(cloud_Ref);
}

std::optional<SwabJob> SwabRegistration::try_accept(std::string* refusal) {
  char text[400];
  const auto refuse = [&](const std::string& why) -> std::optional<SwabJob> {
    ++refused_presses_;
    last_press_refusal_ = why;
    if (refusal) *refusal = "swab refused: " + why;
    return std::nullopt;
  };
  if (done_) return refuse("the swab registration is already complete");
  if (running_) return refuse("the swab registration is still running");
  if (!started_) return refuse("the landmark step comes first");
  const PointCloud cloud = collector_.cloud();
  if (cloud.size() < settings_.min_points) {
    std::snprintf(text, sizeof text, "%d points from %d messages on %s, need %d: keep swabbing the organ surface (hold the swab input), then press accept",
                  cloud.size(), collector_.messages(), settings_.channel.c_str(), settings_.min_points);
    return refuse(text);
  }
  try {
    check_cloud_units(cloud, model_extent_mm_);
  } catch (const std::exception& e) {
    return refuse(std::string(e.what()) + " (check the appliance's swab tip_mm and units)");
  }
  const double extent = bounding_extent_mm(cloud.points_mm);
  if (extent < settings_.min_extent_mm) {
    std::snprintf(text, sizeof text,
                  "the swab spans only %.1f mm (need %.0f): a patch that small cannot fix the pose; swab a wider area (several regions of the organ)",
                  extent, settings_.min_extent_mm);
    return refuse(text);
  }
  SwabJob job;
  job.points_Ref_mm = cloud.points_mm;
  job.X_RefModel_start = X_RefModel_start_;
  job.landmarks_Model_Ref = landmarks_;
  job.landmark_fre_mm = landmark_fre_mm_;
  running_ = true;
  ++attempts_;
  return job;
}

SwabOutcome SwabRegistration::refine(const SwabJob& job) const {
  const auto t0 = std::chrono::steady_clock::now();
  SwabOutcome o;
  o.X_RefModel = job.X_RefModel_start;
  o.points = static_cast<int>(job.points_Ref_mm.cols());
  char text[600];
  const SurfaceIndex index(surface_Model_mm_, tris_);
  int within = 0;
  o.rms_before_mm = trimmed_rms_mm(index, job.X_RefModel_start.inverse() * job.points_Ref_mm, &within);
  const auto keep_start = [&](const std::string& why) {
    o.accepted = false;
    o.message = "swab registration: " + why + "; the " + origin_ + " pose is kept";
    o.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return o;
  };
  if (within < std::max(20, o.points / 2)) {
    std::snprintf(text, sizeof text,
                  "only %d of %d swab points lie within %.0f mm of the registered organ: the swab is not of this organ "
                  "(wrong tool, tip offset or reference?)",
                  within, o.points, kMaxDistanceMm);
    return keep_start(text);
  }
  IcpOptions icp;
  icp.keep_fraction = kKeepFraction;
  icp.max_distance_mm = kMaxDistanceMm;
  // ICP works on X_IntraopModel with Intraop = Ref.
  const IcpResult r = icp_point_to_plane(surface_Model_mm_, tris_, job.points_Ref_mm, Eigen::Matrix3Xd(3, 0), job.X_RefModel_start, icp);
  o.icp = r.summary;
  const Eigen::Isometry3d X_new = r.X_IntraopModel;
  o.rms_after_mm = trimmed_rms_mm(index, X_new.inverse() * job.points_Ref_mm, nullptr);
  const Eigen::Isometry3d delta = job.X_RefModel_start.inverse() * X_new;  // Model -> Model
  o.change_deg = rotation_angle_deg(delta);
  o.change_at_target_mm = (X_new * target_Model_mm_ - job.X_RefModel_start * target_Model_mm_).norm();
  if (!job.landmarks_Model_Ref.empty()) {
    double s = 0.0;
    for (const auto& [m, p] : job.landmarks_Model_Ref) s += (X_new * m - p).squaredNorm();
    o.landmark_rms_after_mm = std::sqrt(s / static_cast<double>(job.landmarks_Model_Ref.size()));
  }
  const std::string& term = r.summary.termination;
  if (term.rfind("too few inliers", 0) == 0 || term == "numerical failure" || term == "no data")
    return keep_start("surface ICP failed (" + term + ")");
  if (!(o.rms_before_mm - o.rms_after_mm >= std::max(kMinImprovement * o.rms_before_mm, kMinImprovementMm))) {
    std::snprintf(text, sizeof text, "the swab does not improve the fit (surface RMS %.2f -> %.2f mm, need %.0f %% and %.2f mm lower)",
                  o.rms_before_mm, o.rms_after_mm, kMinImprovement * 100.0, kMinImprovementMm);
    return keep_start(text);
  }
  if (o.change_deg > settings_.max_change_deg || o.change_at_target_mm > settings_.max_change_mm) {
    std::snprintf(text, sizeof text,
                  "the ICP moved the model %.1f deg / %.1f mm at the target (limits %.0f deg / %.0f mm): it slid to another fit; "
                  "swab more distinct regions",
                  o.change_deg, o.change_at_target_mm, settings_.max_change_deg, settings_.max_change_mm);
    return keep_start(text);
  }
  // The landmarks must still be where they were touched (within their own error plus the
  // swab's): an ICP that slid along a symmetric patch moves them away.
  const double landmark_limit = 3.0 * job.landmark_fre_mm + kLandmarkSlackMm;
  if (!job.landmarks_Model_Ref.empty() && o.landmark_rms_after_mm > landmark_limit) {
    std::snprintf(text, sizeof text, "the landmarks would lie %.1f mm RMS from where they were touched (FRE was %.2f mm, limit %.1f mm)",
                  o.landmark_rms_after_mm, job.landmark_fre_mm, landmark_limit);
    return keep_start(text);
  }
  o.accepted = true;
  o.X_RefModel = X_new;
  o.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::snprintf(text, sizeof text,
                "swab registration done: %d points (%d used, %d trimmed), surface RMS %.2f -> %.2f mm, pose changed %.2f deg / %.2f mm at the "
                "target, %d ICP iterations (%s), %.2f s",
                o.points, o.icp.points_used, o.icp.points_trimmed, o.rms_before_mm, o.rms_after_mm, o.change_deg, o.change_at_target_mm,
                o.icp.iterations, o.icp.termination.c_str(), o.wall_time_s);
  o.message = text;
  return o;
}

void SwabRegistration::finish(const SwabOutcome& outcome) {
  running_ = false;
  last_ = outcome;
  if (outcome.accepted) {
    done_ = true;
  } else {
    collector_ = PointCloudCollector("Ref");  // a new swab from scratch
  }
}

std::string SwabRegistration::status() const {
  char text[300];
  if (done_ && last_) {
    std::snprintf(text, sizeof text, "swab: %d points, surface RMS %.2f mm, moved %.1f deg / %.1f mm", last_->points, last_->rms_after_mm,
                  last_->change_deg, last_->change_at_target_mm);
    return text;
  }
  if (running_) {
    std::snprintf(text, sizeof text, "swab: registering %d points ...", collector_.points());
    return text;
  }
  std::snprintf(text, sizeof text, "swab: %d/%d points - swab the organ surface, then press accept", collector_.points(), settings_.min_points);
  std::string s = text;
  if (last_ && !last_->accepted) s += " (last swab not used)";
  else if (!last_press_refusal_.empty()) s += " (last press refused)";
  return s;
}

}  // namespace arnav::host
