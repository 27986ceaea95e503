// NavigationSession: the security banner (issue 26; docs/overlay.md, "Security banner";
// the decision itself: host/app/security_alarm.hpp). The sealed bus tells the session what
// it dropped (verdict and channel only); frames within the hold time show a SECURITY banner,
// the alert's start and end are said once each.
#include <cstdio>

#include "host/app/navigation_session.hpp"

namespace arnav::host {

namespace {

std::string hold_s(std::int64_t hold_us) {
  char s[32];
  std::snprintf(s, sizeof s, "%g s", static_cast<double>(hold_us) * 1e-6);
  return s;
}

}  // namespace

void NavigationSession::on_bus_drop(seal::Verdict verdict, const std::string& channel, std::int64_t now_us) {
  std::string over, alert;
  {
    std::lock_guard lock(security_mutex_);
    over = security_over_text(now_us);  // an alert that ended unseen (no frame since) is said first
    if (security_alarm_.on_drop(verdict, channel, now_us)) {
      ++security_alerts_;
      security_alert_open_ = true;
      alert = std::string("security: ALERT: ") + seal::to_string(verdict) + " message on " + channel +
              " rejected (not used); the overlay shows a SECURITY banner while messages are rejected";
    }
  }
  if (over.empty() && alert.empty()) return;  // the flood's usual case: no session lock
  std::lock_guard lock(mutex_);
  if (!over.empty()) say(over);
  if (!alert.empty()) say(alert);
}

std::string NavigationSession::security_over_text(std::int64_t now_us) {
  if (!security_alert_open_) return {};
  const std::optional<std::int64_t> last = security_alarm_.last_drop_us();
  if (last && now_us < *last + security_alarm_.hold_us()) return {};
  security_alert_open_ = false;
  const seal::OpenCounters& t = security_alarm_.total();
  return "security: alert over, no message rejected for " + hold_s(security_alarm_.hold_us()) + "; rejected so far " + std::to_string(t.dropped()) +
         " (forged " + std::to_string(t.forged) + ", tampered " + std::to_string(t.tampered) + ", replayed " + std::to_string(t.replayed) +
         ", stale " + std::to_string(t.stale) + ", unsealed " + std::to_string(t.unsealed) + ", malformed " + std::to_string(t.malformed) + ")";
}

void NavigationSession::security_check_over(std::int64_t now_us) {
  std::string over;
  {
    std::lock_guard lock(security_mutex_);
    over = security_over_text(now_us);
  }
  if (!over.empty()) say(over);
}

void NavigationSession::security_frame(std::int64_t now_us, std::string& flags, std::vector<std::string>& banners) {
  security_check_over(now_us);
  std::lock_guard lock(security_mutex_);
  const SecurityWindow w = security_alarm_.window_at(now_us);
  if (w.sealed_rejected() > 0) add_flag(flags, "security_rejected");
  if (w.dropped.unsealed > 0) add_flag(flags, "security_unsealed");
  banners = security_alarm_.banners_at(now_us);
}

nlohmann::json NavigationSession::security_summary() {
  std::lock_guard lock(security_mutex_);
  const seal::OpenCounters& t = security_alarm_.total();
  return {{"alerts", security_alerts_},     {"hold_s", static_cast<double>(security_alarm_.hold_us()) * 1e-6},
          {"dropped", t.dropped()},         {"forged", t.forged},
          {"tampered", t.tampered},         {"replayed", t.replayed},
          {"stale", t.stale},               {"unsealed", t.unsealed},
          {"malformed", t.malformed}};
}

}  // namespace arnav::host
