// NavigationSession: the surface swab step of a live registration
// (registration.live.swab, docs/overlay.md "Swab registration"; the refinement itself:
// host/app/swab_registration.hpp). Swab messages arrive on the LCM thread; the accept
// press (LCM thread, or the replay's) hands a snapshot to a worker thread in live
// sessions (inline in replay, so a replay registers the same way every time); the result
// is applied under the session's lock, and the next frame is drawn with it.
#include <cmath>
#include <cstdio>

#include "arnav/point_cloud_t.hpp"
#include "host/app/navigation_session.hpp"
#include "host/mesh/load_error.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::host {
namespace {

constexpr std::int64_t kReferenceBeforeUs = 100'000;  // reference poses this long before the message's first point count
constexpr std::int64_t kReferenceAfterUs = 50'000;    // ... and this long after its publication

}  // namespace

std::string NavigationSession::swab_channel() const {
  return config_.live_registration && config_.live_registration->swab ? config_.live_registration->swab->channel : std::string();
}

void NavigationSession::swab_begin_after_landmarks() {
  if (!swab_ || !live_ || !live_->done()) return;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> pairs;
  const auto& taken = live_->taken_points_Ref();
  for (std::size_t i = 0; i < taken.size(); ++i) pairs.emplace_back(config_.live_registration->landmarks_Model_mm[i].second, taken[i].second);
  swab_->begin(live_->X_RefModel(), "landmark", pairs, live_->fre_mm());
  say("swab: landmark registration done; swab the organ surface (" + swab_->settings().channel + "), then press '" +
      swab_->settings().accept_input + "' to refine it");
}

std::optional<PointCloud> NavigationSession::swab_cloud_to_Ref(const PointCloud& m, std::int64_t capture_wall_us, std::int64_t publish_wall_us,
                                                               std::string* why) {
  if (m.frame_name == "Ref") return m;
  // Another frame (Cam, Ndi): through the reference tool's poses in that frame over the
  // message's time span, which must agree (the reference did not move meanwhile).
  const std::string& ref = config_.reference->name;
  std::vector<Eigen::Isometry3d> X_RefFrame;
  if (const auto it = poses_.find(ref); it != poses_.end())
    for (const auto& s : it->second.recent)
      if (s.msg.status == tool_pose_t::STATUS_VALID && s.msg.frame_parent == m.frame_name &&
          s.msg.receive_time_wall_us >= capture_wall_us - kReferenceBeforeUs && s.msg.receive_time_wall_us <= publish_wall_us + kReferenceAfterUs)
        X_RefFrame.push_back(get_pose(s.msg).inverse());
  if (X_RefFrame.empty()) {
    *why = "no pose of the reference '" + ref + "' in frame '" + m.frame_name +
           "' around the message's time (the reference hidden while swabbing?): its points are not used";
    return std::nullopt;
  }
  PointCloud out = m;
  out.frame_name = "Ref";
  out.normals.resize(3, 0);
  double spread = 0.0;
  for (int i = 0; i < m.size(); ++i) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& X : X_RefFrame) mean += X * m.points_mm.col(i);
    mean /= static_cast<double>(X_RefFrame.size());
    for (const auto& X : X_RefFrame) spread = std::max(spread, (X * m.points_mm.col(i) - mean).norm());
    out.points_mm.col(i) = mean;
  }
  if (m.has_normals()) {
    out.normals = m.normals;
    for (int i = 0; i < m.size(); ++i) out.normals.col(i) = (X_RefFrame.front().linear() * m.normals.col(i)).normalized();
  }
  if (spread > config_.live_registration->swab->max_reference_motion_mm) {
    char text[300];
    std::snprintf(text, sizeof text,
                  "the reference '%s' moved %.1f mm (limit %.1f) while the message's points were taken in frame '%s': its points are not used",
                  ref.c_str(), spread, config_.live_registration->swab->max_reference_motion_mm, m.frame_name.c_str());
    *why = text;
    return std::nullopt;
  }
  return out;
}

void NavigationSession::on_cloud(const void* data, std::size_t size, const std::string& channel, std::int64_t now_us) {
  (void)now_us;
  std::lock_guard lock(mutex_);
  if (!swab_ || channel != swab_->settings().channel) return;
  PointCloud cloud;
  point_cloud_t raw;
  try {
    cloud = decode_point_cloud_message(data, size, channel);  // checks every count before decoding
    raw.decode(data, 0, static_cast<int>(size));              // the time stamps (already checked to decode)
  } catch (const LoadError& e) {
    ++swab_corrupt_messages_;
    if (swab_reported_.insert("corrupt").second) say(std::string("swab: message refused: ") + e.what());
    return;
  }
  if (!swab_->started() || swab_->running() || swab_->done()) {
    swab_->ignore_message(cloud.size());
    return;
  }
  std::string why;
  const std::optional<PointCloud> in_Ref = swab_cloud_to_Ref(cloud, raw.capture_time_wall_us, raw.publish_time_wall_us, &why);
  if (!in_Ref) {
    swab_->refuse_message(why);
    if (swab_reported_.insert(why.substr(0, 24)).second) say("swab: message " + std::to_string(cloud.sequence) + " refused: " + why);
    return;
  }
  const int before = swab_->points();
  swab_->add(*in_Ref);
  const int min = swab_->settings().min_points;
  if (before == 0 && swab_->points() > 0) say("swab: receiving points on " + channel);
  if (before < min && swab_->points() >= min)
    say("swab: " + std::to_string(swab_->points()) + " points collected (enough): press '" + swab_->settings().accept_input +
        "' to register, or keep swabbing");
}

void NavigationSession::swab_accept(std::int64_t now_us) {
  (void)now_us;
  std::string refusal;
  std::optional<SwabJob> job = swab_->try_accept(&refusal);
  if (!job) {
    say(refusal);
    return;
  }
  say("swab: registering " + std::to_string(job->points_Ref_mm.cols()) + " points (" + swab_->collector().summary() + ") from the " +
      swab_->origin() + " pose");
  if (!options_.threaded) {
    swab_apply(swab_->refine(*job));
    return;
  }
  // A previous worker has finished (the step was not running): join it before the next.
  if (swab_thread_.joinable()) swab_thread_.join();
  swab_thread_ = std::thread([this, job = std::move(*job)] {
    SwabOutcome o;
    try {
      o = swab_->refine(job);
    } catch (const std::exception& e) {
      o.accepted = false;
      o.X_RefModel = job.X_RefModel_start;
      o.message = std::string("swab registration failed: ") + e.what() + "; the pose is kept";
    }
    std::lock_guard lock(mutex_);
    swab_apply(o);
  });
}

void NavigationSession::swab_apply(const SwabOutcome& o) {
  swab_->finish(o);
  say(o.accepted ? o.message : o.message + " - swab again and press accept to retry");
  if (o.accepted) {
    X_RefModel_ = o.X_RefModel;
    registration_changed_ = true;
  }
}

nlohmann::json NavigationSession::swab_summary() {
  const SwabRegistration& s = *swab_;
  std::vector<double> in_use;  // the registration in use now (landmark/prior pose, or the swab's)
  if (X_RefModel_)
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) in_use.push_back(X_RefModel_->matrix()(r, c));
  nlohmann::json j = {{"channel", s.settings().channel},
                      {"accept", s.settings().accept_input},
                      {"method", s.settings().method},
                      {"from", s.origin()},
                      {"started", s.started()},
                      {"done", s.done()},
                      {"attempts", s.attempts()},
                      {"refused_presses", s.refused_presses()},
                      {"points_collected", s.points()},
                      {"messages", s.collector().messages()},
                      {"messages_lost", s.collector().missed()},
                      {"messages_refused", s.refused_messages()},
                      {"messages_corrupt", swab_corrupt_messages_},
                      {"messages_ignored", s.ignored_messages()},
                      {"last_refusal", s.last_refusal()},
                      {"X_RefModel_in_use", in_use}};
  if (const auto& o = s.last_outcome()) {
    std::vector<double> m;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m.push_back(o->X_RefModel.matrix()(r, c));
    j["result"] = {{"accepted", o->accepted},
                   {"message", o->message},
                   {"points", o->points},
                   {"points_used", o->icp.points_used},
                   {"points_trimmed", o->icp.points_trimmed},
                   {"surface_rms_before_mm", o->rms_before_mm},
                   {"surface_rms_after_mm", o->rms_after_mm},
                   {"change_deg", o->change_deg},
                   {"change_at_target_mm", o->change_at_target_mm},
                   {"landmark_rms_after_mm", o->landmark_rms_after_mm},
                   {"icp_iterations", o->icp.iterations},
                   {"icp_termination", o->icp.termination},
                   {"wall_time_s", o->wall_time_s},
                   {"X_RefModel", m}};
  }
  return j;
}

std::string format_swab_summary(const nlohmann::json& s) {
  char line[400];
  if (s.contains("result") && s["result"]["accepted"].get<bool>()) {
    const auto& r = s["result"];
    std::snprintf(line, sizeof line,
                  "  swab (%s, from the %s pose): %d points, surface RMS %.2f -> %.2f mm, pose changed %.2f deg / %.2f mm at the tumour, "
                  "%d ICP iterations, %.2f s\n",
                  s["method"].get<std::string>().c_str(), s["from"].get<std::string>().c_str(), r["points"].get<int>(),
                  r["surface_rms_before_mm"].get<double>(), r["surface_rms_after_mm"].get<double>(), r["change_deg"].get<double>(),
                  r["change_at_target_mm"].get<double>(), r["icp_iterations"].get<int>(), r["wall_time_s"].get<double>());
    return line;
  }
  std::string out;
  std::snprintf(line, sizeof line, "  swab: not applied (%d points collected, %d attempt(s), %d press(es) refused)\n",
                s["points_collected"].get<int>(), s["attempts"].get<int>(), s["refused_presses"].get<int>());
  out = line;
  if (s.contains("result")) out += "    last: " + s["result"]["message"].get<std::string>() + "\n";
  return out;
}

}  // namespace arnav::host
