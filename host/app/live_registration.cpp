#include "host/app/live_registration.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

namespace arnav::host {

LiveRegistration::LiveRegistration(const LiveRegistrationSettings& settings, const Eigen::Vector3d& target_Model_mm)
    : settings_(settings), target_Model_mm_(target_Model_mm) {}

LandmarkTake LiveRegistration::take(const std::vector<TipSample>& tips, std::int64_t now_us) {
  LandmarkTake out;
  char text[256];
  if (done()) {
    out.message = "registration already complete: accept press ignored";
    return out;
  }
  const std::string& name = settings_.landmarks_Model_mm[taken_.size()].first;
  const auto window_us = static_cast<std::int64_t>(settings_.window_ms * 1000.0);
  std::int64_t newest = -1;
  std::vector<Eigen::Vector3d> in_window;
  for (const auto& t : tips) {
    if (t.arrival_us > now_us) continue;
    newest = std::max(newest, t.arrival_us);
    if (t.arrival_us >= now_us - window_us) in_window.push_back(t.p_Ref_mm);
  }
  const auto refuse = [&](const std::string& why) {
    ++refused_;
    out.message = "landmark '" + name + "' refused: " + why;
    last_error_ = why;
    return out;
  };
  if (newest < 0) return refuse("no pointer pose in Ref yet (pointer '" + settings_.pointer + "' and the reference both tracked?)");
  const double age_ms = static_cast<double>(now_us - newest) * 1e-3;
  if (age_ms > settings_.stale_after_ms) {
    std::snprintf(text, sizeof text, "pointer '%s' stale (last pose %.0f ms old, limit %.0f)", settings_.pointer.c_str(), age_ms,
                  settings_.stale_after_ms);
    return refuse(text);
  }
  if (in_window.empty()) in_window.push_back(tips.back().p_Ref_mm);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : in_window) mean += p;
  mean /= static_cast<double>(in_window.size());
  double spread = 0.0;
  for (const auto& p : in_window) spread = std::max(spread, (p - mean).norm());
  if (spread > settings_.max_motion_mm) {
    std::snprintf(text, sizeof text, "pointer moving (tip %.2f mm from its mean over %.0f ms, limit %.2f): hold it still on the landmark",
                  spread, settings_.window_ms, settings_.max_motion_mm);
    return refuse(text);
  }
  taken_.emplace_back(name, mean);
  last_error_.clear();
  out.accepted = true;
  std::snprintf(text, sizeof text, "landmark '%s' taken (%d/%d) at [%.1f, %.1f, %.1f] mm in Ref, %zu poses", name.c_str(), taken(), total(),
                mean.x(), mean.y(), mean.z(), in_window.size());
  out.message = text;
  if (taken() == total()) {
    std::vector<Landmark> pairs;
    for (std::size_t i = 0; i < taken_.size(); ++i) {
      Landmark l;
      l.name = taken_[i].first;
      l.p_Model_mm = settings_.landmarks_Model_mm[i].second;
      l.p_Intraop_mm = taken_[i].second;
      pairs.push_back(l);
    }
    try {
      fit_ = register_landmarks(pairs);
      tre_mm_ = fit_->predicted_tre_mm(target_Model_mm_, settings_.fle_mm);
      std::snprintf(text, sizeof text, "; registration done: FRE %.2f mm, predicted TRE %.2f mm at the target (FLE %.2f mm)", fre_mm(), tre_mm_,
                    settings_.fle_mm);
      out.message += text;
    } catch (const std::invalid_argument& e) {
      taken_.clear();  // start over: the touched points cannot be fitted
      out.accepted = false;
      ++refused_;
      last_error_ = e.what();
      out.message += std::string("; registration failed: ") + e.what() + " - start again from the first landmark";
    }
  }
  return out;
}

std::string LiveRegistration::status() const {
  char text[256];
  if (fit_) {
    std::snprintf(text, sizeof text, "registration: %d/%d landmarks, FRE %.2f mm, TRE %.2f mm", taken(), total(), fre_mm(), tre_mm_);
    return text;
  }
  std::snprintf(text, sizeof text, "registration: %d/%d landmarks - touch '%s' and press accept", taken(), total(),
                settings_.landmarks_Model_mm[taken_.size()].first.c_str());
  std::string s = text;
  if (!last_error_.empty()) s += " (last refused: " + last_error_.substr(0, 60) + ")";
  return s;
}

}  // namespace arnav::host
